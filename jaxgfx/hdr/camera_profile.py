"""Camera profiles: the fitted camera of ``jaxgfx calibrate`` as one JSON file (``camera.json``).

:func:`save_camera_profile` writes, each piece optional (``null`` when the run did not fit it):
the response curve (the dict of :func:`jaxgfx.hdr.save_response`'s file, embedded: LDR
brackets), the white balance gains and the camera -> output matrix with its colour space (RAW
brackets, :class:`jaxgfx.hdr.raw.ColorTransform`), the noise model
(:class:`jaxgfx.hdr.NoiseModel`, normalised units), the lens vignetting
(:class:`jaxgfx.hdr.raw.Vignetting`) and a colour-chart fit
(:class:`jaxgfx.hdr.raw.ChartCalibration`: model, matrix, gains, neutral, per-patch ΔE00 before
and after; :func:`jaxgfx.hdr.raw.apply_chart_calibration` applies it).
:func:`load_camera_profile` returns a :class:`CameraProfile` with the same pieces: arrays are
written with their dtype and as the Python float of equal value, so they come back
bit-identical. :func:`jaxgfx.hdr.load_response` also reads the response out of a camera
profile.

``matrix`` maps white-balanced-and-not camera RGB as ``radiance.exr`` does: ``out = matrix @
camera_rgb``, the white balance gains included (``matrix = M @ diag(gains)``); the gains are
also given on their own (``max`` 1 channel at 1).
"""

from __future__ import annotations

import json
import os
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ._model import CameraResponse
from .noise import NoiseModel
from .raw.chart import ChartCalibration
from .raw.vignetting import Vignetting
from .response_io import _array_entry, response_from_dict, response_to_dict

__all__ = ["CAMERA_PROFILE_FORMAT", "CameraProfile", "save_camera_profile", "load_camera_profile"]

CAMERA_PROFILE_FORMAT = "jaxgfx-camera"
"""The ``format`` field of a camera profile written by :func:`save_camera_profile`."""


class CameraProfile(NamedTuple):
    """The pieces of a camera profile (``None``: not in the file)."""

    response: CameraResponse | None = None
    white_balance_gains: np.ndarray | None = None  # (3,) float64
    matrix: np.ndarray | None = None  # (3, 3) float64, camera RGB -> colorspace
    colorspace: str | None = None
    noise: NoiseModel | None = None
    vignetting: Vignetting | None = None
    chart: ChartCalibration | None = None


def _array(entry, path, name, shape=None, *, allow_nan=False):
    err = f"camera profile {path}: {name}"
    if not (isinstance(entry, dict) and "data" in entry):
        raise ValueError(f"{err}: expected an array record (dtype, shape, data)")
    try:
        a = np.asarray(entry["data"], dtype=entry.get("dtype", "float64"))
        a = a.reshape(entry.get("shape", a.shape))
    except (TypeError, ValueError) as e:
        raise ValueError(f"{err}: not an array ({e})") from None
    if shape is not None and a.shape != shape:
        raise ValueError(f"{err}: expected shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a) | (allow_nan and np.isnan(a))):
        raise ValueError(f"{err}: expected finite values")
    return a


def save_camera_profile(
    path,
    *,
    response: CameraResponse | None = None,
    white_balance_gains=None,
    matrix=None,
    colorspace: str | None = None,
    noise: NoiseModel | None = None,
    vignetting: Vignetting | None = None,
    chart: ChartCalibration | None = None,
    source: dict | None = None,
) -> str:
    """Write a camera profile to the JSON file ``path`` (format in the module doc); returns
    the path. ``source``: free-form provenance (inputs, where the matrix came from).

    >>> import tempfile, os
    >>> p = os.path.join(tempfile.mkdtemp(), "camera.json")
    >>> _ = save_camera_profile(p, matrix=np.eye(3), colorspace="rec709")
    >>> load_camera_profile(p).matrix.tolist()[0]
    [1.0, 0.0, 0.0]
    """
    if response is not None and not isinstance(response, CameraResponse):
        raise TypeError(f"response: expected a CameraResponse, got {type(response).__name__}")
    if noise is not None and not isinstance(noise, NoiseModel):
        raise TypeError(f"noise: expected a NoiseModel, got {type(noise).__name__}")
    if vignetting is not None and not isinstance(vignetting, Vignetting):
        raise TypeError(f"vignetting: expected a Vignetting, got {type(vignetting).__name__}")
    if chart is not None and not isinstance(chart, ChartCalibration):
        raise TypeError(f"chart: expected a ChartCalibration, got {type(chart).__name__}")
    if (matrix is None) != (colorspace is None):
        raise ValueError("matrix, colorspace: give both (the matrix maps camera RGB to it)")
    for name, v, shape in (("white_balance_gains", white_balance_gains, (3,)),
                           ("matrix", matrix, (3, 3))):  # fmt: skip
        if v is not None and np.shape(v) != shape:
            raise ValueError(f"{name}: expected shape {shape}, got {np.shape(v)}")
    noise_doc = None
    if noise is not None:
        noise_doc = {
            k: None if getattr(noise, k) is None else _array_entry(getattr(noise, k))
            for k in ("gain", "read_variance", "black_level", "white_level")
        }
    doc = {
        "format": CAMERA_PROFILE_FORMAT,
        "version": 1,
        "response": None if response is None else response_to_dict(response),
        "white_balance_gains": None
        if white_balance_gains is None
        else _array_entry(np.asarray(white_balance_gains, np.float64)),
        "matrix": None if matrix is None else _array_entry(np.asarray(matrix, np.float64)),
        "colorspace": colorspace,
        "noise": noise_doc,
        "vignetting": None
        if vignetting is None
        else {
            **vignetting.to_dict(),
            "coefficients": _array_entry(vignetting.coefficients),
            "center_yx_px": _array_entry(vignetting.center),
        },
        "chart": None
        if chart is None
        else {
            **chart.to_dict(),
            **{k: _nan_to_null(_array_entry(getattr(chart, k))) for k in _CHART_ARRAYS},
        },
        "source": source or {},
    }
    path = os.fspath(path)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(doc, f, indent=1)
    return path


def load_camera_profile(path) -> CameraProfile:
    """Read a camera profile (``camera.json`` of ``jaxgfx calibrate``,
    :func:`save_camera_profile`). Every error names the file: ``FileNotFoundError`` for a
    missing one, one ``ValueError`` for a file that is not JSON, not a camera profile, or holds a
    malformed piece."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"camera profile not found: {path}")
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"camera profile {path}: not a JSON file ({e})") from None
    if not isinstance(doc, dict) or doc.get("format") != CAMERA_PROFILE_FORMAT:
        raise ValueError(
            f"camera profile {path}: not a camera profile (expected \"format\": "
            f"{CAMERA_PROFILE_FORMAT!r}, as written by jaxgfx calibrate's camera.json)"
        )
    resp = doc.get("response")
    response = None if resp is None else response_from_dict(resp, path)
    gains = doc.get("white_balance_gains")
    gains = None if gains is None else _array(gains, path, "white_balance_gains", (3,))
    matrix = doc.get("matrix")
    matrix = None if matrix is None else _array(matrix, path, "matrix", (3, 3))
    colorspace = doc.get("colorspace")
    if (matrix is None) != (colorspace is None) or not (
        colorspace is None or isinstance(colorspace, str)
    ):
        raise ValueError(f"camera profile {path}: matrix and colorspace go together")
    noise = None
    if doc.get("noise") is not None:
        nd = doc["noise"]
        if not isinstance(nd, dict) or nd.get("gain") is None or nd.get("read_variance") is None:
            raise ValueError(f"camera profile {path}: noise: expected gain and read_variance")
        arrs = {
            k: None if nd.get(k) is None else jnp.asarray(_array(nd[k], path, f"noise.{k}"))
            for k in ("gain", "read_variance", "black_level", "white_level")
        }
        try:
            noise = NoiseModel(**arrs)
        except ValueError as e:
            raise ValueError(f"camera profile {path}: noise: {e}") from None
    vig = None
    if doc.get("vignetting") is not None:
        vd = doc["vignetting"]
        if not isinstance(vd, dict):
            raise ValueError(f"camera profile {path}: vignetting: expected an object")
        vig = Vignetting.from_dict(
            {
                **vd,
                "coefficients": _array(vd.get("coefficients"), path, "vignetting.coefficients"),
                "center_yx_px": _array(vd.get("center_yx_px"), path, "vignetting.center_yx_px"),
            },
            f"camera profile {path}: vignetting",
        )
    chart = None
    if doc.get("chart") is not None:
        cd = doc["chart"]
        if not isinstance(cd, dict):
            raise ValueError(f"camera profile {path}: chart: expected an object")
        arrs = {k: _array(cd.get(k), path, f"chart.{k}") if k in ("matrix", "gains", "neutral")
                else _array_nan(cd.get(k), path, f"chart.{k}") for k in _CHART_ARRAYS}  # fmt: skip
        try:
            chart = ChartCalibration(
                *(jnp.asarray(arrs[k]) for k in _CHART_ARRAYS),
                str(cd.get("model")),
                str(cd.get("illuminant")),
                bool(cd.get("white_balance", True)),
                str(cd.get("before_source", "")),
            )
        except (TypeError, ValueError) as e:
            raise ValueError(f"camera profile {path}: chart: {e}") from None
    return CameraProfile(response, gains, matrix, colorspace, noise, vig, chart)


_CHART_ARRAYS = ("matrix", "gains", "neutral", "delta_e_before", "delta_e_after")


def _nan_to_null(entry):
    """Strict JSON: NaN (a chart patch left out) written as null."""
    return {**entry, "data": [None if v != v else v for v in entry["data"]]}


def _array_nan(entry, path, name):
    """An array record that may hold NaN (written as null: patches left out)."""
    if not (isinstance(entry, dict) and isinstance(entry.get("data"), list)):
        raise ValueError(f"camera profile {path}: {name}: expected an array record")
    data = [np.nan if v is None else v for v in entry["data"]]
    return _array({**entry, "data": data, "dtype": entry.get("dtype", "float64")}, path, name,
                  allow_nan=True)  # fmt: skip
