"""The traversal-backend interface shared by the Embree, Warp and pure-JAX backends.

A backend object wraps ONE :class:`~jaxgfx.render.geometry.TriangleMesh` (the differentiable
leaves) and answers two non-differentiable queries on a batch of rays ``o, d (..., 3)``:

* ``closest_t(o, d, *, tmin, tmax) -> (t, prim_id)``: nearest hit in ``(tmin, tmax)``
  (``t = inf`` and ``prim_id`` arbitrary, >= 0, where nothing is hit);
* ``occluded(o, d, tmax, *, tmin) -> bool``: any hit in ``(tmin, tmax)``.

``intersect(o, d, *, tmin, tmax, shape_id) -> Hit`` then recomputes the hit record in JAX from
the primitive id (:func:`jaxgfx.render.geometry.primitive_hit`), so ``t``, ``p``, normals and uvs
are differentiable w.r.t. the mesh vertices exactly as with the JAX BVH, whatever engine found
the primitive. This is the protocol :func:`jaxgfx.render.geometry.intersect_scene` and
``occluded_scene`` already use for acceleration structures (an object with ``closest_t`` and a
``mesh``), so a backend object can stand in a scene's shape list unchanged.

Host engines (Embree, Warp) are called from traced code through ``jax.pure_callback`` or an XLA
FFI call; their native scene lives on the host and is referenced by the module through a
static keep-alive whose equality is constant, so rebuilding a backend for moved vertices does
not recompile the jitted renderer (the native handle travels as an integer leaf).
"""

from __future__ import annotations

import itertools
import weakref

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx.render.geometry import TriangleMesh, prepare_rays, primitive_hit
from jaxgfx.render.geometry.ray import Hit

__all__ = ["HostTraversal", "KeepAlive", "register_native", "lookup_native", "host_rays"]

_NATIVE: weakref.WeakValueDictionary = weakref.WeakValueDictionary()
_COUNTER = itertools.count(1)


class KeepAlive:
    """Holds a host object for as long as a module (or a compiled function) references it.

    Static field of the backend modules; every ``KeepAlive`` compares equal and hashes alike, so
    the jit cache key does not depend on which native scene is referenced (the integer handle
    is a traced leaf and :func:`lookup_native` finds the scene at run time).
    """

    __slots__ = ("obj", "__weakref__")

    def __init__(self, obj):
        self.obj = obj

    def __eq__(self, other):
        return isinstance(other, KeepAlive)

    def __hash__(self):
        return 0x5EED

    def __repr__(self):
        return f"KeepAlive({type(self.obj).__name__})"


def register_native(obj) -> int:
    """Register a host object; returns its integer handle (see :func:`lookup_native`)."""
    h = next(_COUNTER)
    _NATIVE[h] = obj
    return h


def lookup_native(handle):
    h = int(np.asarray(handle).reshape(-1)[0])
    try:
        return _NATIVE[h]
    except KeyError:
        raise RuntimeError(
            f"traversal backend: native scene {h} was freed (the backend object that owned it "
            "is gone); rebuild the backend"
        ) from None


def host_rays(o, d, tmin, tmax):
    """Flattened float32 NumPy rays with ``tmin`` folded into the origin.

    Embree (through embreex) and Warp start rays at ``t = 0``; a ray with ``tmin > 0`` is moved
    to ``o + tmin d`` and its interval to ``(0, tmax - tmin)``; add ``tmin`` back to the
    returned ``t``. Returns ``(o, d, tmin, tfar, batch_shape)``.
    """
    o, d, tmin, tmax = np.broadcast_arrays(
        np.asarray(o), np.asarray(d), np.asarray(tmin)[..., None], np.asarray(tmax)[..., None]
    )
    batch = o.shape[:-1]
    o = np.ascontiguousarray(o.reshape(-1, 3), np.float32)
    d = np.ascontiguousarray(d.reshape(-1, 3), np.float32)
    tmin = tmin[..., 0].reshape(-1).astype(np.float32)
    tmax = tmax[..., 0].reshape(-1).astype(np.float32)
    shift = tmin > 0
    if shift.any():
        o = np.where(shift[:, None], o + tmin[:, None] * d, o).astype(np.float32)
    tfar = np.where(shift, tmax - tmin, tmax).astype(np.float32)
    tfar = np.minimum(np.maximum(tfar, 0.0), np.float32(3e38))  # embree: finite, >= tnear
    return o, d, np.where(shift, tmin, 0).astype(np.float32), tfar, batch


class HostTraversal(eqx.Module):
    """Base class of the host-engine backends: subclasses implement ``_query(o, d, tmin, tmax,
    any_hit) -> (t, prim_id)`` on stop-gradient JAX arrays of batch shape ``(...)`` (``t`` in
    the input dtype, ``inf`` / ``-1`` on misses)."""

    mesh: eqx.AbstractVar[TriangleMesh]

    def _query(self, o, d, tmin, tmax, any_hit):
        raise NotImplementedError

    def _run(self, o, d, tmin, tmax, any_hit):
        o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
        sg = jax.lax.stop_gradient
        batch = o.shape[:-1]
        tmin_b = jnp.broadcast_to(sg(tmin), batch)
        tmax_b = jnp.broadcast_to(sg(tmax), batch)
        t, prim = self._query(sg(o), sg(d), tmin_b, tmax_b, any_hit)
        return o, d, t.astype(o.dtype), prim

    def closest_t(self, o, d, *, tmin=0.0, tmax=jnp.inf):
        """Nearest ``(t, prim_id)`` per ray (``t = inf`` where nothing is hit); not
        differentiable (see :func:`jaxgfx.render.geometry.intersect_scene`)."""
        _, _, t, prim = self._run(o, d, tmin, tmax, False)
        return jnp.where(prim >= 0, t, jnp.inf), jnp.maximum(prim, 0)

    def occluded(self, o, d, tmax, *, tmin=0.0):
        """Any-hit query for shadow rays: True where some triangle lies in ``(tmin, tmax)``."""
        _, _, _, prim = self._run(o, d, tmin, tmax, True)
        return prim >= 0

    def intersect(self, o, d, *, tmin=0.0, tmax=jnp.inf, shape_id=0) -> Hit:
        """Closest hit as a :class:`~jaxgfx.render.geometry.ray.Hit` whose ``t``, ``p``, normals and
        uvs are recomputed in JAX for the found triangle (differentiable w.r.t.
        ``mesh.vertices``)."""
        o, d, _, prim = self._run(o, d, tmin, tmax, False)
        return primitive_hit(self.mesh, prim, o, d, prim >= 0, shape_id=shape_id)
