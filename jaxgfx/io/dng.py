"""Minimal uncompressed Bayer DNG writer (tifffile), readable bit-exactly by rawpy / LibRaw.

Used to build synthetic RAW brackets with known exposure for the calibration code. The file is
a single-IFD DNG 1.4 (TIFF/EP layout): 16-bit CFA image (Photometric 32803), CFA tags, black
and white levels, ColorMatrix1 (XYZ → camera, D65), AsShotNeutral and the EXIF exposure tags
(ExposureTime, FNumber, ISOSpeedRatings) in IFD0 as TIFF/EP allows. Reference: Adobe, "Digital
Negative (DNG) Specification" 1.4 (2012).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import tifffile

from ._common import output_path

__all__ = ["write_dng", "CFA_COLORS"]

#: CFA letters → DNG CFAPattern colour codes (0 red, 1 green, 2 blue).
CFA_COLORS = {"R": 0, "G": 1, "B": 2}

# TIFF field types
_BYTE, _ASCII, _SHORT, _LONG, _RATIONAL, _SRATIONAL = 1, 2, 3, 4, 5, 10


def _rational(x: float, *, signed: bool = False, denom: int = 1_000_000) -> tuple[int, int]:
    f = Fraction(float(x)).limit_denominator(denom)
    num, den = f.numerator, f.denominator
    lim = 2**31 - 1 if signed else 2**32 - 1
    if abs(num) > lim or den > lim or (not signed and num < 0):
        raise ValueError(f"value {x} cannot be stored as a TIFF rational")
    return num, den


def _rationals(values, *, signed: bool = False) -> list[int]:
    out: list[int] = []
    for v in np.ravel(values):
        out.extend(_rational(v, signed=signed))
    return out


def _per_site(value, name: str) -> np.ndarray:
    arr = (
        np.broadcast_to(np.asarray(value, dtype=np.float64), (4,))
        if np.ndim(value) == 0
        else (np.asarray(value, dtype=np.float64))
    )
    if arr.shape != (4,):
        raise ValueError(f"{name}: expected a scalar or 4 values (one per CFA site), got {value!r}")
    return arr


def write_dng(
    path,
    mosaic_uint16,
    *,
    cfa_pattern: str = "RGGB",
    black_level=0,
    white_level: int = 65535,
    exposure_time: float | None = None,
    iso: float | None = None,
    f_number: float | None = None,
    camera_whitebalance=None,
    color_matrix=None,
    color_matrix2=None,
    calibration_illuminant1: int = 21,
    calibration_illuminant2: int = 17,
    forward_matrix1=None,
    forward_matrix2=None,
    camera_calibration1=None,
    camera_calibration2=None,
    analog_balance=None,
    color_tags: bool = True,
    make: str = "jaxgfx",
    model: str = "synthetic",
) -> None:
    """Write a Bayer mosaic ``(H, W)`` uint16 as an uncompressed DNG.

    ``cfa_pattern``: 4 letters of R/G/B for the 2x2 tile in row-major order (``"RGGB"``,
    ``"BGGR"``, ``"GRBG"``, ``"GBRG"``). ``black_level``: scalar or 4 values per CFA site (in
    ``cfa_pattern`` order), ``white_level``: saturation value (<= 65535). ``exposure_time`` (s),
    ``iso``, ``f_number``: EXIF exposure tags (omitted when ``None``). ``camera_whitebalance``:
    per-channel (R, G, B) multipliers; stored as AsShotNeutral = 1 / multiplier (normalised to
    green = 1). ``color_matrix``: 3x3 XYZ → camera matrix (ColorMatrix1) for
    ``calibration_illuminant1`` (an EXIF LightSource code, default 21 = D65); default identity.
    ``color_matrix2``: ColorMatrix2 for ``calibration_illuminant2`` (default 17 = Standard
    light A). ``forward_matrix1/2`` (camera → XYZ D50, ForwardMatrix1/2),
    ``camera_calibration1/2`` (CameraCalibration1/2) and ``analog_balance`` (3 values) are
    written when given. ``color_tags=False`` writes no colour tags at all (a DNG that is
    invalid for colour management, for tests of the refusal).
    H and W must be even and at least 22 (LibRaw's minimum). Values above ``white_level`` are
    allowed (stored as given).

    rawpy (LibRaw) reads back ``raw_image`` equal to ``mosaic_uint16``, ``raw_pattern`` /
    ``color_desc`` matching ``cfa_pattern``, ``black_level_per_channel``, ``white_level`` and
    ``camera_whitebalance``; :func:`jaxgfx.io.read_raw` also returns ``color_matrix`` (to
    rational precision 1e-6) and the EXIF tags (LibRaw leaves ``rgb_xyz_matrix`` zero for DNGs).
    """
    p = output_path(path)
    mosaic = np.asarray(mosaic_uint16)
    if mosaic.dtype != np.uint16:
        raise TypeError(f"mosaic_uint16: expected dtype uint16, got {mosaic.dtype}")
    if mosaic.ndim != 2 or mosaic.shape[0] % 2 or mosaic.shape[1] % 2 or min(mosaic.shape) < 22:
        raise ValueError(
            "mosaic_uint16: expected an (H, W) array with H, W even and >= 22 (LibRaw rejects "
            f"smaller raws), got shape {mosaic.shape}"
        )
    if (
        not isinstance(cfa_pattern, str)
        or len(cfa_pattern) != 4
        or set(cfa_pattern.upper()) != {"R", "G", "B"}
    ):
        raise ValueError(
            f"cfa_pattern: expected 4 letters of R, G, B like 'RGGB', got {cfa_pattern!r}"
        )
    cfa = [CFA_COLORS[c] for c in cfa_pattern.upper()]
    black = _per_site(black_level, "black_level")
    if np.any(black < 0) or np.any(black >= 65535):
        raise ValueError(f"black_level: expected values in [0, 65535), got {black_level!r}")
    if not (0 < int(white_level) <= 65535) or int(white_level) <= black.max():
        raise ValueError(f"white_level: expected black < white <= 65535, got {white_level!r}")
    cm = np.eye(3) if color_matrix is None else np.asarray(color_matrix, np.float64)
    if cm.shape != (3, 3) or not np.all(np.isfinite(cm)):
        raise ValueError(f"color_matrix: expected a finite 3x3 matrix, got shape {cm.shape}")

    tags = [
        (50706, _BYTE, 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, _BYTE, 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (271, _ASCII, 0, str(make), True),  # Make
        (272, _ASCII, 0, str(model), True),  # Model
        (50708, _ASCII, 0, f"{make} {model}", True),  # UniqueCameraModel
        (33421, _SHORT, 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, _BYTE, 4, tuple(cfa), True),  # CFAPattern
        (50710, _BYTE, 3, (0, 1, 2), True),  # CFAPlaneColor
        (50711, _SHORT, 1, (1,), True),  # CFALayout: rectangular
        (50713, _SHORT, 2, (2, 2), True),  # BlackLevelRepeatDim
        (50714, _RATIONAL, 4, tuple(_rationals(black)), True),  # BlackLevel
        (50717, _LONG, 1, (int(white_level),), True),  # WhiteLevel
    ]
    if color_tags:
        tags += [
            (50721, _SRATIONAL, 9, tuple(_rationals(cm, signed=True)), True),  # ColorMatrix1
            (50778, _SHORT, 1, (int(calibration_illuminant1),), True),  # CalibrationIlluminant1
        ]
        for code, value, name in (
            (50722, color_matrix2, "color_matrix2"),
            (50723, camera_calibration1, "camera_calibration1"),
            (50724, camera_calibration2, "camera_calibration2"),
            (50964, forward_matrix1, "forward_matrix1"),
            (50965, forward_matrix2, "forward_matrix2"),
        ):
            if value is not None:
                m = np.asarray(value, np.float64)
                if m.shape != (3, 3) or not np.all(np.isfinite(m)):
                    raise ValueError(f"{name}: expected a finite 3x3 matrix, got shape {m.shape}")
                tags.append((code, _SRATIONAL, 9, tuple(_rationals(m, signed=True)), True))
        if color_matrix2 is not None:
            tags.append((50779, _SHORT, 1, (int(calibration_illuminant2),), True))
        if analog_balance is not None:
            ab = np.asarray(analog_balance, np.float64).ravel()
            if ab.shape != (3,) or not np.all(ab > 0) or not np.all(np.isfinite(ab)):
                raise ValueError(f"analog_balance: expected 3 positive values, got {ab}")
            tags.append((50727, _RATIONAL, 3, tuple(_rationals(ab)), True))  # AnalogBalance
    if camera_whitebalance is not None:
        wb = np.asarray(camera_whitebalance, np.float64).ravel()
        if wb.shape != (3,) or not np.all(wb > 0) or not np.all(np.isfinite(wb)):
            raise ValueError(
                f"camera_whitebalance: expected 3 positive multipliers (R, G, B), got {wb}"
            )
        neutral = wb[1] / wb
        if color_tags:
            tags.append((50728, _RATIONAL, 3, tuple(_rationals(neutral)), True))  # AsShotNeutral
    for code, value, name in (
        (33434, exposure_time, "exposure_time"),
        (33437, f_number, "f_number"),
    ):
        if value is not None:
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name}: expected a positive number, got {value!r}")
            tags.append((code, _RATIONAL, 1, _rational(value, denom=2**31 - 1), True))
    if iso is not None:
        if not np.isfinite(iso) or not (0 < iso <= 65535):
            raise ValueError(f"iso: expected a number in (0, 65535], got {iso!r}")
        tags.append((34855, _SHORT, 1, (int(round(iso)),), True))  # ISOSpeedRatings

    try:
        tifffile.imwrite(
            p,
            np.ascontiguousarray(mosaic),
            photometric=32803,  # CFA
            planarconfig="contig",
            compression=None,
            subfiletype=0,
            software="jaxgfx",
            metadata=None,
            extratags=tags,
        )
    except (OSError, ValueError, TypeError) as e:
        raise ValueError(f"'{p}': could not write DNG ({e})") from None
