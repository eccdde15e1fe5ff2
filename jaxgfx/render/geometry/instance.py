# ruff: noqa: F722  (jaxtyping shape strings)
"""Instancing: one shape (and its acceleration structure) placed ``K`` times by affine maps.

:class:`Instances` holds ONE shape in its own (local) space — :class:`Spheres`,
:class:`Rectangles`, a :class:`TriangleMesh` or a mesh traversal object (JAX BVH, Embree,
Warp) — and ``to_world (K, 4, 4)``. It is a custom shape of
:func:`~jaxgfx.render.geometry.intersect_scene` (``closest_t`` / ``occluded`` / ``hit``):

* search (two-level, non-differentiable): every ray is mapped into each instance's space,
  ``o' = A⁻¹(o − b)``, ``d' = A⁻¹ d``; the local direction is normalised (spheres need unit
  directions) and the ray interval scaled by ``s = |d'|``, so a local hit at ``t'`` is the
  world hit ``t = t'/s``. The ``K`` local queries run as ONE batch through the shared
  bottom-level structure (JAX BVH, Embree or Warp: one build, one native scene, shared by all
  instances); the top level is a linear loop (a batch axis) over the instances, whose rays
  the bottom level's root box rejects at once when they miss the instance.
* hit record (differentiable): the local record of the found primitive (closed form), mapped
  back: ``p = A p' + b``, normals by the inverse transpose ``normalize(A⁻ᵀ n')``, ``uv``
  unchanged, ``t = t'/s``. SDF shapes (:class:`SDFShape`, :class:`SDFGridShape`: one
  primitive each) build their own record in local space at the search's local ``t = s t_w``.
  Differentiable w.r.t. the shape's parameters (vertices, radii...)
  and ``to_world`` (for the fixed primitive hit).

``prim_id`` of a hit is ``k · n + j`` (instance ``k``, primitive ``j`` of the ``n`` of the
shape), so a per-primitive material table has ``K · n`` entries.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from jaxgfx._math import safe_normalize, sum_last, take_rows
from jaxgfx.render.geometry.accel.bvh_sah import BVH
from jaxgfx.render.geometry.accel.tlas import (
    TopLevel,
    build_tlas,
    inv3,
    tlas_collect,
    two_level_trace,
)
from jaxgfx.render.geometry.intersect import closest_t as _closest_t
from jaxgfx.render.geometry.intersect import primitive_hit
from jaxgfx.render.geometry.mesh import TriangleMesh
from jaxgfx.render.geometry.ray import Hit, hit_record, prepare_rays
from jaxgfx.render.geometry.rectangle import Rectangles
from jaxgfx.render.geometry.sdfgrid import SDFGridShape
from jaxgfx.render.geometry.sphere import Spheres
from jaxgfx.render.geometry.sphere_tracing import SDFShape

__all__ = ["Instances", "check_instance_transforms"]


def check_instance_transforms(to_world, where="to_world"):
    """``to_world`` as a float ``(K, 4, 4)`` NumPy array of invertible affine maps (one
    ``(4, 4)`` is promoted); ``ValueError`` naming ``where[k]`` for a bad or singular one.

    Singular: ``|det A| <= 1e-12 · ‖A‖³`` (Frobenius norm), i.e. zero to working precision."""
    m = np.asarray(to_world, np.float64)
    if m.ndim == 2:
        m = m[None]
    if m.ndim != 3 or m.shape[1:] != (4, 4) or m.shape[0] == 0:
        raise ValueError(f"{where}: expected one or more 4x4 matrices, got shape {m.shape}")
    for k in range(m.shape[0]):
        if not np.all(np.isfinite(m[k])):
            raise ValueError(f"{where}[{k}]: the matrix has non-finite entries")
        if not np.allclose(m[k, 3], [0.0, 0.0, 0.0, 1.0]):
            raise ValueError(f"{where}[{k}]: expected an affine matrix (last row 0 0 0 1)")
        lin = m[k, :3, :3]
        if not abs(np.linalg.det(lin)) > 1e-12 * np.linalg.norm(lin) ** 3:
            raise ValueError(f"{where}[{k}]: the transform is singular (det = 0)")
    return m


def _base(shape):
    """The primitive shape behind a traversal object (its ``mesh``)."""
    return shape.mesh if hasattr(shape, "mesh") else shape


def _is_sdf(shape) -> bool:
    """SDF shapes (sphere-traced trees, grids): one primitive, their own ``hit``."""
    return isinstance(shape, (SDFShape, SDFGridShape))


def _prim_count(shape) -> int:
    if _is_sdf(shape):
        return 1
    s = _base(shape)
    if isinstance(s, TriangleMesh):
        return int(s.faces.shape[0])
    if isinstance(s, Spheres):
        return int(jnp.atleast_1d(s.radii).shape[0])
    if isinstance(s, Rectangles):
        return int(jnp.atleast_2d(s.centers).shape[0])
    raise TypeError(
        "shape: expected Spheres, Rectangles, a TriangleMesh, a mesh traversal object or an "
        "SDF shape, "
        f"got {type(shape).__name__}"
    )


def _box_hit(lo, hi, o, d, t0, t1):
    """Whether rays ``o + t d`` meet the boxes ``[lo, hi]`` for some ``t`` in ``[t0, t1]``
    (slab test; zero direction components use ``±1e30`` reciprocals; exit widened by 1e-6)."""
    inv = 1.0 / jnp.where(d == 0, jnp.where(jnp.signbit(d), -1e-30, 1e-30), d)
    ta, tb = (lo - o) * inv, (hi - o) * inv
    tn = jnp.maximum(jnp.max(jnp.minimum(ta, tb), axis=-1), t0)
    tf = jnp.minimum(jnp.min(jnp.maximum(ta, tb), axis=-1) * (1 + 1e-6), t1)
    return tn <= tf


def _traced(tree):
    return any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(tree))


def _world_boxes(base, m):
    """World-space bounding boxes ``(K, 2, 3)`` of ``base`` under the matrices ``m (K, 4, 4)``
    (the 8 corners of its local box, mapped), widened by a relative 1e-6; ``None`` for a
    sphere-traced SDF (unbounded)."""
    if _is_sdf(base) and not isinstance(base, SDFGridShape):
        return None
    if isinstance(base, SDFGridShape):  # the unit cube
        lo, hi = np.zeros(3), np.ones(3)
    elif isinstance(base, TriangleMesh):
        v = np.asarray(base.vertices, np.float64)
        lo, hi = v.min(0), v.max(0)
    elif isinstance(base, Spheres):
        c, r = np.asarray(base.centers, np.float64), np.asarray(base.radii, np.float64)[:, None]
        lo, hi = (c - r).min(0), (c + r).max(0)
    else:
        c = np.asarray(base.centers, np.float64)
        eu, ev = np.abs(np.asarray(base.edge_u)) / 2, np.abs(np.asarray(base.edge_v)) / 2
        lo, hi = (c - eu - ev).min(0), (c + eu + ev).max(0)
    corners = np.array([[x[0], y[1], z[2], 1.0] for x in (lo, hi) for y in (lo, hi)
                        for z in (lo, hi)])  # fmt: skip
    w = np.einsum("kij,cj->kci", m, corners)[..., :3]
    blo, bhi = w.min(1), w.max(1)
    pad = 1e-6 * np.maximum(np.abs(blo), np.abs(bhi)).max(1, keepdims=True) + 1e-12
    return np.stack([blo - pad, bhi + pad], 1)


def _tlas_query(handle, m, top, cand, o, d, tmin, tmax, any_hit, n):
    """Host two-level query of one Embree scene: ``(t float32, prim int32)``.

    ``cand = (inst, entry t, count)``: each ray's nearest instance boxes from the top level
    (:func:`~jaxgfx.render.geometry.accel.tlas.tlas_collect`, run in JAX before the callback;
    rays that met more boxes than it keeps are completed here by
    :func:`~jaxgfx.render.geometry.accel.tlas.tlas_candidates` over ``top``). The
    ``(ray, instance)`` pairs are mapped into their instances' spaces in one vectorised step and
    queried in ONE call against the shared Embree scene (every local ray meets the same
    scene): first each ray's nearest box, then the others that still start before the best
    hit."""
    from jaxgfx.render.geometry.accel.backends import lookup_native
    from jaxgfx.render.geometry.accel.tlas import tlas_candidates

    host = lookup_native(handle)
    batch = np.shape(o)[:-1]
    o = np.asarray(o, np.float64).reshape(-1, 3)
    d = np.asarray(d, np.float64).reshape(-1, 3)
    t0 = np.broadcast_to(np.asarray(tmin, np.float64), batch).reshape(-1)
    best = np.broadcast_to(np.asarray(tmax, np.float64), batch).reshape(-1).copy()
    prim = np.full(o.shape[0], -1, np.int64)
    m = np.asarray(m, np.float64).reshape(-1, 4, 4)
    ck, ct, cnt = (np.asarray(x) for x in cand)
    C = ck.shape[-1]
    ck, ct, cnt = ck.reshape(-1, C), ct.reshape(-1, C).astype(np.float64), cnt.reshape(-1)
    inv = np.linalg.inv(m[:, :3, :3])

    def query(rr, kk):
        """Query the pairs (ray rr, instance kk) and keep each ray's nearest hit."""
        if rr.size == 0:
            return
        ol = np.einsum("pij,pj->pi", inv[kk], o[rr] - m[kk, :3, 3])
        dl = np.einsum("pij,pj->pi", inv[kk], d[rr])
        s = np.sqrt(np.einsum("pi,pi->p", dl, dl))
        dl /= s[:, None]
        # all pairs' local rays meet the same shared scene: one Embree call
        t, p = host.query(ol, dl, t0[rr] * s, best[rr] * s, any_hit)
        t = np.asarray(t, np.float64) / s
        h = np.flatnonzero(p >= 0)
        if any_hit:
            prim[rr[h]] = kk[h] * n + p[h]
            return
        h = h[np.lexsort((t[h], rr[h]))]  # several candidates of a ray: its nearest hit
        h = h[np.r_[True, rr[h][1:] != rr[h][:-1]]] if h.size else h
        best[rr[h]] = t[h]
        prim[rr[h]] = kk[h] * n + p[h]

    # round 1: each ray's nearest box
    r1 = np.flatnonzero(ck[:, 0] >= 0)
    query(r1, ck[r1, 0])
    # round 2: the other listed boxes entered before the best hit (the lists are sorted)
    live = (ck[:, 1:] >= 0) & (ct[:, 1:] <= best[:, None])
    if any_hit:
        live &= (prim < 0)[:, None]
    r2, j2 = np.nonzero(live)
    k2 = ck[:, 1:][r2, j2]
    over = np.flatnonzero(cnt > C)
    if over.size:  # rays that met more boxes than the list holds: all their boxes (the
        # listed ones again: a repeated query finds nothing closer, and ties in entry t,
        # e.g. an origin inside many boxes, leave no safe cut)
        ro, ko, _ = tlas_candidates(*top, o[over], d[over], t0[over], best[over])
        rest = (prim[over[ro]] < 0) if any_hit else np.ones(ro.size, bool)
        r2, k2 = np.r_[r2, over[ro[rest]]], np.r_[k2, ko[rest]]
    query(r2, k2)
    t = np.where(prim >= 0, best, np.inf).astype(np.float32)
    return t.reshape(batch), prim.astype(np.int32).reshape(batch)


def _split(m):
    return m[..., :3, :3], m[..., :3, 3]


def _apply(lin, x):
    return jnp.einsum("...ij,...j->...i", lin, x)


class Instances(eqx.Module):
    """``K`` instances of one shape: ``shape`` (local space) and ``to_world (K, 4, 4)``
    (float leaf, column-vector affine maps, each invertible). See the module docstring."""

    shape: object
    to_world: Float[Array, "K 4 4"]
    bounds: Float[Array, "K 2 3"] | None
    tlas: TopLevel | None
    n_prims: int = eqx.field(static=True)

    def __init__(self, shape, to_world, bounds=None, tlas=None):
        self.n_prims = _prim_count(shape)
        self.bounds = bounds
        self.tlas = tlas
        if isinstance(to_world, jax.core.Tracer):
            self.to_world = to_world
        else:
            m = check_instance_transforms(to_world)
            dt = jnp.result_type(*[x.dtype for x in jax.tree_util.tree_leaves(_base(shape))
                                   if jnp.issubdtype(x.dtype, jnp.floating)])  # fmt: skip
            self.to_world = jnp.asarray(m, dt)
            if bounds is None and not _traced(shape):
                bx = _world_boxes(_base(shape), m)
                self.bounds = None if bx is None else jnp.asarray(bx, dt)
                if tlas is None and bx is not None:  # the top level over the boxes (host, once)
                    self.tlas = build_tlas(bx)
        self.shape = shape

    @property
    def count(self) -> int:
        """Number of instances ``K``."""
        return self.to_world.shape[0]

    def _local_rays(self, o, d, tmin, tmax):
        """Rays of batch ``(...)`` in every instance's space: ``(K, ...)`` (no derivatives)."""
        sg = jax.lax.stop_gradient
        lin, b = _split(sg(self.to_world).astype(o.dtype))
        inv = inv3(lin)  # (K, 3, 3)
        ex = (slice(None),) + (None,) * (o.ndim - 1)
        ol = _apply(inv[ex], sg(o)[None] - b[ex])
        dl = _apply(inv[ex], sg(d)[None])
        s = jnp.sqrt(sum_last(dl * dl))
        dl = dl / s[..., None]
        batch = o.shape[:-1]
        tmin_w = jnp.broadcast_to(tmin, batch)[None]
        tmax_w = jnp.broadcast_to(tmax, batch)[None]
        if self.bounds is not None:  # top level: rays that miss an instance's box get (0, 0)
            bx = sg(self.bounds).astype(o.dtype)[ex]  # (K, 1.., 2, 3)
            inside = _box_hit(bx[..., 0, :], bx[..., 1, :], sg(o)[None], sg(d)[None],
                              tmin_w, tmax_w)  # fmt: skip
            tmin_w = jnp.where(inside, tmin_w, 0.0)
            tmax_w = jnp.where(inside, tmax_w, 0.0)
        return ol, dl, s, tmin_w * s, tmax_w * s

    def _host_tlas(self, o, d, tmin, tmax, any_hit):
        """Embree: both levels run on the host in ONE callback (world rays in; the top-level
        BVH picks the instances whose boxes each ray meets, see :func:`_tlas_query`), instead
        of ``K`` times the rays through the callback."""
        sg = jax.lax.stop_gradient
        batch = o.shape[:-1]
        out = (jax.ShapeDtypeStruct(batch, jnp.float32), jax.ShapeDtypeStruct(batch, jnp.int32))
        n = self.n_prims

        def cb(h, m, tb, to, tl, ck, ct, cnt, o, d, t0, t1):
            return _tlas_query(h, m, (tb, to, tl), (ck, ct, cnt), o, d, t0, t1, any_hit, n)

        top = self.tlas
        t0 = jnp.broadcast_to(sg(tmin), batch)
        t1 = jnp.broadcast_to(sg(tmax), batch)
        flat = (sg(o).reshape(-1, 3), sg(d).reshape(-1, 3), t0.reshape(-1), t1.reshape(-1))
        cand = tuple(x.reshape(*batch, *x.shape[1:]) for x in tlas_collect(top, *flat))
        t, p = jax.pure_callback(
            cb, out, self.shape.handle, sg(self.to_world), top.bounds, top.offset, top.leaf,
            *cand, sg(o), sg(d),
            t0, t1, vmap_method="expand_dims",
        )  # fmt: skip
        return t.astype(o.dtype), p

    def _host(self):
        from jaxgfx.render.geometry.accel.embree import EmbreeMesh

        return isinstance(self.shape, EmbreeMesh) and self.tlas is not None

    def _two_level(self, o, d, tmin, tmax, any_hit):
        """JAX BVH bottom level under the top-level BVH: one wavefront through both levels
        (:func:`~jaxgfx.render.geometry.accel.tlas.two_level_trace`); ``(t, prim)``."""
        sg = jax.lax.stop_gradient
        batch = o.shape[:-1]
        flat = (sg(o).reshape(-1, 3), sg(d).reshape(-1, 3),
                jnp.broadcast_to(sg(tmin), batch).reshape(-1),
                jnp.broadcast_to(sg(tmax), batch).reshape(-1))  # fmt: skip
        t, p = two_level_trace(self.tlas, self.shape, self.to_world, *flat, any_hit=any_hit)
        return t.reshape(batch), p.reshape(batch)

    def _jax_tlas(self):
        return isinstance(self.shape, BVH) and self.tlas is not None

    def closest_t(self, o, d, *, tmin=0.0, tmax=jnp.inf):
        """Nearest world ``(t, prim_id)`` over all instances (``prim_id = k·n + j``)."""
        o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
        if self._host():
            t, p = self._host_tlas(o, d, tmin, tmax, False)
            return jnp.where(p >= 0, t, jnp.inf), jnp.maximum(p, 0)
        if self._jax_tlas():
            t, p = self._two_level(o, d, tmin, tmax, False)
            return jnp.where(p >= 0, t, jnp.inf), jnp.maximum(p, 0)
        ol, dl, s, tmin_l, tmax_l = self._local_rays(o, d, tmin, tmax)
        t, p = _closest_t(self.shape, ol, dl, tmin_l, tmax_l)
        t = jnp.where(jnp.isfinite(t), t / s, jnp.inf)
        best = jnp.min(t, axis=0)
        k = jnp.argmin(t, axis=0).astype(jnp.int32)
        pk = jnp.take_along_axis(p, k[None], axis=0)[0]
        return best, k * self.n_prims + pk

    def occluded(self, o, d, tmax, *, tmin=0.0):
        """True where any instance has a primitive in ``(tmin, tmax)``."""
        o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
        if self._host():
            return self._host_tlas(o, d, tmin, tmax, True)[1] >= 0
        if self._jax_tlas():
            return self._two_level(o, d, tmin, tmax, True)[1] >= 0
        ol, dl, _, tmin_l, tmax_l = self._local_rays(o, d, tmin, tmax)
        if hasattr(self.shape, "occluded"):
            hit = self.shape.occluded(ol, dl, tmax_l, tmin=tmin_l)
        else:
            hit = jnp.isfinite(_closest_t(self.shape, ol, dl, tmin_l, tmax_l)[0])
        return jnp.any(hit, axis=0)

    def hit(self, prim_id, o, d, valid, t=None) -> Hit:
        """Differentiable world-space hit record of primitive ``prim_id = k·n + j``."""
        o = jnp.asarray(o)
        d = jnp.asarray(d, o.dtype)
        pid = jnp.maximum(prim_id, 0)
        k = jnp.clip(pid // self.n_prims, 0, self.count - 1)
        j = pid % self.n_prims
        m = take_rows(self.to_world.astype(o.dtype), k)  # (..., 4, 4)
        lin, b = _split(m)
        inv = inv3(lin)
        ol = _apply(inv, o - b)
        dl = _apply(inv, d)
        s = jnp.sqrt(sum_last(dl * dl))
        if _is_sdf(self.shape):  # SDFs: their own record at the search's (local) t
            if t is None:
                t = self.closest_t(o, d)[0]
            tl = jax.lax.stop_gradient(jnp.where(valid, t * s, 0.0))
            h = self.shape.hit(j, ol, dl / s[..., None], valid & jnp.isfinite(t), t=tl)
        else:
            h = primitive_hit(_base(self.shape), j, ol, dl / s[..., None], valid)
        inv_t = jnp.swapaxes(inv, -1, -2)
        p = _apply(lin, h.p) + b
        ng = safe_normalize(_apply(inv_t, h.ng))
        ns = safe_normalize(_apply(inv_t, h.ns))
        t = jnp.where(h.valid, h.t, 0.0) / s  # no inf / s: its derivative would be NaN
        return hit_record(h.valid, t, p, ng, ns, h.uv, prim_id, 0)

    def intersect(self, o, d, *, tmin=0.0, tmax=jnp.inf, shape_id=0) -> Hit:
        """Closest hit over all instances (search, then :meth:`hit`)."""
        o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
        t, pid = self.closest_t(o, d, tmin=tmin, tmax=tmax)
        h = self.hit(pid, o, d, jnp.isfinite(t), t=t)
        return eqx.tree_at(lambda h: h.shape_id, h, jnp.where(h.valid, shape_id, -1))

    def flatten(self):
        """The instances as one world-space shape of the same type (for comparisons and for
        shapes that need it): vertices / centres mapped, normals by the inverse transpose."""
        base = _base(self.shape)
        if _is_sdf(base):
            raise ValueError("flatten: SDF instances have no world-space form")
        lin, b = _split(self.to_world)
        if isinstance(base, TriangleMesh):
            v = _apply(lin[:, None], base.vertices[None]) + b[:, None]
            nv = base.vertices.shape[0]
            f = (base.faces[None] + nv * jnp.arange(self.count)[:, None, None]).reshape(-1, 3)
            n = None
            if base.normals is not None:
                it = jnp.swapaxes(inv3(lin), -1, -2)
                n = safe_normalize(_apply(it[:, None], base.normals[None])).reshape(-1, 3)
            uv = None if base.uvs is None else jnp.tile(base.uvs, (self.count, 1))
            return TriangleMesh(v.reshape(-1, 3), f, n, uv)
        if isinstance(base, Rectangles):
            c = (_apply(lin[:, None], base.centers[None]) + b[:, None]).reshape(-1, 3)
            eu = _apply(lin[:, None], base.edge_u[None]).reshape(-1, 3)
            ev = _apply(lin[:, None], base.edge_v[None]).reshape(-1, 3)
            return Rectangles(c, eu, ev)
        # spheres: only similarity transforms keep them spheres
        sv = jnp.linalg.svd(lin, compute_uv=False)
        if not bool(jnp.all(sv[:, 0] - sv[:, 2] <= 1e-6 * sv[:, 0])):
            raise ValueError("flatten: a non-uniformly scaled sphere is an ellipsoid")
        c = (_apply(lin[:, None], base.centers[None]) + b[:, None]).reshape(-1, 3)
        r = (sv[:, 0:1] * base.radii[None]).reshape(-1)
        # the uv frame: the instance's rotation after the sphere's own (as the instanced hit)
        n = base.radii.shape[0]
        bf = base.frames if base.frames is not None else jnp.broadcast_to(jnp.eye(3), (n, 3, 3))
        rot = lin / sv[:, 0, None, None]
        return Spheres(c, r, (rot[:, None] @ bf[None].astype(rot.dtype)).reshape(-1, 3, 3))
