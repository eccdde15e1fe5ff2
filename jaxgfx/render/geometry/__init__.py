"""jaxgfx.render.geometry: rays, shapes, their intersection tests and acceleration structures.

One file per algorithm: ``ray`` (rays, :class:`Hit` records, robust spawning), ``frame``
(orthonormal shading frames), ``sphere``, ``rectangle``, ``mesh`` (:class:`TriangleMesh`),
``triangle_moller_trumbore`` (Möller & Trumbore 1997), ``triangle_unit`` (affine map to the unit
triangle), ``intersect`` (closest hit / any hit over shapes and scenes), ``instance``
(instancing), ``curves`` (Mitsuba's linear and B-spline curves), ``ellipsoids`` (Mitsuba's
ellipsoids), ``area`` (areas and uniform
area sampling for area lights), ``sdf`` (signed distance functions), ``sdfgrid`` (SDF grids,
``.vol`` files), ``sphere_tracing`` (Hart 1996; :class:`SDFShape`), ``mesh_io`` (OBJ / PLY,
procedural meshes) and ``accel/`` (``bvh_sah``, ``grid_dda``, ``kdtree_sah``).
See docs/render_geometry.md.
"""

from jaxgfx._math import take_rows as take_rows
from jaxgfx.render.geometry import accel as accel
from jaxgfx.render.geometry.area import area as area
from jaxgfx.render.geometry.area import primitive_areas as primitive_areas
from jaxgfx.render.geometry.area import sample_area as sample_area
from jaxgfx.render.geometry.curves import BSplineCurves as BSplineCurves
from jaxgfx.render.geometry.curves import LinearCurves as LinearCurves
from jaxgfx.render.geometry.curves import curve_lists as curve_lists
from jaxgfx.render.geometry.curves import read_curves as read_curves
from jaxgfx.render.geometry.curves import write_curves as write_curves
from jaxgfx.render.geometry.ellipsoids import Ellipsoids as Ellipsoids
from jaxgfx.render.geometry.ellipsoids import read_ellipsoids_ply as read_ellipsoids_ply
from jaxgfx.render.geometry.ellipsoids import write_ellipsoids_ply as write_ellipsoids_ply
from jaxgfx.render.geometry.instance import Instances as Instances
from jaxgfx.render.geometry.intersect import closest_t as closest_t
from jaxgfx.render.geometry.intersect import intersect as intersect
from jaxgfx.render.geometry.intersect import intersect_scene as intersect_scene
from jaxgfx.render.geometry.intersect import occluded_scene as occluded_scene
from jaxgfx.render.geometry.intersect import primitive_hit as primitive_hit
from jaxgfx.render.geometry.intersect import small_argmin as small_argmin
from jaxgfx.render.geometry.mesh import TRIANGLE_INTERSECTORS as TRIANGLE_INTERSECTORS
from jaxgfx.render.geometry.mesh import TriangleMesh as TriangleMesh
from jaxgfx.render.geometry.ray import Hit as Hit
from jaxgfx.render.geometry.ray import empty_hit as empty_hit
from jaxgfx.render.geometry.ray import hit_record as hit_record
from jaxgfx.render.geometry.ray import merge_hits as merge_hits
from jaxgfx.render.geometry.ray import offset_ray_origin as offset_ray_origin
from jaxgfx.render.geometry.ray import prepare_rays as prepare_rays
from jaxgfx.render.geometry.ray import spawn_ray as spawn_ray
from jaxgfx.render.geometry.rectangle import Rectangles as Rectangles
from jaxgfx.render.geometry.rectangle import rectangle_intersect as rectangle_intersect
from jaxgfx.render.geometry.sdf import SDF as SDF
from jaxgfx.render.geometry.sdf import SDF_OPS as SDF_OPS
from jaxgfx.render.geometry.sdf import SDFBox as SDFBox
from jaxgfx.render.geometry.sdf import SDFCapsule as SDFCapsule
from jaxgfx.render.geometry.sdf import SDFIntersection as SDFIntersection
from jaxgfx.render.geometry.sdf import SDFPlane as SDFPlane
from jaxgfx.render.geometry.sdf import SDFRoundBox as SDFRoundBox
from jaxgfx.render.geometry.sdf import SDFSmoothUnion as SDFSmoothUnion
from jaxgfx.render.geometry.sdf import SDFSphere as SDFSphere
from jaxgfx.render.geometry.sdf import SDFSubtraction as SDFSubtraction
from jaxgfx.render.geometry.sdf import SDFTorus as SDFTorus
from jaxgfx.render.geometry.sdf import SDFUnion as SDFUnion
from jaxgfx.render.geometry.sdf import sdf_from_dict as sdf_from_dict
from jaxgfx.render.geometry.sdf import sdf_normal as sdf_normal
from jaxgfx.render.geometry.sdfgrid import SDFGrid as SDFGrid
from jaxgfx.render.geometry.sdfgrid import SDFGridShape as SDFGridShape
from jaxgfx.render.geometry.sdfgrid import read_vol as read_vol
from jaxgfx.render.geometry.sdfgrid import write_vol as write_vol
from jaxgfx.render.geometry.sphere import Spheres as Spheres
from jaxgfx.render.geometry.sphere import sphere_intersect as sphere_intersect
from jaxgfx.render.geometry.sphere_tracing import SDFShape as SDFShape
from jaxgfx.render.geometry.sphere_tracing import sphere_trace as sphere_trace
from jaxgfx.render.geometry.triangle_moller_trumbore import (
    triangle_intersect_moller_trumbore as triangle_intersect_moller_trumbore,
)
from jaxgfx.render.geometry.triangle_unit import (
    triangle_affine_matrices as triangle_affine_matrices,
)
from jaxgfx.render.geometry.triangle_unit import (
    triangle_intersect_affine as triangle_intersect_affine,
)

__all__ = [
    "Hit",
    "hit_record",
    "empty_hit",
    "merge_hits",
    "prepare_rays",
    "offset_ray_origin",
    "spawn_ray",
    "Spheres",
    "Rectangles",
    "TriangleMesh",
    "Instances",
    "LinearCurves",
    "BSplineCurves",
    "read_curves",
    "write_curves",
    "curve_lists",
    "Ellipsoids",
    "read_ellipsoids_ply",
    "write_ellipsoids_ply",
    "TRIANGLE_INTERSECTORS",
    "sphere_intersect",
    "rectangle_intersect",
    "triangle_intersect_moller_trumbore",
    "triangle_affine_matrices",
    "triangle_intersect_affine",
    "primitive_hit",
    "small_argmin",
    "closest_t",
    "intersect",
    "intersect_scene",
    "occluded_scene",
    "take_rows",
    "area",
    "primitive_areas",
    "sample_area",
    "SDF",
    "SDFSphere",
    "SDFBox",
    "SDFRoundBox",
    "SDFTorus",
    "SDFPlane",
    "SDFCapsule",
    "SDFUnion",
    "SDFIntersection",
    "SDFSubtraction",
    "SDFSmoothUnion",
    "SDF_OPS",
    "sdf_from_dict",
    "sdf_normal",
    "SDFShape",
    "SDFGrid",
    "SDFGridShape",
    "read_vol",
    "write_vol",
    "sphere_trace",
    "accel",
]
