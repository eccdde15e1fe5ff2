# ruff: noqa: F722  (jaxtyping shape strings)
"""Spheres: the :class:`Spheres` primitive set, the closed-form ray test and its hit record."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxgfx._checks import check_nonnegative
from jaxgfx._math import (
    fusion_barrier,
    safe_arccos,
    safe_atan2,
    safe_div,
    safe_sqrt,
    take_rows,
    vdot,
)
from jaxgfx.render.geometry._points import as_points
from jaxgfx.render.geometry.ray import Hit, hit_record

__all__ = ["Spheres", "sphere_intersect", "sphere_hit"]


class Spheres(eqx.Module):
    """``N`` spheres: ``centers (N, 3)``, ``radii (N,)`` (> 0, world units).

    A 1-element sphere may be given as ``centers (3,)`` and a scalar radius.
    """

    centers: Float[Array, "N 3"]
    radii: Float[Array, " N"]

    def __init__(self, centers, radii):
        c = jnp.asarray(centers)
        if c.ndim == 1:
            c = c[None]
        c = as_points(c, "centers", 3)
        r = jnp.asarray(radii, c.dtype).reshape(-1)
        if r.shape[0] != c.shape[0]:
            raise ValueError(f"radii: expected shape ({c.shape[0]},), got {r.shape}")
        check_nonnegative(r, "radii")
        self.centers, self.radii = c, r


def sphere_intersect(center, radius, o, d, tmin=0.0, tmax=jnp.inf):
    """Ray parameter of the first sphere crossing in ``(tmin, tmax)``, ``inf`` if none.

    Broadcasts ``center (..., 3)``, ``radius (...)`` against ``o, d (..., 3)`` (``d`` unit).
    Uses the cancellation-free discriminant ``r^2 - |f - (f.d) d|^2`` with ``f = o - c`` and the
    stable root pair ``q = -(b + sign(b) sqrt(D))``, ``t = {q, c/q}`` (Haines et al., Ray
    Tracing Gems ch. 7, 2019). From inside the sphere the far root is returned; tangent rays
    (``D = 0``) hit once. Example: ``o = (0, 0, -5)``, ``d = (0, 0, 1)``, unit sphere at the
    origin → ``t = 4``.
    """
    f = o - center
    b = vdot(f, d)
    c = vdot(f, f) - radius * radius
    g = f - b[..., None] * d
    disc = radius * radius - vdot(g, g)
    ok = disc >= 0
    h = safe_sqrt(disc)
    q = -(b + jnp.where(b >= 0, h, -h))
    t1 = safe_div(c, q, fill=0.0)
    t_lo = jnp.minimum(q, t1)
    t_hi = jnp.maximum(q, t1)
    lo_ok = ok & (t_lo > tmin) & (t_lo < tmax)
    hi_ok = ok & (t_hi > tmin) & (t_hi < tmax)
    return jnp.where(lo_ok, t_lo, jnp.where(hi_ok, t_hi, jnp.inf))


def sphere_hit(shape: Spheres, pid, o, d, valid, prim_id, sid) -> Hit:
    """Differentiable hit record of rays ``o, d`` against sphere ``pid`` (see
    :func:`jaxgfx.render.geometry.intersect.primitive_hit`)."""
    c = take_rows(shape.centers, pid)
    r = take_rows(shape.radii, pid)
    # choose the root that the traversal found: the nearest positive one
    f = o - c
    b = vdot(f, d)
    g = f - b[..., None] * d
    h = safe_sqrt(r * r - vdot(g, g))
    t_lo, t_hi = -b - h, -b + h
    t = jnp.where(t_lo > 0, t_lo, t_hi)
    valid = valid & jnp.isfinite(t)
    # materialised: the record's fields are separate kernels that each repeated the test
    valid, tt = fusion_barrier((valid, jnp.where(valid, t, 0.0)))
    p = o + tt[..., None] * d
    ng = safe_div(p - c, jnp.where(r > 0, r, 1.0)[..., None])
    theta = safe_arccos(ng[..., 2])
    phi = safe_atan2(ng[..., 1], ng[..., 0])
    phi = jnp.where(phi < 0, phi + 2 * math.pi, phi)
    uv = jnp.stack([phi / (2 * math.pi), theta / math.pi], axis=-1)
    return hit_record(valid, tt, p, ng, ng, uv, prim_id, sid)
