# ruff: noqa: F722  (jaxtyping shape strings)
"""Analytic shapes: spheres, rectangles (parallelograms) and triangle meshes.

Every intersector is pure JAX, broadcasts over a batch of rays ``(...)`` and is jittable and
vmappable. Closest hits are found by brute force over all primitives of the shape (use
``jaxgfx.render.accel`` for large meshes); the returned ``t``, ``p`` and normals are
differentiable w.r.t. the shape parameters (sphere centres/radii, rectangle corners, vertex
positions) for the fixed primitive that was hit.

Ray convention: ``o, d (..., 3)``, ``d`` of unit length, ``tmin < t < tmax``. See
:class:`jaxgfx.render.ray.Hit` for the normal and ``uv`` conventions.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from jaxgfx._checks import check_finite, check_nonnegative
from jaxgfx._math import (
    fusion_barrier,
    safe_arccos,
    safe_atan2,
    safe_div,
    safe_normalize,
    safe_sqrt,
    sincos,
    sum_last,
    take_rows,
    vdot,
)
from jaxgfx.render.ray import Hit, empty_hit, merge_hits

__all__ = [
    "Spheres",
    "Rectangles",
    "TriangleMesh",
    "TRIANGLE_INTERSECTORS",
    "sphere_intersect",
    "rectangle_intersect",
    "triangle_intersect_moller_trumbore",
    "triangle_intersect_affine",
    "triangle_affine_matrices",
    "intersect",
    "intersect_scene",
    "occluded_scene",
    "closest_t",
    "take_rows",
    "primitive_hit",
    "area",
    "sample_area",
]


def _as_points(x, name, last):
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.float32)
    if x.ndim != 2 or x.shape[-1] != last:
        raise ValueError(f"{name}: expected shape (N, {last}), got {x.shape}")
    check_finite(x, name)
    return x


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
        c = _as_points(c, "centers", 3)
        r = jnp.asarray(radii, c.dtype).reshape(-1)
        if r.shape[0] != c.shape[0]:
            raise ValueError(f"radii: expected shape ({c.shape[0]},), got {r.shape}")
        check_nonnegative(r, "radii")
        self.centers, self.radii = c, r


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
            arrs.append(_as_points(a[None] if a.ndim == 1 else a, name, 3))
        if not arrs[0].shape == arrs[1].shape == arrs[2].shape:
            raise ValueError(
                "edge_u, edge_v: expected the shape of centers "
                f"{arrs[0].shape}, got {arrs[1].shape}, {arrs[2].shape}"
            )
        dt = jnp.result_type(*arrs)
        self.centers, self.edge_u, self.edge_v = (a.astype(dt) for a in arrs)


class TriangleMesh(eqx.Module):
    """Indexed triangle mesh.

    Fields: ``vertices (V, 3)`` float, ``faces (F, 3)`` int32 (counter-clockwise as seen from
    the side the geometric normal points to), optional ``normals (V, 3)`` (per-vertex shading
    normals) and ``uvs (V, 2)``. Zero-area faces are allowed: they are never hit.
    Differentiate w.r.t. ``vertices`` with ``eqx.filter_grad`` or by rebuilding the mesh inside
    the differentiated function (``faces`` is an integer leaf).
    """

    vertices: Float[Array, "V 3"]
    faces: Int[Array, "F 3"]
    normals: Float[Array, "V 3"] | None = None
    uvs: Float[Array, "V 2"] | None = None

    def __init__(self, vertices, faces, normals=None, uvs=None):
        v = _as_points(vertices, "vertices", 3)
        f = jnp.asarray(faces)
        if not jnp.issubdtype(f.dtype, jnp.integer) or f.ndim != 2 or f.shape[-1] != 3:
            raise ValueError(
                f"faces: expected an integer array of shape (F, 3), got {f.dtype}{f.shape}"
            )
        if f.shape[0] == 0:
            raise ValueError("faces: expected at least one triangle, got 0")
        if not isinstance(f, jax.core.Tracer):
            fn = np.asarray(f)
            if fn.min() < 0 or fn.max() >= v.shape[0]:
                raise ValueError(
                    f"faces: indices must lie in [0, {v.shape[0] - 1}], "
                    f"got range [{fn.min()}, {fn.max()}]"
                )
        self.vertices = v
        self.faces = f.astype(jnp.int32)
        if normals is not None:
            normals = _as_points(normals, "normals", 3).astype(v.dtype)
            if normals.shape[0] != v.shape[0]:
                raise ValueError(f"normals: expected shape {v.shape}, got {normals.shape}")
        if uvs is not None:
            uvs = _as_points(uvs, "uvs", 2).astype(v.dtype)
            if uvs.shape[0] != v.shape[0]:
                raise ValueError(f"uvs: expected shape ({v.shape[0]}, 2), got {uvs.shape}")
        self.normals, self.uvs = normals, uvs

    @property
    def triangles(self) -> Float[Array, "F 3 3"]:
        """Corner positions ``(F, 3, 3)`` (face, corner, xyz)."""
        return self.vertices[self.faces]


# ---------------------------------------------------------------------------------------------
# Closed-form primitive intersections (broadcasting; return t = inf where there is no hit)


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


def rectangle_intersect(center, edge_u, edge_v, o, d, tmin=0.0, tmax=jnp.inf):
    """``(t, s, u)`` of a ray against parallelograms (see :class:`Rectangles`).

    ``t = inf`` where the ray misses, is parallel to the plane (no NaN), or the hit is outside
    ``(tmin, tmax)``. Edges are closed: ``s, u`` in [0, 1] count as hits.
    """
    n = jnp.cross(edge_u, edge_v)
    denom = vdot(d, n)
    t = safe_div(vdot(center - o, n), denom, fill=jnp.inf)
    rel = o + jnp.where(jnp.isfinite(t), t, 0.0)[..., None] * d - center
    # Dual basis of (edge_u, edge_v) within the plane: s = rel.(edge_v x n)/|n|^2 + 1/2.
    nn = vdot(n, n)
    s = safe_div(vdot(rel, jnp.cross(edge_v, n)), nn) + 0.5
    u = safe_div(vdot(rel, jnp.cross(n, edge_u)), nn) + 0.5
    ok = (denom != 0) & (t > tmin) & (t < tmax) & (s >= 0) & (s <= 1) & (u >= 0) & (u <= 1)
    return jnp.where(ok, t, jnp.inf), s, u


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


def _mt_all(tri, o, d, tmin, tmax):
    return triangle_intersect_moller_trumbore(
        tri[:, 0], tri[:, 1], tri[:, 2], o[..., None, :], d[..., None, :], tmin, tmax
    )[0]


def _affine_all(tri, o, d, tmin, tmax):
    m = triangle_affine_matrices(tri[:, 0], tri[:, 1], tri[:, 2])
    return triangle_intersect_affine(m, o[..., None, :], d[..., None, :], tmin, tmax)[0]


TRIANGLE_INTERSECTORS = {
    "MollerTrumbore1997": _mt_all,
    "affine": _affine_all,
}
"""Brute-force triangle intersectors selectable by ``method=`` in :func:`intersect`."""


# ---------------------------------------------------------------------------------------------
# Differentiable hit records for a known primitive


def _finish(valid, t, p, ng, ns, uv, prim_id, shape_id):
    v3 = valid[..., None]
    return Hit(
        t=jnp.where(valid, t, jnp.inf),
        valid=valid,
        p=jnp.where(v3, p, 0.0),
        ng=jnp.where(v3, ng, 0.0),
        ns=jnp.where(v3, ns, 0.0),
        uv=jnp.where(v3, uv, 0.0),
        prim_id=jnp.where(valid, prim_id, -1).astype(jnp.int32),
        shape_id=jnp.where(valid, shape_id, -1).astype(jnp.int32),
    )


def primitive_hit(shape, prim_id, o, d, valid, *, shape_id=0) -> Hit:
    """Hit record of rays ``o, d`` against the known primitive ``prim_id (...)`` of ``shape``.

    Recomputes ``t`` in closed form for that primitive only (no ``tmin``/``tmax`` test), so the
    result is differentiable w.r.t. the shape parameters; acceleration structures find
    ``prim_id`` with non-differentiable traversal and call this. ``valid (...)`` masks rays
    without a hit.
    """
    o = jnp.asarray(o)
    d = jnp.asarray(d, o.dtype)
    pid = jnp.maximum(prim_id, 0)
    sid = jnp.asarray(shape_id, jnp.int32)
    if isinstance(shape, Spheres):
        c = take_rows(shape.centers, pid)
        r = take_rows(shape.radii, pid)
        t = sphere_intersect(c, r, o, d, -jnp.inf, jnp.inf)
        # choose the root that the traversal found: the nearest positive one
        f = o - c
        b = vdot(f, d)
        g = f - b[..., None] * d
        h = safe_sqrt(r * r - vdot(g, g))
        t_lo, t_hi = -b - h, -b + h
        t = jnp.where(t_lo > 0, t_lo, t_hi)
        valid = valid & jnp.isfinite(t)
        tt = jnp.where(valid, t, 0.0)
        p = o + tt[..., None] * d
        ng = safe_div(p - c, jnp.where(r > 0, r, 1.0)[..., None])
        theta = safe_arccos(ng[..., 2])
        phi = safe_atan2(ng[..., 1], ng[..., 0])
        phi = jnp.where(phi < 0, phi + 2 * math.pi, phi)
        uv = jnp.stack([phi / (2 * math.pi), theta / math.pi], axis=-1)
        return _finish(valid, tt, p, ng, ng, uv, prim_id, sid)
    if isinstance(shape, Rectangles):
        c, eu, ev = (take_rows(a, pid) for a in (shape.centers, shape.edge_u, shape.edge_v))
        t, s, u = rectangle_intersect(c, eu, ev, o, d, -jnp.inf, jnp.inf)
        valid = valid & jnp.isfinite(t)
        tt = jnp.where(valid, t, 0.0)
        p = c + (s - 0.5)[..., None] * eu + (u - 0.5)[..., None] * ev
        ng = safe_normalize(jnp.cross(eu, ev)) * jnp.ones_like(p)
        uv = jnp.stack([s, u], axis=-1)
        return _finish(valid, tt, p, ng, ng, uv, prim_id, sid)
    if isinstance(shape, TriangleMesh):
        f = shape.faces[pid]
        v0, v1, v2 = (shape.vertices[f[..., k]] for k in range(3))
        e1, e2 = v1 - v0, v2 - v0
        P = jnp.cross(d, e2)
        det = vdot(P, e1)
        T = o - v0
        Q = jnp.cross(T, e1)
        valid = valid & (det != 0)
        t = safe_div(vdot(Q, e2), det)
        b1 = safe_div(vdot(P, T), det)
        b2 = safe_div(vdot(Q, d), det)
        b0 = 1.0 - b1 - b2
        p = b0[..., None] * v0 + b1[..., None] * v1 + b2[..., None] * v2
        ng = safe_normalize(jnp.cross(e1, e2))
        if shape.normals is not None:
            nv = shape.normals
            ns = safe_normalize(
                b0[..., None] * nv[f[..., 0]]
                + b1[..., None] * nv[f[..., 1]]
                + b2[..., None] * nv[f[..., 2]]
            )
            ns = jnp.where(sum_last(ns * ns, keepdims=True) > 0, ns, ng)
        else:
            ns = ng
        if shape.uvs is not None:
            tv = shape.uvs
            uv = (
                b0[..., None] * tv[f[..., 0]]
                + b1[..., None] * tv[f[..., 1]]
                + b2[..., None] * tv[f[..., 2]]
            )
        else:
            uv = jnp.stack([b1, b2], axis=-1)
        return _finish(valid, t, p, ng, ns, uv, prim_id, sid)
    raise TypeError(f"shape: expected Spheres, Rectangles or TriangleMesh, got {type(shape)}")


def _rays(o, d, tmin, tmax):
    o = jnp.asarray(o)
    if not jnp.issubdtype(o.dtype, jnp.floating):
        o = o.astype(jnp.float32)
    d = jnp.asarray(d, o.dtype)
    if o.shape[-1:] != (3,) or d.shape[-1:] != (3,):
        raise ValueError(f"o, d: expected shape (..., 3), got {o.shape} and {d.shape}")
    o, d = jnp.broadcast_arrays(o, d)
    return o, d, jnp.asarray(tmin, o.dtype), jnp.asarray(tmax, o.dtype)


def _small_argmin(ts):
    """``(min, argmin)`` over the last axis; unrolled for short axes (XLA CPU's variadic
    argmin reduction breaks loop fusion and costs more than the intersection tests)."""
    n = ts.shape[-1]
    if n > 8:
        return jnp.min(ts, axis=-1), jnp.argmin(ts, axis=-1).astype(jnp.int32)
    best, idx = ts[..., 0], jnp.zeros(ts.shape[:-1], jnp.int32)
    for i in range(1, n):
        closer = ts[..., i] < best
        best = jnp.where(closer, ts[..., i], best)
        idx = jnp.where(closer, i, idx)
    return best, idx


def closest_t(shape, o, d, tmin, tmax, *, method: str = "MollerTrumbore1997"):
    """Nearest ray parameter and primitive index ``(t, prim_id)`` of rays against ``shape``.

    The non-differentiable first phase of :func:`intersect` (``t = inf``, ``prim_id`` arbitrary
    where nothing is hit); :func:`primitive_hit` then builds the differentiable record.
    ``shape`` may also be an acceleration structure (anything with a ``closest_t`` method).
    """
    if hasattr(shape, "closest_t"):
        return shape.closest_t(o, d, tmin=tmin, tmax=tmax)
    sg = jax.lax.stop_gradient
    o, d = sg(o), sg(d)
    ob, db = o[..., None, :], d[..., None, :]
    tmin_b, tmax_b = tmin[..., None], tmax[..., None]
    if isinstance(shape, Spheres):
        ts = sphere_intersect(sg(shape.centers), sg(shape.radii), ob, db, tmin_b, tmax_b)
    elif isinstance(shape, Rectangles):
        ts = rectangle_intersect(
            sg(shape.centers), sg(shape.edge_u), sg(shape.edge_v), ob, db, tmin_b, tmax_b
        )[0]
    elif isinstance(shape, TriangleMesh):
        if method not in TRIANGLE_INTERSECTORS:
            raise ValueError(
                f"method: expected one of {tuple(TRIANGLE_INTERSECTORS)}, got {method!r}"
            )
        ts = TRIANGLE_INTERSECTORS[method](sg(shape.triangles), o, d, tmin_b, tmax_b)
    else:
        raise TypeError(f"shape: expected Spheres, Rectangles or TriangleMesh, got {type(shape)}")
    return _small_argmin(ts)


def intersect(
    shape, o, d, *, tmin=0.0, tmax=jnp.inf, method: str = "MollerTrumbore1997", shape_id=0
) -> Hit:
    """Closest hit of rays ``o, d (..., 3)`` with all primitives of ``shape`` (brute force).

    ``shape``: :class:`Spheres`, :class:`Rectangles` or :class:`TriangleMesh`; ``method``
    selects the triangle test (a key of :data:`TRIANGLE_INTERSECTORS`). Cost and memory are
    ``O(rays x primitives)``. Returns a :class:`jaxgfx.render.ray.Hit` of batch shape ``(...)``.
    """
    o, d, tmin, tmax = _rays(o, d, tmin, tmax)
    t, pid = closest_t(shape, o, d, tmin, tmax, method=method)
    return primitive_hit(shape, pid, o, d, jnp.isfinite(t), shape_id=shape_id)


def _concat_shapes(shapes):
    """One shape holding the primitives of several shapes of the same type, and the prefix
    offsets of each part's primitive indices."""
    counts = [s.centers.shape[0] for s in shapes]
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int32)
    if len(shapes) == 1:
        return shapes[0], offsets
    cat = lambda *xs: jnp.concatenate(xs, axis=0)  # noqa: E731
    return jax.tree_util.tree_map(cat, *shapes), offsets


def intersect_scene(shapes, o, d, *, tmin=0.0, tmax=jnp.inf) -> Hit:
    """Closest hit over a list of shapes; ``shape_id`` is the index in ``shapes``.

    Each element is a shape accepted by :func:`intersect`, an acceleration structure (with
    ``closest_t`` and a ``mesh``), or any object with the methods
    ``closest_t(o, d, *, tmin, tmax) -> (t, prim_id)`` (non-differentiable search, ``t = inf``
    on misses) and ``hit(prim_id, o, d, valid, t) -> Hit`` (differentiable record at the
    search's ``t``).

    Two phases: the nearest ``(t, shape, primitive)`` is found with the cheap tests of every
    shape, then ONE differentiable hit record is built per shape
    type (all spheres of the scene together, all rectangles together, each mesh), so a scene of
    many analytic shapes costs one record, not one per shape.
    """
    o, d, tmin, tmax = _rays(o, d, tmin, tmax)
    batch = o.shape[:-1]
    best = jnp.full(batch, jnp.inf, o.dtype)
    sid = jnp.full(batch, -1, jnp.int32)
    pid = jnp.zeros(batch, jnp.int32)
    for i, s in enumerate(shapes):
        t, p = closest_t(s, o, d, tmin, tmax)
        closer = t < best
        best = jnp.where(closer, t, best)
        sid = jnp.where(closer, i, sid)
        pid = jnp.where(closer, p, pid)
    # Materialise the first phase: otherwise XLA fuses (and recomputes) the intersection tests
    # into each consumer of sid / pid below (measured 5x slower on CPU).
    best, sid, pid = fusion_barrier((best, sid, pid))
    valid = jnp.isfinite(best)
    groups = {}
    for i, s in enumerate(shapes):
        kind = type(s) if isinstance(s, (Spheres, Rectangles)) else ("single", i)
        groups.setdefault(kind, []).append(i)
    out = None
    for kind, members in groups.items():
        if isinstance(kind, tuple):
            shape, gpid = shapes[members[0]], pid
            sel = sid == members[0] if len(groups) > 1 else valid
        else:
            shape, offsets = _concat_shapes([shapes[i] for i in members])
            off = jnp.zeros(batch, jnp.int32)
            sel = jnp.zeros(batch, bool) if len(groups) > 1 else valid
            for i, ofs in zip(members, offsets, strict=True):
                if ofs:
                    off = jnp.where(sid == i, int(ofs), off)
                if len(groups) > 1:
                    sel = sel | (sid == i)
            gpid = pid + off
        if hasattr(shape, "hit"):  # custom shapes (e.g. SDFs): their own record
            h = shape.hit(gpid, o, d, valid & sel, t=best)
        else:
            shape = shape.mesh if hasattr(shape, "mesh") else shape
            h = primitive_hit(shape, gpid, o, d, valid & sel, shape_id=0)
        h = eqx.tree_at(
            lambda h: (h.shape_id, h.prim_id),
            h,
            (jnp.where(h.valid, sid, -1), jnp.where(h.valid, pid, -1)),
        )
        out = h if out is None else merge_hits(out, h)
    if out is None:
        return empty_hit(batch, o.dtype)
    # materialise the record, except uv: XLA then drops uv (arccos/atan2 for spheres) when no
    # texture reads it
    t, v, p, ng, ns, prim, shp = fusion_barrier(
        (out.t, out.valid, out.p, out.ng, out.ns, out.prim_id, out.shape_id)
    )
    return Hit(t=t, valid=v, p=p, ng=ng, ns=ns, uv=out.uv, prim_id=prim, shape_id=shp)


def occluded_scene(shapes, o, d, tmax, *, tmin=0.0):
    """True where any primitive of ``shapes`` lies on the ray in ``(tmin, tmax)`` (shadow rays:
    no hit record is built; acceleration structures use their any-hit traversal)."""
    o, d, tmin, tmax = _rays(o, d, tmin, tmax)
    out = jnp.zeros(o.shape[:-1], bool)
    for s in shapes:
        if hasattr(s, "occluded"):  # any-hit traversal of acceleration structures
            out = out | s.occluded(o, d, tmax, tmin=tmin)
        else:
            out = out | jnp.isfinite(closest_t(s, o, d, tmin, tmax)[0])
    return out


# ---------------------------------------------------------------------------------------------
# Areas and uniform area sampling (for area lights)


def _prim_areas(shape):
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
    return jnp.sum(_prim_areas(shape))


def sample_area(shape, u) -> tuple[Float[Array, "*b 3"], Float[Array, "*b 3"], Float[Array, "*b"]]:
    """Uniform-by-area point on ``shape`` from uniform numbers ``u (..., 2)`` in [0, 1)^2.

    Returns ``(p, n, pdf_area)``: position, unit geometric normal (same convention as the hit
    records) and the area density ``1 / area(shape)``. The primitive is chosen with
    probability proportional to its area from ``u[..., 0]``, which is then rescaled to [0, 1)
    and reused. Spheres: ``z = 1 - 2 u0``, ``phi = 2 pi u1``; triangles: ``b0 = 1 - sqrt(u0)``,
    ``b1 = u1 sqrt(u0)`` (Shirley & Chiu 1997 / pbrt-v4 §6.5); rectangles: ``s, t = u``.
    Positions are differentiable w.r.t. the shape parameters (reparametrisation).
    Example: a unit sphere gives ``pdf_area = 1 / (4 pi) = 0.0795775``.
    """
    u = jnp.asarray(u)
    if not jnp.issubdtype(u.dtype, jnp.floating):
        u = u.astype(jnp.float32)
    if u.shape[-1:] != (2,):
        raise ValueError(f"u: expected shape (..., 2), got {u.shape}")
    a = _prim_areas(shape)
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
    elif isinstance(shape, Rectangles):
        eu, ev = take_rows(shape.edge_u, idx), take_rows(shape.edge_v, idx)
        p = take_rows(shape.centers, idx) + (u0 - 0.5)[..., None] * eu + (u1 - 0.5)[..., None] * ev
        n = safe_normalize(jnp.cross(eu, ev))
    else:
        tri = shape.triangles[idx]
        su = safe_sqrt(u0)
        b0 = 1.0 - su
        b1 = u1 * su
        b2 = 1.0 - b0 - b1
        p = b0[..., None] * tri[..., 0, :] + b1[..., None] * tri[..., 1, :]
        p = p + b2[..., None] * tri[..., 2, :]
        n = safe_normalize(
            jnp.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])
        )
    return p, n, pdf
