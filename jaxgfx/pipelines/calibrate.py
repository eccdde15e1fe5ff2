"""The main job: calibrate a camera from a bracketed stack and merge a radiance map.

``run_calibrate(config, inputs, out_dir)`` loads a bracketed stack (LDR files with EXIF or
sidecar exposure times, RAW files, or — with no inputs — the embedded synthetic stack generated
from a known radiance, response and noise model), optionally aligns it, fits the camera
response (LDR) or the sensor calibration (RAW: black/white level, linearity, actual exposure
ratios, photon-transfer noise model), merges an HDR radiance map with a per-pixel variance, and
writes::

    radiance.exr        linear radiance (float32, relative units; see report.json "anchor")
    variance.exr        per-pixel variance of the radiance estimate
    confidence.png      per-pixel confidence (relative standard error mapped to [0, 1])
    response.png        fitted response curves (and the ground truth for synthetic stacks)
    preview.png         exposure-normalised sRGB preview of the radiance map
    report.json         fitted parameters, uncertainties, residuals, errors, timings

The CLI (``jaxgfx calibrate``) and ``experiments/calibrate.py`` both call this function.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from typing import Any

import numpy as np

from jaxgfx.config import config_to_dict, load_config

__all__ = [
    "SyntheticConfig",
    "ResponseConfig",
    "MergeConfig",
    "AlignConfig",
    "CalibrateConfig",
    "run_calibrate",
    "run_calibrate_cli",
    "RAW_EXTENSIONS",
]

RAW_EXTENSIONS = (".dng", ".nef", ".cr2", ".cr3", ".arw", ".raf", ".orf", ".rw2", ".pef", ".srw")
LDR_EXTENSIONS = (".jpg", ".jpeg", ".png", ".tif", ".tiff")


@dataclasses.dataclass(frozen=True)
class SyntheticConfig:
    """The embedded default stack: known radiance, response and noise."""

    seed: int = 0
    height: int = 240
    width: int = 320
    dynamic_range: float = 1.0e4
    response: str = "filmic"
    exposure_times: tuple[float, ...] = (0.5, 4.0, 32.0, 256.0, 2048.0)
    bits: int = 8
    gain: float = 2.0e-4
    read_sigma: float = 1.0e-3

    def validate(self):
        if self.height < 8 or self.width < 8:
            raise ValueError("synthetic.height/width: expected at least 8 pixels")
        if len(self.exposure_times) < 2 or any(t <= 0 for t in self.exposure_times):
            raise ValueError("synthetic.exposure_times: expected >= 2 positive times")
        if self.bits not in (8, 16):
            raise ValueError(f"synthetic.bits: expected 8 or 16, got {self.bits}")


@dataclasses.dataclass(frozen=True)
class ResponseConfig:
    method: str = "debevec"
    options: dict = dataclasses.field(default_factory=dict)
    compare: tuple[str, ...] = ("debevec", "robertson", "polynomial", "spline")


@dataclasses.dataclass(frozen=True)
class MergeConfig:
    weighting: str = "hat"


@dataclasses.dataclass(frozen=True)
class AlignConfig:
    enabled: bool = False
    method: str = "phase"


@dataclasses.dataclass(frozen=True)
class CalibrateConfig:
    exposure_times: tuple[float, ...] | None = None
    synthetic: SyntheticConfig = SyntheticConfig()
    response: ResponseConfig = ResponseConfig()
    merge: MergeConfig = MergeConfig()
    align: AlignConfig = AlignConfig()
    demosaic: str = "malvar"
    preview_key: float = 0.18


def _collect_inputs(inputs) -> list[str]:
    files: list[str] = []
    for item in inputs or []:
        item = os.fspath(item)
        if os.path.isdir(item):
            for name in sorted(os.listdir(item)):
                if name.lower().endswith(RAW_EXTENSIONS + LDR_EXTENSIONS):
                    files.append(os.path.join(item, name))
        elif os.path.exists(item):
            files.append(item)
        else:
            raise FileNotFoundError(f"input not found: {item}")
    if inputs and not files:
        raise ValueError(f"inputs: no image files found in {list(inputs)}")
    return files


SIDECAR_NAMES = ("exposure_times.txt", "exposure_times.yaml", "exposure_times.json")


def _find_sidecar(inputs) -> str | None:
    """An ``exposure_times.{txt,yaml,json}`` file inside an input directory, if any."""
    for item in inputs or []:
        if os.path.isdir(item):
            for name in SIDECAR_NAMES:
                path = os.path.join(item, name)
                if os.path.exists(path):
                    return path
    return None


class _Steps:
    """Progress reporting (tqdm) plus per-step wall-clock timings for the report."""

    def __init__(self, total: int, enabled: bool):
        from tqdm.auto import tqdm

        self.bar = tqdm(total=total, disable=not enabled, desc="calibrate", unit="step")
        self.timings: dict[str, float] = {}
        self._t = time.perf_counter()
        self._name = None

    def start(self, name: str):
        self._close_step()
        self._name = name
        self.bar.set_postfix_str(name)
        self._t = time.perf_counter()

    def _close_step(self):
        if self._name is not None:
            self.timings[self._name] = round(time.perf_counter() - self._t, 4)
            self.bar.update(1)
            self._name = None

    def close(self):
        self._close_step()
        self.bar.close()


def _plot_response(path, responses: dict, truth=None, title="camera response"):
    """Plot g(Z) = ln to_linear(Z) per channel for each fitted response (and the truth,
    shifted by the best constant ln offset, since the anchor is arbitrary)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    z = np.linspace(0.0, 1.0, 256)

    def curve(resp):
        zz = np.ascontiguousarray(np.broadcast_to(z[:, None], (256, resp.channels)), np.float32)
        return np.log(np.maximum(np.asarray(resp.to_linear_normalized(zz), np.float64), 1e-12))

    colors = ("tab:red", "tab:green", "tab:blue")
    styles = ["-", "--", "-.", ":"]
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ref = None
    for k, (name, resp) in enumerate(responses.items()):
        g = curve(resp)
        if ref is None:
            ref = g[:, min(1, g.shape[1] - 1)]
        for c in range(g.shape[1]):
            ax.plot(
                z * 255,
                g[:, c],
                styles[k % len(styles)],
                color=colors[c % 3],
                lw=1.2,
                label=name if c == 0 else None,
            )
    if truth is not None:
        g = curve(truth)[:, min(1, truth.channels - 1)]
        sl = slice(10, 246)
        g = g + np.mean(ref[sl] - g[sl]) if ref is not None else g
        ax.plot(z * 255, g, color="k", lw=2.5, alpha=0.35, label="ground truth (G)")
    ax.set_xlabel("pixel level Z (of 255)")
    ax.set_ylabel("g(Z) = ln relative exposure")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _response_summary(resp) -> dict:
    out = {}
    for name, value in vars(resp).items():
        if hasattr(value, "shape") and np.size(value) <= 4096:
            out[name] = np.asarray(value).tolist()
        elif isinstance(value, (str, int, float, bool)):
            out[name] = value
    return out


def _preview(radiance: np.ndarray, key: float) -> np.ndarray:
    from jaxgfx import color

    lum = np.asarray(color.luminance(np.maximum(radiance, 0)))
    logavg = float(np.exp(np.mean(np.log(lum[lum > 0] + 1e-9)))) if np.any(lum > 0) else 1.0
    scaled = radiance * (key / max(logavg, 1e-12))
    mapped = scaled / (1.0 + scaled)  # global Reinhard curve for the preview only
    return np.asarray(color.linear_to_srgb(np.clip(mapped, 0.0, 1.0)))


def _to_float01(images: np.ndarray) -> np.ndarray:
    if np.issubdtype(images.dtype, np.integer):
        return images.astype(np.float32) / float(np.iinfo(images.dtype).max)
    return images.astype(np.float32)


def _jsonable(x: Any):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if hasattr(x, "to_dict"):
        return _jsonable(x.to_dict())
    if hasattr(x, "shape") or isinstance(x, (np.generic,)):
        a = np.asarray(x)
        return a.item() if a.ndim == 0 else a.tolist()
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def _write_outputs(out_dir, radiance, variance, cfg: CalibrateConfig) -> dict:
    from jaxgfx import io

    paths = {}
    paths["radiance"] = os.path.join(out_dir, "radiance.exr")
    io.write_exr(paths["radiance"], np.ascontiguousarray(radiance, np.float32))
    paths["variance"] = os.path.join(out_dir, "variance.exr")
    io.write_exr(paths["variance"], np.ascontiguousarray(variance, np.float32))
    rel = np.sqrt(np.maximum(variance, 0)) / np.maximum(np.abs(radiance), 1e-12)
    conf = np.clip(1.0 - rel.mean(axis=-1) / 0.1, 0.0, 1.0)  # 0 at >= 10% relative std. error
    paths["confidence"] = os.path.join(out_dir, "confidence.png")
    io.write_png(paths["confidence"], conf.astype(np.float32))
    paths["preview"] = os.path.join(out_dir, "preview.png")
    io.write_png(paths["preview"], _preview(radiance, cfg.preview_key))
    return paths


def _run_ldr(cfg, images, times, truth, out_dir, steps: _Steps, report: dict):
    import jax

    from jaxgfx import hdr

    steps.start("fit response")
    resp = hdr.recover_response(
        images, times, method=cfg.response.method, **dict(cfg.response.options)
    )
    jax.block_until_ready(jax.tree_util.tree_leaves(resp))
    steps.start("merge")
    radiance, variance = hdr.merge_radiance(
        images, times, resp, weighting=cfg.merge.weighting, return_variance=True
    )
    radiance = np.asarray(radiance, np.float32)
    variance = np.asarray(variance, np.float32)
    steps.start("evaluate")
    report["response"] = {"method": cfg.response.method, "summary": _response_summary(resp)}
    curves = {cfg.response.method: resp}
    if truth is not None:
        true_resp, true_radiance = truth
        errs = {}
        for m in dict.fromkeys((cfg.response.method, *cfg.response.compare)):
            r = curves.get(m) or hdr.recover_response(images, times, method=m)
            curves[m] = r
            e = hdr.merge_radiance(images, times, r, weighting=cfg.merge.weighting)
            errs[m] = {
                "curve_rmse_ln": float(hdr.response_curve_error(r, true_resp)),
                "radiance_median_abs_ln": float(hdr.radiance_error(e, true_radiance)),
            }
        report["errors_vs_ground_truth"] = errs
    steps.start("write outputs")
    paths = _write_outputs(out_dir, radiance, variance, cfg)
    paths["response_plot"] = os.path.join(out_dir, "response.png")
    _plot_response(paths["response_plot"], curves, truth[0] if truth is not None else None)
    return paths


def _run_raw(cfg, files, out_dir, steps: _Steps, report: dict):
    from jaxgfx import hdr, image, io
    from jaxgfx.hdr.raw_calibration import calibrate_raw_stack

    steps.start("read raw")
    raws = [io.read_raw(f) for f in files]
    patterns = {r.cfa_pattern for r in raws}
    if len(patterns) != 1:
        raise ValueError(f"inputs: RAW files have different CFA patterns {sorted(patterns)}")
    pattern = patterns.pop()
    times = np.array(
        cfg.exposure_times if cfg.exposure_times else [r.exposure_time for r in raws], np.float64
    )
    if np.any(~np.isfinite(times)) or np.any(times <= 0):
        raise ValueError("exposure_times: missing in the RAW files' EXIF; pass --times")
    order = np.argsort(times)
    mosaics = np.stack([raws[i].mosaic for i in order]).astype(np.float32)
    times = times[order]
    black = np.asarray(raws[0].black_level, np.float32)
    white = float(raws[0].white_level)
    steps.start("raw calibration")
    cal = calibrate_raw_stack(mosaics, times, cfa_pattern=pattern, black=black, white=white)
    report["raw_calibration"] = _jsonable(cal.to_dict())
    steps.start("merge")
    norm = np.stack([r.normalized() for r in (raws[i] for i in order)])[..., None]
    ratios = np.asarray(cal.ratios.ratios, np.float64)
    ref = int(np.asarray(cal.ratios.reference))
    good = ratios.shape == times.shape and np.all(np.isfinite(ratios)) and np.all(ratios > 0)
    eff_times = times[ref] * ratios if good else times
    resp = hdr.CameraResponse.gamma(1.0, channels=1, anchor="unit")
    weighting = "noise" if cal.noise is not None else "hat"
    rad, var = hdr.merge_radiance(
        np.clip(norm, 0.0, 1.0),
        eff_times,
        resp,
        weighting=weighting,
        noise=cal.noise,
        return_variance=True,
    )
    steps.start("demosaic")
    rgb = np.asarray(image.demosaic(np.asarray(rad)[..., 0], pattern, method=cfg.demosaic))
    var_rgb = np.asarray(
        image.demosaic(np.asarray(var)[..., 0], pattern, method="bilinear"), np.float32
    )
    steps.start("write outputs")
    return _write_outputs(out_dir, rgb.astype(np.float32), var_rgb, cfg)


def run_calibrate(
    config: CalibrateConfig | None = None,
    inputs=None,
    out_dir: str = "out/calibrate",
    *,
    progress: bool = True,
) -> dict:
    """Run the calibration job; returns the report dict (also written to ``report.json``)."""
    import jax

    from jaxgfx import hdr, io

    cfg = config or CalibrateConfig()
    os.makedirs(out_dir, exist_ok=True)
    files = _collect_inputs(inputs)
    is_raw = bool(files) and all(f.lower().endswith(RAW_EXTENSIONS) for f in files)
    if files and not is_raw and any(f.lower().endswith(RAW_EXTENSIONS) for f in files):
        raise ValueError("inputs: mix of RAW and LDR files; calibrate one kind at a time")
    steps = _Steps(total=5 if files else 6, enabled=progress)
    t_all = time.perf_counter()
    report: dict = {"config": config_to_dict(cfg), "inputs": files or "embedded synthetic stack"}
    try:
        if is_raw:
            paths = _run_raw(cfg, files, out_dir, steps, report)
        else:
            steps.start("load")
            truth = None
            if files:
                images, times = io.read_ldr_stack(
                    files, exposure_times=cfg.exposure_times, sidecar=_find_sidecar(inputs)
                )
            else:
                s = cfg.synthetic
                key = jax.random.key(s.seed)
                k1, k2 = jax.random.split(key)
                radiance = hdr.synthetic_radiance(
                    k1, s.height, s.width, dynamic_range=s.dynamic_range
                )
                true_resp = hdr.synthetic_response(s.response)
                times = np.asarray(s.exposure_times, np.float64)
                images = hdr.make_bracketed_stack(
                    k2,
                    radiance,
                    times,
                    true_resp,
                    bits=s.bits,
                    gain=s.gain,
                    read_sigma=s.read_sigma,
                ).images
                truth = (true_resp, np.asarray(radiance))
                report["synthetic"] = {"response": s.response, "bits": s.bits}
            images = np.asarray(images)
            times = np.asarray(times, np.float64)
            report["exposure_times"] = times.tolist()
            report["image_shape"] = list(images.shape)
            if cfg.align.enabled:
                steps.start("align")
                from jaxgfx.hdr.align import align_stack

                aligned, shifts = align_stack(_to_float01(images), method=cfg.align.method)
                report["alignment_shifts_px"] = np.asarray(shifts).tolist()
                images = np.asarray(aligned)
            paths = _run_ldr(cfg, images, times, truth, out_dir, steps, report)
    finally:
        steps.close()
    report["timings_s"] = {**steps.timings, "total": round(time.perf_counter() - t_all, 4)}
    report["outputs"] = paths
    paths["report"] = os.path.join(out_dir, "report.json")
    with open(paths["report"], "w", encoding="utf-8") as f:
        json.dump(_jsonable(report), f, indent=2)
    return report


def run_calibrate_cli(args) -> int:
    """Entry used by ``jaxgfx calibrate`` and ``experiments/calibrate.py``."""
    overrides: dict = {}
    if getattr(args, "times", None):
        try:
            overrides["exposure_times"] = [float(eval_fraction(t)) for t in args.times.split(",")]
        except ValueError:
            raise ValueError(
                f"--times: expected comma-separated numbers, got {args.times!r}"
            ) from None
    cfg = load_config(CalibrateConfig, args.config, **overrides)
    if getattr(args, "method", None):
        cfg = dataclasses.replace(
            cfg, response=dataclasses.replace(cfg.response, method=args.method)
        )
    report = run_calibrate(cfg, args.inputs, args.out, progress=not args.quiet)
    print(f"outputs in {os.path.abspath(args.out)}:")
    for name, p in report["outputs"].items():
        print(f"  {name:14s} {p}")
    if "errors_vs_ground_truth" in report:
        e = report["errors_vs_ground_truth"][cfg.response.method]
        print(
            f"curve error {e['curve_rmse_ln']:.4f} (RMSE ln-exposure), radiance error "
            f"{e['radiance_median_abs_ln']:.4f} (median |ln E - ln E_true|)"
        )
    return 0


def eval_fraction(text: str) -> float:
    """Parse '1/250' or '0.004' as a float."""
    text = text.strip()
    if "/" in text:
        num, den = text.split("/", 1)
        return float(num) / float(den)
    return float(text)
