"""Shared helpers for :mod:`jaxgfx.color` (private)."""

from __future__ import annotations

import jax.numpy as jnp

from .._checks import as_float_array, check_finite

__all__ = ["as_colour", "as_values", "cast_const"]


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
