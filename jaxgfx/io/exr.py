"""OpenEXR reading and writing (host-only NumPy) through the ``OpenEXR`` package's ``File`` API.

Channel order convention (used by :func:`read_exr` when ``channels`` is not given): ``R, G, B,
A`` first (those present, in that order), then every other channel sorted alphabetically
(``Y``, ``Z``, ``diffuse.R``...). A file holding only ``Y`` therefore reads as ``(H, W, 1)``.

The pixels of the data window are returned (not padded to the display window; both windows
are in :func:`read_exr_header`). Scanline and tiled files are read (tiled: the full-resolution
level). Only the first part of a multi-part file is read; deep and sub-sampled (chroma
``xSampling`` / ``ySampling`` > 1) images are rejected with ``ValueError``. ``UINT`` channels
are returned as float32 like the others (exact up to 2**24).
"""

from __future__ import annotations

import numpy as np
import OpenEXR

from jaxgfx._checks import check_choice

from ._common import as_image_array, existing_file, output_path

__all__ = ["read_exr", "read_exr_header", "write_exr", "EXR_COMPRESSIONS"]

#: Compression names accepted by :func:`write_exr`. ``pxr24``, ``b44``, ``b44a``, ``dwaa`` and
#: ``dwab`` are lossy; the others are lossless.
EXR_COMPRESSIONS = {
    "none": OpenEXR.NO_COMPRESSION,
    "rle": OpenEXR.RLE_COMPRESSION,
    "zips": OpenEXR.ZIPS_COMPRESSION,
    "zip": OpenEXR.ZIP_COMPRESSION,
    "piz": OpenEXR.PIZ_COMPRESSION,
    "pxr24": OpenEXR.PXR24_COMPRESSION,
    "b44": OpenEXR.B44_COMPRESSION,
    "b44a": OpenEXR.B44A_COMPRESSION,
    "dwaa": OpenEXR.DWAA_COMPRESSION,
    "dwab": OpenEXR.DWAB_COMPRESSION,
}
_COMPRESSION_NAMES = {v: k for k, v in EXR_COMPRESSIONS.items()}
_PIXEL_TYPE_NAMES = {OpenEXR.HALF: "half", OpenEXR.FLOAT: "float", OpenEXR.UINT: "uint"}
_STORAGE_NAMES = {
    OpenEXR.scanlineimage: "scanline",
    OpenEXR.tiledimage: "tiled",
    OpenEXR.deepscanline: "deepscanline",
    OpenEXR.deeptile: "deeptile",
}
# Header attributes that describe the image layout; everything else is a custom attribute.
_STANDARD_ATTRIBUTES = {
    "channels",
    "compression",
    "dataWindow",
    "displayWindow",
    "lineOrder",
    "pixelAspectRatio",
    "screenWindowCenter",
    "screenWindowWidth",
    "type",
    "tiles",
    "name",
    "version",
    "chunkCount",
}
_RGBA = ("R", "G", "B", "A")


def _channel_sort_key(name: str):
    return (0, _RGBA.index(name), "") if name in _RGBA else (1, 0, name)


def _open(path) -> tuple[OpenEXR.File, object]:
    """Open ``path`` with OpenEXR (all pixels loaded); wrap library failures in ValueError."""
    p = existing_file(path)
    with open(p, "rb") as fh:
        magic = fh.read(4)
    if magic != b"\x76\x2f\x31\x01":
        raise ValueError(f"'{p}': not an OpenEXR file (bad magic number {magic!r})")
    try:
        f = OpenEXR.File(str(p), separate_channels=True)
        part = f.parts[0]
        channels = part.channels  # forces the pixel read for every channel
        _ = {k: c.pixels for k, c in channels.items()}
    except (RuntimeError, OSError, ValueError, TypeError, IndexError) as e:
        raise ValueError(f"'{p}': corrupt or truncated OpenEXR file ({e})") from None
    return f, p


def _header_dict(part, p) -> dict:
    header = part.header
    (x0, y0), (x1, y1) = (np.asarray(v) for v in header["dataWindow"])
    storage = header.get("type", OpenEXR.scanlineimage)
    chans = {}
    for name, c in part.channels.items():
        chans[name] = {
            "type": _PIXEL_TYPE_NAMES.get(c.type(), str(c.type())),
            "sampling": (int(c.xSampling), int(c.ySampling)),
        }
    dw0, dw1 = (np.asarray(v) for v in header["displayWindow"])
    return {
        "width": int(x1 - x0 + 1),
        "height": int(y1 - y0 + 1),
        "channels": {k: chans[k] for k in sorted(chans, key=_channel_sort_key)},
        "compression": _COMPRESSION_NAMES.get(
            header.get("compression"), str(header.get("compression"))
        ),
        "storage": _STORAGE_NAMES.get(storage, str(storage)),
        "data_window": ((int(x0), int(y0)), (int(x1), int(y1))),
        "display_window": ((int(dw0[0]), int(dw0[1])), (int(dw1[0]), int(dw1[1]))),
        "pixel_aspect_ratio": float(header.get("pixelAspectRatio", 1.0)),
        "attributes": {k: v for k, v in header.items() if k not in _STANDARD_ATTRIBUTES},
    }


def read_exr_header(path) -> dict:
    """Read the header of an OpenEXR file (first part).

    Returns a dict with keys ``width``, ``height`` (pixels of the data window), ``channels``
    (``{name: {"type": "half"|"float"|"uint", "sampling": (xs, ys)}}`` in :func:`read_exr`'s
    order), ``compression`` (a key of :data:`EXR_COMPRESSIONS`), ``storage`` (``"scanline"``,
    ``"tiled"``...), ``data_window`` / ``display_window`` (``((xmin, ymin), (xmax, ymax))``
    inclusive), ``pixel_aspect_ratio`` and ``attributes`` (every non-standard attribute, e.g.
    those passed to :func:`write_exr` as ``header``).

    Raises ``FileNotFoundError`` for a missing file, ``ValueError`` naming the file when it is
    not a readable OpenEXR file.
    """
    f, p = _open(path)
    return _header_dict(f.parts[0], p)


def read_exr(path, *, channels=None) -> np.ndarray:
    """Read an OpenEXR image as float32 ``(H, W, C)``.

    ``channels``: ``None`` reads every channel in the module's order (``R, G, B, A`` first, then
    the others alphabetically); a list of names (e.g. ``["Z"]`` or ``["B", "G", "R"]``) reads
    those in the given order. Half and uint channels are converted to float32 (half → float32 is
    exact). Reference: OpenEXR file layout, Kainz et al., "Technical Introduction to OpenEXR"
    (2004).

    >>> import os, tempfile
    >>> path = os.path.join(tempfile.mkdtemp(), "doc.exr")
    >>> write_exr(path, np.full((2, 3, 3), 0.5, np.float32))
    >>> read_exr(path).shape
    (2, 3, 3)
    """
    f, p = _open(path)
    part = f.parts[0]
    storage = part.header.get("type", OpenEXR.scanlineimage)
    if storage in (OpenEXR.deepscanline, OpenEXR.deeptile):
        raise ValueError(f"'{p}': deep OpenEXR images are not supported")
    available = part.channels
    if channels is None:
        names = sorted(available, key=_channel_sort_key)
    else:
        if isinstance(channels, str):
            channels = [channels]
        names = list(channels)
        missing = [n for n in names if n not in available]
        if missing:
            raise ValueError(
                f"'{p}': channels {missing} not in file; available: "
                f"{sorted(available, key=_channel_sort_key)}"
            )
    if not names:
        raise ValueError(f"'{p}': file has no channels")
    planes = []
    for n in names:
        c = available[n]
        if c.xSampling != 1 or c.ySampling != 1:
            raise ValueError(
                f"'{p}': channel {n!r} is sub-sampled ({c.xSampling}x{c.ySampling}); unsupported"
            )
        px = np.asarray(c.pixels)
        if px.ndim != 2:
            raise ValueError(f"'{p}': channel {n!r} has unexpected pixel shape {px.shape}")
        planes.append(px.astype(np.float32))
    shapes = {pl.shape for pl in planes}
    if len(shapes) != 1:
        raise ValueError(f"'{p}': channels have different sizes {sorted(shapes)}")
    return np.stack(planes, axis=-1)


def _default_names(c: int) -> list[str]:
    if c == 1:
        return ["Y"]
    if c == 3:
        return ["R", "G", "B"]
    if c == 4:
        return ["R", "G", "B", "A"]
    raise ValueError(f"image: {c} channels have no default names; pass channels=[...] (C names)")


_OS_FAILURES = (
    ("Permission denied", PermissionError, 13),
    ("Read-only file system", PermissionError, 30),
    ("Is a directory", IsADirectoryError, 21),
    ("No such file or directory", FileNotFoundError, 2),
    ("No space left on device", OSError, 28),
)


def write_exr(path, image, *, half=False, channels=None, compression="zip", header=None) -> None:
    """Write ``image`` ``(H, W)`` or ``(H, W, C)`` as a scanline OpenEXR file.

    ``half``: store 16-bit half floats (values beyond ±65504 become ±inf; relative step 2**-11)
    instead of 32-bit floats. ``channels``: channel names (length C); defaults are ``Y`` (C=1),
    ``R, G, B`` (C=3), ``R, G, B, A`` (C=4); other C require names. ``compression``: a key of
    :data:`EXR_COMPRESSIONS` (default ``"zip"``, lossless). ``header``: extra attributes
    (``{name: str | int | float | ndarray}``) stored in the file and returned by
    :func:`read_exr_header` under ``"attributes"``.

    Pixel planes are always copied to C-contiguous arrays of the stored dtype before writing:
    the OpenEXR binding writes strided (e.g. transposed) arrays in memory order, silently
    scrambling the image.
    """
    p = output_path(path)
    arr = as_image_array(image)
    if arr.ndim == 2:
        arr = arr[..., None]
    h, w, c = arr.shape
    names = _default_names(c) if channels is None else list(channels)
    if len(names) != c or not all(isinstance(n, str) and n for n in names):
        raise ValueError(f"channels: expected {c} non-empty names, got {channels!r}")
    if len(set(names)) != c:
        raise ValueError(f"channels: names must be unique, got {names}")
    if not isinstance(compression, str) or compression.lower() not in EXR_COMPRESSIONS:
        check_choice(compression, "compression", sorted(EXR_COMPRESSIONS))  # (case-insensitive)
    extra = {} if header is None else dict(header)
    clash = set(extra) & _STANDARD_ATTRIBUTES
    if clash:
        raise ValueError(f"header: reserved attribute names {sorted(clash)}")
    dtype = np.float16 if half else np.float32
    with np.errstate(over="ignore"):
        planes = {n: np.ascontiguousarray(arr[..., i], dtype=dtype) for i, n in enumerate(names)}
    hdr = {
        "compression": EXR_COMPRESSIONS[compression.lower()],
        "type": OpenEXR.scanlineimage,
        **extra,
    }
    try:
        OpenEXR.File(hdr, planes).write(str(p))
    except (RuntimeError, TypeError, ValueError) as e:
        # OpenEXR reports file-system failures as RuntimeError text: raise the OSError the
        # other writers raise for them (see _common.output_path)
        for text, err, code in _OS_FAILURES:
            if text in str(e):
                raise err(code, f"could not write OpenEXR file ({text})", str(p)) from None
        raise ValueError(f"'{p}': could not write OpenEXR file ({e})") from None
