# ruff: noqa: F722  (jaxtyping shape strings)
"""Spheres: the :class:`Spheres` primitive set, the closed-form ray test and its hit record."""

from __future__ import annotations

import math

import equinox as eqx
import jax
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

__all__ = ["Spheres", "sphere_intersect", "sphere_hit", "sphere_local", "sphere_uv"]


class Spheres(eqx.Module):
    """``N`` spheres: ``centers (N, 3)``, ``radii (N,)`` (> 0, world units), and optionally
    ``frames (N, 3, 3)``: orthogonal matrices whose columns are each sphere's local x, y, z
    axes in world space (Mitsuba's rotated ``to_world``). The uv ``(φ/2π, θ/π)`` and the
    tangents are those of the unit normal in that local frame; without ``frames`` the local
    frame is the world's.

    A 1-element sphere may be given as ``centers (3,)`` and a scalar radius (and ``(3, 3)``).
    """

    centers: Float[Array, "N 3"]
    radii: Float[Array, " N"]
    frames: Float[Array, "N 3 3"] | None = None

    def __init__(self, centers, radii, frames=None):
        c = jnp.asarray(centers)
        if c.ndim == 1:
            c = c[None]
        c = as_points(c, "centers", 3)
        r = jnp.asarray(radii, c.dtype).reshape(-1)
        if r.shape[0] != c.shape[0]:
            raise ValueError(f"radii: expected shape ({c.shape[0]},), got {r.shape}")
        check_nonnegative(r, "radii")
        self.centers, self.radii = c, r
        if frames is not None:
            f = jnp.asarray(frames, c.dtype)
            f = f[None] if f.ndim == 2 else f
            if f.shape != (c.shape[0], 3, 3):
                raise ValueError(f"frames: expected shape ({c.shape[0]}, 3, 3), got {f.shape}")
            if not isinstance(f, jax.core.Tracer):
                eye = jnp.eye(3, dtype=f.dtype)
                err = jnp.abs(jnp.swapaxes(f, -1, -2) @ f - eye).max()
                if not bool(err <= 1e-4):
                    raise ValueError(f"frames: expected orthogonal 3x3 matrices (|FᵀF - I| = "
                                     f"{float(err):.2g})")  # fmt: skip
        else:
            f = None
        self.frames = f


def sphere_local(shape: Spheres, pid, n):
    """Unit normals ``n (..., 3)`` of sphere ``pid`` in its local frame (``Fᵀ n``)."""
    if shape.frames is None:
        return n
    f = take_rows(shape.frames, pid).astype(n.dtype)
    return jnp.einsum("...ji,...j->...i", f, n)


def sphere_uv(local):
    """Mitsuba's sphere uv ``(φ/2π, θ/π)`` of a local unit normal: ``φ = atan2(y, x)`` in
    ``[0, 2π)``, ``θ = arccos z``."""
    theta = safe_arccos(local[..., 2])
    phi = safe_atan2(local[..., 1], local[..., 0])
    phi = jnp.where(phi < 0, phi + 2 * math.pi, phi)
    return jnp.stack([phi / (2 * math.pi), theta / math.pi], axis=-1)


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
    uv = sphere_uv(sphere_local(shape, pid, ng))
    return hit_record(valid, tt, p, ng, ng, uv, prim_id, sid)
