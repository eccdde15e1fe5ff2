"""Acceleration structures for triangle meshes: BVH, uniform grid and kd-tree in JAX, and the
traversal backends (Embree, NVIDIA Warp, the JAX BVH) behind the renderer's intersection.

The JAX structures are built on the host (NumPy) and traversed in JAX (the BVH as a wavefront:
a pool of ray slots refilled from a queue, :func:`.bvh_sah.wavefront_trace`; grid and kd-tree
with a ``lax.while_loop`` per ray, vmapped); all share the interface
``accel.intersect(o, d, *, tmin, tmax, shape_id) -> Hit``,
``accel.closest_t(o, d, *, tmin, tmax)`` and ``accel.occluded(o, d, tmax, *, tmin) -> bool``.
Pass the structure to jitted functions as an argument (it is a pytree) rather than closing over
it. Backends (:mod:`.backends`, docs/render_backends.md): ``build_traversal(mesh, "auto" |
"embree" | "warp" | "jax")``, ``scene_with_accel(scene, accel)``.
"""

from jaxgfx.render.geometry.accel.backends import ACCEL_BACKENDS as ACCEL_BACKENDS
from jaxgfx.render.geometry.accel.backends import accel_of as accel_of
from jaxgfx.render.geometry.accel.backends import available_backends as available_backends
from jaxgfx.render.geometry.accel.backends import build_traversal as build_traversal
from jaxgfx.render.geometry.accel.backends import resolve_backend as resolve_backend
from jaxgfx.render.geometry.accel.backends import scene_with_accel as scene_with_accel
from jaxgfx.render.geometry.accel.bvh_sah import BVH as BVH
from jaxgfx.render.geometry.accel.bvh_sah import build_bvh as build_bvh
from jaxgfx.render.geometry.accel.embree import EmbreeMesh as EmbreeMesh
from jaxgfx.render.geometry.accel.embree import build_embree as build_embree
from jaxgfx.render.geometry.accel.grid_dda import UniformGrid as UniformGrid
from jaxgfx.render.geometry.accel.grid_dda import build_grid as build_grid
from jaxgfx.render.geometry.accel.grid_dda import grid_resolution as grid_resolution
from jaxgfx.render.geometry.accel.kdtree_sah import KDTree as KDTree
from jaxgfx.render.geometry.accel.kdtree_sah import build_kdtree as build_kdtree
from jaxgfx.render.geometry.accel.warp_nvidia import WarpMesh as WarpMesh
from jaxgfx.render.geometry.accel.warp_nvidia import build_warp as build_warp

ACCEL_BUILDERS = {
    "bvh_sah": build_bvh,
    "grid_AmanatidesWoo1987": build_grid,
    "kdtree_sah": build_kdtree,
}
"""Builders selectable by string in scene configs."""

__all__ = [
    "ACCEL_BACKENDS",
    "ACCEL_BUILDERS",
    "BVH",
    "EmbreeMesh",
    "WarpMesh",
    "accel_of",
    "available_backends",
    "build_embree",
    "build_traversal",
    "build_warp",
    "resolve_backend",
    "scene_with_accel",
    "KDTree",
    "UniformGrid",
    "build_bvh",
    "build_grid",
    "build_kdtree",
    "grid_resolution",
]
