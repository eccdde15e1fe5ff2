"""Shared helpers for :mod:`jaxgfx.color` (private)."""

from __future__ import annotations

import jax.numpy as jnp

from .._checks import as_float_array, check_finite

__all__ = ["as_colour", "as_values", "cast_const", "matvec3"]


def as_colour(x, name: str, *, channels: int = 3):
    """Validate a colour array ``(..., channels)`` and return it as a float JAX array.

    Raises ``ValueError`` naming ``name`` when the last axis has the wrong size or a concrete
    array holds NaN/Inf; ``TypeError`` for non-numeric input. Tracers pass through.
    """
    arr = as_float_array(x, name)
    if arr.ndim < 1 or arr.shape[-1] != channels:
        raise ValueError(f"{name}: expected shape (..., {channels}), got shape {arr.shape}")
    check_finite(arr, name)
    return arr


def as_values(x, name: str):
    """Validate an array of any shape (finite, numeric) and return it as a float JAX array."""
    arr = as_float_array(x, name)
    check_finite(arr, name)
    return arr


def cast_const(c, like):
    """Cast a NumPy constant to ``like``'s floating dtype."""
    return jnp.asarray(c, dtype=jnp.result_type(like))


def matvec3(m, x):
    """``y[..., i] = sum_j m[..., i, j] x[..., j]`` for 3x3 ``m`` (broadcast over batch axes).

    Written as three broadcast multiply-adds: on XLA:CPU this is ~5x faster than ``x @ m.T``
    (a dot with a contraction of size 3) on large images.
    """
    m = jnp.asarray(m)
    if m.ndim > 2:  # batched matrices (..., 3, 3) against images (..., H, W, 3)
        extra = x.ndim - m.ndim + 1
        m = m.reshape(m.shape[:-2] + (1,) * extra + m.shape[-2:])
    return x[..., 0:1] * m[..., 0] + x[..., 1:2] * m[..., 1] + x[..., 2:3] * m[..., 2]
