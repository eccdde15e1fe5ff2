"""Camera RAW reading through rawpy (LibRaw), with EXIF exposure data through tifffile.

:func:`read_raw` returns the undemosaiced sensor mosaic and its calibration metadata as a
frozen :class:`RawImage`; :func:`read_raw_linear_rgb` demosaics with LibRaw in linear camera
space. Exposure time, ISO and aperture are read from the TIFF/EXIF tags of TIFF-based raws
(DNG, NEF, CR2, ARW, PEF, ...; tags 33434 ExposureTime, 33437 FNumber, 34855 ISOSpeedRatings,
in IFD0, the EXIF IFD or SubIFDs) with ``tifffile`` and :func:`read_raw_exif` (also Canon
CR3); when absent they are ``None`` and ``RawImage.exif_fields`` says which were found.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import rawpy
import tifffile

from ._common import existing_file
from ._exif import read_raw_exif

__all__ = ["RawImage", "read_raw", "read_raw_linear_rgb", "read_raw_stack", "read_raw_exif"]

_EXIF_TAGS = {
    "exposure_time": (33434, ("ExposureTime",)),
    "f_number": (33437, ("FNumber",)),
    "iso": (34855, ("ISOSpeedRatings", "PhotographicSensitivity")),
}


#: DNG colour tags read into :attr:`RawImage.dng_color` (flat float64 arrays; illuminants as
#: EXIF LightSource codes). Adobe, DNG Specification 1.4, chapter 6.
_DNG_COLOR_TAGS = {
    50721: "color_matrix1",
    50722: "color_matrix2",
    50723: "camera_calibration1",
    50724: "camera_calibration2",
    50727: "analog_balance",
    50728: "as_shot_neutral",
    50729: "as_shot_white_xy",
    50778: "calibration_illuminant1",
    50779: "calibration_illuminant2",
    50964: "forward_matrix1",
    50965: "forward_matrix2",
}


@dataclasses.dataclass(frozen=True, eq=False)
class RawImage:
    """An undemosaiced RAW frame (host NumPy data).

    Attributes:
        mosaic: ``(H, W)`` uint16 visible sensor area, an owned copy (not a LibRaw view).
        raw_colors: ``(H, W)`` uint8 colour index of each pixel (0..3) into ``color_desc``.
        cfa_pattern: colours of the repeating CFA tile in row-major order, e.g. ``"RGGB"``
            (2x2 Bayer) or a 36-letter string for 6x6 X-Trans.
        color_desc: LibRaw's colour names for indices 0..3, e.g. ``"RGBG"``.
        black_level: ``(4,)`` float64 black level per CFA site of the 2x2 tile, in
            ``cfa_pattern`` order (``"RGGB"`` → R, G1, G2, B; the order of
            ``jaxgfx.hdr.cfa_channels``). For non-2x2 CFAs: per colour index.
        black_level_per_color: ``(4,)`` the same levels per colour index 0..3 (rawpy's
            ``black_level_per_channel``, indexed by ``raw_colors``).
        white_level: saturation level (raw units).
        camera_whitebalance: ``(4,)`` as-shot multipliers per colour index, i.e. in
            ``color_desc`` order (LibRaw ``cam_mul``; 0 when absent).
        color_matrix: ``(3, 4)`` camera → sRGB matrix from LibRaw (``rgb_cam``).
        rgb_xyz_matrix: ``(4, 3)`` XYZ → camera matrix (LibRaw ``cam_xyz``; for DNGs where
            LibRaw leaves it zero, the file's ColorMatrix1 in the first three rows).
        exposure_time: seconds, or ``None``; ``iso``; ``f_number``: from EXIF, or ``None``.
        make, model: camera make and model strings ("" when unknown).
        path: the file read.
        exif_fields: names among ``exposure_time, iso, f_number`` that were found.
        is_dng: the file is a DNG (has the DNGVersion tag).
        dng_color: the DNG colour tags found (``color_matrix1/2``, ``forward_matrix1/2``,
            ``camera_calibration1/2``, ``analog_balance``, ``as_shot_neutral``,
            ``as_shot_white_xy``, ``calibration_illuminant1/2``), flat float64 arrays.
    """

    mosaic: np.ndarray
    raw_colors: np.ndarray
    cfa_pattern: str
    color_desc: str
    black_level: np.ndarray
    black_level_per_color: np.ndarray
    white_level: int
    camera_whitebalance: np.ndarray
    color_matrix: np.ndarray
    rgb_xyz_matrix: np.ndarray
    exposure_time: float | None
    iso: float | None
    f_number: float | None
    make: str
    model: str
    path: str
    exif_fields: tuple[str, ...] = ()
    is_dng: bool = False
    dng_color: dict = dataclasses.field(default_factory=dict)

    def normalized(self) -> np.ndarray:
        """Float32 mosaic ``(x - black[c]) / (white - black[c])`` per CFA site (not clipped:
        noise below black stays negative, saturated pixels reach ~1)."""
        black = self.black_level_per_color[self.raw_colors]
        return ((self.mosaic - black) / (self.white_level - black)).astype(np.float32)


def _as_float(v, *, rational: bool = True) -> float | None:
    """A tag value as float: ``(num, den)`` pairs are rationals when ``rational``; for other
    sequences (e.g. ISOSpeedRatings with several values) the first element."""
    if v is None:
        return None
    if rational and isinstance(v, tuple) and len(v) == 2:
        num, den = v
        return float(num) / float(den) if den else None
    if isinstance(v, (tuple, list, np.ndarray)):
        v = np.ravel(v)
        return float(v[0]) if v.size else None
    try:
        return float(v)
    except (TypeError, ValueError):
        return None


def _tiff_metadata(p: Path) -> dict:
    """EXIF exposure tags, make/model, ColorMatrix1 and strip extents of a TIFF-based raw."""
    out: dict = {}
    try:
        with tifffile.TiffFile(p) as tif:
            size = p.stat().st_size
            for page in tif.pages[:4]:
                tags = page.tags
                for key, code in (("make", 271), ("model", 272)):
                    if key not in out and code in tags:
                        out[key] = str(tags[code].value).strip("\x00 ")
                if 50706 in tags:
                    out["is_dng"] = True
                for code, key in _DNG_COLOR_TAGS.items():
                    if key not in out.setdefault("dng_color", {}) and code in tags:
                        tag = tags[code]
                        vals = np.asarray(tag.value, np.float64).ravel()
                        if vals.size == 2 * tag.count:  # (S)RATIONAL: numerator, denominator
                            vals = vals[0::2] / np.where(vals[1::2] == 0, 1.0, vals[1::2])
                        out["dng_color"][key] = vals
                if "color_matrix1" in out["dng_color"]:
                    out["color_matrix1"] = out["dng_color"]["color_matrix1"]
                for key, (code, _names) in _EXIF_TAGS.items():
                    if key not in out and code in tags:
                        out[key] = _as_float(tags[code].value, rational=key != "iso")
                exif = tags[34665].value if 34665 in tags else None
                if isinstance(exif, dict):
                    for key, (_, names) in _EXIF_TAGS.items():
                        for n in names:
                            if key not in out and n in exif:
                                out[key] = _as_float(exif[n], rational=key != "iso")
                ends = [o + c for o, c in zip(page.dataoffsets, page.databytecounts, strict=False)]
                if ends and max(ends) > size:
                    out["truncated"] = True
    except (tifffile.TiffFileError, OSError, ValueError, KeyError, IndexError, TypeError):
        return {}
    return out


def _open_raw(p: Path):
    try:
        raw = rawpy.imread(str(p))
    except rawpy.LibRawError as e:
        raise ValueError(f"'{p}': not a readable RAW file ({type(e).__name__}: {e})") from None
    except (OSError, ValueError) as e:
        raise ValueError(f"'{p}': not a readable RAW file ({e})") from None
    return raw


def _cfa_string(pattern: np.ndarray, desc: str) -> str:
    return "".join(desc[int(i)] if 0 <= int(i) < len(desc) else "?" for i in pattern.ravel())


def read_raw(path) -> RawImage:
    """Read a camera RAW file (any format LibRaw supports) without demosaicing.

    The mosaic and colour-index arrays are copied while the LibRaw handle is open (rawpy's
    ``raw_image`` is a view into LibRaw's buffer that dangles after ``close``). Raises
    ``FileNotFoundError`` for a missing file and ``ValueError`` naming the file for corrupt,
    truncated or unsupported files (LibRaw errors are caught).

    >>> r = read_raw("bracket_0.dng")  # doctest: +SKIP
    >>> r.cfa_pattern, r.mosaic.dtype  # doctest: +SKIP
    ('RGGB', dtype('uint16'))
    """
    p = existing_file(path)
    meta = _tiff_metadata(p)
    if any(meta.get(k) is None for k in ("exposure_time", "iso", "f_number")):
        # NEF / CR2 / ARW sub-IFDs that tifffile did not reach, and CR3 (not TIFF)
        for k, v in read_raw_exif(p).items():
            meta.setdefault(k, v)
    if meta.get("truncated"):
        raise ValueError(f"'{p}': truncated RAW file (image data extends past end of file)")
    raw = _open_raw(p)
    try:
        with raw:
            mosaic = np.array(raw.raw_image_visible, dtype=np.uint16, copy=True)
            colors = np.array(raw.raw_colors_visible, dtype=np.uint8, copy=True)
            desc = raw.color_desc.decode("ascii", "replace")
            pattern = np.array(raw.raw_pattern, copy=True)
            black = np.array(raw.black_level_per_channel, dtype=np.float64)
            white = int(raw.white_level)
            cam_wb = np.array(raw.camera_whitebalance, dtype=np.float64)
            color_matrix = np.array(raw.color_matrix, dtype=np.float64, copy=True)
            rgb_xyz = np.array(raw.rgb_xyz_matrix, dtype=np.float64, copy=True)
    except rawpy.LibRawError as e:
        raise ValueError(f"'{p}': corrupt RAW data ({type(e).__name__}: {e})") from None
    if mosaic.ndim != 2 or mosaic.size == 0:
        raise ValueError(f"'{p}': not a single-plane CFA raw (mosaic shape {mosaic.shape})")
    if not np.any(rgb_xyz) and "color_matrix1" in meta and meta["color_matrix1"].size >= 9:
        rgb_xyz = np.zeros((4, 3))
        cm = meta["color_matrix1"].ravel()
        n = cm.size // 3
        rgb_xyz[:n] = cm[: 3 * n].reshape(n, 3)
    if pattern.shape == (2, 2) and colors.shape[0] >= 2 and colors.shape[1] >= 2:
        pattern = colors[:2, :2]  # the tile at the visible origin (margins may shift it)
        black_sites = black[pattern.ravel()]
    else:
        black_sites = black.copy()
    found = tuple(k for k in ("exposure_time", "iso", "f_number") if meta.get(k) is not None)
    return RawImage(
        mosaic=mosaic,
        raw_colors=colors,
        cfa_pattern=_cfa_string(pattern, desc),
        color_desc=desc,
        black_level=black_sites,
        black_level_per_color=black,
        white_level=white,
        camera_whitebalance=cam_wb,
        color_matrix=color_matrix,
        rgb_xyz_matrix=rgb_xyz,
        exposure_time=meta.get("exposure_time"),
        iso=meta.get("iso"),
        f_number=meta.get("f_number"),
        make=meta.get("make", ""),
        model=meta.get("model", ""),
        path=str(p),
        exif_fields=found,
        is_dng=bool(meta.get("is_dng", False)),
        dng_color=dict(meta.get("dng_color", {})),
    )


def read_raw_linear_rgb(path) -> np.ndarray:
    """Demosaic a RAW file with LibRaw into linear camera RGB, float32 ``(H, W, 3)`` in ~[0, 1].

    Settings: ``gamma=(1, 1)`` (no transfer curve), ``no_auto_bright=True``, ``output_bps=16``,
    ``user_wb=[1, 1, 1, 1]`` (no white balance), ``output_color=rawpy.ColorSpace.raw`` (camera
    primaries, no colour matrix), ``adjust_maximum_thr=0`` (keep the file's white level),
    default AHD demosaicing; LibRaw subtracts black and scales ``white - black`` to 65535, and
    the result is divided by 65535. So for a flat colour patch the value of channel ``c`` is
    ``(x_c - black_c) / (white - black_c)``, up to LibRaw's integer scaling.
    """
    p = existing_file(path)
    meta = _tiff_metadata(p)
    if meta.get("truncated"):
        raise ValueError(f"'{p}': truncated RAW file (image data extends past end of file)")
    raw = _open_raw(p)
    try:
        with raw:
            rgb = raw.postprocess(
                gamma=(1, 1),
                no_auto_bright=True,
                output_bps=16,
                user_wb=[1.0, 1.0, 1.0, 1.0],
                output_color=rawpy.ColorSpace.raw,
                adjust_maximum_thr=0.0,
            )
    except rawpy.LibRawError as e:
        raise ValueError(f"'{p}': corrupt RAW data ({type(e).__name__}: {e})") from None
    return (np.asarray(rgb, np.float32) / 65535.0).astype(np.float32)


def read_raw_stack(paths, *, exposure_times=None) -> tuple[list[RawImage], np.ndarray]:
    """Read a bracket of RAW files, sorted by exposure time (shortest first).

    ``exposure_times``: ``N`` positive seconds in ``paths`` order (``None`` or empty: each
    file's EXIF ExposureTime, times the aperture and ISO ratios when the frames differ in them
    too, :func:`jaxgfx.io.exposure_values`; explicit times are taken as the exposures).
    Returns ``(raws, times)``: the :class:`RawImage` frames and
    ``(N,)`` float64 seconds, ascending (:func:`jaxgfx.io.exposure_order`). Raises
    ``ValueError`` naming the file with no (or a zero) exposure time, or when the CFA
    patterns or mosaic sizes differ.
    """
    from .ldr import exposure_order, exposure_values, parse_exposure_time

    if isinstance(paths, (str, bytes)) or not hasattr(paths, "__len__") or len(paths) == 0:
        raise ValueError(f"paths: expected a non-empty list of RAW files, got {paths!r}")
    raws = [read_raw(q) for q in paths]
    n = len(raws)
    if exposure_times is not None and len(exposure_times) > 0:
        if len(exposure_times) != n:
            raise ValueError(
                f"exposure_times: expected {n} values (one per file), got {len(exposure_times)}"
            )
        times = [
            parse_exposure_time(t, f"exposure_times[{i}]") for i, t in enumerate(exposure_times)
        ]
    else:
        times = []
        for r in raws:
            if r.exposure_time is None:
                raise ValueError(f"'{r.path}': no EXIF ExposureTime; pass exposure times (--times)")
            times.append(parse_exposure_time(r.exposure_time, f"'{r.path}': EXIF ExposureTime"))
        # frames that differ in aperture or ISO too: exposure = time x aperture^2 x ISO ratio
        times = exposure_values(
            times, [r.f_number for r in raws], [r.iso for r in raws],
            names=[f"'{r.path}': EXIF" for r in raws],
        )  # fmt: skip
    patterns = {r.cfa_pattern for r in raws}
    if len(patterns) != 1:
        raise ValueError(f"paths: RAW files have different CFA patterns {sorted(patterns)}")
    sizes = {Path(r.path).name: r.mosaic.shape for r in raws}
    if len(set(sizes.values())) != 1:
        raise ValueError(f"paths: RAW mosaics have different sizes: {sizes}")
    times = np.asarray(times, np.float64)
    order = exposure_order(times)
    return [raws[i] for i in order], times[order]
