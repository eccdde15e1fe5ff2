# ruff: noqa: F722  (jaxtyping shape strings)
"""NVIDIA Warp traversal backend (``wp.Mesh`` + ``wp.mesh_query_ray``; optional:
``pip install jaxgfx[warp]``).

The Warp mesh (its BVH built by Warp on the device that runs JAX: CPU here, CUDA on a GPU) is
built once per mesh (:func:`build_warp`); traced code launches one Warp kernel per ray batch
through Warp's JAX FFI interop (``wp.jax_kernel``: no Python call and, on a GPU, no copy). The
64-bit mesh id travels as a ``uint32[2]`` leaf (a uint64 does not exist in JAX without x64).
Warp's barycentrics weight vertices 0 and 1; only the face index is used here, the hit record
is recomputed in JAX (see :mod:`._base`).
"""

from __future__ import annotations

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, UInt32

from jaxgfx.render.geometry import TriangleMesh
from jaxgfx.render.traversal._base import HostTraversal, KeepAlive

__all__ = ["WarpMesh", "build_warp", "warp_available"]


def warp_available() -> bool:
    """True when ``warp`` (NVIDIA Warp, ``warp-lang``) imports."""
    try:
        import warp  # noqa: F401
    except ImportError:
        return False
    return True


@functools.cache
def _kernels():
    import warp as wp

    if wp.config.log_level == wp.LOG_INFO:  # the default: no init/module-load banners
        wp.config.log_level = wp.LOG_WARNING
    wp.init()

    @wp.kernel
    def closest(
        o: wp.array(dtype=wp.vec3),
        d: wp.array(dtype=wp.vec3),
        tmin: wp.array(dtype=wp.float32),
        tmax: wp.array(dtype=wp.float32),
        mesh_id: wp.array(dtype=wp.uint32),
        t_out: wp.array(dtype=wp.float32),
        prim_out: wp.array(dtype=wp.int32),
    ):
        i = wp.tid()
        mid = wp.uint64(mesh_id[0]) | (wp.uint64(mesh_id[1]) << wp.uint64(32))
        t0 = wp.max(tmin[i], 0.0)
        start = o[i] + t0 * d[i]
        q = wp.mesh_query_ray(mid, start, d[i], tmax[i] - t0)
        if q.result and q.t <= 0.0:
            # a hit at exactly t = 0 (ray starting on a triangle) would hide the next one: the
            # interval is open, so look again from just beyond the origin
            eps = 1e-7 * (wp.length(start) + 1.0)
            q = wp.mesh_query_ray(mid, start + eps * d[i], d[i], tmax[i] - t0 - eps)
            t0 = t0 + eps
        if q.result and q.t > 0.0 and q.t < tmax[i] - t0:
            t_out[i] = q.t + t0
            prim_out[i] = q.face
        else:
            t_out[i] = wp.inf
            prim_out[i] = -1

    wp_closest = wp.jax_kernel(closest, num_outputs=2, vmap_method="broadcast_all")
    return wp, closest, wp_closest


class _WarpScene:
    __slots__ = ("mesh", "points", "indices", "__weakref__")

    def __init__(self, wp, vertices, faces, device):
        self.points = wp.array(np.asarray(vertices, np.float32), dtype=wp.vec3, device=device)
        self.indices = wp.array(
            np.asarray(faces, np.int32).reshape(-1), dtype=wp.int32, device=device
        )
        self.mesh = wp.Mesh(points=self.points, indices=self.indices)


class WarpMesh(HostTraversal):
    """A triangle mesh traced by NVIDIA Warp (build with :func:`build_warp`).

    Fields: ``mesh`` (the differentiable :class:`TriangleMesh`), ``mesh_id`` (``uint32[2]``,
    the low and high words of Warp's 64-bit mesh id). The Warp BVH is not refit when
    ``mesh.vertices`` change: rebuild (no recompilation of jitted callers).
    """

    mesh: TriangleMesh
    mesh_id: UInt32[Array, " 2"]
    keep: KeepAlive = eqx.field(static=True)

    def _query(self, o, d, tmin, tmax, any_hit):
        _, _, call = _kernels()
        batch = o.shape[:-1]
        n = int(np.prod(batch))
        if n == 0:
            return jnp.zeros(batch, jnp.float32), jnp.zeros(batch, jnp.int32)
        f32 = jnp.float32
        t, prim = call(
            o.reshape(n, 3).astype(f32),
            d.reshape(n, 3).astype(f32),
            tmin.reshape(n).astype(f32),
            jnp.minimum(tmax.reshape(n).astype(f32), 3e38),
            self.mesh_id,
            launch_dims=(n,),
            output_dims=(n,),
        )
        return t.reshape(batch), prim.reshape(batch)


def build_warp(mesh: TriangleMesh, *, device: str | None = None) -> WarpMesh:
    """Build a Warp mesh (and its BVH) over ``mesh`` on ``device`` (default: the device of
    JAX's default backend, ``"cpu"`` or ``"cuda:0"``). Raises ``ImportError`` with the install
    hint when ``warp`` is missing."""
    if not isinstance(mesh, TriangleMesh):
        raise TypeError(f"mesh: expected a TriangleMesh, got {type(mesh).__name__}")
    if isinstance(mesh.vertices, jax.core.Tracer):
        raise TypeError("mesh: traversal backends are built on the host, not under jit")
    if not warp_available():
        raise ImportError("the Warp backend needs warp: pip install 'jaxgfx[warp]'")
    wp, _, _ = _kernels()
    if device is None:
        device = "cuda:0" if jax.default_backend() == "gpu" else "cpu"
    host = _WarpScene(wp, np.asarray(mesh.vertices), np.asarray(mesh.faces), device)
    mid = int(host.mesh.id)
    words = np.array([mid & 0xFFFFFFFF, mid >> 32], np.uint32)
    return WarpMesh(mesh, jnp.asarray(words), KeepAlive(host))
