"""Acceleration structures for triangle meshes: BVH, uniform grid and kd-tree.

All three are built on the host (NumPy) and traversed in JAX (``lax.while_loop`` per ray,
vmapped); they share the interface ``accel.intersect(o, d, *, tmin, tmax, shape_id) -> Hit``
and ``accel.occluded(o, d, tmax, *, tmin) -> bool``. Pass the structure to jitted functions
as an argument (it is a pytree) rather than closing over it.
"""

from jaxgfx.render.geometry.accel.bvh_sah import BVH as BVH
from jaxgfx.render.geometry.accel.bvh_sah import build_bvh as build_bvh
from jaxgfx.render.geometry.accel.grid_dda import UniformGrid as UniformGrid
from jaxgfx.render.geometry.accel.grid_dda import build_grid as build_grid
from jaxgfx.render.geometry.accel.grid_dda import grid_resolution as grid_resolution
from jaxgfx.render.geometry.accel.kdtree_sah import KDTree as KDTree
from jaxgfx.render.geometry.accel.kdtree_sah import build_kdtree as build_kdtree

ACCEL_BUILDERS = {
    "bvh_sah": build_bvh,
    "grid_AmanatidesWoo1987": build_grid,
    "kdtree_sah": build_kdtree,
}
"""Builders selectable by string in scene configs."""

__all__ = [
    "ACCEL_BUILDERS",
    "BVH",
    "KDTree",
    "UniformGrid",
    "build_bvh",
    "build_grid",
    "build_kdtree",
    "grid_resolution",
]
