"""Validation of shape parameters at the Python boundary (shared by the shape classes)."""

from __future__ import annotations

import jax.numpy as jnp

from jaxgfx._checks import check_finite


def as_points(x, name, last):
    """``x`` as a float array of shape ``(N, last)``, checked finite; ``ValueError`` naming
    ``name`` otherwise."""
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.float32)
    if x.ndim != 2 or x.shape[-1] != last:
        raise ValueError(f"{name}: expected shape (N, {last}), got {x.shape}")
    check_finite(x, name)
    return x
