"""Surface tangents ``dp/du``, ``dp/dv`` at hits (for normal and bump mapping).

Computed on demand from a :class:`~jaxgfx.render.geometry.ray.Hit` (its ``shape_id``,
``prim_id``, ``p`` and ``ng``), so scenes that never ask for them pay nothing. The
parameterisations are those of the hit's ``uv`` (Mitsuba 3's for each shape):

* triangles with UVs: the affine map of the triangle's UVs, ``dp/du = (Δv₂ e₁ - Δv₁ e₂) / det``,
  ``dp/dv = (Δu₁ e₂ - Δu₂ e₁) / det`` (``e₁ = v₁ - v₀``, ``e₂ = v₂ - v₀``, ``Δ`` of the UVs,
  ``det = Δu₁ Δv₂ - Δv₁ Δu₂``); without UVs (``uv`` = barycentrics): ``e₁``, ``e₂``;
* rectangles: ``edge_u``, ``edge_v``;
* spheres (``uv = (φ/2π, θ/π)``): ``dp/du = 2π r (-n_y, n_x, 0)``,
  ``dp/dv = π r (n_z cos φ, n_z sin φ, -sin θ)`` (``n`` in the sphere's local frame, the
  results rotated back by its ``frames``);
* shapes with a ``tangents(prim_id, p, ng)`` method (linear curves): theirs;
* anything else (SDF shapes, custom shapes), degenerate UV triangles and misses: zero vectors;
  consumers then fall back to an arbitrary tangent.
"""

from __future__ import annotations

import jax.numpy as jnp

from jaxgfx._math import safe_div, safe_sqrt, take_rows
from jaxgfx.render.geometry.mesh import TriangleMesh
from jaxgfx.render.geometry.rectangle import Rectangles
from jaxgfx.render.geometry.sphere import Spheres, sphere_local

__all__ = ["surface_tangents", "shape_tangents"]


def shape_tangents(shape, pid, p, ng):
    """``(dp/du, dp/dv)`` (..., 3) on primitive ``pid (...)`` of one shape at points ``p``
    with geometric normals ``ng``; zeros for shapes without a known parameterisation."""
    zero = jnp.zeros_like(p)
    if hasattr(shape, "tangents"):
        return shape.tangents(pid, p, ng)
    if hasattr(shape, "mesh") and not hasattr(shape, "hit"):
        shape = shape.mesh
    if isinstance(shape, Rectangles):
        eu = take_rows(jnp.atleast_2d(shape.edge_u), pid).astype(p.dtype)
        ev = take_rows(jnp.atleast_2d(shape.edge_v), pid).astype(p.dtype)
        return eu * jnp.ones_like(p), ev * jnp.ones_like(p)
    if isinstance(shape, Spheres):
        r = take_rows(jnp.atleast_1d(shape.radii), pid).astype(p.dtype)[..., None]
        nl = sphere_local(shape, pid, ng)  # in the sphere's local frame
        x, y, z = nl[..., 0], nl[..., 1], nl[..., 2]
        rho = safe_sqrt(x * x + y * y)  # sin θ
        cphi = safe_div(x, rho, fill=1.0)
        sphi = safe_div(y, rho)
        dpdu = 2 * jnp.pi * r * jnp.stack([-y, x, jnp.zeros_like(x)], axis=-1)
        dpdv = jnp.pi * r * jnp.stack([z * cphi, z * sphi, -rho], axis=-1)
        if shape.frames is not None:
            f = take_rows(shape.frames, pid).astype(p.dtype)
            dpdu = jnp.einsum("...ij,...j->...i", f, dpdu)
            dpdv = jnp.einsum("...ij,...j->...i", f, dpdv)
        return dpdu, dpdv
    if isinstance(shape, TriangleMesh):
        f = shape.faces[pid]
        v0, v1, v2 = (shape.vertices[f[..., k]].astype(p.dtype) for k in range(3))
        e1, e2 = v1 - v0, v2 - v0
        if shape.uvs is None:
            return e1, e2
        t0, t1, t2 = (shape.uvs[f[..., k]].astype(p.dtype) for k in range(3))
        d1, d2 = t1 - t0, t2 - t0
        det = d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]
        inv = safe_div(jnp.ones_like(det), det)[..., None]
        dpdu = (d2[..., 1:2] * e1 - d1[..., 1:2] * e2) * inv
        dpdv = (d1[..., 0:1] * e2 - d2[..., 0:1] * e1) * inv
        return dpdu, dpdv
    return zero, zero


def surface_tangents(shapes, hit):
    """``(dp/du, dp/dv)`` (..., 3) at the hits of a scene's shape list (selected by
    ``hit.shape_id``; zeros where nothing was hit). See the module docstring."""
    dpdu = jnp.zeros_like(hit.p)
    dpdv = jnp.zeros_like(hit.p)
    for i, s in enumerate(shapes):
        n = _count(s)
        pid = jnp.clip(hit.prim_id, 0, max(n - 1, 0))
        du, dv = shape_tangents(s, pid, hit.p, hit.ng)
        sel = (hit.shape_id == i)[..., None]
        dpdu = jnp.where(sel, du, dpdu)
        dpdv = jnp.where(sel, dv, dpdv)
    return dpdu, dpdv


def _count(shape):
    if hasattr(shape, "primitive_count"):
        return shape.primitive_count
    if hasattr(shape, "mesh") and not hasattr(shape, "hit"):
        shape = shape.mesh
    if isinstance(shape, TriangleMesh):
        return shape.faces.shape[0]
    if isinstance(shape, Spheres):
        return jnp.atleast_1d(shape.radii).shape[0]
    if isinstance(shape, Rectangles):
        return jnp.atleast_2d(shape.centers).shape[0]
    return 1
