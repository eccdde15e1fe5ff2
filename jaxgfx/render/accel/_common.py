"""Shared pieces of the acceleration structures: ray preparation, slab and chunked triangle
tests, and the differentiable re-intersection of the found primitive."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._math import max_last, sum_last
from jaxgfx.render.ray import Hit
from jaxgfx.render.shapes import TriangleMesh, _rays, primitive_hit

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
    tf = jnp.minimum(jnp.min(jnp.maximum(ta, tb), axis=-1) * _GROW[jnp.dtype(o.dtype)], t1)
    return tn, tf, tn <= tf


def tri_chunk(tris, idx, mask, o, d, tmin, tmax):
    """Möller-Trumbore on ``tris[idx]`` (``idx (K,)``); returns ``(t_min, slot)`` over the chunk."""
    tri = tris[jnp.maximum(idx, 0)]
    v0, v1, v2 = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = v1 - v0, v2 - v0
    P = jnp.cross(d, e2)
    det = sum_last(P * e1)
    ok = det != 0
    inv_det = 1.0 / jnp.where(ok, det, 1.0)
    T = o - v0
    b1 = sum_last(P * T) * inv_det
    Q = jnp.cross(T, e1)
    b2 = sum_last(Q * d) * inv_det
    t = sum_last(Q * e2) * inv_det
    hit = mask & ok & (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > tmin) & (t < tmax)
    t = jnp.where(hit, t, jnp.inf)
    j = jnp.argmin(t)
    return t[j], j


def as_numpy_triangles(mesh: TriangleMesh):
    if not isinstance(mesh, TriangleMesh):
        raise TypeError(f"mesh: expected a TriangleMesh, got {type(mesh).__name__}")
    if isinstance(mesh.vertices, jax.core.Tracer):
        raise TypeError("mesh: acceleration structures are built on the host, not under jit")
    return np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)]


class TriangleAccel(eqx.Module):
    """Base class: subclasses implement ``_trace(tris, o, d, inv, tmin, tmax, any_hit)``
    for ONE ray, returning ``(t, prim_id)`` (``prim_id = -1``: no hit)."""

    mesh: eqx.AbstractVar[TriangleMesh]

    def _trace(self, tris, o, d, inv, tmin, tmax, any_hit):
        raise NotImplementedError

    def _run(self, o, d, tmin, tmax, any_hit):
        o, d, tmin, tmax = _rays(o, d, tmin, tmax)
        batch = o.shape[:-1]
        sg = jax.lax.stop_gradient
        O = sg(o).reshape(-1, 3)
        D = sg(d).reshape(-1, 3)
        TMIN = jnp.broadcast_to(sg(tmin), batch).reshape(-1)
        TMAX = jnp.broadcast_to(sg(tmax), batch).reshape(-1)
        tris = sg(self.mesh.vertices)[self.mesh.faces].astype(O.dtype)

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
        differentiable (see :func:`jaxgfx.render.shapes.intersect_scene`)."""
        _, _, t, prim = self._run(o, d, tmin, tmax, False)
        return jnp.where(prim >= 0, t, jnp.inf), jnp.maximum(prim, 0)

    def occluded(self, o, d, tmax, *, tmin=0.0):
        """Any-hit query for shadow rays: True where some triangle lies in ``(tmin, tmax)``.
        Stops at the first hit found (not necessarily the closest)."""
        _, _, _, prim = self._run(o, d, tmin, tmax, True)
        return prim >= 0
