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
    frames.png          merge.deghost only: hue = each pixel's reference frame (blue shortest
                        .. red longest exposure), brightness = share of the frames merged there
    vignetting.png      RAW with flat_field: the fitted lens falloff
    chart.png           RAW with chart: patches reference | before | after and their ΔE00
    camera.json         the fitted camera (hdr.load_camera_profile)
    response.png        fitted response curves (and the ground truth for synthetic stacks)
    loo.png             leave-one-out self-check per level band and held frame (LDR)
    preview.png         exposure-normalised sRGB preview of the radiance map
    tonemap_<op>.png    one display image per operator of ``config.tonemap`` (jaxgfx.tonemap)
    report.json         fitted parameters, uncertainties, residuals, errors, timings

Only when the whole run succeeded do they appear in ``out`` (staged next to it, then moved
into place); ``out`` holding a previous run's results is refused unless ``overwrite``.
``jaxgfx calibrate`` and ``experiments/calibrate.py`` are thin argument-to-job layers over
:func:`run_calibrate`; the report is assembled in :func:`build_report` only.

The package is the job's stages: ``config`` (frozen, self-validating dataclasses), ``inputs``
(files, kind, sidecar), ``ldr`` (load, align, response fit, merge, self-check), ``raw`` (align,
sensor calibration, merge, demosaic), ``report`` (result record, outputs, report.json), ``plots``
and ``job`` (``run_calibrate``).
"""

from __future__ import annotations

from .config import AlignConfig as AlignConfig
from .config import CalibrateConfig as CalibrateConfig
from .config import MergeConfig as MergeConfig
from .config import ResponseConfig as ResponseConfig
from .config import SyntheticConfig as SyntheticConfig
from .inputs import SIDECAR_NAMES as SIDECAR_NAMES
from .job import CalibrateJob as CalibrateJob
from .job import run_calibrate as run_calibrate
from .report import OUTPUT_NAMES as OUTPUT_NAMES
from .report import CalibrateResult as CalibrateResult
from .report import build_report as build_report

__all__ = [
    "SyntheticConfig",
    "ResponseConfig",
    "MergeConfig",
    "AlignConfig",
    "CalibrateConfig",
    "CalibrateJob",
    "CalibrateResult",
    "OUTPUT_NAMES",
    "SIDECAR_NAMES",
    "build_report",
    "run_calibrate",
]
