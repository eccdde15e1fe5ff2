# ruff: noqa: F722  (jaxtyping shape strings)
"""Embree 4 traversal backend (CPU) through ``embreex`` (optional: ``pip install jaxgfx[embree]``).

The Embree scene is built and committed once per mesh on the host (:func:`build_embree`) and
reused by every render; traced code reaches it through ``jax.pure_callback`` (one host call per
ray batch, ~0.1-0.2 ms of overhead, the rays copied to float32). ``embreex`` traces the batch
with ``rtcIntersect1``/``rtcOccluded1`` in a compiled loop (one thread, GIL held). The hit
record is then recomputed in JAX from the primitive id (see :mod:`._base`).

Reference: Wald et al. 2014, "Embree: a kernel framework for efficient CPU ray tracing", ACM
TOG 33(4).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Int

from jaxgfx.render.geometry import TriangleMesh
from jaxgfx.render.traversal._base import (
    HostTraversal,
    KeepAlive,
    host_rays,
    lookup_native,
    register_native,
)

__all__ = ["EmbreeMesh", "build_embree", "embree_available"]


def embree_available() -> bool:
    """True when ``embreex`` (Embree 4 bindings) imports."""
    try:
        import embreex.mesh_construction  # noqa: F401
        import embreex.rtcore_scene  # noqa: F401
    except ImportError:
        return False
    return True


class _EmbreeScene:
    """Host side: the committed Embree scene of one mesh and the batch query."""

    __slots__ = ("scene", "mesh", "n_tris", "__weakref__")

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        from embreex import mesh_construction, rtcore_scene

        self.scene = rtcore_scene.EmbreeScene()
        v = np.ascontiguousarray(vertices, np.float32)
        f = np.ascontiguousarray(faces, np.int32)
        self.mesh = mesh_construction.TriangleMesh(self.scene, v, f)
        self.n_tris = f.shape[0]
        # commit now (embreex commits lazily on the first query): the build is timed here
        self.scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32))

    def query(self, o, d, tmin, tmax, any_hit):
        O, D, t0, tfar, batch = host_rays(o, d, tmin, tmax)
        if O.shape[0] == 0:
            return np.zeros(batch, np.float32), np.zeros(batch, np.int32)
        if any_hit:
            gid = self.scene.run(O, D, dists=tfar.copy(), query="OCCLUDED")
            prim = np.where(gid >= 0, 0, -1).astype(np.int32)
            return np.zeros(batch, np.float32), prim.reshape(batch)
        r = self.scene.run(O, D, dists=tfar.copy(), output=1)
        prim = r["primID"].astype(np.int32)
        ts = r["tfar"]
        ok = (prim >= 0) & (ts > 0) & (ts < tfar)
        t = np.where(ok, ts + t0, np.inf).astype(np.float32)
        return t.reshape(batch), np.where(ok, prim, -1).reshape(batch)


class EmbreeMesh(HostTraversal):
    """A triangle mesh traced by Embree 4 (build with :func:`build_embree`).

    Fields: ``mesh`` (the differentiable :class:`TriangleMesh`), ``handle`` (int32 scalar
    leaf naming the committed host scene). Like the JAX BVH, the Embree scene is not refit when
    ``mesh.vertices`` change: rebuild after moving vertices by more than a negligible amount
    (a rebuild does not recompile jitted callers).
    """

    mesh: TriangleMesh
    handle: Int[Array, ""]
    keep: KeepAlive = eqx.field(static=True)

    def _query(self, o, d, tmin, tmax, any_hit):
        batch = o.shape[:-1]
        out = (
            jax.ShapeDtypeStruct(batch, jnp.float32),
            jax.ShapeDtypeStruct(batch, jnp.int32),
        )

        def cb(h, o, d, tmin, tmax):
            return lookup_native(h).query(o, d, tmin, tmax, any_hit)

        return jax.pure_callback(cb, out, self.handle, o, d, tmin, tmax, vmap_method="expand_dims")


def build_embree(mesh: TriangleMesh) -> EmbreeMesh:
    """Build and commit an Embree scene over ``mesh`` (host; float32 vertex copy).

    Raises ``ImportError`` with the install hint when ``embreex`` is missing.
    Example: ``build_embree(make_icosphere(3)).closest_t(o, d)``.
    """
    if not isinstance(mesh, TriangleMesh):
        raise TypeError(f"mesh: expected a TriangleMesh, got {type(mesh).__name__}")
    if isinstance(mesh.vertices, jax.core.Tracer):
        raise TypeError("mesh: traversal backends are built on the host, not under jit")
    if not embree_available():
        raise ImportError("the Embree backend needs embreex: pip install 'jaxgfx[embree]'")
    host = _EmbreeScene(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    return EmbreeMesh(mesh, jnp.asarray(register_native(host), jnp.int32), KeepAlive(host))
