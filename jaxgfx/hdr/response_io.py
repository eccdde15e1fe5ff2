"""Response files: :func:`save_response` writes a :class:`CameraResponse` to JSON and
:func:`load_response` reads it back exactly (also the ``report.json`` of ``jaxgfx
calibrate``, whose ``response.summary`` holds the same fields).

The file (``"format": "jaxgfx-response"``, version 1) holds the curve family ``kind``, the
``method`` that produced it, ``code_max`` (the bit depth of the levels it was fitted on:
255, 65535, or 1.0 for float levels), ``anchor``, ``params`` and ``exposure_ratios`` (with
their dtypes) and the numeric ``diagnostics``. A float32 value is written as the Python float
of equal value (float32 -> float64 is exact, and JSON keeps 17 significant digits), so a
saved and loaded response has bit-identical arrays.
"""

from __future__ import annotations

import json
import os

import jax.numpy as jnp
import numpy as np

from .._checks import check_choice
from ._model import RESPONSE_KINDS, CameraResponse

__all__ = [
    "save_response",
    "load_response",
    "response_to_dict",
    "response_from_dict",
    "RESPONSE_FILE_FORMAT",
]

RESPONSE_FILE_FORMAT = "jaxgfx-response"
"""The ``format`` field of a response file written by :func:`save_response`."""

_FIELDS = ("kind", "method", "code_max", "anchor", "params")


def _array_entry(a) -> dict:
    a = np.asarray(a)
    return {"dtype": str(a.dtype), "shape": list(a.shape), "data": a.ravel().tolist()}


def _array_from(entry, path, name):
    if isinstance(entry, dict) and "data" in entry:
        try:
            a = np.asarray(entry["data"], dtype=entry.get("dtype", "float32"))
            return a.reshape(entry.get("shape", a.shape))
        except (TypeError, ValueError) as e:
            raise ValueError(f"response file {path}: {name}: not an array ({e})") from None
    try:  # calibrate's report.json: nested lists (float32 written by the library)
        return np.asarray(entry, np.float32)
    except (TypeError, ValueError) as e:
        raise ValueError(f"response file {path}: {name}: not an array ({e})") from None


def response_to_dict(response: CameraResponse) -> dict:
    """The JSON-ready dict :func:`save_response` writes (also embedded in a camera profile,
    :func:`jaxgfx.hdr.save_camera_profile`); :func:`response_from_dict` inverts it."""
    if not isinstance(response, CameraResponse):
        raise TypeError(f"response: expected a CameraResponse, got {type(response).__name__}")
    diag = {
        k: _array_entry(v)
        for k, v in response.diagnostics.items()
        if hasattr(v, "shape") or isinstance(v, (int, float))
    }
    return {
        "format": RESPONSE_FILE_FORMAT,
        "version": 1,
        "kind": response.kind,
        "method": response.method,
        "code_max": float(response.code_max),
        "anchor": float(response.anchor),
        "params": _array_entry(response.params),
        "exposure_ratios": None
        if response.exposure_ratios is None
        else _array_entry(response.exposure_ratios),
        "diagnostics": diag,
    }


def save_response(path, response: CameraResponse) -> str:
    """Write ``response`` to the JSON file ``path`` (format in the module doc); returns the
    path. :func:`load_response` reads it back with identical fields and arrays.

    >>> import tempfile, os
    >>> r = CameraResponse.gamma(2.2, channels=3, code_max=255.0)
    >>> p = save_response(os.path.join(tempfile.mkdtemp(), "camera.json"), r)
    >>> bool(np.all(np.asarray(load_response(p, bits=8).params) == np.asarray(r.params)))
    True
    """
    doc = response_to_dict(response)
    path = os.fspath(path)
    with open(path, "w", encoding="utf-8") as f:
        json.dump(doc, f, indent=1)
    return path


def _bits_of(code_max: float):
    return {255.0: 8, 65535.0: 16, 1.0: None}.get(float(code_max), "other")


def load_response(path, *, bits: int | None = None) -> CameraResponse:
    """Read a :class:`CameraResponse` from ``path``: a file of :func:`save_response`, the
    ``report.json`` of ``jaxgfx calibrate`` (its ``response.summary``), or a camera profile
    (``camera.json``, :func:`jaxgfx.hdr.save_camera_profile`, its ``response``).

    ``bits`` (8 or 16): the bit depth of the photos it will linearise; a response fitted on
    levels of another bit depth raises ``ValueError`` (a response fitted on float levels,
    ``code_max`` 1.0, is depth-independent and accepted). Errors name the file:
    ``FileNotFoundError`` for a missing one, ``ValueError`` for one that is not JSON, holds no
    response, or an unknown curve kind.
    """
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise FileNotFoundError(f"response file not found: {path}")
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"response file {path}: not a JSON response file ({e})") from None
    if not isinstance(doc, dict):
        raise ValueError(f"response file {path}: expected a JSON object")
    if doc.get("format") != RESPONSE_FILE_FORMAT:
        section = doc.get("response")
        section = section if isinstance(section, dict) else {}
        # a camera profile (jaxgfx.hdr.save_camera_profile) embeds a response file's dict
        summary = section if section.get("format") == RESPONSE_FILE_FORMAT else None
        summary = summary or section.get("summary")
        if not isinstance(summary, dict):
            raise ValueError(
                f"response file {path}: neither a response file (format "
                f"{RESPONSE_FILE_FORMAT!r}) nor a calibrate report with a 'response' section "
                "(a RAW calibration has no response curve)"
            )
        doc = summary
    return response_from_dict(doc, path, bits=bits)


def response_from_dict(doc: dict, path, *, bits: int | None = None) -> CameraResponse:
    """The :class:`CameraResponse` of a dict of :func:`response_to_dict` (``path``: the file
    it came from, for the messages; ``bits`` as in :func:`load_response`)."""
    if not isinstance(doc, dict):
        raise ValueError(f"response file {path}: expected a JSON object for the response")
    missing = [k for k in _FIELDS if k not in doc]
    if missing:
        raise ValueError(f"response file {path}: missing field(s) {', '.join(missing)}")
    check_choice(doc["kind"], f"response file {path}: kind", RESPONSE_KINDS)
    code_max = float(doc["code_max"])
    file_bits = _bits_of(code_max)
    if file_bits == "other":
        raise ValueError(f"response file {path}: code_max {code_max:g} is not 255, 65535 or 1")
    if bits is not None:
        if bits not in (8, 16):
            raise ValueError(f"bits: expected 8 or 16, got {bits!r}")
        if file_bits is not None and file_bits != bits:
            raise ValueError(
                f"response file {path}: a {file_bits}-bit response (levels 0..{code_max:g}) "
                f"cannot linearise {bits}-bit photos; calibrate from a {bits}-bit bracket"
            )
    params = jnp.asarray(_array_from(doc["params"], path, "params"))
    ratios = doc.get("exposure_ratios")
    ratios = None if ratios is None else jnp.asarray(_array_from(ratios, path, "exposure_ratios"))
    diag = {
        k: jnp.asarray(_array_from(v, path, f"diagnostics.{k}"))
        for k, v in (doc.get("diagnostics") or {}).items()
        if isinstance(v, dict)
    }
    if params.ndim < 1:
        raise ValueError(f"response file {path}: params: expected an array, got a scalar")
    return CameraResponse(
        params, doc["kind"], str(doc["method"]), code_max, float(doc["anchor"]), ratios, diag
    )
