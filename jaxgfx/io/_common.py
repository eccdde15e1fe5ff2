"""Shared helpers for the host-only readers and writers (path checks, error wrapping)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

__all__ = ["existing_file", "output_path", "as_image_array"]


def existing_file(path, name: str = "path") -> Path:
    """Return ``path`` as a :class:`Path`; raise ``FileNotFoundError`` if it is not a file."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name}: expected a file path (str or os.PathLike), got {type(path)}")
    p = Path(path)
    if p.is_dir():
        raise IsADirectoryError(21, f"{name}: is a folder, expected a file", str(p))
    if not p.is_file():
        raise FileNotFoundError(f"{name}: no such file: '{p}'")
    return p


def output_path(path, name: str = "path") -> Path:
    """Return ``path`` as a :class:`Path` that can be written: every writer checks this first,
    so they all fail the same way, naming the path — ``FileNotFoundError`` (folder missing),
    ``NotADirectoryError`` (a file where the folder should be), ``IsADirectoryError``
    (``path`` is a folder), ``PermissionError`` (folder not writable, or read-only file
    system)."""
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError(f"{name}: expected a file path (str or os.PathLike), got {type(path)}")
    p = Path(path)
    parent = p.parent
    if not parent.is_dir():
        if parent.exists():
            raise NotADirectoryError(20, f"{name}: not a folder", str(parent))
        raise FileNotFoundError(f"{name}: folder does not exist: '{parent}'")
    if p.is_dir():
        raise IsADirectoryError(21, f"{name}: is a folder, expected a file path", str(p))
    if not os.access(parent, os.W_OK) or (p.exists() and not os.access(p, os.W_OK)):
        raise PermissionError(13, f"{name}: not writable", str(p))
    return p


def as_image_array(image, name: str = "image", *, ndims=(2, 3)) -> np.ndarray:
    """Convert ``image`` (NumPy / JAX / lists) to a NumPy array with ``ndim`` in ``ndims``."""
    if isinstance(image, (str, bytes)) or image is None:
        raise TypeError(f"{name}: expected an image array, got {type(image).__name__}")
    arr = np.asarray(image)
    if arr.dtype == np.bool_ or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    ):
        raise TypeError(f"{name}: expected a numeric image array, got dtype {arr.dtype}")
    if arr.ndim not in ndims:
        raise ValueError(f"{name}: expected an array with ndim in {ndims}, got shape {arr.shape}")
    if arr.size == 0:
        raise ValueError(f"{name}: expected a non-empty image, got shape {arr.shape}")
    return arr
