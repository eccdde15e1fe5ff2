# ruff: noqa: F722  (jaxtyping shape strings)
"""Rectangles (parallelograms): the :class:`Rectangles` primitive set, the ray test and its hit
record."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxgfx._math import cross, fusion_barrier, safe_div, safe_normalize, take_rows, vdot
from jaxgfx.render.geometry._points import as_points
from jaxgfx.render.geometry.ray import Hit, hit_record

__all__ = ["Rectangles", "rectangle_intersect", "rectangle_hit"]


class Rectangles(eqx.Module):
    """``N`` parallelograms: ``centers (N, 3)``, full edge vectors ``edge_u, edge_v (N, 3)``.

    The surface is ``center + (s - 1/2) edge_u + (t - 1/2) edge_v`` for ``s, t`` in [0, 1]
    (a rectangle when the edges are orthogonal); ``uv = (s, t)``; the geometric normal is
    ``normalize(edge_u x edge_v)``; the surface is hit from both sides. Single rectangles may be
    given with ``(3,)`` arrays.
    """

    centers: Float[Array, "N 3"]
    edge_u: Float[Array, "N 3"]
    edge_v: Float[Array, "N 3"]

    def __init__(self, centers, edge_u, edge_v):
        arrs = []
        for name, a in (("centers", centers), ("edge_u", edge_u), ("edge_v", edge_v)):
            a = jnp.asarray(a)
            arrs.append(as_points(a[None] if a.ndim == 1 else a, name, 3))
        if not arrs[0].shape == arrs[1].shape == arrs[2].shape:
            raise ValueError(
                "edge_u, edge_v: expected the shape of centers "
                f"{arrs[0].shape}, got {arrs[1].shape}, {arrs[2].shape}"
            )
        dt = jnp.result_type(*arrs)
        self.centers, self.edge_u, self.edge_v = (a.astype(dt) for a in arrs)


def rectangle_intersect(center, edge_u, edge_v, o, d, tmin=0.0, tmax=jnp.inf):
    """``(t, s, u)`` of a ray against parallelograms (see :class:`Rectangles`).

    ``t = inf`` where the ray misses, is parallel to the plane (no NaN), or the hit is outside
    ``(tmin, tmax)``. Edges are closed: ``s, u`` in [0, 1] count as hits.
    """
    n = cross(edge_u, edge_v)
    denom = vdot(d, n)
    t = safe_div(vdot(center - o, n), denom, fill=jnp.inf)
    rel = o + jnp.where(jnp.isfinite(t), t, 0.0)[..., None] * d - center
    # Dual basis of (edge_u, edge_v) within the plane: s = rel.(edge_v x n)/|n|^2 + 1/2.
    nn = vdot(n, n)
    s = safe_div(vdot(rel, cross(edge_v, n)), nn) + 0.5
    u = safe_div(vdot(rel, cross(n, edge_u)), nn) + 0.5
    ok = (denom != 0) & (t > tmin) & (t < tmax) & (s >= 0) & (s <= 1) & (u >= 0) & (u <= 1)
    return jnp.where(ok, t, jnp.inf), s, u


def rectangle_hit(shape: Rectangles, pid, o, d, valid, prim_id, sid) -> Hit:
    """Differentiable hit record of rays ``o, d`` against rectangle ``pid``."""
    c, eu, ev = (take_rows(a, pid) for a in (shape.centers, shape.edge_u, shape.edge_v))
    # materialised: the record's fields are separate kernels that each repeated the test
    t, s, u = fusion_barrier(rectangle_intersect(c, eu, ev, o, d, -jnp.inf, jnp.inf))
    valid = valid & jnp.isfinite(t)
    tt = jnp.where(valid, t, 0.0)
    p = c + (s - 0.5)[..., None] * eu + (u - 0.5)[..., None] * ev
    ng = safe_normalize(cross(eu, ev)) * jnp.ones_like(p)
    uv = jnp.stack([s, u], axis=-1)
    return hit_record(valid, tt, p, ng, ng, uv, prim_id, sid)
