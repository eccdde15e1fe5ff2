"""jaxgfx.render: a Monte Carlo renderer in pure, jittable, differentiable JAX.

Entry points: :func:`load_scene` (dict / YAML / Mitsuba 3 XML -> :class:`Scene`) and
:func:`render`. The subpackages follow the data flow: ``scene/`` (description, schema,
loader, parameter table, Mitsuba export and XML import) -> ``camera`` -> ``geometry/``
(rays, shapes, intersection tests, SDFs,
``accel/``) -> ``bsdf/`` (BSDF models, microfacet distributions, Fresnel, textures) with
``emitters`` and ``sampling`` (warps with pdf and inverse) -> ``integrators/`` (integrator objects)
-> ``film``, ``estimator`` (the sample layout and pass scan) and
``render`` (``sampler``: counter-based uniform numbers). See docs/architecture.md,
docs/render.md, docs/render_bsdf.md, docs/render_geometry.md and docs/render_scenes.md.
"""

from jaxgfx.render import bsdf as bsdf
from jaxgfx.render.bsdf.textured import Checkerboard as Checkerboard
from jaxgfx.render.bsdf.textured import Textured as Textured
from jaxgfx.render.camera import MatrixCamera as MatrixCamera
from jaxgfx.render.camera import PerspectiveCamera as PerspectiveCamera
from jaxgfx.render.camera import ThinLensCamera as ThinLensCamera
from jaxgfx.render.distributed import render_sharded as render_sharded
from jaxgfx.render.emitters import AreaLight as AreaLight
from jaxgfx.render.emitters import ConstantEnvironment as ConstantEnvironment
from jaxgfx.render.emitters import EnvironmentMap as EnvironmentMap
from jaxgfx.render.emitters import PointLights as PointLights
from jaxgfx.render.film import BoxFilter as BoxFilter
from jaxgfx.render.film import CatmullRomFilter as CatmullRomFilter
from jaxgfx.render.film import GaussianFilter as GaussianFilter
from jaxgfx.render.film import LanczosFilter as LanczosFilter
from jaxgfx.render.film import MitchellFilter as MitchellFilter
from jaxgfx.render.film import TentFilter as TentFilter
from jaxgfx.render.geometry import Hit as Hit
from jaxgfx.render.geometry import Rectangles as Rectangles
from jaxgfx.render.geometry import SDFShape as SDFShape
from jaxgfx.render.geometry import Spheres as Spheres
from jaxgfx.render.geometry import TriangleMesh as TriangleMesh
from jaxgfx.render.geometry import accel as accel
from jaxgfx.render.geometry import intersect_scene as intersect_scene
from jaxgfx.render.geometry import spawn_ray as spawn_ray
from jaxgfx.render.geometry.mesh_io import load_obj as load_obj
from jaxgfx.render.geometry.mesh_io import load_ply as load_ply
from jaxgfx.render.integrators import AOV_CHANNELS as AOV_CHANNELS
from jaxgfx.render.integrators import INTEGRATORS as INTEGRATORS
from jaxgfx.render.integrators import AOVIntegrator as AOVIntegrator
from jaxgfx.render.integrators import DirectIntegrator as DirectIntegrator
from jaxgfx.render.integrators import Integrator as Integrator
from jaxgfx.render.integrators import PathIntegrator as PathIntegrator
from jaxgfx.render.integrators import WhittedIntegrator as WhittedIntegrator
from jaxgfx.render.render import render as render
from jaxgfx.render.scene import Scene as Scene
from jaxgfx.render.scene import load_scene as load_scene
from jaxgfx.render.scene import read_xml as read_xml
from jaxgfx.render.sunsky import SunSky as SunSky

__all__ = [
    "accel",
    "bsdf",
    "render",
    "render_sharded",
    "load_scene",
    "read_xml",
    "Scene",
    "INTEGRATORS",
    "AOV_CHANNELS",
    "Integrator",
    "PathIntegrator",
    "DirectIntegrator",
    "WhittedIntegrator",
    "AOVIntegrator",
    "PerspectiveCamera",
    "ThinLensCamera",
    "MatrixCamera",
    "BoxFilter",
    "CatmullRomFilter",
    "LanczosFilter",
    "MitchellFilter",
    "GaussianFilter",
    "TentFilter",
    "PointLights",
    "AreaLight",
    "ConstantEnvironment",
    "EnvironmentMap",
    "SunSky",
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
