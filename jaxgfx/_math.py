"""Safe elementwise math: finite values *and* finite gradients everywhere.

Every function guards both branches of its ``jnp.where`` so that reverse-mode AD never
multiplies a zero cotangent by an infinite/NaN partial derivative (the "double where" trick).
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = [
    "safe_div",
    "safe_sqrt",
    "safe_log",
    "safe_pow",
    "safe_norm",
    "safe_normalize",
    "safe_arccos",
    "safe_atan2",
    "eps_for",
]


def eps_for(x) -> float:
    """Machine epsilon of ``x``'s floating dtype (float32 if ``x`` is not floating)."""
    dt = jnp.result_type(x)
    if not jnp.issubdtype(dt, jnp.floating):
        dt = jnp.float32
    return float(jnp.finfo(dt).eps)


def safe_div(a, b, *, fill=0.0):
    """``a / b`` where ``b != 0``, else ``fill``; gradient is 0 (not NaN) where ``b == 0``."""
    nz = b != 0
    b_safe = jnp.where(nz, b, 1.0)
    return jnp.where(nz, a / b_safe, fill)


def safe_sqrt(x):
    """``sqrt(max(x, 0))`` with gradient 0 at and below 0 (instead of inf/NaN)."""
    pos = x > 0
    x_safe = jnp.where(pos, x, 1.0)
    return jnp.where(pos, jnp.sqrt(x_safe), 0.0)


def safe_log(x, *, floor=None):
    """``log(max(x, floor))``; ``floor`` defaults to the dtype's smallest normal number."""
    if floor is None:
        dt = jnp.result_type(x)
        if not jnp.issubdtype(dt, jnp.floating):
            dt = jnp.float32
        floor = float(jnp.finfo(dt).tiny)
    ok = x > floor
    x_safe = jnp.where(ok, x, 1.0)
    return jnp.where(ok, jnp.log(x_safe), jnp.log(jnp.asarray(floor, jnp.result_type(x, 1.0))))


def safe_pow(x, p):
    """``max(x, 0) ** p`` with finite gradient w.r.t. both ``x`` and ``p`` at ``x == 0``."""
    pos = x > 0
    x_safe = jnp.where(pos, x, 1.0)
    return jnp.where(pos, x_safe**p, 0.0)


def safe_norm(v, *, axis=-1, keepdims=False):
    """Euclidean norm with zero (not NaN) gradient at the zero vector."""
    return safe_sqrt(jnp.sum(v * v, axis=axis, keepdims=keepdims))


def safe_normalize(v, *, axis=-1):
    """``v / |v|``; the zero vector maps to zero with a finite gradient."""
    n = safe_norm(v, axis=axis, keepdims=True)
    return safe_div(v, n)


def safe_arccos(x):
    """``arccos(clip(x, -1, 1))`` with finite gradient at the clip boundaries."""
    eps = eps_for(x)
    inside = jnp.abs(x) < 1.0 - eps
    x_safe = jnp.where(inside, x, 0.0)
    return jnp.where(inside, jnp.arccos(x_safe), jnp.where(x > 0, 0.0, jnp.pi))


def safe_atan2(y, x):
    """``atan2(y, x)`` that returns 0 with zero gradient at the origin."""
    origin = (x == 0) & (y == 0)
    x_safe = jnp.where(origin, 1.0, x)
    y_safe = jnp.where(origin, 0.0, y)
    return jnp.where(origin, 0.0, jnp.arctan2(y_safe, x_safe))
