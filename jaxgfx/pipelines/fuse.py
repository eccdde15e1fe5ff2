"""The exposure-fusion job: an LDR bracket → a display image (``jaxgfx fuse IN... OUT``).

``run_fuse(job)`` checks the inputs (LDR image files, or one directory of them, at least two
frames of one size) and the output path before computing, reads the frames as display-referred
floats in [0, 1] (grey replicated to RGB, alpha dropped), fuses them with
:func:`jaxgfx.hdr.exposure_fusion` (Mertens, Kautz & Van Reeth 2007; no exposure times and no
response curve needed) and writes the result (``.png`` / ``.jpg``: 8-bit, ``.tif``: 16-bit
integer code values). Output safety as the other jobs (:mod:`jaxgfx.pipelines._output`).
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

from jaxgfx.io import LDR_WRITE_EXTENSIONS
from jaxgfx.pipelines._output import StagedFiles, check_output_extension

__all__ = ["FuseJob", "run_fuse", "FUSE_PARAMETERS"]

_DISPLAY_EXT = LDR_WRITE_EXTENSIONS

FUSE_PARAMETERS = {
    "contrast_weight": "exponent of the contrast measure (|Laplacian|), >= 0",
    "saturation_weight": "exponent of the saturation measure (std of R, G, B), >= 0",
    "exposedness_weight": "exponent of the well-exposedness measure, >= 0",
    "sigma": "width of the well-exposedness Gaussian, > 0",
}
"""Continuous parameters of :func:`jaxgfx.hdr.exposure_fusion` exposed by ``jaxgfx fuse``."""


def _expand_inputs(inputs) -> list[str]:
    from jaxgfx.io import LDR_EXTENSIONS

    known = " ".join(sorted(LDR_EXTENSIONS))
    if isinstance(inputs, (str, os.PathLike)):
        inputs = [inputs]
    files: list[str] = []
    for item in inputs:
        item = os.fspath(item)
        if os.path.isdir(item):
            found = sorted(
                os.path.join(item, f)
                for f in os.listdir(item)
                if os.path.splitext(f)[1].lower() in LDR_EXTENSIONS and not f.startswith(".")
            )
            if not found:
                raise ValueError(f"inputs: directory {item!r} holds no LDR images ({known})")
            files.extend(found)
        elif os.path.isfile(item):
            ext = os.path.splitext(item)[1].lower()
            if ext not in LDR_EXTENSIONS:
                raise ValueError(
                    f"inputs: cannot fuse {item!r}: expected LDR images "
                    f"({known}), got {ext or '(no extension)'!r} (exposure "
                    "fusion blends display-referred frames; OUTPUT comes last)"
                )
            files.append(item)
        else:
            raise FileNotFoundError(2, "inputs: no such file or directory", item)
    return files


@dataclasses.dataclass(frozen=True)
class FuseJob:
    """One fusion run: ``inputs`` (LDR files and/or directories of them, >= 2 frames),
    ``output`` (display image), ``params`` (a subset of :data:`FUSE_PARAMETERS` → float)."""

    inputs: tuple
    output: str
    params: dict = dataclasses.field(default_factory=dict)
    overwrite: bool = False

    def validate(self) -> list[str]:
        """Check parameters, inputs and output; returns the input files."""
        for name, value in self.params.items():
            opt = f"--{name.replace('_', '-')}"
            if name not in FUSE_PARAMETERS:
                raise ValueError(f"{opt}: not a parameter of exposure fusion")
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{opt}: expected a number, got {value!r}")
            v = float(value)
            bad = not np.isfinite(v) or (v <= 0 if name == "sigma" else v < 0)
            if bad:
                what = "> 0" if name == "sigma" else ">= 0"
                raise ValueError(f"{opt}: expected a finite value {what}, got {value!r}")
        files = _expand_inputs(self.inputs)
        if len(files) < 2:
            raise ValueError(
                f"inputs: exposure fusion needs at least 2 frames of a bracket, got {len(files)}"
            )
        check_output_extension(self.output, "output", _DISPLAY_EXT)
        out = os.path.abspath(os.fspath(self.output))
        for f in files:
            if os.path.abspath(f) == out:
                raise ValueError(f"output: {self.output!r} is also an input")
        return files


def _read_frames(files) -> np.ndarray:
    from jaxgfx import io

    frames, shapes = [], {}
    for f in files:
        img = io.read_image(f, as_float=True)
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, -1)
        img = img[..., :3]
        if img.shape[-1] == 1:
            img = np.repeat(img, 3, -1)
        shapes.setdefault(img.shape[:2], []).append(os.path.basename(f))
        frames.append(np.asarray(img, np.float32))
    if len(shapes) > 1:
        sizes = "; ".join(f"{w}x{h}: {', '.join(n)}" for (h, w), n in shapes.items())
        raise ValueError(f"inputs: the frames differ in size ({sizes})")
    return np.stack(frames)


def run_fuse(job: FuseJob) -> dict:
    """Run the job. Returns ``{"outputs": {"output": path}, "inputs": [files], "seconds":
    float (fusion incl. compilation), "shape": (H, W, 3)}``."""
    from jaxgfx import io
    from jaxgfx.hdr import exposure_fusion
    from jaxgfx.pipelines.tonemap import to_display_file

    if not isinstance(job, FuseJob):
        raise TypeError(f"job: expected a FuseJob, got {type(job).__name__}")
    files = job.validate()
    paths = {"output": os.fspath(job.output)}
    ext = os.path.splitext(paths["output"])[1].lower()
    with StagedFiles(paths, overwrite=job.overwrite) as stage:
        frames = _read_frames(files)
        t0 = time.perf_counter()
        out = np.asarray(exposure_fusion(frames, **job.params), np.float32)
        dt = time.perf_counter() - t0
        io.write_any(stage.staging["output"], to_display_file(out, ext))
    return {"outputs": paths, "inputs": files, "seconds": dt, "shape": out.shape}
