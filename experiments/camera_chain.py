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
   photos' exposure ratios given, as EXIF gives them), ``srgb`` (assumed sRGB, exposure
   fitted).

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


def calibrate(cal: dict, out: str, overwrite: bool) -> str:
    """Write the bracket as JPEG files, run the calibrate job; returns its report.json."""
    import jax
    from PIL import Image

    from jaxgfx import hdr
    from jaxgfx.pipelines.calibrate import CalibrateConfig, CalibrateJob, run_calibrate

    key = jax.random.key(int(cal["seed"]))
    n = int(cal["size"])
    rad = hdr.synthetic_radiance(key, n, n, dynamic_range=float(cal["dynamic_range"]))
    times = np.asarray(cal["exposure_times"], np.float32)
    st = hdr.make_jpeg_stack(
        jax.random.fold_in(key, 1), rad, times, cal["curve"], gain=float(cal["gain"]),
        read_sigma=float(cal["read_sigma"]), quality=int(cal["jpeg_quality"]),
    )
    folder = os.path.join(out, "bracket")
    os.makedirs(folder, exist_ok=True)
    for j, img in enumerate(np.asarray(st.images)):
        # the frames are already JPEG-decoded; saving them losslessly as PNG keeps exactly
        # those codes (a second JPEG pass would compress twice)
        Image.fromarray(img).save(os.path.join(folder, f"frame_{j}.png"))
    from jaxgfx.config import load_config

    cfg = load_config(CalibrateConfig, {
        "exposure_times": [float(t) for t in times],
        "response": {"method": cal["method"], "compare": [cal["method"]]},
    })
    run_calibrate(CalibrateJob(cfg, (folder,), os.path.join(out, "calibrate"), overwrite,
                               progress=False))
    return os.path.join(out, "calibrate", "report.json")


def camera_for(variant: str, fit: dict, report: str) -> dict:
    clip = {"clip_code": int(fit["clip_code"])} if fit.get("clip_code") is not None else {}
    if fit.get("clipped") is not None:
        clip["clipped"] = fit["clipped"]
    return dict(_camera_for(variant, fit, report), **clip)


def _camera_for(variant: str, fit: dict, report: str) -> dict:
    tc = fit["camera"]
    if variant == "true_camera":
        # camera.exposure is the first photo's (the others are at their given ratios)
        e0 = float(tc["exposure"]) * float(tc.get("exposures", [1.0])[0])
        return {"response": {"model": tc["response"]}, "exposure": {"init": e0}}
    if variant == "calibrated":
        return {"response": {"from": report},
                "exposure": {"init": 1.0, "fit": True, "auto": bool(fit.get("auto_exposure"))}}
    if variant == "joint":
        fc = fit["free_curve"]
        return {"response": {"model": "table", "fit": True, **fc},
                "exposure": {"init": 1.0, "fit": True, "auto": bool(fit.get("auto_exposure"))}}
    return {"response": {"model": "srgb"},
            "exposure": {"init": 1.0, "fit": True, "auto": bool(fit.get("auto_exposure"))}}


def response_errors(resp, truth) -> dict:
    """ln-exposure error of ``resp`` against ``truth`` over levels 10-245 after the best
    constant offset: RMS (``jaxgfx.hdr.response_curve_error``) and max."""
    import jax.numpy as jnp

    from jaxgfx import hdr

    zn = jnp.asarray(np.arange(10, 246) / 255.0, jnp.float32)[:, None]
    a = np.log(np.asarray(resp.to_linear_normalized(jnp.broadcast_to(zn, (236, resp.channels)))))
    b = np.log(np.asarray(truth.to_linear_normalized(jnp.broadcast_to(zn, (236, 1)))))
    d = a - b
    d = d - d.mean(axis=0, keepdims=True)
    return {"rms_ln": float(hdr.response_curve_error(resp, truth)),
            "max_ln": float(np.max(np.abs(d)))}


def errors_vs_time(result: dict, truth: dict):
    """(seconds, alpha relative error, albedo max error) per step."""
    a = np.asarray(result["history"]["materials.metal.alpha"], np.float64)
    rho = np.asarray(result["history"]["materials.clay.reflectance"], np.float64)
    t_alpha = float(truth["materials.metal.alpha"])
    t_rho = np.asarray(truth["materials.clay.reflectance"], np.float64)
    secs = np.concatenate([[0.0], np.cumsum(result["seconds_history"])])
    return secs, np.abs(a - t_alpha) / t_alpha, np.max(np.abs(rho - t_rho), axis=-1)


def plot(path, results: dict, truth: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for name, res in results.items():
        s, ea, er = errors_vs_time(res, truth)
        axes[0].semilogy(s, np.maximum(ea, 1e-4), label=name, lw=1.2)
        axes[1].semilogy(s, np.maximum(er, 1e-4), label=name, lw=1.2)
    axes[0].axhline(0.05, color="k", ls="--", lw=0.8)
    axes[1].axhline(0.03, color="k", ls="--", lw=0.8)
    axes[0].set_ylabel("|alpha - truth| / truth")
    axes[1].set_ylabel("clay albedo: max |error|")
    for ax in axes:
        ax.set_xlabel("seconds of fit steps (after compilation)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("material error against time, by the camera the fit assumes "
                 "(dashed: the issue's targets)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default="configs/camera_chain.yaml")
    p.add_argument("--out", default="out/camera_chain")
    p.add_argument("--steps", type=int, default=None)
    p.add_argument("--variants", default=None)
    p.add_argument("--clip-code", type=int, default=None,
                   help="override fit.clip_code (codes >= it are censored; 255: none)")
    p.add_argument("--auto-exposure", default=None, choices=("on", "off"),
                   help="override fit.auto_exposure (camera.exposure.auto of the fitted ones)")
    p.add_argument("--clipped", default=None, choices=("bound", "unmeasured"),
                   help="override fit.clipped (camera.clipped of every fit)")
    p.add_argument("--overwrite", action="store_true")
    p.add_argument("--quiet", action="store_true")
    a = p.parse_args(argv)

    from jaxgfx import hdr
    from jaxgfx.pipelines.fit import FitJob, enable_compilation_cache, run_fit

    enable_compilation_cache()
    base = read_yaml(a.config)
    base_dir = os.path.dirname(os.path.abspath(a.config))
    fit = base["fit"]
    if a.clip_code is not None:
        fit["clip_code"] = a.clip_code
    if a.clipped is not None:
        fit["clipped"] = a.clipped
    if a.auto_exposure is not None:
        fit["auto_exposure"] = a.auto_exposure == "on"
    os.makedirs(a.out, exist_ok=True)
    report = calibrate(base["calibration"], a.out, a.overwrite)
    true_resp = hdr.synthetic_response(base["calibration"]["curve"], channels=1)
    calibrated = hdr.load_response(report, bits=8)
    summary = {
        "calibration": {"report": report, "response": response_errors(calibrated, true_resp)},
        "truth": fit["truth"],
        "truth_camera": fit["camera"],
        "clip_code": fit.get("clip_code"),
        "clipped": fit.get("clipped", "bound"),
        "auto_exposure": bool(fit.get("auto_exposure")),
        "variants": {},
    }
    print("calibrated response", json.dumps(summary["calibration"]), flush=True)
    variants = a.variants.split(",") if a.variants else base.get("variants", VARIANTS)
    results = {}
    for v in variants:
        cfg = {
            "scene": fit["scene"],
            "target": {"synthetic": fit["truth"], "spp": int(fit["target_spp"]), "seed": 7,
                       "camera": fit["camera"]},
            "params": fit["params"],
            "camera": camera_for(v, fit, os.path.abspath(report)),
            "optimizer": dict(fit["optimizer"], **({"steps": a.steps} if a.steps else {})),
            "render": fit["render"],
            "progress": not a.quiet,
        }
        out = run_fit(FitJob.load(cfg, os.path.join(a.out, f"fit_{v}"), base_dir=base_dir,
                                  overwrite=a.overwrite))
        results[v] = out
        entry = {
            "params": out["params"],
            "errors": out["errors"],
            "alpha_rel_error": out["errors"]["materials.metal.alpha"]
            / float(fit["truth"]["materials.metal.alpha"]),
            "camera": out["camera"],
            "seconds": out["seconds"],
            "compile_seconds": out["compile_seconds"],
            "load_average": list(os.getloadavg()),
        }
        resp = hdr.load_response(os.path.join(a.out, f"fit_{v}", "response.json"), bits=8)
        entry["response_error"] = response_errors(resp, true_resp)
        summary["variants"][v] = entry
        print(v, json.dumps(entry), flush=True)
    with open(os.path.join(a.out, "summary.json"), "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=1)
    plot(os.path.join(a.out, "chain.png"), results, fit["truth"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
