"""Fitting tone-mapping parameters to a target display image by gradient optimisation."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax.numpy as jnp

from .._checks import check_choice, check_image
from ..color.spaces import rgb_to_xyz, xyz_to_lab
from ..color.transfer import srgb_to_linear
from ..optim import fit as optim_fit
from ..optim import fit_least_squares
from ._common import check_hdr
from ._local import durand_range_bins
from ._registry import TONEMAP_METHODS, TONEMAP_PARAMETERS

__all__ = ["fit_tonemap", "TonemapFit", "FIT_LOSSES"]

FIT_LOSSES = ("lab", "l2")


class TonemapFit(NamedTuple):
    """Result of :func:`fit_tonemap`: fitted ``params`` (dict of floats), the loss per step
    ``loss_history`` (``(steps + 1,)`` for Adam; initial and final for least squares) and the
    final ``loss``."""

    params: dict
    loss_history: jnp.ndarray
    loss: float


_CONSTRAINT_BOUNDS = {"positive": (0.0, None), "unit": (0.0, 1.0), "above1": (1.0, None)}
"""Each :class:`ParamSpec` constraint as bounds of :func:`jaxgfx.optim.fit` (its smooth
bijections: softplus for one-sided, sigmoid for two-sided bounds; ``"real"``: none)."""


def _lab(display, encode):
    lin = srgb_to_linear(jnp.clip(display, 0.0, 1.0)) if encode == "srgb" else display
    return xyz_to_lab(rgb_to_xyz(lin))


@functools.lru_cache(maxsize=64)
def _residual_fn(op_name, static, loss, encode):
    """One residual closure per configuration, so repeated fits reuse the compiled program."""
    op = TONEMAP_METHODS[op_name]
    static = dict(static)

    def residual(params, args):
        hdr, target = args
        y = op(hdr, encode=encode, **static, **params)
        if loss == "lab":
            r = _lab(y, encode) - _lab(target, encode)
        else:
            r = y - target
        return r.reshape(-1)

    return residual


@functools.lru_cache(maxsize=64)
def _mse_fn(residual):
    def mse(params, args):
        r = residual(params, args)
        return jnp.mean(r * r)

    return mse


def _static_options(op_name, hdr, fit_names):
    if op_name == "contrast_inversion":
        return {"radius": 24}
    if op_name == "durand" and "sigma_range" in fit_names:
        return {"range_bins": durand_range_bins(hdr, 0.1)}
    return {}


def fit_tonemap(
    op_name: str,
    hdr,
    target_ldr,
    *,
    init: dict | None = None,
    fit: tuple[str, ...] | None = None,
    fixed: dict | None = None,
    steps: int = 300,
    loss: str = "lab",
    solver: str = "adam",
    learning_rate: float = 0.05,
    encode: str = "srgb",
) -> TonemapFit:
    """Recover an operator's parameters from an (HDR, display image) pair.

    Minimises the mean squared CIELAB difference (``loss="lab"``: ``mean ΔE76^2`` of the
    display images decoded to linear sRGB) or of display values (``"l2"``) over the
    operator's continuous parameters (:data:`TONEMAP_PARAMETERS`), each kept in its range by
    the bijections of :mod:`jaxgfx.optim` (softplus for positive / > 1, sigmoid for (0, 1)
    parameters), by :func:`jaxgfx.optim.fit` with Adam (``steps`` iterations,
    ``learning_rate``) or :func:`jaxgfx.optim.fit_least_squares` (Levenberg-Marquardt, at most
    ``steps`` iterations). E.g. recover the curve a camera applied to its JPEG from the RAW.

    Args:
        op_name: a key of :data:`TONEMAP_METHODS` (``"reinhard_devlin"`` included).
        hdr: linear radiance ``(H, W, 3)``.
        target_ldr: display image ``(H, W, 3)`` in [0, 1] with encoding ``encode``.
        init: starting values (default: the documented defaults).
        fit: names of the parameters to fit (default: all of :data:`TONEMAP_PARAMETERS`).
        fixed: other keyword options for the operator, held fixed.
        steps: iterations. loss: ``"lab"`` or ``"l2"``. solver: ``"adam"`` or
            ``"least_squares"``.

    Returns:
        :class:`TonemapFit` with the fitted parameters as Python floats.
    """
    check_choice(op_name, "op_name", tuple(TONEMAP_METHODS))
    check_choice(loss, "loss", FIT_LOSSES)
    check_choice(solver, "solver", ("adam", "least_squares"))
    x = check_hdr(hdr)
    t = check_image(target_ldr, "target_ldr")
    if t.shape != x.shape:
        raise ValueError(f"target_ldr: expected the shape of hdr {x.shape}, got {t.shape}")
    if loss == "lab" and x.shape[-1] != 3:
        raise ValueError(f"loss: 'lab' needs RGB images (..., 3); got shape {x.shape}")
    specs = TONEMAP_PARAMETERS[op_name]
    names = tuple(specs) if fit is None else tuple(fit)
    for n in names:
        if n not in specs:
            raise ValueError(f"fit: {n!r} is not a parameter of {op_name!r} ({sorted(specs)})")
    init = dict(init or {})
    params0 = {
        n: jnp.asarray(init.get(n, specs[n].initial), jnp.result_type(float)) for n in names
    }
    bounds = {n: _CONSTRAINT_BOUNDS.get(specs[n].constraint) for n in names}
    static = {**_static_options(op_name, x, names), **(fixed or {})}
    residual = _residual_fn(op_name, tuple(sorted(static.items())), loss, encode)
    mse = _mse_fn(residual)
    args = (x, t)
    if solver == "adam":
        res = optim_fit(  # `fit` is this function's argument (the names to fit)
            mse, params0, optimizer="adam", steps=int(steps), learning_rate=learning_rate,
            args=args, bounds=bounds, progress=False, keep_history=False,
        )  # fmt: skip
        hist = jnp.concatenate([jnp.asarray(res.loss), mse(res.params, args)[None]])
    else:
        res = fit_least_squares(
            residual, params0, solver="lm", args=args, bounds=bounds, max_steps=int(steps),
            rtol=1e-8, atol=1e-10,
        )  # fmt: skip
        hist = jnp.stack([mse(params0, args), mse(res.params, args)])
    params = {n: float(res.params[n]) for n in names}
    return TonemapFit(params, hist, float(hist[-1]))
