"""The tone-mapping job: an HDR image file → a display image (``jaxgfx tonemap IN OUT``).

``run_tonemap(job)`` checks the operator, its parameters and the output path, reads the linear
radiance (``.exr`` or Radiance ``.hdr``), applies
``jaxgfx.tonemap.TONEMAP_METHODS[job.op]`` with ``job.params`` and writes the sRGB display
image (``.png`` / ``.jpg``: 8-bit, ``.tif``: 16-bit integer sRGB code values). NaN/Inf
input pixels raise an error naming the file; negative values are clamped to 0 and counted
(``negative_clamped``, printed by the CLI). Output safety as the other jobs
(:mod:`jaxgfx.pipelines._output`).
"""

from __future__ import annotations

import dataclasses
import os
import time

import numpy as np

from jaxgfx._checks import check_choice
from jaxgfx.io import HDR_EXTENSIONS, LDR_WRITE_EXTENSIONS, TIFF_EXTENSIONS
from jaxgfx.pipelines._output import StagedFiles, check_output_extension

__all__ = ["TonemapJob", "run_tonemap", "tonemap_image", "prepare_radiance", "operator_help"]

_DISPLAY_EXT = LDR_WRITE_EXTENSIONS
_INPUT_EXT = tuple(sorted(HDR_EXTENSIONS))


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

        check_choice(self.op, "op", TONEMAP_METHODS)
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
        ext = os.path.splitext(os.fspath(self.input))[1].lower()
        if ext not in _INPUT_EXT:
            raise ValueError(
                f"input: cannot read {os.fspath(self.input)!r} as linear radiance: "
                f"expected {' '.join(_INPUT_EXT)}, got {ext or '(no extension)'!r} "
                "(display images are not linear; INPUT comes before OUTPUT)"
            )
        check_output_extension(self.output, "output", _DISPLAY_EXT)


def _default_text(spec) -> str:
    return "image-max" if spec.default is None else f"{spec.default:g}"


def operator_help() -> list[str]:
    """One line per operator: name, public function, parameters with defaults."""
    from jaxgfx.tonemap import TONEMAP_METHODS, TONEMAP_PARAMETERS

    lines = []
    for name, fn in TONEMAP_METHODS.items():
        ps = ", ".join(f"{p}={_default_text(s)}" for p, s in TONEMAP_PARAMETERS[name].items())
        lines.append(f"{name:19s} {fn.__name__:28s} {ps}")
    return lines


def prepare_radiance(radiance, name: str = "radiance") -> tuple[np.ndarray, int]:
    """Linear ``(H, W, C)`` radiance → float32 RGB for the operators, and the number of
    negative values clamped to 0.

    Non-finite values raise ``ValueError`` naming ``name`` and how many pixels hold them (a
    NaN or Inf cannot be displayed honestly: zeroing it would show a black pixel where the
    scene is brightest). Negative values -- noise of a merged or denoised radiance map --
    are clamped to 0 and counted. Extra channels beyond RGB are dropped; one channel is
    repeated.
    """
    img = np.asarray(radiance, np.float32)
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.size == 0:
        raise ValueError(f"{name}: expected a non-empty (H, W, C) image, got shape {img.shape}")
    if img.shape[-1] == 1:
        img = np.repeat(img, 3, -1)
    img = img[..., :3]
    bad = ~np.isfinite(img).all(-1)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise ValueError(
            f"{name}: {int(bad.sum())} of {bad.size} pixels hold NaN or Inf values (first at "
            f"row {r}, column {c}); tone mapping needs finite radiance: repair or crop them"
        )
    n_negative = int(np.sum(img < 0))
    return np.maximum(img, 0.0), n_negative


def tonemap_image(radiance: np.ndarray, op: str = "drago", *, name="radiance", **params):
    """Host helper: linear ``(H, W, C)`` radiance → sRGB display image ``(H, W, 3)`` float32.

    See :func:`prepare_radiance`: NaN/Inf raise ``ValueError`` naming ``name``, negative
    values are clamped to 0.
    """
    from jaxgfx.tonemap import TONEMAP_METHODS

    img, _ = prepare_radiance(radiance, name)
    return np.asarray(TONEMAP_METHODS[op](img, **params), np.float32)


def to_display_file(image: np.ndarray, ext: str) -> np.ndarray:
    """The array written for a display image: 16-bit integer sRGB code values for TIFF
    (viewers read float TIFFs as linear light, which would show the sRGB-encoded values
    twice encoded); the float image for PNG/JPEG (quantised to 8 bits by the writers)."""
    if ext in TIFF_EXTENSIONS:
        return np.round(np.clip(image, 0.0, 1.0) * 65535.0).astype(np.uint16)
    return image


def _apply(job: TonemapJob, img: np.ndarray) -> np.ndarray:
    from jaxgfx.tonemap import TONEMAP_METHODS

    try:
        return np.asarray(TONEMAP_METHODS[job.op](img, **job.params), np.float32)
    except (ValueError, TypeError) as e:  # a parameter's range: name the CLI option
        name = str(e).split(":", 1)[0]
        if name in job.params:
            raise type(e)(f"--{name.replace('_', '-')}{str(e)[len(name) :]}") from None
        raise


def run_tonemap(job: TonemapJob) -> dict:
    """Run the job. Returns ``{"outputs": {"output": path}, "seconds": float, "shape":
    (H, W, C), "negative_clamped": int}``."""
    from jaxgfx import io

    if not isinstance(job, TonemapJob):
        raise TypeError(f"job: expected a TonemapJob, got {type(job).__name__}")
    job.validate()
    paths = {"output": os.fspath(job.output)}
    ext = os.path.splitext(paths["output"])[1].lower()
    with StagedFiles(paths, overwrite=job.overwrite) as stage:
        hdr = io.read_any(job.input)
        img, n_negative = prepare_radiance(hdr, f"input {os.fspath(job.input)!r}")
        t0 = time.perf_counter()
        out = _apply(job, img)
        dt = time.perf_counter() - t0
        io.write_any(stage.staging["output"], to_display_file(out, ext))
    return {"outputs": paths, "seconds": dt, "shape": out.shape, "negative_clamped": n_negative}
