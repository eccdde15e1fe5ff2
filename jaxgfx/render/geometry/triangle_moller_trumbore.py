"""Möller & Trumbore (1997) ray-triangle test (Cramer's rule on the edge vectors)."""

from __future__ import annotations

import jax.numpy as jnp

from jaxgfx._math import safe_div, vdot

__all__ = ["triangle_intersect_moller_trumbore", "moller_trumbore_all"]


def triangle_intersect_moller_trumbore(v0, v1, v2, o, d, tmin=0.0, tmax=jnp.inf):
    """Möller & Trumbore 1997 ray-triangle test: ``(t, b1, b2)``.

    Solves ``o + t d = (1 - b1 - b2) v0 + b1 v1 + b2 v2`` by Cramer's rule:
    ``P = d x e2``, ``T = o - v0``, ``Q = T x e1``, ``(t, b1, b2) = (Q.e2, P.T, Q.d) / P.e1``
    with ``e1 = v1 - v0``, ``e2 = v2 - v0``. Two-sided; edges count as inside. Degenerate
    (zero-area) triangles and rays parallel to the plane give ``det = 0`` → ``t = inf`` with
    finite ``b1, b2`` and gradients. Broadcasts ``v* (..., 3)`` against ``o, d (..., 3)``.
    Example: triangle (0,0,0),(1,0,0),(0,1,0), ray from (0.25, 0.25, 1) along -z →
    ``(1, 0.25, 0.25)``.
    """
    e1 = v1 - v0
    e2 = v2 - v0
    P = jnp.cross(d, e2)
    det = vdot(P, e1)
    T = o - v0
    Q = jnp.cross(T, e1)
    ok = det != 0
    t = safe_div(vdot(Q, e2), det)
    b1 = safe_div(vdot(P, T), det)
    b2 = safe_div(vdot(Q, d), det)
    hit = ok & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > tmin) & (t < tmax)
    return jnp.where(hit, t, jnp.inf), b1, b2


def moller_trumbore_all(tri, o, d, tmin, tmax):
    """Ray parameters ``t (..., F)`` of rays ``o, d (..., 3)`` against all triangles
    ``tri (F, 3, 3)`` (``inf`` where missed)."""
    return triangle_intersect_moller_trumbore(
        tri[:, 0], tri[:, 1], tri[:, 2], o[..., None, :], d[..., None, :], tmin, tmax
    )[0]
