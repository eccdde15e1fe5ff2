"""White-furnace test: directional albedo of a BSDF by Monte Carlo."""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["furnace"]


def furnace(bsdf, wo, *, key, n: int = 100_000):
    """Directional albedo ``a(wo) = ∫ f(wo, wi) |cos θ_i| dω_i`` estimated from ``bsdf.sample``.

    Mean of the sample weights (``eval / pdf``, or the delta throughput) over ``n`` samples
    drawn with ``key``. ``wo`` (3,) local direction. Returns ``(mean (3,), stderr (3,))``; the
    albedo of an energy-conserving BSDF is <= 1 (Lambert with reflectance 1: exactly 1).
    """
    if n < 2:
        raise ValueError(f"n: expected >= 2, got {n}")
    wo = jnp.asarray(wo)
    if wo.shape != (3,):
        raise ValueError(f"wo: expected shape (3,), got {wo.shape}")
    k1, k2 = jax.random.split(key)
    u1 = jax.random.uniform(k1, (n,), dtype=wo.dtype)
    u2 = jax.random.uniform(k2, (n, 2), dtype=wo.dtype)
    w = bsdf.sample(jnp.broadcast_to(wo, (n, 3)), u1, u2).weight
    mean = jnp.mean(w, axis=0)
    se = jnp.std(w, axis=0, ddof=1) / jnp.sqrt(n)
    return mean, se
