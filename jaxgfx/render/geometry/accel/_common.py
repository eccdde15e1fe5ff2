"""Shared pieces of the acceleration structures: ray preparation, slab and chunked triangle
tests, and the differentiable re-intersection of the found primitive."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._math import max_last
from jaxgfx.render.geometry.intersect import primitive_hit, small_argmin
from jaxgfx.render.geometry.mesh import TriangleMesh
from jaxgfx.render.geometry.ray import Hit, prepare_rays

# Conservative slab test: scale the exit distance by 1 + 2 gamma_3 (pbrt-v4 §6.8.2) so that
# rounding never culls a box the ray actually crosses.
_GROW = {jnp.dtype(jnp.float32): 1.0 + 2 * 3 * 2.0**-24, jnp.dtype(jnp.float64): 1.0 + 1e-15}
# Direction components that are exactly zero use this reciprocal (finite, so 0 * inv is 0).
_BIG = 1e30
STACK_SIZE = 64


def safe_inv(d):
    """Componentwise ``1 / d`` with ``±1e30`` for zero components (keeps slab tests NaN-free)."""
    return 1.0 / jnp.where(d == 0, jnp.where(jnp.signbit(d), -1.0 / _BIG, 1.0 / _BIG), d)


def slab(bmin, bmax, o, inv, t0, t1):
    """Entry/exit ``(tn, tf, hit)`` of the ray against boxes ``bmin, bmax (..., 3)``."""
    ta = (bmin - o) * inv
    tb = (bmax - o) * inv
    tn = jnp.maximum(max_last(jnp.minimum(ta, tb)), t0)
    far = jnp.maximum(ta, tb)
    far = jnp.minimum(jnp.minimum(far[..., 0], far[..., 1]), far[..., 2])  # unrolled min
    tf = jnp.minimum(far * _GROW[jnp.dtype(o.dtype)], t1)
    return tn, tf, tn <= tf


def tri_chunk(tris, idx, mask, o, d, tmin, tmax, *, reduce=True):
    """Möller-Trumbore on ``tris[idx]`` (``idx (K,)``); returns ``(t_min, slot)`` over the chunk.

    Written per component with an unrolled minimum over the K slots: XLA CPU fuses it into
    one loop (the vector form with cross products and an argmin reduction was split into
    several kernels per traversal step).
    """
    tri = tris[jnp.maximum(idx, 0)]  # (K, 3, 3)
    v0 = [tri[:, 0, i] for i in range(3)]
    e1 = [tri[:, 1, i] - v0[i] for i in range(3)]
    e2 = [tri[:, 2, i] - v0[i] for i in range(3)]
    dx, dy, dz = d[0], d[1], d[2]
    # P = d x e2
    px = dy * e2[2] - dz * e2[1]
    py = dz * e2[0] - dx * e2[2]
    pz = dx * e2[1] - dy * e2[0]
    det = px * e1[0] + py * e1[1] + pz * e1[2]
    ok = det != 0
    inv_det = 1.0 / jnp.where(ok, det, 1.0)
    tx, ty, tz = o[0] - v0[0], o[1] - v0[1], o[2] - v0[2]
    b1 = (px * tx + py * ty + pz * tz) * inv_det
    # Q = T x e1
    qx = ty * e1[2] - tz * e1[1]
    qy = tz * e1[0] - tx * e1[2]
    qz = tx * e1[1] - ty * e1[0]
    b2 = (qx * dx + qy * dy + qz * dz) * inv_det
    t = (qx * e2[0] + qy * e2[1] + qz * e2[2]) * inv_det
    hit = mask & ok & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > tmin) & (t < tmax)
    t = jnp.where(hit, t, jnp.inf)
    return small_argmin(t) if reduce else t


def as_numpy_triangles(mesh: TriangleMesh):
    if not isinstance(mesh, TriangleMesh):
        raise TypeError(f"mesh: expected a TriangleMesh, got {type(mesh).__name__}")
    if isinstance(mesh.vertices, jax.core.Tracer):
        raise TypeError("mesh: acceleration structures are built on the host, not under jit")
    return np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)]


def flat_rays(o, d, tmin, tmax):
    """``(o, d, batch, (O, D, TMIN, TMAX))``: the rays (``prepare_rays``) and, for traversal,
    their flat ``(N, 3)`` / ``(N,)`` copies without derivatives."""
    o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
    batch = o.shape[:-1]
    sg = jax.lax.stop_gradient
    flat = (
        sg(o).reshape(-1, 3),
        sg(d).reshape(-1, 3),
        jnp.broadcast_to(sg(tmin), batch).reshape(-1),
        jnp.broadcast_to(sg(tmax), batch).reshape(-1),
    )
    return o, d, batch, flat


class TriangleAccel(eqx.Module):
    """Base class: subclasses implement ``_trace(tris, o, d, inv, tmin, tmax, any_hit)``
    for ONE ray, returning ``(t, prim_id)`` (``prim_id = -1``: no hit)."""

    mesh: eqx.AbstractVar[TriangleMesh]

    def _trace(self, tris, o, d, inv, tmin, tmax, any_hit):
        raise NotImplementedError

    def _run(self, o, d, tmin, tmax, any_hit):
        o, d, batch, (O, D, TMIN, TMAX) = flat_rays(o, d, tmin, tmax)
        tris = jax.lax.stop_gradient(self.mesh.vertices)[self.mesh.faces].astype(O.dtype)

        def one(o1, d1, a, b):
            return self._trace(tris, o1, d1, safe_inv(d1), a, b, any_hit)

        t, prim = jax.vmap(one)(O, D, TMIN, TMAX)
        return o, d, t.reshape(batch), prim.reshape(batch)

    def intersect(self, o, d, *, tmin=0.0, tmax=jnp.inf, shape_id=0) -> Hit:
        """Closest hit of rays ``o, d (..., 3)`` in ``(tmin, tmax)``: a :class:`Hit` whose
        ``t``, ``p``, normals are differentiable w.r.t. ``mesh.vertices`` (closed-form
        re-intersection of the found triangle)."""
        o, d, _, prim = self._run(o, d, tmin, tmax, False)
        return primitive_hit(self.mesh, prim, o, d, prim >= 0, shape_id=shape_id)

    def closest_t(self, o, d, *, tmin=0.0, tmax=jnp.inf):
        """Nearest ``(t, prim_id)`` per ray (``t = inf`` where nothing is hit); not
        differentiable (see :func:`jaxgfx.render.geometry.intersect_scene`)."""
        _, _, t, prim = self._run(o, d, tmin, tmax, False)
        return jnp.where(prim >= 0, t, jnp.inf), jnp.maximum(prim, 0)

    def occluded(self, o, d, tmax, *, tmin=0.0):
        """Any-hit query for shadow rays: True where some triangle lies in ``(tmin, tmax)``.
        Stops at the first hit found (not necessarily the closest)."""
        _, _, _, prim = self._run(o, d, tmin, tmax, True)
        return prim >= 0
