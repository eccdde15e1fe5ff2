"""jaxgfx.render: a Monte Carlo renderer in pure, jittable, differentiable JAX.

Entry points: :func:`load_scene` (dict / YAML -> :class:`Scene`) and :func:`render`.
Building blocks live in submodules: ``camera``, ``film``, ``ray``, ``shapes``, ``sdf``, ``mesh``,
``accel``, ``frame``, ``warp``, ``fresnel``, ``microfacet``, ``bsdf``, ``texture``, ``textured``,
``sdf_shape``, ``emitters``, ``integrators``, ``sampler`` (counter-based uniform numbers) and
``mitsuba`` (export to Mitsuba 3 for comparisons). See docs/render.md, docs/render_bsdf.md,
docs/render_geometry.md and docs/render_scenes.md.
"""

from jaxgfx.render import accel as accel
from jaxgfx.render import bsdf as bsdf
from jaxgfx.render.camera import MatrixCamera as MatrixCamera
from jaxgfx.render.camera import PerspectiveCamera as PerspectiveCamera
from jaxgfx.render.emitters import AreaLight as AreaLight
from jaxgfx.render.emitters import ConstantEnvironment as ConstantEnvironment
from jaxgfx.render.emitters import EnvironmentMap as EnvironmentMap
from jaxgfx.render.emitters import PointLights as PointLights
from jaxgfx.render.film import BoxFilter as BoxFilter
from jaxgfx.render.film import GaussianFilter as GaussianFilter
from jaxgfx.render.integrators import AOV_CHANNELS as AOV_CHANNELS
from jaxgfx.render.integrators import INTEGRATORS as INTEGRATORS
from jaxgfx.render.mesh import load_obj as load_obj
from jaxgfx.render.mesh import load_ply as load_ply
from jaxgfx.render.ray import Hit as Hit
from jaxgfx.render.ray import spawn_ray as spawn_ray
from jaxgfx.render.render import render as render
from jaxgfx.render.scene import Scene as Scene
from jaxgfx.render.scene import load_scene as load_scene
from jaxgfx.render.sdf_shape import SDFShape as SDFShape
from jaxgfx.render.shapes import Rectangles as Rectangles
from jaxgfx.render.shapes import Spheres as Spheres
from jaxgfx.render.shapes import TriangleMesh as TriangleMesh
from jaxgfx.render.shapes import intersect_scene as intersect_scene
from jaxgfx.render.textured import Checkerboard as Checkerboard
from jaxgfx.render.textured import Textured as Textured

__all__ = [
    "accel",
    "bsdf",
    "render",
    "load_scene",
    "Scene",
    "INTEGRATORS",
    "AOV_CHANNELS",
    "PerspectiveCamera",
    "MatrixCamera",
    "BoxFilter",
    "GaussianFilter",
    "PointLights",
    "AreaLight",
    "ConstantEnvironment",
    "EnvironmentMap",
    "Spheres",
    "Rectangles",
    "TriangleMesh",
    "Hit",
    "intersect_scene",
    "spawn_ray",
    "load_obj",
    "load_ply",
    "SDFShape",
    "Textured",
    "Checkerboard",
]
