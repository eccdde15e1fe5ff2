# ruff: noqa: F722  (jaxtyping shape strings)
"""Surface areas and uniform-by-area sampling of shapes (for area lights)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxgfx._math import (
    cross,
    safe_arccos,
    safe_div,
    safe_normalize,
    safe_sqrt,
    sincos,
    sum_last,
    take_rows,
)
from jaxgfx.render.geometry.mesh import TriangleMesh
from jaxgfx.render.geometry.rectangle import Rectangles
from jaxgfx.render.geometry.sphere import Spheres

__all__ = ["area", "sample_area", "primitive_areas", "has_uv_map", "point_at_uv"]


def primitive_areas(shape):
    """Area of each primitive of ``shape``: ``(N,)`` (world units squared)."""
    if isinstance(shape, Spheres):
        return 4 * math.pi * shape.radii**2
    if isinstance(shape, Rectangles):
        return jnp.linalg.norm(jnp.cross(shape.edge_u, shape.edge_v), axis=-1)
    if isinstance(shape, TriangleMesh):
        tri = shape.triangles
        cr = jnp.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        return 0.5 * jnp.sqrt(sum_last(cr * cr) + jnp.finfo(cr.dtype).tiny)
    raise TypeError(f"shape: expected Spheres, Rectangles or TriangleMesh, got {type(shape)}")


def area(shape) -> Float[Array, ""]:
    """Total surface area of all primitives of ``shape`` (world units squared)."""
    return jnp.sum(primitive_areas(shape))


def sample_area(shape, u, *, with_uv: bool = False) -> tuple:
    """Uniform-by-area point on ``shape`` from uniform numbers ``u (..., 2)`` in [0, 1)^2.

    Returns ``(p, n, pdf_area)``: position, unit geometric normal (same convention as the hit
    records) and the area density ``1 / area(shape)``. The primitive is chosen with
    probability proportional to its area from ``u[..., 0]``, which is then rescaled to [0, 1)
    and reused. Spheres: ``z = 1 - 2 u0``, ``phi = 2 pi u1``; triangles: ``b0 = 1 - sqrt(u0)``,
    ``b1 = u1 sqrt(u0)`` (Shirley & Chiu 1997 / pbrt-v4 §6.5); rectangles: ``s, t = u``.
    Positions are differentiable w.r.t. the shape parameters (reparametrisation).
    ``with_uv`` (static): also return the point's surface coordinates ``uv (..., 2)``, the
    ``uv`` a ray hitting that point gets (rectangles ``(s, t)``; spheres
    ``(phi / 2 pi, theta / pi)``; meshes the interpolated vertex ``uvs``, else the
    barycentrics ``(b1, b2)``), for textured emitters; without it nothing is computed for them.
    Example: a unit sphere gives ``pdf_area = 1 / (4 pi) = 0.0795775``.
    """
    u = jnp.asarray(u)
    if not jnp.issubdtype(u.dtype, jnp.floating):
        u = u.astype(jnp.float32)
    if u.shape[-1:] != (2,):
        raise ValueError(f"u: expected shape (..., 2), got {u.shape}")
    a = primitive_areas(shape)
    total = jnp.sum(a)
    cdf = jnp.cumsum(jax.lax.stop_gradient(a)) / jax.lax.stop_gradient(total)
    u0, u1 = u[..., 0], u[..., 1]
    if a.shape[0] > 1:
        idx = jnp.clip(jnp.searchsorted(cdf, u0, side="right"), 0, a.shape[0] - 1)
        lo = jnp.where(idx > 0, take_rows(cdf, jnp.maximum(idx - 1, 0)), 0.0)
        width = take_rows(cdf, idx) - lo
        u0 = jnp.clip(safe_div(u0 - lo, width), 0.0, 1.0 - jnp.finfo(u.dtype).epsneg)
    else:  # one primitive: no selection, u0 is used as is
        idx = jnp.zeros(u0.shape, jnp.int32)
    pdf = safe_div(jnp.ones_like(u0), total * jnp.ones_like(u0))
    if isinstance(shape, Spheres):
        z = 1.0 - 2.0 * u0
        r_xy = safe_sqrt(1.0 - z * z)
        phi = 2 * math.pi * u1
        sp, cp = sincos(phi)
        n = jnp.stack([r_xy * cp, r_xy * sp, z], axis=-1)
        p = take_rows(shape.centers, idx) + take_rows(shape.radii, idx)[..., None] * n
        if with_uv:  # sphere_hit: phi = atan2(n_y, n_x) in [0, 2 pi), theta = acos(n_z)
            uv = jnp.stack([u1, safe_arccos(z) / math.pi], axis=-1)
    elif isinstance(shape, Rectangles):
        eu, ev = take_rows(shape.edge_u, idx), take_rows(shape.edge_v, idx)
        p = take_rows(shape.centers, idx) + (u0 - 0.5)[..., None] * eu + (u1 - 0.5)[..., None] * ev
        n = safe_normalize(cross(eu, ev))
        if with_uv:  # rectangle_hit: p = c + (s - 1/2) e_u + (t - 1/2) e_v
            uv = jnp.stack([u0, u1], axis=-1)
    else:
        tri = shape.triangles[idx]
        su = safe_sqrt(u0)
        b0 = 1.0 - su
        b1 = u1 * su
        b2 = 1.0 - b0 - b1
        p = b0[..., None] * tri[..., 0, :] + b1[..., None] * tri[..., 1, :]
        p = p + b2[..., None] * tri[..., 2, :]
        n = safe_normalize(cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :]))
        if with_uv:  # mesh_hit: interpolated vertex uvs, else (b1, b2)
            if shape.uvs is not None:
                tuv = shape.uvs[shape.faces[idx]]
                uv = b0[..., None] * tuv[..., 0, :] + b1[..., None] * tuv[..., 1, :]
                uv = uv + b2[..., None] * tuv[..., 2, :]
            else:
                uv = jnp.stack([b1, b2], axis=-1)
    if with_uv:
        return p, n, pdf, uv.astype(p.dtype)
    return p, n, pdf


def has_uv_map(shape) -> bool:
    """Whether :func:`point_at_uv` maps ``uv`` onto ``shape``: one rectangle or one sphere
    (their ``uv`` is a closed-form parameterisation; static, known at trace time)."""
    return isinstance(shape, (Rectangles, Spheres)) and shape.centers.shape[0] == 1


def point_at_uv(shape, uv):
    """The point of a one-primitive rectangle / sphere with surface coordinates ``uv (..., 2)``
    (the ``uv`` its hits get) and ``|dp/du x dp/dv|``, the area per unit ``uv`` area.

    Returns ``(p, n, jacobian)``. Rectangles: ``p = c + (u - 1/2) e_u + (v - 1/2) e_v``,
    jacobian ``|e_u x e_v|`` (the area); spheres: ``phi = 2 pi u``, ``theta = pi v``,
    jacobian ``2 pi^2 r^2 sin(theta)`` (0 at the poles). Mitsuba 3's
    ``Shape::eval_parameterization`` for these shapes. Differentiable w.r.t. the shape.
    Example: a unit sphere at ``uv = (0, 1/2)`` gives ``p = (1, 0, 0)``, jacobian ``2 pi^2``.
    """
    if isinstance(shape, Rectangles):
        c, eu, ev = shape.centers[0], shape.edge_u[0], shape.edge_v[0]
        cr = cross(eu, ev)
        p = c + (uv[..., :1] - 0.5) * eu + (uv[..., 1:2] - 0.5) * ev
        n = jnp.broadcast_to(safe_normalize(cr), p.shape)
        jac = jnp.broadcast_to(safe_sqrt(sum_last(cr * cr)), p.shape[:-1])
        return p, n, jac
    if isinstance(shape, Spheres):
        st, ct = sincos(math.pi * uv[..., 1])
        sp, cp = sincos(2 * math.pi * uv[..., 0])
        n = jnp.stack([st * cp, st * sp, ct], axis=-1)
        r = shape.radii[0]
        jac = 2 * math.pi**2 * r * r * jnp.abs(st)
        return shape.centers[0] + r * n, n, jac
    raise TypeError(f"shape: expected a Rectangles or Spheres, got {type(shape).__name__}")
