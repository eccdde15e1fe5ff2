"""Named image operations for the ``jaxgfx filter`` command.

Each entry maps an operation name to a function ``(image, **params) -> image`` and the
parameter names it accepts. Display-referred inputs (PNG/JPEG/TIFF) are processed as floats in
[0, 1]; outputs are clipped to [0, 1] when written to a display-referred format.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable

import numpy as np

from jaxgfx._checks import check_choice
from jaxgfx.io import LDR_WRITE_EXTENSIONS

__all__ = [
    "FILTER_OPS",
    "FilterOp",
    "FilterJob",
    "apply_filter",
    "apply_filter_file",
    "check_filter_params",
    "run_filter",
]


@dataclasses.dataclass(frozen=True)
class FilterOp:
    """A ``jaxgfx filter`` operation: ``fn(image, *params)``, its parameter names, the defaults
    of parameters the library function has none for (``cli_defaults``), and ``source``: the
    library function (``"image.canny"``) whose signature gives every other default — one
    source of truth, so the CLI cannot drift from the library."""

    fn: Callable
    params: tuple[str, ...]
    cli_defaults: dict
    doc: str
    source: str | None = None

    @property
    def defaults(self) -> dict:
        out = dict(self.cli_defaults)
        if self.source is not None:
            import inspect

            mod, name = self.source.split(".")
            fn = getattr(_image() if mod == "image" else _color(), name)
            for k, prm in inspect.signature(fn).parameters.items():
                if k in self.params and prm.default is not inspect.Parameter.empty:
                    if prm.default is not None:
                        out[k] = prm.default
        return out


def _image():
    from jaxgfx import image

    return image


def _color():
    from jaxgfx import color

    return color


def _edge_map(mask):
    return np.asarray(mask, np.float32)


def _magnitude(gx_gy):
    gx, gy = gx_gy
    return np.sqrt(np.asarray(gx) ** 2 + np.asarray(gy) ** 2)


FILTER_OPS: dict[str, FilterOp] = {
    "gaussian": FilterOp(
        lambda im, sigma, padding: _image().gaussian_blur(im, sigma, padding=padding),
        ("sigma", "padding"),
        {"sigma": 2.0},
        "Gaussian blur (truncated at 3 sigma)",
        "image.gaussian_blur",
    ),
    "box": FilterOp(
        lambda im, radius, padding: _image().box_blur(im, 2 * int(radius) + 1, padding=padding),
        ("radius", "padding"),
        {"radius": 2},
        "box (mean) filter of size 2r+1",
        "image.box_blur",
    ),
    "median": FilterOp(
        lambda im, size, padding: _image().median_filter(im, size, padding=padding),
        ("size", "padding"),
        {"size": 3},
        "exact median filter",
        "image.median_filter",
    ),
    "bilateral": FilterOp(
        lambda im, sigma_spatial, sigma_range: _image().bilateral_filter(
            im, sigma_spatial, sigma_range
        ),
        ("sigma_spatial", "sigma_range"),
        {"sigma_spatial": 3.0, "sigma_range": 0.1},
        "edge-preserving bilateral filter",
    ),
    "unsharp": FilterOp(
        lambda im, sigma, amount: _image().unsharp_mask(im, sigma, amount),
        ("sigma", "amount"),
        {"sigma": 2.0, "amount": 1.0},
        "unsharp-mask sharpening",
    ),
    "log": FilterOp(
        lambda im, sigma: _image().laplacian_of_gaussian(im, sigma),
        ("sigma",),
        {"sigma": 2.0},
        "Laplacian of Gaussian ('hat' filter) response",
    ),
    "sobel": FilterOp(
        lambda im: _magnitude(_image().image_gradients(im, operator="sobel")),
        (),
        {},
        "Sobel gradient magnitude",
    ),
    "prewitt": FilterOp(
        lambda im: _magnitude(_image().image_gradients(im, operator="prewitt")),
        (),
        {},
        "Prewitt gradient magnitude",
    ),
    "roberts": FilterOp(
        lambda im: _magnitude(_image().image_gradients(im, operator="roberts")),
        (),
        {},
        "Roberts cross gradient magnitude",
    ),
    "canny": FilterOp(
        lambda im, sigma, low, high: _edge_map(_image().canny(im, sigma, low, high)),
        ("sigma", "low", "high"),
        {},
        "Canny edges (white on black)",
        "image.canny",
    ),
    "stretch": FilterOp(
        lambda im, low, high: _image().stretch_contrast(im, low=low, high=high),
        ("low", "high"),
        {},
        "linear contrast stretch between quantiles",
        "image.stretch_contrast",
    ),
    "gamma": FilterOp(
        lambda im, gamma: _image().gamma_correct(im, gamma),
        ("gamma",),
        {"gamma": 0.5},
        "gamma correction x**gamma",
    ),
    "equalize": FilterOp(
        lambda im: _image().equalize_histogram(im),
        (),
        {},
        "histogram equalisation",
    ),
    "lowpass": FilterOp(
        lambda im, cutoff: _image().fourier_lowpass(im, cutoff),
        ("cutoff",),
        {"cutoff": 0.1},
        "Gaussian Fourier low-pass",
    ),
    "highpass": FilterOp(
        lambda im, cutoff: _image().fourier_highpass(im, cutoff),
        ("cutoff",),
        {"cutoff": 0.1},
        "Gaussian Fourier high-pass",
    ),
    "grey-world": FilterOp(
        lambda im: _color().white_balance_grey_world(im),
        (),
        {},
        "grey-world white balance",
    ),
    "white-patch": FilterOp(
        lambda im, high: _color().white_balance_white_patch(im, quantile=high),
        ("high",),
        {"high": 0.99},
        "white-patch (robust brightest pixel) white balance",
    ),
    "demosaic": FilterOp(
        lambda im, pattern: _image().demosaic(im[..., 0] if im.ndim == 3 else im, pattern),
        ("pattern",),
        {},
        "Malvar-He-Cutler demosaicing of a single-channel Bayer mosaic",
        "image.demosaic",
    ),
}


def check_filter_params(op: str, params: dict) -> dict:
    """The keyword arguments for ``op``: defaults updated with ``params``. Raises
    ``ValueError`` for an unknown op or parameter, naming it (``--radius``, ...)."""
    check_choice(op, "op", sorted(FILTER_OPS))
    spec = FILTER_OPS[op]
    unknown = sorted(set(params) - set(spec.params))
    if unknown:
        raise ValueError(
            f"op {op!r} takes parameters {list(spec.params) or 'none'}; "
            f"unexpected: {', '.join('--' + u.replace('_', '-') for u in unknown)}"
        )
    for name, check in _PARAM_CHECKS.items():
        if name in params:
            check(params[name])
    return {**spec.defaults, **params}


def _nonneg_int(name):
    def check(v):
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise ValueError(f"--{name}: expected an integer >= 0, got {v!r}")

    return check


def _positive(name):
    def check(v):
        if not (isinstance(v, (int, float)) and np.isfinite(v) and v > 0):
            raise ValueError(f"--{name}: expected a finite value > 0, got {v!r}")

    return check


def _finite(name):
    def check(v):
        if not (isinstance(v, (int, float)) and np.isfinite(v)):
            raise ValueError(f"--{name}: expected a finite number, got {v!r}")

    return check


# CLI-level checks of parameters that the ops transform before the library sees them
# (``box`` turns --radius r into a size 2r+1): the error names the option the user typed.
_PARAM_CHECKS = {
    "radius": _nonneg_int("radius"),
    "sigma": _positive("sigma"),
    "sigma_spatial": _positive("sigma-spatial"),
    "sigma_range": _positive("sigma-range"),
    "cutoff": _positive("cutoff"),
    "gamma": _positive("gamma"),
    "amount": _finite("amount"),
    "low": _finite("low"),
    "high": _finite("high"),
}


def apply_filter(image, op: str, **params):
    """Apply the named operation to an image array; unknown op/params raise ValueError."""
    kwargs = check_filter_params(op, params)
    return np.asarray(FILTER_OPS[op].fn(image, **kwargs))


_DISPLAY_EXT = LDR_WRITE_EXTENSIONS  # display formats: clipped to [0, 1]


@dataclasses.dataclass(frozen=True)
class FilterJob:
    """One ``jaxgfx filter`` run: ``input`` → ``op(**params)`` → ``output`` (format from the
    extension; display formats are clipped to [0, 1]). ``overwrite``: replace an existing
    ``output`` (else refused)."""

    input: str
    output: str
    op: str = "gaussian"
    params: dict = dataclasses.field(default_factory=dict)
    overwrite: bool = False


def run_filter(job: FilterJob) -> str:
    """Run a :class:`FilterJob`: the op, its parameters and the output path are checked
    before the input is read; the output is staged and moved into place at the end.
    Returns the output path."""
    from jaxgfx import io
    from jaxgfx.pipelines._output import StagedFiles, check_output_extension

    kwargs = check_filter_params(job.op, dict(job.params))
    ext = check_output_extension(job.output, "output")
    if os.path.isdir(job.input):
        raise IsADirectoryError(21, "input: is a directory, expected an image file", job.input)
    with StagedFiles({"output": job.output}, overwrite=job.overwrite) as stage:
        img = np.asarray(io.read_any(job.input))
        if np.issubdtype(img.dtype, np.integer):
            img = img.astype(np.float32) / np.iinfo(img.dtype).max
        out = np.asarray(FILTER_OPS[job.op].fn(img.astype(np.float32), **kwargs))
        if ext in _DISPLAY_EXT:
            out = np.clip(out, 0.0, 1.0)
        io.write_any(stage.staging["output"], out)
    return os.fspath(job.output)


def apply_filter_file(src, dst, op: str, **params) -> str:
    """Read ``src``, apply ``op``, write ``dst`` (format from its extension), replacing an
    existing ``dst``. Returns ``dst``. (``run_filter`` with ``overwrite=True``.)"""
    return run_filter(FilterJob(os.fspath(src), os.fspath(dst), op, dict(params), overwrite=True))
