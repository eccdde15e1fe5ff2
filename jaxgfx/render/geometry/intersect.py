"""Closest-hit and any-hit queries of rays against shapes and lists of shapes.

Two phases everywhere: a cheap non-differentiable search for the nearest ``(t, primitive)``
(:func:`closest_t`; brute force over the primitives, or an acceleration structure's traversal),
then ONE differentiable hit record for the primitive found (:func:`primitive_hit`), so ``t``,
``p`` and the normals are differentiable w.r.t. the shape parameters for the fixed primitive
that was hit.

Ray convention: ``o, d (..., 3)``, ``d`` of unit length, ``tmin < t < tmax``. See
:class:`jaxgfx.render.geometry.ray.Hit` for the normal and ``uv`` conventions.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import check_choice
from jaxgfx._math import fusion_barrier
from jaxgfx.render.geometry.mesh import TRIANGLE_INTERSECTORS, TriangleMesh, mesh_hit
from jaxgfx.render.geometry.ray import Hit, empty_hit, merge_hits, prepare_rays
from jaxgfx.render.geometry.rectangle import Rectangles, rectangle_hit, rectangle_intersect
from jaxgfx.render.geometry.sphere import Spheres, sphere_hit, sphere_intersect

__all__ = [
    "primitive_hit",
    "small_argmin",
    "closest_t",
    "intersect",
    "intersect_scene",
    "occluded_scene",
]


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
        return sphere_hit(shape, pid, o, d, valid, prim_id, sid)
    if isinstance(shape, Rectangles):
        return rectangle_hit(shape, pid, o, d, valid, prim_id, sid)
    if isinstance(shape, TriangleMesh):
        return mesh_hit(shape, pid, o, d, valid, prim_id, sid)
    raise TypeError(f"shape: expected Spheres, Rectangles or TriangleMesh, got {type(shape)}")


def small_argmin(ts):
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
        check_choice(method, "method", TRIANGLE_INTERSECTORS)
        ts = TRIANGLE_INTERSECTORS[method](sg(shape.triangles), o, d, tmin_b, tmax_b)
    else:
        raise TypeError(f"shape: expected Spheres, Rectangles or TriangleMesh, got {type(shape)}")
    return small_argmin(ts)


def intersect(
    shape, o, d, *, tmin=0.0, tmax=jnp.inf, method: str = "MollerTrumbore1997", shape_id=0
) -> Hit:
    """Closest hit of rays ``o, d (..., 3)`` with all primitives of ``shape`` (brute force).

    ``shape``: :class:`Spheres`, :class:`Rectangles` or :class:`TriangleMesh`; ``method``
    selects the triangle test (a key of :data:`TRIANGLE_INTERSECTORS`). Cost and memory are
    ``O(rays x primitives)``. Returns a :class:`jaxgfx.render.geometry.ray.Hit` of batch
    shape ``(...)``.
    """
    o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
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
    o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
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
        if out is not None and out.uv.shape[-1] != h.uv.shape[-1]:  # mesh attributes: pad
            out, h = _pad_uv(out, h)
        out = h if out is None else merge_hits(out, h)
    if out is None:
        return empty_hit(batch, o.dtype)
    # materialise the record, except uv: XLA then drops uv (arccos/atan2 for spheres) when no
    # texture reads it
    t, v, p, ng, ns, prim, shp = fusion_barrier(
        (out.t, out.valid, out.p, out.ng, out.ns, out.prim_id, out.shape_id)
    )
    return Hit(t=t, valid=v, p=p, ng=ng, ns=ns, uv=out.uv, prim_id=prim, shape_id=shp)


def _pad_uv(a, b):
    """Two hit records with ``uv`` zero-padded to the same number of columns (meshes with
    attributes carry them after the two texture coordinates)."""
    n = max(a.uv.shape[-1], b.uv.shape[-1])

    def pad(h):
        w = ((0, 0),) * (h.uv.ndim - 1) + ((0, n - h.uv.shape[-1]),)
        return eqx.tree_at(lambda h: h.uv, h, jnp.pad(h.uv, w))

    return pad(a), pad(b)


def occluded_scene(shapes, o, d, tmax, *, tmin=0.0):
    """True where any primitive of ``shapes`` lies on the ray in ``(tmin, tmax)`` (shadow rays:
    no hit record is built; acceleration structures use their any-hit traversal)."""
    o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
    out = jnp.zeros(o.shape[:-1], bool)
    for s in shapes:
        if hasattr(s, "occluded"):  # any-hit traversal of acceleration structures
            out = out | s.occluded(o, d, tmax, tmin=tmin)
        else:
            out = out | jnp.isfinite(closest_t(s, o, d, tmin, tmax)[0])
    return out
