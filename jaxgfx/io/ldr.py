"""Low-dynamic-range images (PNG, JPEG, TIFF, BMP) and exposure stacks (host-only NumPy).

Reading uses Pillow, and tifffile for ``.tif`` / ``.tiff``. Pillow cannot decode 16-bit colour
PNGs (it truncates them to 8 bits); those are detected from the PNG header and read with
OpenCV when it is installed (``opencv-python-headless``), else a ``ValueError`` says so.
16-bit colour PNGs are written by a small standard encoder here (filter 0 + zlib), 8-bit and
16-bit grey ones by Pillow.
"""

from __future__ import annotations

import json
import struct
import zlib
from fractions import Fraction
from pathlib import Path

import numpy as np
import tifffile
import yaml
from PIL import Image, UnidentifiedImageError

from ._common import as_image_array, existing_file, output_path

__all__ = [
    "read_image",
    "write_png",
    "read_ldr_stack",
    "exif_exposure_time",
    "parse_exposure_time",
    "exposure_order",
]

TIFF_EXTENSIONS = (".tif", ".tiff")
"""TIFF files (read and written with ``tifffile``; may hold integer or float samples)."""
_EXIF_IFD = 0x8769
_EXPOSURE_TIME = 0x829A


def _to_float(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint8:
        return img.astype(np.float32) / np.float32(255)
    if img.dtype == np.uint16:
        return img.astype(np.float32) / np.float32(65535)
    return img.astype(np.float32)


def _png_depth_and_type(p: Path) -> tuple[int, int] | None:
    with open(p, "rb") as fh:
        head = fh.read(26)
    if len(head) < 26 or head[:8] != b"\x89PNG\r\n\x1a\n" or head[12:16] != b"IHDR":
        return None
    return head[24], head[25]


def _read_png16_color(p: Path) -> np.ndarray:
    try:
        import cv2
    except ImportError:  # pragma: no cover - cv2 is installed in the dev environment
        raise ValueError(
            f"'{p}': 16-bit colour PNG needs OpenCV (opencv-python-headless) to decode"
        ) from None
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if img is None or img.dtype != np.uint16 or img.ndim != 3:
        raise ValueError(f"'{p}': corrupt or truncated 16-bit PNG")
    return np.ascontiguousarray(img[..., [2, 1, 0, 3][: img.shape[-1]]])


def read_image(path, *, as_float: bool = False) -> np.ndarray:
    """Read an 8- or 16-bit image: ``(H, W)`` grey, ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA.

    Returns uint8 / uint16 as stored (float TIFFs as float32), or with ``as_float=True``
    float32 in [0, 1] (``x / 255`` or ``x / 65535``; float data unchanged). Palette images are
    expanded to RGB(A), 1-bit to uint8 {0, 255}. No colour management or transfer curve is
    applied (sRGB-encoded files stay encoded). Raises ``FileNotFoundError`` for a missing file
    and ``ValueError`` naming the file for an unreadable, corrupt or truncated one.
    """
    p = existing_file(path)
    if p.suffix.lower() in TIFF_EXTENSIONS:
        try:
            img = tifffile.imread(p)
        except (tifffile.TiffFileError, OSError, ValueError, IndexError) as e:
            raise ValueError(f"'{p}': corrupt or unsupported TIFF ({e})") from None
        img = np.asarray(img)
        if img.ndim == 3 and img.shape[0] in (3, 4) and img.shape[-1] not in (3, 4):
            img = np.moveaxis(img, 0, -1)  # planar TIFF
        if img.ndim not in (2, 3):
            raise ValueError(f"'{p}': expected a single 2-D image, got array shape {img.shape}")
    else:
        info = _png_depth_and_type(p)
        if info is not None:
            with open(p, "rb") as fh:
                fh.seek(max(0, p.stat().st_size - 12))
                if fh.read(12)[4:8] != b"IEND":
                    raise ValueError(f"'{p}': truncated PNG (no IEND chunk at the end)")
        if info is not None and info[0] == 16 and info[1] in (2, 6):
            img = _read_png16_color(p)
        else:
            try:
                with Image.open(p) as im:
                    im.load()
                    mode = im.mode
                    if mode == "P":
                        im = im.convert("RGBA" if "transparency" in im.info else "RGB")
                    elif mode == "1":
                        im = im.convert("L")
                    elif mode == "CMYK" or mode == "YCbCr":
                        im = im.convert("RGB")
                    elif mode == "LA":
                        im = im.convert("RGBA")
                    img = np.asarray(im)
                    if mode in ("I", "I;16", "I;16B", "I;16L") and img.dtype != np.uint16:
                        if img.min() < 0 or img.max() > 65535:
                            raise ValueError(f"'{p}': 32-bit integer images are not supported")
                        img = img.astype(np.uint16)
            except (
                UnidentifiedImageError,
                OSError,
                SyntaxError,
                Image.DecompressionBombError,
            ) as e:
                raise ValueError(f"'{p}': corrupt, truncated or unsupported image ({e})") from None
    img = np.array(img, copy=True)
    return _to_float(img) if as_float else img


# ----------------------------------------------------------------------------- writing


def _png_chunk(tag: bytes, data: bytes) -> bytes:
    crc = zlib.crc32(tag + data) & 0xFFFFFFFF
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", crc)


def _write_png16_color(p: Path, img: np.ndarray) -> None:
    h, w, c = img.shape
    ctype = {3: 2, 4: 6}[c]
    rows = img.astype(">u2").reshape(h, w * c).view(np.uint8)
    raw = np.concatenate([np.zeros((h, 1), np.uint8), rows], axis=1)  # filter 0 per row
    ihdr = struct.pack(">IIBBBBB", w, h, 16, ctype, 0, 0, 0)
    data = b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr)
    data += _png_chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)) + _png_chunk(b"IEND", b"")
    p.write_bytes(data)


def write_png(path, image, *, bits: int = 8) -> None:
    """Write ``(H, W)``, ``(H, W, 1)``, ``(H, W, 3)`` or ``(H, W, 4)`` as an 8- or 16-bit PNG.

    Floating input is taken as [0, 1], clipped and rounded: ``round(clip(x, 0, 1) (2**bits-1))``
    (NaN raises). Integer input is written unchanged and must fit in ``bits``.
    """
    p = output_path(path)
    if bits not in (8, 16):
        raise ValueError(f"bits: expected 8 or 16, got {bits!r}")
    arr = as_image_array(image)
    if arr.ndim == 3 and arr.shape[-1] == 1:
        arr = arr[..., 0]
    if arr.ndim == 3 and arr.shape[-1] not in (3, 4):
        raise ValueError(f"image: expected 1, 3 or 4 channels, got shape {arr.shape}")
    dtype = np.uint8 if bits == 8 else np.uint16
    top = 2**bits - 1
    if np.issubdtype(arr.dtype, np.floating):
        if np.isnan(arr).any():
            raise ValueError("image: contains NaN")
        arr = np.round(np.clip(arr, 0.0, 1.0) * top).astype(dtype)
    else:
        if arr.min() < 0 or arr.max() > top:
            raise ValueError(
                f"image: integer values must be in [0, {top}] for bits={bits}, "
                f"got [{arr.min()}, {arr.max()}]"
            )
        arr = arr.astype(dtype)
    arr = np.ascontiguousarray(arr)
    if bits == 16 and arr.ndim == 3:
        _write_png16_color(p, arr)
    elif bits == 16:
        Image.fromarray(arr, mode=None).save(p, format="PNG")
    else:
        Image.fromarray(arr).save(p, format="PNG")


# ----------------------------------------------------------------------------- stacks


def parse_exposure_time(value, where: str = "exposure time") -> float:
    """Parse one exposure time in seconds: a number or a string like ``"0.004"`` or
    ``"1/250"``. The one parser of exposure times in jaxgfx (sidecars, ``--times``, configs).

    Raises ``ValueError`` starting with ``where`` for text that is not a number or fraction
    (``"1/0"`` included) and for a time that is not finite and > 0.

    >>> parse_exposure_time("1/250")
    0.004
    """
    try:
        if isinstance(value, str):
            t = float(Fraction(value.strip()))
        elif isinstance(value, bool) or not isinstance(value, (int, float, np.number)):
            raise TypeError
        else:
            t = float(value)
    except (ValueError, TypeError, ZeroDivisionError, OverflowError):
        raise ValueError(
            f"{where}: expected a number of seconds or a fraction like 1/250, got {value!r}"
        ) from None
    if not np.isfinite(t) or t <= 0:
        raise ValueError(f"{where}: exposure time must be finite and > 0 seconds, got {value!r}")
    return t


def exposure_order(times) -> np.ndarray:
    """Indices that sort exposure ``times`` ascending (stable: equal times keep file order).
    The one place the host-side pipelines order a bracket (LDR stacks and RAW stacks).

    >>> exposure_order([4.0, 1.0, 4.0, 0.5]).tolist()
    [3, 1, 0, 2]
    """
    return np.argsort(np.asarray(times, np.float64), kind="stable")


def exposure_values(times, f_numbers=None, isos=None, *, names=None) -> np.ndarray:
    """Relative exposures of a bracket: ``time x (N_ref / N)^2 x (ISO / ISO_ref)``.

    ``times``: ``(N,)`` seconds; ``f_numbers`` / ``isos``: one per frame (``None`` entries:
    unknown). A factor is applied only when every frame has its value and they differ (a bracket
    in time alone is returned unchanged); the reference is the first frame's, so the result is
    seconds at the first frame's aperture and ISO. ``names`` (one per frame) name the frame
    in errors: a non-finite or non-positive f-number or ISO raises ``ValueError``.

    >>> exposure_values([1.0, 1.0, 1.0], [4.0, 2.0, 4.0], [100, 100, 400]).tolist()
    [1.0, 4.0, 4.0]
    """
    t = np.asarray(times, np.float64).ravel()
    names = names if names is not None else [f"frame {i}" for i in range(t.size)]
    for label, vals, power in (("f-number", f_numbers, -2.0), ("ISO", isos, 1.0)):
        if vals is None or len(vals) != t.size or any(v is None for v in vals):
            continue
        v = np.asarray(vals, np.float64)
        for name, x in zip(names, v, strict=True):
            if not (np.isfinite(x) and x > 0):
                raise ValueError(f"{name}: {label} must be finite and > 0, got {x:g}")
        if np.allclose(v, v[0], rtol=1e-6):
            continue
        t = t * (v / v[0]) ** power
    return t


def exif_exposure_time(path) -> float | None:
    """EXIF ExposureTime (tag 0x829A, seconds) of an image file, or ``None`` if absent.

    Read with Pillow ``getexif()`` (IFD0 and the Exif sub-IFD 0x8769), or tifffile for TIFFs.
    """
    p = existing_file(path)
    try:
        if p.suffix.lower() in TIFF_EXTENSIONS:
            with tifffile.TiffFile(p) as tif:
                tags = tif.pages[0].tags
                if _EXPOSURE_TIME in tags:
                    v = tags[_EXPOSURE_TIME].value
                    return float(v[0]) / float(v[1]) if isinstance(v, tuple) else float(v)
                exif = tags[_EXIF_IFD].value if _EXIF_IFD in tags else {}
                v = exif.get("ExposureTime") if isinstance(exif, dict) else None
                if v is None:
                    return None
                return float(v[0]) / float(v[1]) if isinstance(v, tuple) else float(v)
        with Image.open(p) as im:
            exif = im.getexif()
            v = exif.get_ifd(_EXIF_IFD).get(_EXPOSURE_TIME, exif.get(_EXPOSURE_TIME))
    except (UnidentifiedImageError, OSError, SyntaxError, tifffile.TiffFileError) as e:
        raise ValueError(f"'{p}': cannot read EXIF ({e})") from None
    return None if v is None else float(v)


def _exif_aperture_iso(path) -> tuple[float | None, float | None]:
    """EXIF FNumber (0x829D) and ISO (0x8827) of a Pillow-readable image (``None``: absent or
    unreadable; TIFFs: not read here)."""
    p = existing_file(path)
    if p.suffix.lower() in TIFF_EXTENSIONS:
        return None, None
    try:
        with Image.open(p) as im:
            exif = im.getexif()
            sub = exif.get_ifd(_EXIF_IFD)
            fn, iso = sub.get(33437, exif.get(33437)), sub.get(34855, exif.get(34855))
    except (UnidentifiedImageError, OSError, SyntaxError):
        return None, None
    iso = iso[0] if isinstance(iso, (tuple, list)) and iso else iso
    try:
        return (None if fn is None else float(fn)), (None if iso is None else float(iso))
    except (TypeError, ValueError, ZeroDivisionError):
        return None, None


def _read_sidecar(sidecar, names: list[str]) -> list[float]:
    s = existing_file(sidecar, "sidecar")
    text = s.read_text()
    try:
        if s.suffix.lower() in (".yaml", ".yml"):
            data = yaml.safe_load(text)
        elif s.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            data = text.replace(",", " ").split()
    except (yaml.YAMLError, json.JSONDecodeError) as e:
        raise ValueError(f"'{s}': cannot parse sidecar ({e})") from None
    if isinstance(data, dict):
        if "exposure_times" in data:
            data = data["exposure_times"]
        else:
            missing = [n for n in names if n not in data]
            if missing:
                raise ValueError(f"'{s}': no exposure time for {missing}")
            return [parse_exposure_time(data[n], f"'{s}' [{n}]") for n in names]
    if not isinstance(data, list) or len(data) != len(names):
        raise ValueError(
            f"'{s}': expected a list of {len(names)} exposure times (one per image), got {data!r}"
        )
    return [parse_exposure_time(v, f"'{s}' [{i}]") for i, v in enumerate(data)]


def read_ldr_stack(paths, *, exposure_times=None, sidecar=None, return_order: bool = False):
    """Read an exposure bracket of LDR images, sorted by exposure time (shortest first).

    ``paths``: image files of equal size. Exposure times come from, in order of precedence,
    ``exposure_times`` (N positive seconds, in ``paths`` order; ``None`` or empty = not
    given), ``sidecar`` (a ``.txt`` with
    N numbers or fractions like ``1/250``, or a ``.yaml`` / ``.json`` holding a list, a
    ``{"exposure_times": [...]}`` mapping, or ``{file name: time}``), else each file's EXIF
    ExposureTime (:func:`exif_exposure_time`), times the aperture and ISO ratios when the EXIF
    FNumber / ISO differ between frames (:func:`exposure_values`).

    Returns ``(images, times)``, or ``(images, times, order)`` with ``return_order=True``:
    ``images`` ``(N, H, W, 3)`` uint8 or uint16 (grey is replicated to 3 channels, alpha
    dropped), ``times`` ``(N,)`` float64 seconds ascending, ``order`` ``(N,)`` int indices into
    ``paths`` (``images[k]`` is ``paths[order[k]]``).
    Raises ``ValueError`` naming the file with no exposure time, listing the sizes when they
    differ, or when bit depths differ.
    """
    if isinstance(paths, (str, bytes)) or not hasattr(paths, "__len__") or len(paths) == 0:
        raise ValueError(f"paths: expected a non-empty list of image files, got {paths!r}")
    files = [existing_file(q, "paths") for q in paths]
    n = len(files)
    if exposure_times is not None and np.size(exposure_times) > 0:
        t = np.asarray(exposure_times, np.float64).ravel()
        if t.shape != (n,) or not np.all(np.isfinite(t)) or not np.all(t > 0):
            raise ValueError(
                f"exposure_times: expected {n} positive values, got {exposure_times!r}"
            )
        times = t
    elif sidecar is not None:
        times = np.array(_read_sidecar(sidecar, [f.name for f in files]))
    else:
        times = np.empty(n)
        for i, f in enumerate(files):
            v = exif_exposure_time(f)
            if v is None:
                raise ValueError(
                    f"'{f}': no EXIF ExposureTime; pass exposure_times= or a sidecar file"
                )
            if not np.isfinite(v) or v <= 0:
                raise ValueError(
                    f"'{f}': EXIF ExposureTime is {v:g} s (expected > 0); "
                    "pass exposure_times= or a sidecar file"
                )
            times[i] = v
        # frames that differ in aperture or ISO too: exposure = time x aperture^2 x ISO ratio
        ap_iso = [_exif_aperture_iso(f) for f in files]
        times = exposure_values(
            times, [a for a, _ in ap_iso], [i for _, i in ap_iso],
            names=[f"'{f}': EXIF" for f in files],
        )  # fmt: skip
    images = []
    for f in files:
        img = read_image(f)
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=-1)
        img = img[..., :3]
        if img.dtype not in (np.uint8, np.uint16):
            raise ValueError(f"'{f}': expected an 8- or 16-bit image, got {img.dtype}")
        images.append(img)
    sizes = {f.name: im.shape[:2] for f, im in zip(files, images, strict=True)}
    if len(set(sizes.values())) > 1:
        raise ValueError(f"images have different sizes (H, W): {sizes}")
    dtypes = {im.dtype for im in images}
    if len(dtypes) > 1:
        raise ValueError(f"images have different bit depths: {sorted(str(d) for d in dtypes)}")
    order = exposure_order(times)
    stack = np.stack([images[i] for i in order])
    return (stack, times[order], order) if return_order else (stack, times[order])
