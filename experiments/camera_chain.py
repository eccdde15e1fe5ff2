"""One differentiable chain from a calibrated camera to a photographed object.

    python -m experiments.camera_chain --config configs/camera_chain.yaml --out out/camera_chain

1. Calibration: a bracket of a synthetic HDR chart (``jaxgfx.hdr.synthetic_radiance``) through
   a hostile measured-like curve (``jaxgfx.hdr.synthetic_response("camera")``: toe, shoulder,
   sRGB encoding), shot and read noise, clipped highlights, 8-bit JPEG
   (``jaxgfx.hdr.make_jpeg_stack``), written as JPEG files and calibrated by the calibrate job
   (``jaxgfx calibrate``, :func:`jaxgfx.pipelines.calibrate.run_calibrate`) -> ``report.json``.
2. Targets: the two-sphere scene (configs/scenes/inverse.yaml) photographed through the same
   camera at three exposures (shot + read noise, clipping, 8-bit JPEG).
3. The same roughness + albedo fit (``jaxgfx fit``, one compiled program for all four) under
   four cameras: ``true_camera`` (the true curve and exposure), ``calibrated`` (the response
   loaded from report.json with ``camera.response.from``, the exposure fitted),
   ``joint`` (a free-form monotone response and the exposure fitted with the materials; the
   photos' exposure ratios given, as EXIF gives them; ``fit.free_curve.init: bracket`` starts
   the curve from the response recovered from the target photos themselves, recorded as
   ``start_response_error``), ``srgb`` (assumed sRGB, exposure fitted).

Writes ``summary.json`` (per variant: fitted values, errors, the response's error against the
true curve over levels 10-245, seconds) and ``chain.png`` (parameter error against seconds),
each fit's own outputs in ``fit_<variant>/`` and the calibration in ``calibrate/``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from jaxgfx.config import read_yaml

VARIANTS = ("true_camera", "calibrated", "joint", "srgb")


DORF = os.path.join(
    os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
    "tests",
    "data",
    "dorf",
    "ektachrome320t.crf",
)


def true_response(curve, base_dir: str):
    """The camera's true response, 3 channels: a ``jaxgfx.hdr.synthetic_response`` name
    (``"camera"``: the analytic hostile curve) or ``{dorf: path}``: the measured curves of a
    DoRF file (``hdr.read_dorf_curves``; its first three curves as R, G, B, e.g. Ektachrome
    320T's red, green and blue; a one-curve file is used for all three channels) through
    ``hdr.response_from_curve``. A relative path is relative to the config's folder."""
    from jaxgfx import hdr

    if isinstance(curve, str):
        return hdr.synthetic_response(curve, channels=3)
    if not isinstance(curve, dict) or set(curve) != {"dorf"}:
        raise ValueError(
            f"calibration.curve: expected a response name or {{dorf: path}}, got {curve!r}"
        )
    path = curve["dorf"]
    path = path if os.path.isabs(path) else os.path.normpath(os.path.join(base_dir, path))
    curves = list(hdr.read_dorf_curves(path).values())
    curves = (curves * 3)[:3] if len(curves) == 1 else curves[:3]
    if len(curves) != 3:
        raise ValueError(f"calibration.curve.dorf: {path}: expected 1 or >= 3 curves")
    irr = np.stack([c[0] for c in curves], axis=1)
    bri = np.stack([c[1] for c in curves], axis=1)
    return hdr.response_from_curve(irr, bri)


def calibrate(cal: dict, out: str, overwrite: bool, resp=None, seed: int = 0) -> str:
    """Write the bracket (through ``resp``, default ``cal["curve"]``) as PNG files, run the
    calibrate job; returns its report.json."""
    import jax
    from PIL import Image

    from jaxgfx import hdr
    from jaxgfx.pipelines.calibrate import CalibrateConfig, CalibrateJob, run_calibrate

    key = jax.random.key(int(cal["seed"]) + 1000 * int(seed))
    n = int(cal["size"])
    rad = hdr.synthetic_radiance(key, n, n, dynamic_range=float(cal["dynamic_range"]))
    times = np.asarray(cal["exposure_times"], np.float32)
    st = hdr.make_jpeg_stack(
        jax.random.fold_in(key, 1),
        rad,
        times,
        cal["curve"] if resp is None else resp,
        gain=float(cal["gain"]),
        read_sigma=float(cal["read_sigma"]),
        quality=int(cal["jpeg_quality"]),
    )
    folder = os.path.join(out, "bracket")
    os.makedirs(folder, exist_ok=True)
    for j, img in enumerate(np.asarray(st.images)):
        # the frames are already JPEG-decoded; saving them losslessly as PNG keeps exactly
        # those codes (a second JPEG pass would compress twice)
        Image.fromarray(img).save(os.path.join(folder, f"frame_{j}.png"))
    from jaxgfx.config import load_config

    cfg = load_config(
        CalibrateConfig,
        {
            "exposure_times": [float(t) for t in times],
            "response": {"method": cal["method"], "compare": [cal["method"]]},
        },
    )
    run_calibrate(
        CalibrateJob(cfg, (folder,), os.path.join(out, "calibrate"), overwrite, progress=False)
    )
    return os.path.join(out, "calibrate", "report.json")


def _set(desc: dict, path: str, value) -> None:
    """Set ``desc``'s entry at a fit parameter path (``materials.clay.reflectance``)."""
    *keys, last = path.split(".")
    d = desc
    for k in keys:
        d = d[k]
    d[last] = value


def linear_target(fit: dict, base_dir: str, seed: int, renderer: str) -> np.ndarray:
    """The scene with the true materials, ``(H, W, 3)`` linear radiance at the fit's size:
    rendered by Mitsuba 3 (``renderer="mitsuba"``: the same scene description through
    ``to_mitsuba_dict`` (``render_mitsuba``, ``scalar_rgb``, its ``path`` integrator at the
    fit's depth, ``fit.target_spp``, sampler seed ``seed``) or by jaxgfx (``"jaxgfx"``: the
    fit's own synthetic target render, key ``seed``)."""
    from jaxgfx.config import read_yaml

    r = fit["render"]
    if renderer == "mitsuba":
        from jaxgfx.render.scene.mitsuba import render_mitsuba

        scene = os.path.join(base_dir, fit["scene"])
        desc = read_yaml(scene)
        for k, v in fit["truth"].items():
            _set(desc, k, v)
        desc["camera"] = dict(desc["camera"], width=int(r["width"]), height=int(r["height"]))
        return render_mitsuba(
            desc,
            spp=int(fit["target_spp"]),
            integrator=r["integrator"],
            max_depth=int(r.get("max_depth", 3)),
            seed=int(seed),
            base_dir=os.path.dirname(scene),
        )
    if renderer != "jaxgfx":
        raise ValueError(f"fit.targets: expected 'mitsuba' or 'jaxgfx', got {renderer!r}")
    from jaxgfx.config import load_config
    from jaxgfx.pipelines.fit import FitConfig, prepare_fit
    from jaxgfx.pipelines.fit.job import _target

    cfg = load_config(
        FitConfig,
        {
            "scene": fit["scene"],
            "params": fit["params"],
            "render": fit["render"],
            "target": {"synthetic": fit["truth"], "spp": int(fit["target_spp"]), "seed": int(seed)},
        },
    )
    return np.asarray(_target(cfg, prepare_fit(cfg, base_dir=base_dir))[1], np.float32)


def chroma_edge_mask(codes: np.ndarray, threshold: float, radius: int) -> np.ndarray:
    """``(H, W)`` 0/1: 0 where a photo's decoded chroma (Cb, Cr of JFIF / BT.601, in codes)
    spans more than ``threshold`` codes over the ``(2 radius + 1)²`` window around the pixel —
    where the JPEG codec's 4:2:0 chroma (one sample per 2×2 pixels, upsampled over its
    neighbours) mixes two surfaces. Computed from the photo alone (no truth)."""
    from scipy.ndimage import maximum_filter, minimum_filter

    x = codes.astype(np.float64)
    y = 0.299 * x[..., 0] + 0.587 * x[..., 1] + 0.114 * x[..., 2]
    span = np.zeros(y.shape)
    for c in (0.564 * (x[..., 2] - y), 0.713 * (x[..., 0] - y)):
        w = 2 * radius + 1
        span = np.maximum(span, maximum_filter(c, w) - minimum_filter(c, w))
    return (span <= threshold).astype(np.uint8)


def photos(img: np.ndarray, tc: dict, resp, seed: int, out: str, edge_mask=None) -> list:
    """``img`` photographed at each exposure of ``tc`` (``exposure`` × ``exposures``) through a
    :class:`jaxgfx.hdr.Camera` with response ``resp``, shot and read noise (``tc.noise``),
    clipping, 8 bits, then ``tc.jpeg`` (Pillow, 4:2:0); written as PNG (the decoded codes) under
    ``out``: the fit's target list ``[{file, exposure}]``. ``edge_mask`` ``{threshold,
    radius}``: each photo's :func:`chroma_edge_mask` is written as its alpha channel (alpha 0:
    the pixel does not count in the fit)."""
    import jax
    import jax.numpy as jnp

    from jaxgfx.hdr import Camera, NoiseModel, jpeg_roundtrip
    from jaxgfx.io import write_png

    n = tc.get("noise") or {}
    noise = NoiseModel(
        jnp.full((3,), float(n.get("gain", 0.0)), jnp.float32),
        jnp.full((3,), float(n.get("read_sigma", 0.0)) ** 2, jnp.float32),
    )
    key = jax.random.fold_in(jax.random.key(int(seed)), 1)
    ex = [float(tc["exposure"]) * float(r) for r in tc["exposures"]]
    codes = np.stack(
        [
            np.asarray(
                Camera(resp, jnp.asarray(e, jnp.float32), noise=noise, bits=8).capture(
                    jnp.asarray(img), jax.random.fold_in(key, j)
                ),
                np.uint8,
            )
            for j, e in enumerate(ex)
        ]
    )
    if tc.get("jpeg") is not None:
        codes = jpeg_roundtrip(codes, quality=int(tc["jpeg"]))
    os.makedirs(out, exist_ok=True)
    target = []
    for j, e in enumerate(ex):
        path = os.path.abspath(os.path.join(out, f"photo_{j}.png"))
        q = np.asarray(codes[j], np.uint8)
        if edge_mask:
            m = chroma_edge_mask(q, float(edge_mask["threshold"]), int(edge_mask["radius"]))
            q = np.concatenate([q, (255 * m)[..., None].astype(np.uint8)], axis=-1)
        write_png(path, q)
        target.append({"file": path, "exposure": e})
    return target


def camera_for(variant: str, fit: dict, report: str, true_file: str) -> dict:
    clip = {"clip_code": int(fit["clip_code"])} if fit.get("clip_code") is not None else {}
    if fit.get("clipped") is not None:
        clip["clipped"] = fit["clipped"]
    return dict(_camera_for(variant, fit, report, true_file), **clip)


def _camera_for(variant: str, fit: dict, report: str, true_file: str) -> dict:
    tc = fit["camera"]
    if variant == "true_camera":
        # camera.exposure is the first photo's (the others are at their given ratios)
        e0 = float(tc["exposure"]) * float(tc.get("exposures", [1.0])[0])
        return {"response": {"from": true_file}, "exposure": {"init": e0}}
    fitted = {"exposure": {"init": 1.0, "fit": True, "auto": bool(fit.get("auto_exposure"))}}
    wb = fit.get("white_balance")
    if wb is True or (isinstance(wb, (list, tuple)) and variant in wb):
        fitted["white_balance"] = {"init": [1.0, 1.0, 1.0], "fit": True}
    if variant == "calibrated":
        return {"response": {"from": report}, **fitted}
    if variant == "joint":
        fc = fit["free_curve"]
        return {"response": {"model": "table", "fit": True, **fc}, **fitted}
    return {"response": {"model": "srgb"}, **fitted}


def response_errors(resp, truth) -> dict:
    """ln-exposure error of ``resp`` against ``truth`` over levels 10-245 after the best
    constant offset per channel: RMS (``jaxgfx.hdr.response_curve_error``) and max."""
    import jax.numpy as jnp

    from jaxgfx import hdr

    zn = jnp.asarray(np.arange(10, 246) / 255.0, jnp.float32)[:, None]
    a = np.log(np.asarray(resp.to_linear_normalized(jnp.broadcast_to(zn, (236, resp.channels)))))
    b = np.log(np.asarray(truth.to_linear_normalized(jnp.broadcast_to(zn, (236, truth.channels)))))
    d = a - b
    d = d - d.mean(axis=0, keepdims=True)
    return {
        "rms_ln": float(hdr.response_curve_error(resp, truth)),
        "max_ln": float(np.max(np.abs(d))),
    }


def start_curve(curve_init: dict, target: list, fc: dict):
    """The free-form curve a ``camera.response.init: bracket`` fit started from: the
    recovered response (``curve_init.method``) of the photos ``curve_init.photos`` of
    ``target`` at their relative exposures, on the fit's knots (``free_init``)."""
    import jax.numpy as jnp

    from jaxgfx import hdr
    from jaxgfx.io import read_image
    from jaxgfx.pipelines.fit.camera import free_init, free_response

    codes = np.stack([read_image(target[i]["file"])[..., :3] for i in curve_init["photos"]])
    resp = hdr.recover_response(
        codes,
        np.asarray(curve_init["exposures"]),
        method=curve_init["method"],
        **curve_init.get("options", {}),
    )
    u = free_init(resp, int(fc.get("knots", 33)), int(fc.get("channels", 1)))
    return free_response(jnp.asarray(u))


def compare_starts(specs: str, target: list, truth, knots: int) -> list:
    """The response each recovery method gives from the target photos at their relative
    exposures (what ``camera.response.init: bracket`` would start from), against the truth
    over levels 10-245: as recovered and on ``knots`` free-curve knots (``free_init``).
    ``specs``: ``;``-separated ``method`` or ``method:option=value,...`` (e.g.
    ``debevec;subspace:n_poly=1``)."""
    import jax.numpy as jnp

    from jaxgfx import hdr
    from jaxgfx.io import read_image
    from jaxgfx.pipelines.fit.camera import free_init, free_response

    codes = np.stack([read_image(t["file"])[..., :3] for t in target])
    times = np.asarray([t["exposure"] for t in target], np.float64)
    rows = []
    for spec in specs.split(";"):
        method, _, opts = spec.partition(":")
        options = {k: int(v) if v.isdigit() else float(v) for k, v in
                   (kv.split("=") for kv in opts.split(",") if kv)}  # fmt: skip
        resp = hdr.recover_response(codes, times, method=method, **options)
        on_knots = free_response(jnp.asarray(free_init(resp, knots, 3)))
        rows.append(
            {
                "spec": spec,
                "recovered": response_errors(resp, truth),
                "on_knots": response_errors(on_knots, truth),
            }
        )
    return rows


def errors_vs_time(result: dict, truth: dict):
    """(seconds, alpha relative error, albedo max error) per step."""
    a = np.asarray(result["history"]["materials.metal.alpha"], np.float64)
    rho = np.asarray(result["history"]["materials.clay.reflectance"], np.float64)
    t_alpha = float(truth["materials.metal.alpha"])
    t_rho = np.asarray(truth["materials.clay.reflectance"], np.float64)
    secs = np.concatenate([[0.0], np.cumsum(result["seconds_history"])])
    return secs, np.abs(a - t_alpha) / t_alpha, np.max(np.abs(rho - t_rho), axis=-1)


COLORS = {"true_camera": "C0", "calibrated": "C1", "joint": "C2", "srgb": "C3"}


def plot(path, results: dict, truth: dict) -> None:
    """``results``: ``{variant: [fit result per seed]}``; one line per seed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for name, runs in results.items():
        for i, res in enumerate(runs):
            s, ea, er = errors_vs_time(res, truth)
            kw = {
                "color": COLORS.get(name),
                "lw": 1.0,
                "alpha": 0.8,
                "label": name if i == 0 else None,
            }
            axes[0].semilogy(s, np.maximum(ea, 1e-4), **kw)
            axes[1].semilogy(s, np.maximum(er, 1e-4), **kw)
    axes[0].axhline(0.05, color="k", ls="--", lw=0.8)
    axes[0].axhline(0.10, color="k", ls=":", lw=0.8)
    axes[1].axhline(0.03, color="k", ls="--", lw=0.8)
    axes[1].axhline(0.05, color="k", ls=":", lw=0.8)
    axes[0].set_ylabel("|alpha - truth| / truth")
    axes[1].set_ylabel("clay albedo: max |error|")
    for ax in axes:
        ax.set_xlabel("seconds of fit steps (after compilation)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(
        "material error against time by the camera the fit assumes, one line per seed "
        "(dashed / dotted: the calibrated / joint targets)",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def mean_sd(xs) -> list:
    x = np.asarray(xs, np.float64)
    return [float(x.mean()), float(x.std(ddof=1)) if x.size > 1 else 0.0]


def finish(summary: dict, results: dict, truth: dict, out: str, plot_it: bool = True) -> None:
    """Mean ± sd over the seeds per variant into ``summary``; write summary.json and chain.png."""
    summary["mean_sd"] = {
        v: {
            "alpha_rel_error": mean_sd([e["alpha_rel_error"] for e in runs]),
            "albedo_max_error": mean_sd([e["errors"]["materials.clay.reflectance"] for e in runs]),
            "response_max_ln": mean_sd([e["response_error"]["max_ln"] for e in runs]),
            "response_rms_ln": mean_sd([e["response_error"]["rms_ln"] for e in runs]),
            **(
                {
                    "start_response_max_ln": mean_sd(
                        [e["start_response_error"]["max_ln"] for e in runs]
                    ),
                    "start_response_rms_ln": mean_sd(
                        [e["start_response_error"]["rms_ln"] for e in runs]
                    ),
                }
                if all("start_response_error" in e for e in runs) and runs
                else {}
            ),
            "alpha": mean_sd([e["params"]["materials.metal.alpha"] for e in runs]),
            "albedo": [
                mean_sd(c)
                for c in zip(
                    *[e["params"]["materials.clay.reflectance"] for e in runs], strict=True
                )
            ],
        }
        for v, runs in summary["runs"].items()
    }
    summary["calibration_mean_sd"] = {
        k: mean_sd([c["response"][k] for c in summary["calibration"]]) for k in ("rms_ln", "max_ln")
    }
    print("mean_sd", json.dumps(summary["mean_sd"], indent=1), flush=True)
    with open(os.path.join(out, "summary.json"), "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=1)
    if plot_it:
        plot(os.path.join(out, "chain.png"), results, truth)


def merge(dirs: list, out: str) -> None:
    """One summary and plot from several runs' folders (e.g. some variants run apart): their
    ``summary.json`` runs and each fit's ``result.json`` history, seeds in order."""
    summary, results = None, {}
    for d in dirs:
        with open(os.path.join(d, "summary.json"), encoding="utf-8") as f:
            s = json.load(f)
        if summary is None:
            summary = dict(s, runs={}, merged_from=[])
        summary["merged_from"].append(os.path.abspath(d))
        for v, runs in s["runs"].items():
            summary["runs"][v] = runs
            results[v] = []
            for e in runs:
                with open(os.path.join(d, f"seed{e['seed']}", f"fit_{v}", "result.json")) as f:
                    results[v].append(json.load(f))
    os.makedirs(out, exist_ok=True)
    finish(summary, results, summary["truth"], out)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default="configs/camera_chain.yaml")
    p.add_argument("--out", default="out/camera_chain")
    p.add_argument("--steps", type=int, default=None)
    p.add_argument("--variants", default=None)
    p.add_argument("--seeds", default=None, help="override fit.seeds, e.g. 0,1,2")
    p.add_argument("--size", type=int, default=None, help="override the fit's render size")
    p.add_argument("--spp", type=int, default=None, help="override the fit's render.spp")
    p.add_argument(
        "--targets",
        default=None,
        choices=("mitsuba", "jaxgfx"),
        help="override fit.targets (the renderer of the photos)",
    )
    p.add_argument(
        "--curve",
        default=None,
        help="override calibration.curve: a synthetic_response name or 'dorf'",
    )
    p.add_argument(
        "--white-balance",
        default=None,
        help="override fit.white_balance: on | off | the variants that fit it (a,b)",
    )
    p.add_argument(
        "--free-curve",
        default=None,
        help="override fit.free_curve keys, e.g. init=1.6,smoothness=0.01 or "
        "init_method=subspace,init_options.n_poly=1",
    )
    p.add_argument(
        "--edge-mask",
        default=None,
        help="override fit.edge_mask: THRESHOLD,RADIUS (codes, pixels) or off",
    )
    p.add_argument("--drop", default="", help="fit.camera keys to remove (jpeg,noise)")
    p.add_argument("--jpeg-chroma", default=None, help="override fit.loss.jpeg_chroma")
    p.add_argument(
        "--clip-code",
        type=int,
        default=None,
        help="override fit.clip_code (codes >= it are censored; 255: none)",
    )
    p.add_argument(
        "--auto-exposure",
        default=None,
        choices=("on", "off"),
        help="override fit.auto_exposure (camera.exposure.auto of the fitted ones)",
    )
    p.add_argument(
        "--clipped",
        default=None,
        choices=("bound", "unmeasured"),
        help="override fit.clipped (camera.clipped of every fit)",
    )
    p.add_argument(
        "--starts",
        default=None,
        help="also compare the curves recovery methods give from each seed's photos, e.g. "
        "'debevec;subspace:n_poly=1' (--variants none: only that)",
    )
    p.add_argument("--no-plot", action="store_true")
    p.add_argument(
        "--merge", default=None, help="DIR,DIR,...: one summary and plot of these runs in --out"
    )
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--quiet", action="store_true")
    a = p.parse_args(argv)
    if a.merge:
        merge(a.merge.split(","), a.out)
        return 0

    from jaxgfx import hdr
    from jaxgfx.pipelines.fit import FitJob, enable_compilation_cache, run_fit

    enable_compilation_cache()
    base = read_yaml(a.config)
    base_dir = os.path.dirname(os.path.abspath(a.config))
    fit = base["fit"]
    cal = base["calibration"]
    if a.clip_code is not None:
        fit["clip_code"] = a.clip_code
    if a.clipped is not None:
        fit["clipped"] = a.clipped
    if a.auto_exposure is not None:
        fit["auto_exposure"] = a.auto_exposure == "on"
    if a.white_balance is not None:
        wb = a.white_balance
        fit["white_balance"] = wb == "on" if wb in ("on", "off") else wb.split(",")
    if a.free_curve:
        for kv in a.free_curve.split(","):
            k, v = kv.split("=")
            try:
                v = float(v) if "." in v else int(v)
            except ValueError:
                pass
            fc = fit["free_curve"] = dict(fit["free_curve"])
            if "." in k:  # a nested key, e.g. init_options.n_poly=1
                k, sub = k.split(".", 1)
                fc[k] = dict(fc.get(k) or {}, **{sub: v})
            else:
                fc[k] = v
    if a.edge_mask is not None:
        fit["edge_mask"] = (
            None
            if a.edge_mask == "off"
            else dict(zip(("threshold", "radius"), map(float, a.edge_mask.split(",")), strict=True))
        )
    drop = [k for k in a.drop.split(",") if k]
    fit["camera"] = {k: v for k, v in fit["camera"].items() if k not in drop}
    if a.targets is not None:
        fit["targets"] = a.targets
    if a.curve is not None:
        cal["curve"] = {"dorf": DORF} if a.curve == "dorf" else a.curve
    if a.size is not None:
        fit["render"] = dict(fit["render"], width=a.size, height=a.size)
    if a.spp is not None:
        fit["render"] = dict(fit["render"], spp=a.spp)
    if a.jpeg_chroma is not None:
        fit["loss"] = dict(fit.get("loss") or {}, jpeg_chroma=a.jpeg_chroma)
    seeds = [int(x) for x in a.seeds.split(",")] if a.seeds else list(fit.get("seeds", [0]))
    renderer = fit.get("targets", "jaxgfx")
    os.makedirs(a.out, exist_ok=True)
    true_resp = true_response(cal["curve"], base_dir)
    true_file = os.path.abspath(
        hdr.save_response(os.path.join(a.out, "true_response.json"), true_resp)
    )
    variants = a.variants.split(",") if a.variants else base.get("variants", VARIANTS)
    variants = [] if variants == ["none"] else variants
    summary = {
        "curve": cal["curve"],
        "targets": renderer,
        "seeds": seeds,
        "size": [int(fit["render"]["width"]), int(fit["render"]["height"])],
        "render": fit["render"],
        "loss": fit.get("loss"),
        "truth": fit["truth"],
        "truth_camera": fit["camera"],
        "clip_code": fit.get("clip_code"),
        "clipped": fit.get("clipped", "bound"),
        "auto_exposure": bool(fit.get("auto_exposure")),
        "white_balance": fit.get("white_balance"),
        "dropped": drop,
        "edge_mask": fit.get("edge_mask"),
        "runs": {v: [] for v in variants},
        "calibration": [],
    }
    results = {v: [] for v in variants}
    for seed in seeds:
        sd = os.path.join(a.out, f"seed{seed}")
        report = os.path.abspath(calibrate(cal, sd, a.overwrite, true_resp, seed))
        cal_err = response_errors(hdr.load_response(report, bits=8), true_resp)
        summary["calibration"].append({"seed": seed, "report": report, "response": cal_err})
        print("seed", seed, "calibrated response", json.dumps(cal_err), flush=True)
        img = linear_target(fit, base_dir, seed, renderer)
        target = photos(
            img, fit["camera"], true_resp, seed, os.path.join(sd, "photos"), fit.get("edge_mask")
        )
        if a.starts:
            knots = int(fit["free_curve"].get("knots", 33))
            rows = compare_starts(a.starts, target, true_resp, knots)
            summary.setdefault("starts", []).append({"seed": seed, "knots": knots, "rows": rows})
            for r in rows:
                print("seed", seed, "start", json.dumps(r), flush=True)
        for v in variants:
            cfg = {
                "scene": fit["scene"],
                "target": target,
                "params": fit["params"],
                "camera": camera_for(v, fit, report, true_file),
                "optimizer": dict(fit["optimizer"], **({"steps": a.steps} if a.steps else {})),
                "render": fit["render"],
                "loss": fit.get("loss") or {},
                "seed": int(seed),
                "progress": not a.quiet,
            }
            out = run_fit(
                FitJob.load(
                    cfg, os.path.join(sd, f"fit_{v}"), base_dir=base_dir, overwrite=a.overwrite
                )
            )
            results[v].append(out)
            # photo files carry no truth: the errors against fit.truth (max abs per parameter)
            errors = {
                k: float(
                    np.max(
                        np.abs(np.asarray(out["params"][k], np.float64) - np.asarray(t, np.float64))
                    )
                )
                for k, t in fit["truth"].items()
            }
            entry = {
                "seed": seed,
                "params": out["params"],
                "errors": errors,
                "alpha_rel_error": errors["materials.metal.alpha"]
                / float(fit["truth"]["materials.metal.alpha"]),
                "camera": out["camera"],
                "seconds": out["seconds"],
                "compile_seconds": out["compile_seconds"],
                "load_average": list(os.getloadavg()),
            }
            resp = hdr.load_response(os.path.join(sd, f"fit_{v}", "response.json"), bits=8)
            entry["response_error"] = response_errors(resp, true_resp)
            if (out["camera"] or {}).get("curve_init"):
                entry["start_response_error"] = response_errors(
                    start_curve(out["camera"]["curve_init"], target, fit["free_curve"]), true_resp
                )
            summary["runs"][v].append(entry)
            print(v, json.dumps(entry), flush=True)
    finish(summary, results, fit["truth"], a.out, plot_it=not a.no_plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
