"""The main job: calibrate a camera from a bracketed stack and merge a radiance map.

``run_calibrate(job)`` (a :class:`CalibrateJob`: config, inputs, out) loads a bracketed
stack (LDR files with EXIF or sidecar exposure times, RAW files, or — with no inputs — the
embedded synthetic stack generated from a known radiance, response and noise model),
optionally aligns it, fits the camera
response (LDR) or the sensor calibration (RAW: black/white level, linearity, actual exposure
ratios, photon-transfer noise model), merges an HDR radiance map with a per-pixel variance, and
writes::

    radiance.exr        linear radiance (float32, relative units; see report.json "anchor")
    variance.exr        per-pixel variance of the radiance estimate
    confidence.png      per-pixel confidence (relative standard error mapped to [0, 1])
    response.png        fitted response curves (and the ground truth for synthetic stacks)
    loo.png             leave-one-out self-check per level band and held frame (LDR)
    preview.png         exposure-normalised sRGB preview of the radiance map
    tonemap_<op>.png    one display image per operator of ``config.tonemap`` (jaxgfx.tonemap)
    report.json         fitted parameters, uncertainties, residuals, errors, timings

Only when the whole run succeeded do they appear in ``out`` (staged next to it, then moved
into place); ``out`` holding a previous run's results is refused unless ``overwrite``.
``jaxgfx calibrate`` and ``experiments/calibrate.py`` are thin argument-to-job layers over
:func:`run_calibrate`; the report is assembled in :func:`build_report` only.
"""

from __future__ import annotations

import dataclasses
import json
import os
import time
from typing import Any

import numpy as np

from jaxgfx.config import config_to_dict
from jaxgfx.io import kind_of
from jaxgfx.pipelines._output import StagedDir

__all__ = [
    "SyntheticConfig",
    "ResponseConfig",
    "MergeConfig",
    "AlignConfig",
    "CalibrateConfig",
    "CalibrateJob",
    "CalibrateResult",
    "OUTPUT_NAMES",
    "build_report",
    "run_calibrate",
]


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
        for name in ("height", "width"):
            if getattr(self, name) < 8:
                raise ValueError(
                    f"synthetic.{name}: expected at least 8 pixels, got {getattr(self, name)}"
                )
        if len(self.exposure_times) < 2 or any(t <= 0 for t in self.exposure_times):
            raise ValueError("synthetic.exposure_times: expected >= 2 positive times")
        if self.bits not in (8, 16):
            raise ValueError(f"synthetic.bits: expected 8 or 16, got {self.bits}")
        if self.seed < 0:
            raise ValueError(f"synthetic.seed: expected an integer >= 0, got {self.seed}")
        if not (np.isfinite(self.dynamic_range) and self.dynamic_range > 1):
            raise ValueError(
                f"synthetic.dynamic_range: expected a finite value > 1, got {self.dynamic_range}"
            )
        for name in ("gain", "read_sigma"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"synthetic.{name}: expected a finite value >= 0, got {v}")
        if any(not np.isfinite(t) for t in self.exposure_times):
            raise ValueError("synthetic.exposure_times: expected finite times")
        from jaxgfx.hdr import SYNTHETIC_RESPONSES

        if self.response not in SYNTHETIC_RESPONSES:
            raise ValueError(
                f"synthetic.response: expected one of {', '.join(SYNTHETIC_RESPONSES)}, "
                f"got {self.response!r}"
            )


_CHOICES = {
    "response.method": ("debevec", "robertson", "gamma", "polynomial", "spline"),
    "merge.weighting": ("hat", "gaussian", "linear", "noise"),
    "align.method": ("phase", "mtb"),
    "demosaic": ("malvar", "bilinear"),
}


def _check_choice(value, where: str):
    if value not in _CHOICES[where]:
        raise ValueError(f"{where}: expected one of {', '.join(_CHOICES[where])}, got {value!r}")


@dataclasses.dataclass(frozen=True)
class ResponseConfig:
    method: str = "debevec"
    options: dict = dataclasses.field(default_factory=dict)
    compare: tuple[str, ...] = ("debevec", "robertson", "polynomial", "spline")

    def validate(self):
        _check_choice(self.method, "response.method")
        for i, m in enumerate(self.compare):
            if m not in _CHOICES["response.method"]:
                raise ValueError(
                    f"response.compare[{i}]: expected one of "
                    f"{', '.join(_CHOICES['response.method'])}, got {m!r}"
                )
        from jaxgfx.hdr import check_response_options

        check_response_options(self.method, self.options, name="response.options")


@dataclasses.dataclass(frozen=True)
class MergeConfig:
    weighting: str = "hat"

    def validate(self):
        _check_choice(self.weighting, "merge.weighting")


@dataclasses.dataclass(frozen=True)
class AlignConfig:
    enabled: bool = False
    method: str = "phase"

    def validate(self):
        _check_choice(self.method, "align.method")


@dataclasses.dataclass(frozen=True)
class CalibrateConfig:
    """What to compute (the YAML of ``configs/calibrate.yaml``); every field checked on load."""

    exposure_times: tuple[float, ...] | None = None
    synthetic: SyntheticConfig = SyntheticConfig()
    response: ResponseConfig = ResponseConfig()
    merge: MergeConfig = MergeConfig()
    align: AlignConfig = AlignConfig()
    demosaic: str = "malvar"
    preview_key: float = 0.18
    tonemap: tuple[str, ...] = ()

    def validate(self):
        _check_choice(self.demosaic, "demosaic")
        from jaxgfx.tonemap import TONEMAP_METHODS

        for i, op in enumerate(self.tonemap):
            if op not in TONEMAP_METHODS:
                raise ValueError(
                    f"tonemap[{i}]: expected one of {', '.join(TONEMAP_METHODS)}, got {op!r}"
                )
        if not (np.isfinite(self.preview_key) and self.preview_key > 0):
            raise ValueError(
                f"preview_key: expected a finite value > 0 (log-average maps to it), "
                f"got {self.preview_key!r}"
            )
        if self.exposure_times is not None:
            from jaxgfx.io import parse_exposure_time

            for i, t in enumerate(self.exposure_times):
                parse_exposure_time(t, f"exposure_times[{i}]")
        if self.merge.weighting == "noise":
            raise ValueError(
                "merge.weighting: 'noise' needs a noise model, which LDR calibration does not "
                "fit (RAW inputs use it automatically); expected hat, gaussian or linear"
            )


OUTPUT_NAMES = (
    "radiance.exr",
    "variance.exr",
    "confidence.png",
    "preview.png",
    "response.png",
    "loo.png",
    "report.json",
) + tuple(
    f"tonemap_{op}.png"
    for op in (
        "exposure drago reinhard reinhard_devlin filmic hable reinhard_local "
        "contrast_inversion durand fattal"
    ).split()
)
"""Every file a calibration run may write into ``out`` (a RAW run writes no response.png)."""


@dataclasses.dataclass(frozen=True)
class CalibrateJob:
    """One run of the calibration job: the config plus where to read and write.

    ``inputs``: image files or one folder (empty: the embedded synthetic stack);
    ``out``: the results folder (see :mod:`jaxgfx.pipelines._output` for the guarantees);
    ``overwrite``: replace the results of a previous run in ``out`` (else refused).
    """

    config: CalibrateConfig = CalibrateConfig()
    inputs: tuple[str, ...] = ()
    out: str = "out/calibrate"
    overwrite: bool = False
    progress: bool = True


def _collect_inputs(inputs) -> list[str]:
    files: list[str] = []
    for item in inputs or []:
        item = os.fspath(item)
        if os.path.isdir(item):
            for name in sorted(os.listdir(item)):
                if kind_of(name) in ("raw", "ldr"):
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
    shifted by the best constant ln offset, since the anchor is arbitrary) to ``path``."""
    import matplotlib.pyplot as plt

    fig = _response_figure(responses, truth, title)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _response_figure(responses: dict, truth=None, title="camera response"):
    """The figure of :func:`_plot_response`. Only levels 1..255 where a curve is defined
    (``to_linear > 0``) are drawn: at level 0 the exposure is 0 and ln 0 = -inf (clamping it
    stretched the axis to -27 and flattened every curve), and the fits carry no data there."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    z = np.linspace(0.0, 1.0, 256)

    def curve(resp):
        zz = np.ascontiguousarray(np.broadcast_to(z[:, None], (256, resp.channels)), np.float32)
        lin = np.asarray(resp.to_linear_normalized(zz), np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(np.isfinite(lin) & (lin > 0), np.log(lin), np.nan)
        g[0] = np.nan  # level 0: no exposure is known there
        return g

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
        g = g + np.nanmean(ref[sl] - g[sl]) if ref is not None else g
        ax.plot(z * 255, g, color="k", lw=2.5, alpha=0.35, label="ground truth (G)")
    ax.set_xlim(0, 255)
    ax.set_xlabel("pixel level Z (of 255)")
    ax.set_ylabel("g(Z) = ln relative exposure")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _plot_loo(path, loo):
    """Leave-one-out self-check: mean |error| and bias per level band, and per held frame."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = loo.to_dict()
    edges = d["band_edges"]
    labels = [f"{edges[i]:g}-{edges[i + 1]:g}" for i in range(len(edges) - 1)]
    nan = float("nan")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.6))
    x = np.arange(len(labels))
    band = [nan if v is None else v for v in d["per_band"]]
    bias = [nan if v is None else v for v in d["per_band_bias"]]
    a1.bar(x - 0.2, band, 0.4, label="mean |error|")
    a1.bar(x + 0.2, bias, 0.4, label="mean error (bias)")
    a1.axhline(0, color="k", lw=0.8)
    a1.set_xticks(x, labels, fontsize=8)
    a1.set_xlabel("level of the held-out frame (of 255)")
    a1.set_ylabel("predicted - actual (levels)")
    a1.legend(fontsize=8)
    a1.set_title(f"leave-one-out: {d['mean_abs_error']:.2f} levels overall")
    pf = [nan if v is None else v for v in d["per_frame"]]
    a2.bar(np.arange(len(pf)), pf)
    a2.set_xticks(np.arange(len(pf)), [f"{t:.3g} s" for t in d["exposure_times"]], fontsize=8)
    a2.set_xlabel("held-out frame (exposure time)")
    a2.set_ylabel("mean |error| (levels)")
    for a in (a1, a2):
        a.grid(alpha=0.3, axis="y")
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
    """Global Reinhard (2002) with key ``key``, L_white = the maximum (jaxgfx.tonemap)."""
    from jaxgfx.pipelines.tonemap import tonemap_image

    return tonemap_image(radiance, "reinhard", key=key)


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


def _write_outputs(folder, result: CalibrateResult, cfg: CalibrateConfig) -> list[str]:
    """Write the images and the plot into ``folder``; returns the file names written."""
    from jaxgfx import io

    radiance, variance = result.radiance, result.variance
    io.write_exr(os.path.join(folder, "radiance.exr"), np.ascontiguousarray(radiance, np.float32))
    io.write_exr(os.path.join(folder, "variance.exr"), np.ascontiguousarray(variance, np.float32))
    rel = np.sqrt(np.maximum(variance, 0)) / np.maximum(np.abs(radiance), 1e-12)
    conf = np.clip(1.0 - rel.mean(axis=-1) / 0.1, 0.0, 1.0)  # 0 at >= 10% relative std. error
    io.write_png(os.path.join(folder, "confidence.png"), conf.astype(np.float32))
    io.write_png(os.path.join(folder, "preview.png"), _preview(radiance, cfg.preview_key))
    names = ["radiance.exr", "variance.exr", "confidence.png", "preview.png"]
    if cfg.tonemap:
        from jaxgfx.pipelines.tonemap import tonemap_image

        for op in dict.fromkeys(cfg.tonemap):
            io.write_png(os.path.join(folder, f"tonemap_{op}.png"), tonemap_image(radiance, op))
            names.append(f"tonemap_{op}.png")
    if result.loo is not None:
        _plot_loo(os.path.join(folder, "loo.png"), result.loo)
        names.append("loo.png")
    if result.curves:
        _plot_response(
            os.path.join(folder, "response.png"),
            result.curves,
            result.truth[0] if result.truth is not None else None,
        )
        names.append("response.png")
    return names


_OUTPUT_KEYS = {
    "radiance.exr": "radiance",
    "variance.exr": "variance",
    "confidence.png": "confidence",
    "preview.png": "preview",
    "response.png": "response_plot",
    "loo.png": "loo_plot",
    "report.json": "report",
    **{n: n[: -len(".png")] for n in OUTPUT_NAMES if n.startswith("tonemap_")},
}


def build_report(job: CalibrateJob, files, result: CalibrateResult, timings: dict, outputs):
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
    if result.response is not None:
        report["response"] = {
            "method": cfg.response.method,
            "summary": _response_summary(result.response),
        }
    if result.loo is not None:  # the self-check: no ground truth needed (docs/hdr.md)
        report["leave_one_out"] = result.loo.to_dict()
    if result.errors is not None:
        report["errors_vs_ground_truth"] = result.errors
    report["timings_s"] = timings
    report["outputs"] = outputs
    return report


def _load_ldr(cfg: CalibrateConfig, files, sidecar, steps, result_kw: dict):
    """The LDR stack (files, or the embedded synthetic one) as ``(images, times, truth)``."""
    import jax

    from jaxgfx import hdr, io

    steps.start("load")
    if files:
        images, times = io.read_ldr_stack(files, exposure_times=cfg.exposure_times, sidecar=sidecar)
        truth = None
    else:
        s = cfg.synthetic
        k1, k2 = jax.random.split(jax.random.key(s.seed))
        radiance = hdr.synthetic_radiance(k1, s.height, s.width, dynamic_range=s.dynamic_range)
        true_resp = hdr.synthetic_response(s.response)
        times = np.asarray(s.exposure_times, np.float64)
        images = hdr.make_bracketed_stack(
            k2, radiance, times, true_resp, bits=s.bits, gain=s.gain, read_sigma=s.read_sigma
        ).images
        truth = (true_resp, np.asarray(radiance))
        result_kw["synthetic"] = {"response": s.response, "bits": s.bits}
    images = np.asarray(images)
    times = np.asarray(times, np.float64)
    result_kw["times"] = times
    result_kw["image_shape"] = images.shape
    if cfg.align.enabled:
        steps.start("align")
        aligned, shifts = hdr.align_stack(_to_float01(images), method=cfg.align.method)
        result_kw["alignment_shifts"] = shifts
        images = np.asarray(aligned)
    return images, times, truth


def _fit_ldr(cfg: CalibrateConfig, images, times, truth, steps, result_kw) -> CalibrateResult:
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
    steps.start("evaluate")
    loo = hdr.leave_one_out(images, times, resp, weighting=cfg.merge.weighting)
    result_kw["loo"] = loo
    curves = {cfg.response.method: resp}
    errors = None
    if truth is not None:
        true_resp, true_radiance = truth
        errors = {}
        for m in dict.fromkeys((cfg.response.method, *cfg.response.compare)):
            r = curves.get(m) or hdr.recover_response(images, times, method=m)
            curves[m] = r
            e = hdr.merge_radiance(images, times, r, weighting=cfg.merge.weighting)
            errors[m] = {
                "curve_rmse_ln": float(hdr.response_curve_error(r, true_resp)),
                "radiance_median_abs_ln": float(hdr.radiance_error(e, true_radiance)),
            }
    return CalibrateResult(
        radiance=np.asarray(radiance, np.float32),
        variance=np.asarray(variance, np.float32),
        response=resp,
        curves=curves,
        truth=truth,
        errors=errors,
        **result_kw,
    )


def _fit_raw(cfg: CalibrateConfig, files, steps) -> CalibrateResult:
    from jaxgfx import hdr, image, io

    steps.start("read raw")
    raws, times = io.read_raw_stack(files, exposure_times=cfg.exposure_times)
    pattern = raws[0].cfa_pattern
    mosaics = np.stack([r.mosaic for r in raws]).astype(np.float32)
    black = np.asarray(raws[0].black_level, np.float32)
    white = float(raws[0].white_level)
    steps.start("raw calibration")
    cal = hdr.calibrate_raw_stack(mosaics, times, cfa_pattern=pattern, black=black, white=white)
    steps.start("merge")
    norm = np.stack([r.normalized() for r in raws])[..., None]
    ratios = np.asarray(cal.ratios.ratios, np.float64)
    ref = int(np.asarray(cal.ratios.reference))
    good = ratios.shape == times.shape and np.all(np.isfinite(ratios)) and np.all(ratios > 0)
    eff_times = times[ref] * ratios if good else times
    resp = hdr.CameraResponse.gamma(1.0, channels=1, anchor="unit")
    weighting = "noise" if cal.noise is not None else "hat"
    noise = None  # the mosaic is merged as one channel: the CFA channels' model, pooled
    if cal.noise is not None:
        noise = hdr.NoiseModel(
            np.mean(np.asarray(cal.noise.gain), keepdims=True),
            np.mean(np.asarray(cal.noise.read_variance), keepdims=True),
        )
    rad, var = hdr.merge_radiance(
        np.clip(norm, 0.0, 1.0),
        eff_times,
        resp,
        weighting=weighting,
        noise=noise,
        return_variance=True,
    )
    steps.start("demosaic")
    rgb = np.asarray(image.demosaic(np.asarray(rad)[..., 0], pattern, method=cfg.demosaic))
    var_rgb = np.asarray(
        image.demosaic(np.asarray(var)[..., 0], pattern, method="bilinear"), np.float32
    )
    return CalibrateResult(
        radiance=rgb.astype(np.float32),
        variance=var_rgb,
        times=times,
        image_shape=mosaics.shape,
        raw_calibration=cal,
    )


def _as_job(job, inputs, out_dir, progress, overwrite) -> CalibrateJob:
    if job is None or isinstance(job, CalibrateConfig):
        job = CalibrateJob(config=job or CalibrateConfig())
    if not isinstance(job, CalibrateJob):
        raise TypeError(f"job: expected a CalibrateJob or CalibrateConfig, got {type(job)}")
    changes: dict = {}
    if inputs is not None:
        changes["inputs"] = (inputs,) if isinstance(inputs, (str, os.PathLike)) else inputs
    if out_dir is not None:
        changes["out"] = out_dir
    if progress is not None:
        changes["progress"] = progress
    if overwrite is not None:
        changes["overwrite"] = overwrite
    job = dataclasses.replace(job, **changes)
    return dataclasses.replace(
        job, inputs=tuple(os.fspath(i) for i in job.inputs or ()), out=os.fspath(job.out)
    )


def run_calibrate(
    job: CalibrateJob | CalibrateConfig | None = None,
    inputs=None,
    out_dir=None,
    *,
    progress: bool | None = None,
    overwrite: bool | None = None,
) -> dict:
    """Run the calibration job; returns the report dict (also written to ``report.json``).

    ``job``: a :class:`CalibrateJob` (or a :class:`CalibrateConfig`, with ``inputs``,
    ``out_dir``, ``progress``, ``overwrite`` given here; explicit arguments override the
    job's fields). Inputs and the output folder are checked before any computation; results
    appear in ``out`` only when the whole run succeeded (see :mod:`jaxgfx.pipelines._output`).
    The returned dict also has ``"replaced"``: the previous results that were replaced.
    """
    job = _as_job(job, inputs, out_dir, progress, overwrite)
    cfg = job.config
    files = _collect_inputs(job.inputs)
    is_raw = bool(files) and all(kind_of(f) == "raw" for f in files)
    if files and not is_raw and any(kind_of(f) == "raw" for f in files):
        raise ValueError("inputs: mix of RAW and LDR files; calibrate one kind at a time")
    if files and len(files) < 2:
        raise ValueError(f"inputs: a bracket needs at least 2 images, got {files}")
    t_all = time.perf_counter()
    with StagedDir(job.out, OUTPUT_NAMES, overwrite=job.overwrite) as stage:
        steps = _Steps(total=5 if files else 6, enabled=job.progress)
        try:
            if is_raw:
                result = _fit_raw(cfg, files, steps)
            else:
                result_kw: dict = {}
                images, times, truth = _load_ldr(
                    cfg, files, _find_sidecar(job.inputs), steps, result_kw
                )
                result = _fit_ldr(cfg, images, times, truth, steps, result_kw)
            steps.start("write outputs")
            names = _write_outputs(stage.path, result, cfg)
        finally:
            steps.close()
        names.append("report.json")
        outputs = {_OUTPUT_KEYS[n]: os.path.join(job.out, n) for n in names}
        timings = {**steps.timings, "total": round(time.perf_counter() - t_all, 4)}
        report = build_report(job, files, result, timings, outputs)
        with open(os.path.join(stage.path, "report.json"), "w", encoding="utf-8") as f:
            json.dump(_jsonable(report), f, indent=2)
    return {**report, "replaced": stage.replaced}
