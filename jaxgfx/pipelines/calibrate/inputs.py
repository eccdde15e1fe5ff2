"""The job's inputs: image files (or one folder, with an optional exposure-time sidecar)
gathered and classified by :func:`jaxgfx.io.kind_of` before any computation."""

from __future__ import annotations

import os

import numpy as np

from jaxgfx.io import kind_of

__all__ = ["SIDECAR_NAMES", "collect_inputs", "find_sidecar", "stack_kind"]

SIDECAR_NAMES = ("exposure_times.txt", "exposure_times.yaml", "exposure_times.json")


def collect_inputs(inputs) -> list[str]:
    """The image files of ``inputs`` (files, or folders: their RAW and LDR files, sorted)."""
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


def stack_kind(files) -> str:
    """``"synthetic"`` (no files), ``"raw"`` or ``"ldr"``; a mix or a single image is refused."""
    if not files:
        return "synthetic"
    is_raw = all(kind_of(f) == "raw" for f in files)
    if not is_raw and any(kind_of(f) == "raw" for f in files):
        raise ValueError("inputs: mix of RAW and LDR files; calibrate one kind at a time")
    if len(files) < 2:
        raise ValueError(f"inputs: a bracket needs at least 2 images, got {files}")
    return "raw" if is_raw else "ldr"


def find_sidecar(inputs) -> str | None:
    """An ``exposure_times.{txt,yaml,json}`` file inside an input directory, if any."""
    for item in inputs or []:
        if os.path.isdir(item):
            for name in SIDECAR_NAMES:
                path = os.path.join(item, name)
                if os.path.exists(path):
                    return path
    return None


def to_float01(images: np.ndarray) -> np.ndarray:
    """Integer images scaled to [0, 1] (float32); float images as float32."""
    if np.issubdtype(images.dtype, np.integer):
        return images.astype(np.float32) / float(np.iinfo(images.dtype).max)
    return images.astype(np.float32)
