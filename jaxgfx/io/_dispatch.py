"""Read / write any supported file by its extension (used by the command-line interface)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import tifffile
from PIL import Image

from ._common import as_image_array, existing_file, output_path
from .exr import read_exr, write_exr
from .hdr_rgbe import read_hdr, write_hdr
from .ldr import TIFF_EXTENSIONS, read_image, write_png
from .raw import read_raw_linear_rgb

__all__ = [
    "read_any",
    "write_any",
    "kind_of",
    "FILE_KINDS",
    "RAW_EXTENSIONS",
    "LDR_EXTENSIONS",
    "HDR_EXTENSIONS",
    "WRITE_EXTENSIONS",
    "HDR_WRITE_EXTENSIONS",
    "LDR_WRITE_EXTENSIONS",
    "LINEAR_WRITE_EXTENSIONS",
    "DISPLAY_WRITE_EXTENSIONS",
    "TIFF_EXTENSIONS",
]

RAW_EXTENSIONS = frozenset(
    {
        ".dng",
        ".nef",
        ".nrw",
        ".cr2",
        ".cr3",
        ".crw",
        ".arw",
        ".srf",
        ".sr2",
        ".raf",
        ".orf",
        ".rw2",
        ".pef",
        ".srw",
        ".x3f",
        ".3fr",
        ".iiq",
        ".erf",
        ".kdc",
        ".mrw",
        ".mos",
        ".raw",
    }
)
HDR_WRITE_EXTENSIONS = (".exr", ".hdr", ".pic", ".rgbe")
"""Radiance files :func:`write_any` writes (linear float): OpenEXR and Radiance RGBE."""
LDR_WRITE_EXTENSIONS = (".png", ".jpg", ".jpeg", *TIFF_EXTENSIONS)
"""Display-referred images :func:`write_any` writes (8/16-bit code values; TIFF also float)."""
WRITE_EXTENSIONS = HDR_WRITE_EXTENSIONS + LDR_WRITE_EXTENSIONS
"""What :func:`write_any` can write (``.bmp`` and camera raws are read-only here)."""
LINEAR_WRITE_EXTENSIONS = HDR_WRITE_EXTENSIONS + TIFF_EXTENSIONS
"""Written extensions that can hold linear radiance (float): the radiance files and TIFF."""
DISPLAY_WRITE_EXTENSIONS = tuple(e for e in LDR_WRITE_EXTENSIONS if e not in TIFF_EXTENSIONS)
"""Written extensions that hold only display-encoded integer code values (``.png``, JPEG)."""
LDR_EXTENSIONS = frozenset(LDR_WRITE_EXTENSIONS) | {".bmp"}
_HDR_EXTENSIONS = frozenset(HDR_WRITE_EXTENSIONS) - {".exr"}
HDR_EXTENSIONS = frozenset(HDR_WRITE_EXTENSIONS)
"""Radiance files: OpenEXR and Radiance RGBE."""

FILE_KINDS = {
    "raw": RAW_EXTENSIONS,
    "ldr": LDR_EXTENSIONS,
    "hdr": HDR_EXTENSIONS,
    "npy": frozenset({".npy"}),
}
"""File kinds by extension (lower case, with the dot): camera raws, display-referred images
(8/16-bit), radiance files and NumPy arrays. The one table every command reads."""


def kind_of(path) -> str | None:
    """The kind of file ``path`` names by its extension (case-insensitive): ``"raw"``,
    ``"ldr"``, ``"hdr"``, ``"npy"``, or ``None`` for an unknown extension.

    Example: ``kind_of("IMG_0001.NRW")`` → ``"raw"``; ``kind_of("a.exr")`` → ``"hdr"``.
    """
    ext = os.path.splitext(os.fspath(path))[1].lower()
    for kind, exts in FILE_KINDS.items():
        if ext in exts:
            return kind
    return None


def read_any(path) -> np.ndarray:
    """Read any supported image as float32 ``(H, W, C)`` (``(H, W)`` for grey LDR files).

    ``.exr`` → :func:`read_exr`; ``.hdr`` / ``.pic`` / ``.rgbe`` → :func:`read_hdr`; LDR
    (``.png .jpg .jpeg .tif .tiff .bmp``) → :func:`read_image` with ``as_float=True`` (values in
    [0, 1], still display-encoded); camera raws (``.dng .nef .cr2 .arw ...``) →
    :func:`read_raw_linear_rgb` (linear camera RGB). Unknown extensions raise ``ValueError``.
    """
    p = existing_file(path)
    ext = p.suffix.lower()
    if ext == ".exr":
        return read_exr(p)
    if ext in _HDR_EXTENSIONS:
        return read_hdr(p)
    if ext in LDR_EXTENSIONS:
        return read_image(p, as_float=True)
    if ext in RAW_EXTENSIONS:
        return read_raw_linear_rgb(p)
    raise ValueError(f"'{p}': unsupported extension {ext!r}; known: {_known()}")


def _known() -> list[str]:
    return sorted({".exr"} | _HDR_EXTENSIONS | LDR_EXTENSIONS | RAW_EXTENSIONS)


def write_any(path, image) -> None:
    """Write ``image`` by extension: ``.exr`` (float32, zip), ``.hdr`` (RGBE, RLE), ``.png``
    (16-bit for uint16 input, else 8-bit; floats in [0, 1]), ``.jpg`` / ``.jpeg`` (8-bit,
    quality 95), ``.tif`` / ``.tiff`` (dtype kept: float32 linear or uint8/uint16). Raw
    formats cannot be written here (use :func:`write_dng` with a mosaic)."""
    p = Path(path) if isinstance(path, (str, os.PathLike)) else path
    ext = p.suffix.lower() if isinstance(p, Path) else ""
    if isinstance(p, Path) and ext not in WRITE_EXTENSIONS and ext not in RAW_EXTENSIONS:
        raise ValueError(
            f"'{p}': cannot write {ext or 'files without an extension'!r}; "
            f"writable: {' '.join(WRITE_EXTENSIONS)}"
        )
    p = output_path(path)
    arr = as_image_array(image)
    if ext == ".exr":
        write_exr(p, arr)
    elif ext in _HDR_EXTENSIONS:
        write_hdr(p, arr)
    elif ext == ".png":
        write_png(p, arr, bits=16 if arr.dtype == np.uint16 else 8)
    elif ext in (".jpg", ".jpeg"):
        if arr.ndim == 3 and arr.shape[-1] not in (1, 3):
            raise ValueError(f"image: JPEG needs 1 or 3 channels, got shape {arr.shape}")
        if np.issubdtype(arr.dtype, np.floating):
            arr = np.round(np.clip(np.nan_to_num(arr), 0.0, 1.0) * 255)
        elif arr.min() < 0 or arr.max() > 255:
            raise ValueError("image: integer JPEG input must be in [0, 255]")
        Image.fromarray(np.ascontiguousarray(arr.astype(np.uint8).squeeze())).save(
            p, format="JPEG", quality=95
        )
    elif ext in TIFF_EXTENSIONS:
        if np.issubdtype(arr.dtype, np.floating):
            arr = arr.astype(np.float32)
        tifffile.imwrite(p, np.ascontiguousarray(arr), photometric=_photometric(arr))
    elif ext in RAW_EXTENSIONS:
        raise ValueError(f"'{p}': cannot write raw images; use write_dng(path, mosaic)")
    else:
        raise ValueError(
            f"'{p}': cannot write {ext or 'files without an extension'!r}; "
            f"writable: {' '.join(WRITE_EXTENSIONS)}"
        )


def _photometric(arr: np.ndarray) -> str:
    return "rgb" if arr.ndim == 3 and arr.shape[-1] in (3, 4) else "minisblack"
