"""Image losses for inverse problems: L2, relative L2, L1 in linear, log or CIE Lab space, with
an optional pixel mask, and a censored (quantisation- and clipping-aware) L2 for 8-bit targets.

All losses take a prediction ``x`` and a target ``y`` of the same shape ``(..., H, W, C)`` (or
any shape; the mask broadcasts against it) and return the *mean* over the (masked) elements, a
scalar. Jittable and differentiable in ``x`` with finite gradients at 0, at negative values (MC
noise) and at the clipping levels.

Spaces (applied to ``x`` and ``y`` before the difference, see :data:`LOSS_SPACES`):

* ``"linear"``: the values as given;
* ``"log"``: ``log(max(v, 0) + offset)`` (``offset`` default ``1e-2``; a soft log that makes the
  loss scale-invariant above ``offset`` and tolerant of zeros);
* ``"lab"``: linear sRGB (Rec. 709 primaries, D65) → CIE XYZ → CIE 1976 L*a*b* with
  :mod:`jaxgfx.color` (``C = 3`` required); L2 in Lab is the mean squared ΔE*ab (1976).

References: relative L2 — Lehtinen et al. 2018 ("Noise2Noise") and Nimier-David et al. 2020
("Radiative backpropagation"), the ``stop_gradient`` denominator keeps the estimator's
expectation; censored least squares (Tobit) — Tobin 1958.

Example: ``l2_loss(jnp.array([1.0, 3.0]), jnp.array([0.0, 1.0]))`` → ``2.5``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._checks import as_float_array, check_choice

__all__ = [
    "l2_loss",
    "relative_l2_loss",
    "l1_loss",
    "image_loss",
    "censored_l2_loss",
    "LOSSES",
    "LOSS_SPACES",
]


def _to_space(v, space, offset):
    if space == "linear":
        return v
    if space == "log":
        return jnp.log(jnp.maximum(v, 0.0) + offset)
    from jaxgfx.color import rgb_to_xyz, xyz_to_lab

    return xyz_to_lab(rgb_to_xyz(v))


LOSS_SPACES = ("linear", "log", "lab")


def _prepare(x, y, space, mask, offset):
    x = as_float_array(x, "x")
    y = as_float_array(y, "y")
    if x.shape != y.shape:
        raise ValueError(f"y: expected the shape of x {x.shape}, got {y.shape}")
    check_choice(space, "space", LOSS_SPACES)
    if space == "lab" and (x.ndim == 0 or x.shape[-1] != 3):
        raise ValueError(f"x: space='lab' needs RGB values (..., 3), got shape {x.shape}")
    if space == "log" and not offset > 0:
        raise ValueError(f"offset: expected a positive number for space='log', got {offset!r}")
    if mask is not None:
        mask = as_float_array(mask, "mask")
        try:
            shape = jnp.broadcast_shapes(mask.shape, x.shape)
        except ValueError:
            shape = None
        if shape is None and mask.shape == x.shape[:-1]:
            mask = mask[..., None]
            shape = x.shape
        if shape != x.shape:
            raise ValueError(
                f"mask: expected a shape broadcastable to {x.shape} (or {x.shape[:-1]}), got "
                f"{mask.shape}"
            )
    return x, y, mask


def _reduce(e, mask):
    if mask is None:
        return jnp.mean(e)
    w = jnp.broadcast_to(mask, e.shape)
    tot = jnp.sum(w)
    safe = jnp.where(tot > 0, tot, 1.0)
    return jnp.where(tot > 0, jnp.sum(w * e) / safe, 0.0)


def l2_loss(x, y, *, space: str = "linear", mask=None, offset: float = 1e-2):
    """Mean squared error ``mean(w · (T(x) - T(y))²) / mean(w)`` in ``space`` (module doc).

    ``mask``: weights ``(..., H, W)`` or broadcastable to ``x`` (0 = ignore); an all-zero mask
    gives 0. Example: ``l2_loss(jnp.array([1.0, 3.0]), jnp.array([0.0, 1.0]))`` → ``2.5``.
    """
    x, y, mask = _prepare(x, y, space, mask, offset)
    d = _to_space(x, space, offset) - _to_space(y, space, offset)
    return _reduce(d * d, mask)


def relative_l2_loss(
    x, y, *, space: str = "linear", mask=None, eps: float = 1e-2, offset: float = 1e-2
):
    """Relative MSE ``mean((T(x) - T(y))² / (stop_gradient(T(x))² + eps))``.

    The denominator carries no gradient, so with an unbiased Monte Carlo ``x`` the gradient is
    a per-pixel reweighting of the L2 gradient (bright pixels and highlights do not dominate).
    ``eps`` (> 0) keeps black pixels finite. Example: ``relative_l2_loss(jnp.array([2.0]),
    jnp.array([1.0]), eps=1e-12)`` → ``≈ 0.25``.
    """
    if not eps > 0:
        raise ValueError(f"eps: expected a positive number, got {eps!r}")
    x, y, mask = _prepare(x, y, space, mask, offset)
    tx = _to_space(x, space, offset)
    d = tx - _to_space(y, space, offset)
    return _reduce(d * d / (jax.lax.stop_gradient(tx) ** 2 + eps), mask)


def l1_loss(x, y, *, space: str = "linear", mask=None, offset: float = 1e-2):
    """Mean absolute error in ``space``; the gradient at ``x == y`` is 0 (``sign(0) = 0``).

    Example: ``l1_loss(jnp.array([1.0, 3.0]), jnp.array([0.0, 1.0]))`` → ``1.5``.
    """
    x, y, mask = _prepare(x, y, space, mask, offset)
    d = _to_space(x, space, offset) - _to_space(y, space, offset)
    return _reduce(jnp.abs(d), mask)


LOSSES = {"l2": l2_loss, "relative_l2": relative_l2_loss, "l1": l1_loss}
"""Image losses by name: ``fn(x, y, *, space, mask, ...) -> scalar``."""


def image_loss(x, y, *, kind: str = "l2", space: str = "linear", mask=None, **options):
    """Dispatch to :data:`LOSSES` by name (``kind``): ``"l2"``, ``"relative_l2"``, ``"l1"``."""
    check_choice(kind, "kind", tuple(LOSSES))
    return LOSSES[kind](x, y, space=space, mask=mask, **options)


def censored_l2_loss(v, codes, *, code_max: float = 255.0, mask=None):
    """Quantisation- and clipping-aware L2 between a continuous display value ``v`` (the
    camera model's output in ``[0, 1]`` *before* quantisation; may exceed the range) and
    integer target ``codes`` (``0 … code_max``, e.g. an 8-bit photo).

    Unsaturated codes: ``(v - q/code_max)²`` (the expectation of the squared error against the
    uniformly distributed pre-quantisation value, up to the constant ``1/(12 code_max²)``).
    Clipped codes carry only a bound (censored data, Tobin 1958): ``q = code_max`` says
    ``v ≥ (code_max - ½)/code_max`` and costs ``max(0, (code_max - ½)/code_max - v)²``; ``q = 0``
    says ``v ≤ ½/code_max`` and costs ``max(0, v - ½/code_max)²``. So blown-out highlights pull
    the prediction up to the clipping level but not beyond, instead of pulling a bright
    specular peak *down* to 1.

    Example: ``censored_l2_loss(jnp.array([1.3, 0.5]), jnp.array([255.0, 102.0]))`` →
    ``0.5 · (0.5 - 0.4)² = 0.005`` (the clipped pixel costs nothing).
    """
    v = as_float_array(v, "v")
    q = as_float_array(codes, "codes")
    if q.shape != v.shape:
        raise ValueError(f"codes: expected the shape of v {v.shape}, got {q.shape}")
    if not code_max > 0:
        raise ValueError(f"code_max: expected a positive number, got {code_max!r}")
    if mask is not None:
        _, _, mask = _prepare(v, v, "linear", mask, 1.0)
    c = jnp.asarray(code_max, v.dtype)
    y = q / c
    hi = (c - 0.5) / c
    lo = 0.5 / c
    e = jnp.where(
        q >= c,
        jnp.maximum(hi - v, 0.0),
        jnp.where(q <= 0, jnp.maximum(v - lo, 0.0), v - y),
    )
    return _reduce(e * e, mask)
