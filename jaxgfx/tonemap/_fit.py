"""Fitting tone-mapping parameters to a target display image by gradient optimisation."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import optax
import optimistix as optx

from .._checks import check_choice, check_image
from ..color.spaces import rgb_to_xyz, xyz_to_lab
from ..color.transfer import srgb_to_linear
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


def _to_free(v, kind):
    v = jnp.asarray(v, jnp.result_type(float))
    if kind == "positive":
        return jnp.log(v)
    if kind == "unit":
        return jnp.log(v) - jnp.log1p(-v)
    if kind == "above1":
        return jnp.log(v - 1.0)
    return v


def _from_free(u, kind):
    if kind == "positive":
        return jnp.exp(u)
    if kind == "unit":
        return jax.nn.sigmoid(u)
    if kind == "above1":
        return 1.0 + jnp.exp(u)
    return u


def _lab(display, encode):
    lin = srgb_to_linear(jnp.clip(display, 0.0, 1.0)) if encode == "srgb" else display
    return xyz_to_lab(rgb_to_xyz(lin))


@functools.lru_cache(maxsize=64)
def _residual_fn(op_name, kinds, static, loss, encode):
    """One residual closure per configuration, so repeated fits reuse the compiled program."""
    op = TONEMAP_METHODS[op_name]
    kinds = dict(kinds)
    static = dict(static)

    def residual(free, hdr, target):
        params = {k: _from_free(free[k], kinds[k]) for k in free}
        y = op(hdr, encode=encode, **static, **params)
        if loss == "lab":
            r = _lab(y, encode) - _lab(target, encode)
        else:
            r = y - target
        return r.reshape(-1)

    return residual


@functools.partial(jax.jit, static_argnames=("residual", "steps", "lr"))
def _adam(free0, hdr, target, *, residual, steps, lr):
    opt = optax.adam(lr)

    def loss_fn(free):
        r = residual(free, hdr, target)
        return jnp.mean(r * r)

    def step(carry, _):
        free, state = carry
        value, g = jax.value_and_grad(loss_fn)(free)
        updates, state = opt.update(g, state, free)
        return (optax.apply_updates(free, updates), state), value

    (free, _), hist = jax.lax.scan(step, (free0, opt.init(free0)), None, length=steps)
    return free, jnp.concatenate([hist, loss_fn(free)[None]])


@functools.partial(jax.jit, static_argnames=("residual", "steps"))
def _lm(free0, hdr, target, *, residual, steps):
    solver = optx.LevenbergMarquardt(rtol=1e-8, atol=1e-10)

    def fn(free, args):
        return residual(free, *args)

    sol = optx.least_squares(fn, solver, free0, (hdr, target), max_steps=steps, throw=False)
    r0 = residual(free0, hdr, target)
    r1 = residual(sol.value, hdr, target)
    return sol.value, jnp.stack([jnp.mean(r0 * r0), jnp.mean(r1 * r1)])


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
    operator's continuous parameters (:data:`TONEMAP_PARAMETERS`), optimised in an
    unconstrained space (log for positive, logit for (0, 1) parameters) by Adam (optax,
    ``steps`` iterations, ``learning_rate``) or Levenberg-Marquardt (optimistix, at most
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
    free0 = {n: _to_free(init.get(n, specs[n].initial), specs[n].constraint) for n in names}
    kinds = {n: specs[n].constraint for n in names}
    static = {**_static_options(op_name, x, names), **(fixed or {})}
    residual = _residual_fn(
        op_name, tuple(kinds.items()), tuple(sorted(static.items())), loss, encode
    )
    if solver == "adam":
        free, hist = _adam(free0, x, t, residual=residual, steps=int(steps), lr=learning_rate)
    else:
        free, hist = _lm(free0, x, t, residual=residual, steps=int(steps))
    params = {n: float(_from_free(free[n], kinds[n])) for n in names}
    return TonemapFit(params, hist, float(hist[-1]))
