"""The tone-mapping job: an HDR image file → a display image (``jaxgfx tonemap IN OUT``).

``run_tonemap(job)`` checks the operator, its parameters and the output path, reads the linear
radiance (``.exr`` or Radiance ``.hdr``), applies
``jaxgfx.tonemap.TONEMAP_METHODS[job.op]`` with ``job.params`` and writes the sRGB display
image (``.png`` / ``.jpg`` / ``.tif``). Output safety as the other jobs
(:mod:`jaxgfx.pipelines._output`).
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

from jaxgfx.pipelines._output import HDR_EXTENSIONS, StagedFiles, check_output_extension

__all__ = ["TonemapJob", "run_tonemap", "tonemap_image", "operator_help"]

_DISPLAY_EXT = (".png", ".jpg", ".jpeg", ".tif", ".tiff")


@dataclasses.dataclass(frozen=True)
class TonemapJob:
    """One tone-mapping run: ``input`` (linear HDR file), ``output`` (display image), ``op``
    (a key of ``TONEMAP_METHODS``) and its continuous ``params`` (name → float)."""

    input: str
    output: str
    op: str = "drago"
    params: dict = dataclasses.field(default_factory=dict)
    overwrite: bool = False

    def validate(self):
        from jaxgfx.tonemap import TONEMAP_METHODS, TONEMAP_PARAMETERS

        if self.op not in TONEMAP_METHODS:
            raise ValueError(f"op: expected one of {', '.join(TONEMAP_METHODS)}, got {self.op!r}")
        known = TONEMAP_PARAMETERS[self.op]
        for name, value in self.params.items():
            if name not in known:
                raise ValueError(
                    f"--{name.replace('_', '-')}: not a parameter of {self.op!r} "
                    f"(its parameters: {', '.join(known) or '-'})"
                )
            if not isinstance(value, (int, float)) or not np.isfinite(value):
                raise ValueError(f"--{name.replace('_', '-')}: expected a number, got {value!r}")
        if not os.path.isfile(self.input):
            what = "is a directory" if os.path.isdir(self.input) else "no such file"
            raise FileNotFoundError(2, f"input: {what}", self.input)
        check_output_extension(self.input, "input", HDR_EXTENSIONS)
        check_output_extension(self.output, "output", _DISPLAY_EXT)


def operator_help() -> list[str]:
    """One line per operator: name, public function, parameters with defaults."""
    from jaxgfx.tonemap import TONEMAP_METHODS, TONEMAP_PARAMETERS

    lines = []
    for name, fn in TONEMAP_METHODS.items():
        ps = ", ".join(f"{p}={s.default:g}" for p, s in TONEMAP_PARAMETERS[name].items())
        lines.append(f"{name:19s} {fn.__name__:28s} {ps}")
    return lines


def tonemap_image(radiance: np.ndarray, op: str = "drago", **params) -> np.ndarray:
    """Host helper: linear ``(H, W, C)`` radiance → sRGB display image ``(H, W, 3)`` float32.

    Negative values (noise in merged radiance) are clipped to 0 and non-finite ones set to 0
    before the operator (which refuses them); extra channels beyond RGB are dropped.
    """
    from jaxgfx.tonemap import TONEMAP_METHODS

    img = np.asarray(radiance, np.float32)
    if img.ndim == 2:
        img = img[..., None]
    if img.shape[-1] == 1:
        img = np.repeat(img, 3, -1)
    img = np.where(np.isfinite(img[..., :3]), np.maximum(img[..., :3], 0.0), 0.0)
    return np.asarray(TONEMAP_METHODS[op](img, **params), np.float32)


def run_tonemap(job: TonemapJob) -> dict:
    """Run the job. Returns ``{"outputs": {"output": path}, "seconds": float, "shape":
    (H, W, C)}``."""
    from jaxgfx import io

    if not isinstance(job, TonemapJob):
        raise TypeError(f"job: expected a TonemapJob, got {type(job).__name__}")
    job.validate()
    paths = {"output": os.fspath(job.output)}
    with StagedFiles(paths, overwrite=job.overwrite) as stage:
        hdr = io.read_any(job.input)
        t0 = time.perf_counter()
        out = tonemap_image(hdr, job.op, **job.params)
        dt = time.perf_counter() - t0
        io.write_any(stage.staging["output"], out)
    return {"outputs": paths, "seconds": dt, "shape": out.shape}
