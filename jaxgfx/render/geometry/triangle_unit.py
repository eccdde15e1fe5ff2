# ruff: noqa: F722  (jaxtyping shape strings)
"""The unit-triangle ray test: an affine map takes each triangle to the unit triangle, where the
hit is a division and two comparisons (precomputed per triangle; Baldwin & Weber 2016 style)."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxgfx._math import safe_div, vdot

__all__ = ["triangle_affine_matrices", "triangle_intersect_affine", "unit_triangle_all"]


def triangle_affine_matrices(v0, v1, v2) -> Float[Array, "... 3 4"]:
    """World → unit-triangle affine maps ``(..., 3, 4)`` for the affine ray-triangle test.

    ``T^-1 = [v1 - v0 | v2 - v0 | n] X + v0`` with ``n = (v1 - v0) x (v2 - v0)`` maps the unit
    triangle (1,0,0), (0,1,0), (0,0,0) onto (v1, v2, v0) and ``(0,0,1)`` onto ``v0 + n``; this
    returns its inverse ``[M | -M v0]`` in closed form: the rows of ``M`` are
    ``(e2 x n, n x e1, n) / |n|^2``. Zero-area triangles get ``M = 0`` (never hit).
    """
    e1 = v1 - v0
    e2 = v2 - v0
    n = jnp.cross(e1, e2)
    nn = vdot(n, n)[..., None]
    M = jnp.stack(
        [safe_div(jnp.cross(e2, n), nn), safe_div(jnp.cross(n, e1), nn), safe_div(n, nn)],
        axis=-2,
    )
    tr = -jnp.einsum("...ij,...j->...i", M, v0)
    return jnp.concatenate([M, tr[..., None]], axis=-1)


def triangle_intersect_affine(m, o, d, tmin=0.0, tmax=jnp.inf):
    """Unit-triangle ray test (affine transform to the unit triangle): ``(t, b1, b2)``.

    With ``m (..., 3, 4)`` from :func:`triangle_affine_matrices`: ``o' = M o + c``,
    ``d' = M d``, ``t = -o'_z / d'_z``, ``b1 = o'_x + t d'_x``, ``b2 = o'_y + t d'_y``; a hit
    when ``b1, b2 >= 0`` and ``b1 + b2 <= 1``. Gives the same ``(t, b1, b2)`` as
    :func:`triangle_intersect_moller_trumbore` (up to rounding). ``t`` is in world units since
    the affine map preserves the ray parameter.
    """
    M = m[..., :3]
    oo = jnp.einsum("...ij,...j->...i", M, o) + m[..., 3]
    dd = jnp.einsum("...ij,...j->...i", M, d)
    ok = dd[..., 2] != 0
    t = safe_div(-oo[..., 2], dd[..., 2])
    b1 = oo[..., 0] + t * dd[..., 0]
    b2 = oo[..., 1] + t * dd[..., 1]
    hit = ok & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > tmin) & (t < tmax)
    return jnp.where(hit, t, jnp.inf), b1, b2


def unit_triangle_all(tri, o, d, tmin, tmax):
    """Ray parameters ``t (..., F)`` of rays ``o, d (..., 3)`` against all triangles
    ``tri (F, 3, 3)`` (``inf`` where missed)."""
    m = triangle_affine_matrices(tri[:, 0], tri[:, 1], tri[:, 2])
    return triangle_intersect_affine(m, o[..., None, :], d[..., None, :], tmin, tmax)[0]
