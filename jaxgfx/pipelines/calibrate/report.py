"""What a run writes: the result record (:class:`CalibrateResult`), the images and figures
(:func:`write_outputs`) and ``report.json``, assembled in one place (:func:`build_report`)."""

from __future__ import annotations

import dataclasses
import json
import os
from typing import Any

import numpy as np

from jaxgfx.config import config_to_dict
from jaxgfx.tonemap import TONEMAP_METHODS

from . import plots

__all__ = [
    "CalibrateResult",
    "OUTPUT_NAMES",
    "build_report",
    "output_paths",
    "write_outputs",
    "write_report",
]

OUTPUT_NAMES = (
    "radiance.exr",
    "variance.exr",
    "confidence.png",
    "frames.png",
    "preview.png",
    "response.png",
    "loo.png",
    "vignetting.png",
    "chart.png",
    "camera.json",
    "report.json",
) + tuple(f"tonemap_{op}.png" for op in TONEMAP_METHODS)
"""Every file a calibration run may write into ``out`` (a RAW run writes no response.png)."""


def _response_summary(resp) -> dict:
    out = {}
    for name, value in vars(resp).items():
        if hasattr(value, "shape") and np.size(value) <= 4096:
            out[name] = np.asarray(value).tolist()
        elif isinstance(value, (str, int, float, bool)):
            out[name] = value
    return out


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


@dataclasses.dataclass
class CalibrateResult:
    """What the computation produced (host NumPy), before anything is written."""

    radiance: np.ndarray
    variance: np.ndarray
    times: np.ndarray | None = None
    image_shape: tuple | None = None
    response: Any = None  # the fitted CameraResponse (LDR)
    curves: dict | None = None  # method -> CameraResponse, for response.png
    truth: tuple | None = None  # (true response, true radiance) of a synthetic stack
    errors: dict | None = None  # method -> errors vs the ground truth
    raw_calibration: Any = None  # RawCalibration (RAW)
    loo: Any = None  # hdr.LeaveOneOut self-check (LDR)
    alignment_shifts: Any = None
    synthetic: dict | None = None
    color: Any = None  # hdr.raw.ColorTransform (RAW): camera RGB -> the output colour space
    vignetting: Any = None  # hdr.raw.Vignetting (RAW with a flat field)
    chart: Any = None  # raw.ChartResult (RAW with config.chart): the fit, patches, corners
    frames: Any = None  # hdr.DeghostResult of a ghost-free merge (merge.deghost): frames.png


def write_outputs(folder, result: CalibrateResult, cfg) -> list[str]:
    """Write the images and the plot into ``folder``; returns the file names written."""
    from jaxgfx import io
    from jaxgfx.hdr.raw import exr_chromaticities

    radiance, variance = result.radiance, result.variance
    chroma = None if result.color is None else exr_chromaticities(result.color.colorspace)
    header = None if chroma is None else {"chromaticities": chroma}
    for name, img in (("radiance.exr", radiance), ("variance.exr", variance)):
        io.write_exr(
            os.path.join(folder, name), np.ascontiguousarray(img, np.float32), header=header
        )
    rel = np.sqrt(np.maximum(variance, 0)) / np.maximum(np.abs(radiance), 1e-12)
    conf = np.clip(1.0 - rel.mean(axis=-1) / 0.1, 0.0, 1.0)  # 0 at >= 10% relative std. error
    io.write_png(os.path.join(folder, "confidence.png"), conf.astype(np.float32))
    io.write_png(os.path.join(folder, "preview.png"), plots._preview(radiance, cfg.preview_key))
    names = ["radiance.exr", "variance.exr", "confidence.png", "preview.png"]
    if result.frames is not None:  # which frame each pixel came from (merge.deghost)
        fm = plots.frames_map(result.frames.used, result.frames.reference, result.times)
        io.write_png(os.path.join(folder, "frames.png"), fm)
        names.append("frames.png")
    if cfg.tonemap:
        from jaxgfx.pipelines.tonemap import tonemap_image

        for op in dict.fromkeys(cfg.tonemap):
            io.write_png(os.path.join(folder, f"tonemap_{op}.png"), tonemap_image(radiance, op))
            names.append(f"tonemap_{op}.png")
    _write_camera_profile(os.path.join(folder, "camera.json"), result)
    names.append("camera.json")
    if result.vignetting is not None:
        plots._plot_vignetting(os.path.join(folder, "vignetting.png"), result.vignetting)
        names.append("vignetting.png")
    if result.chart is not None:
        plots._plot_chart(os.path.join(folder, "chart.png"), result.chart)
        names.append("chart.png")
    if result.loo is not None:
        plots._plot_loo(os.path.join(folder, "loo.png"), result.loo)
        names.append("loo.png")
    if result.curves:
        plots._plot_response(
            os.path.join(folder, "response.png"),
            result.curves,
            result.truth[0] if result.truth is not None else None,
        )
        names.append("response.png")
    return names


def _write_camera_profile(path, result: CalibrateResult) -> None:
    """``camera.json`` (:func:`jaxgfx.hdr.save_camera_profile`): what this run fitted."""
    from jaxgfx import hdr

    kw: dict = {"response": result.response, "vignetting": result.vignetting}
    if result.chart is not None:
        kw["chart"] = result.chart.calibration
    if result.color is not None:
        ct = result.color
        neutral = np.asarray(ct.neutral, np.float64)
        kw.update(
            white_balance_gains=neutral.max() / neutral,
            matrix=np.asarray(ct.matrix, np.float64),
            colorspace=ct.colorspace,
            source={"matrix": ct.matrix_source, "white_balance": ct.white_balance_source},
        )
    if result.raw_calibration is not None:
        kw["noise"] = result.raw_calibration.noise
    hdr.save_camera_profile(path, **kw)


_OUTPUT_KEYS = {
    "radiance.exr": "radiance",
    "variance.exr": "variance",
    "confidence.png": "confidence",
    "frames.png": "frames",
    "preview.png": "preview",
    "response.png": "response_plot",
    "loo.png": "loo_plot",
    "vignetting.png": "vignetting_plot",
    "chart.png": "chart_plot",
    "camera.json": "camera_profile",
    "report.json": "report",
    **{n: n[: -len(".png")] for n in OUTPUT_NAMES if n.startswith("tonemap_")},
}


def build_report(job, files, result: CalibrateResult, timings: dict, outputs):
    """The report (``report.json``): config, inputs, fitted parameters, errors, timings and
    output paths. The one place its fields are assembled; add new fields here."""
    cfg = job.config
    report: dict = {"config": config_to_dict(cfg), "inputs": files or "embedded synthetic stack"}
    if result.synthetic is not None:
        report["synthetic"] = result.synthetic
    if result.times is not None:
        report["exposure_times"] = np.asarray(result.times).tolist()
    if result.image_shape is not None:
        report["image_shape"] = list(result.image_shape)
    if result.alignment_shifts is not None:
        report["alignment_shifts_px"] = np.asarray(result.alignment_shifts).tolist()
    if result.raw_calibration is not None:
        report["raw_calibration"] = _jsonable(result.raw_calibration.to_dict())
    if result.color is not None:
        report["color"] = result.color.to_dict()
    if result.vignetting is not None:
        report["vignetting"] = {"flat_field": cfg.flat_field, **result.vignetting.to_dict()}
    if result.chart is not None:
        report["chart"] = result.chart.to_dict()
    if result.response is not None:
        report["response"] = {
            "method": cfg.response.method,
            "summary": _response_summary(result.response),
        }
    if result.loo is not None:  # the self-check: no ground truth needed (docs/hdr.md)
        report["leave_one_out"] = result.loo.to_dict()
    if result.errors is not None:
        report["errors_vs_ground_truth"] = result.errors
    if result.frames is not None:
        report["deghost"] = _frames_summary(result.frames, result.times)
    report["timings_s"] = timings
    report["outputs"] = outputs
    return report


def _frames_summary(res, times) -> dict:
    """``report.json`` "deghost": per frame (input order) its exposure time, its colour in
    ``frames.png`` and the fractions of pixels where it is the reference / was merged."""
    used = np.asarray(res.used) > 0.5
    ref = np.asarray(res.reference)
    n = used.shape[0]
    colors = plots.frame_colors(times)
    return {
        "frames_png": "hue = reference frame (colour below); brightness 0.25 + 0.75 k / N for "
        "k of the N frames merged at the pixel",
        "mean_frames_used": float(used.sum(axis=0).mean()),
        "per_frame": [
            {
                "index": j,
                "exposure_time": float(np.asarray(times)[j]),
                "color_rgb": [round(float(c), 4) for c in colors[j]],
                "reference_fraction": float(np.mean(ref == j)),
                "used_fraction": float(used[j].mean()),
            }
            for j in range(n)
        ],
    }


def write_report(folder, report: dict) -> None:
    """``report.json`` (strict JSON: NaN/Inf as null) into ``folder``."""
    with open(os.path.join(folder, "report.json"), "w", encoding="utf-8") as f:
        json.dump(_jsonable(report), f, indent=2)


def output_paths(out, names) -> dict:
    """``{report key: path}`` of the files ``names`` written into ``out``."""
    return {_OUTPUT_KEYS[n]: os.path.join(out, n) for n in names}
