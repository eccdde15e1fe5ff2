"""Scene descriptions shared by the render tests (plain dicts for ``load_scene``).

Builders for the recurring pieces (camera, ground rectangle, lights) and the scenes several test
files render. Keeping one spelling per scene lets tests of one *structure* (same shapes,
material names and types, lights, image size) share one compiled program: ``render`` is jitted
on the scene pytree, whose array leaves (positions, albedos, radii) may differ freely.
"""

from __future__ import annotations

import os

import numpy as np

EXAMPLE_YAML = os.path.join(
    os.path.dirname(__file__), "..", "..", "configs", "scenes", "example.yaml"
)


def camera(origin, target, *, fov, width, height=None, up=None) -> dict:
    """A look-at camera description (``height`` defaults to ``width``)."""
    cam = {"origin": list(origin), "target": list(target)}
    if up is not None:
        cam["up"] = list(up)
    return cam | {"fov": fov, "width": width, "height": width if height is None else height}


def rectangle(center=(0, 0, 0), normal=(0, 1, 0), size=(2.0, 2.0), material=None) -> dict:
    """A rectangle description (the ground plane by default: 2 x 2 in ``y = 0``)."""
    d = {"type": "rectangle", "center": list(center), "normal": list(normal), "size": list(size)}
    return d if material is None else d | {"material": material}


def sphere(center=(0, 0, 0), radius=1.0, material=None) -> dict:
    d = {"type": "sphere", "center": list(center), "radius": radius}
    return d if material is None else d | {"material": material}


def point_light(position, intensity) -> dict:
    return {"type": "point", "position": list(position), "intensity": intensity}


def area_light(center, normal, size, radiance) -> dict:
    """A rectangular area light (emits from the side ``normal`` points to)."""
    return {"type": "area", "radiance": radiance, "shape": rectangle(center, normal, size)}


def diffuse(reflectance=0.5) -> dict:
    return {"type": "diffuse", "reflectance": reflectance}


def plane_scene(emitters, material=None, *, cam=None) -> dict:
    """A 2 x 2 ground rectangle of material ``m`` (diffuse 0.5 by default) seen from 3 units
    above by a 16 x 16 camera of 20 degrees; ``cam`` overrides camera fields."""
    return {
        "camera": camera([0, 3, 0.0], [0, 0, 0.0], fov=20.0, width=16, up=[0, 0, 1]) | (cam or {}),
        "shapes": [rectangle(material="m")],
        "materials": {"m": material or diffuse(0.5)},
        "emitters": list(emitters),
    }


def textured_plane_scene(reflectance, *, material=None, width=8) -> dict:
    """The ground rectangle (material ``m``, diffuse with ``reflectance`` unless ``material``)
    seen from above by a ``width``² camera of 30 degrees, lit by a point light."""
    return {
        "camera": camera([0, 3, 0.01], [0, 0, 0], fov=30, width=width, up=[0, 0, -1]),
        "shapes": [rectangle(material="m")],
        "materials": {"m": material or diffuse(reflectance)},
        "emitters": [point_light([0.3, 2.0, 0.2], 10)],
    }


def sphere_floor_scene() -> dict:
    """A rough-conductor sphere (``metal``, alpha 0.3) on a diffuse floor (``floor``), lit by a
    point light and a rectangular area light: every integrator term has a gradient."""
    return {
        "camera": camera([0, 1, 4], [0, 0.5, 0], fov=40, width=8, up=[0, 1, 0]),
        "shapes": [sphere([0, 0.5, 0], 0.5, "metal"), rectangle(size=[4, 4], material="floor")],
        "materials": {
            "metal": {"type": "roughconductor", "alpha": 0.3},
            "floor": diffuse(0.5),
        },
        "emitters": [
            point_light([1, 2, 1], 5.0),
            area_light([0, 2, 0], [0, -1, 0], [1, 1], 4.0),
        ],
    }


def metal_floor_scene(material, *, cam_origin=(0, 1.2, 3.0), cam_target=(0, 0, 0), light=None):
    """A 4 x 4 floor of ``material`` (named ``floor``) under a tilted rectangular area light of
    radiance 5, seen by a 10 x 10 camera of 50 degrees."""
    light = light or {"center": [0, 2.5, -1.0], "normal": [0, -1, 0.3], "size": [1.5, 1.5]}
    return {
        "camera": camera(cam_origin, cam_target, fov=50, width=10),
        "shapes": [rectangle(size=[4, 4], material="floor")],
        "materials": {"floor": material},
        "emitters": [{"type": "area", "shape": {"type": "rectangle", **light}, "radiance": 5}],
    }


def inside_sphere_scene(albedo=0.5, radius=2.0, intensity=10.0, *, width=8) -> dict:
    """A camera inside a closed diffuse sphere (material ``m``) with a point light at its
    centre (the integrating sphere)."""
    return {
        "camera": camera([0.5, 0.2, 0.3], [0, 0, -1], fov=60, width=width),
        "shapes": [sphere([0, 0, 0], radius, "m")],
        "materials": {"m": diffuse(albedo)},
        "emitters": [point_light([0, 0, 0], intensity)],
    }


def env_scene(emitter, width=12) -> dict:
    """A diffuse (0.6) sphere on a 3 x 3 floor, both material ``m``, under ``emitter``."""
    return {
        "camera": camera([0, 1.0, 3.0], [0, 0.2, 0], fov=50, width=width),
        "shapes": [sphere([0, 0.5, 0], 0.5, "m"), rectangle(size=[3, 3], material="m")],
        "materials": {"m": diffuse(0.6)},
        "emitters": [emitter],
    }


def example_scene(width=16, *, floor=0.5, metal=1.0, full=True) -> dict:
    """The example scene (configs/scenes/example.yaml) at ``width``²; ``full=False`` drops the
    glass sphere and the constant sky (a smaller program: compiles ~3x faster)."""
    import yaml

    with open(EXAMPLE_YAML) as f:
        desc = yaml.safe_load(f)
    if not full:
        desc["shapes"] = [s for s in desc["shapes"] if s.get("material") != "glass"]
        desc["materials"].pop("glass")
        desc["emitters"] = [e for e in desc["emitters"] if e["type"] != "constant"]
    desc["camera"] |= {"width": width, "height": width}
    desc["materials"]["floor"]["reflectance"] = [floor] * 3
    desc["materials"]["metal"]["reflectance"] = metal
    return desc


def sensor_test_xml(sensors: str = "", meter: str = "") -> str:
    """The Mitsuba XML scene of the sensor tests (meters, batch, distant): the ``<sensor>``
    elements ``sensors``, path depth 3, a constant environment, a 6 x 6 diffuse floor in
    ``y = 0``, an emitting sphere (black diffuse, Mitsuba's BSDF of an emitter without one) and
    a diffuse sphere holding ``meter`` (an irradiance meter's ``<sensor>``)."""
    return f"""<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    {sensors}
    <emitter type="constant"><rgb name="radiance" value="0.2, 0.3, 0.4"/></emitter>
    <shape type="rectangle">
        <transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
    </shape>
    <shape type="sphere"><point name="center" value="0.3, 1.6, 0.2"/>
        <float name="radius" value="0.4"/>
        <bsdf type="diffuse"><float name="reflectance" value="0"/></bsdf>
        <emitter type="area"><rgb name="radiance" value="4, 3, 2"/></emitter></shape>
    <shape type="sphere"><point name="center" value="0, 0.5, 0"/><float name="radius" value="0.3"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.7"/></bsdf>{meter}</shape>
</scene>
"""


def replicate_block_z(a, b, n=8):
    """``(z, mean_a, mean_b)`` of the ``n x n`` block means of replicate stacks ``a``, ``b``
    ``(K, H, W, 3)`` (e.g. K jaxgfx and K Mitsuba renders of one scene): ``|z|`` from Welch
    standard errors of the K replicates, plus a round-off floor for noise-free blocks."""
    k = a.shape[0]

    def blocks(x):
        return x.reshape(k, x.shape[1] // n, n, x.shape[2] // n, n, 3).mean((2, 4))

    ba, bb = blocks(a), blocks(b)
    var = ba.var(0, ddof=1) / k + bb.var(0, ddof=1) / k + (1e-4 * (ba.mean(0) + bb.mean(0))) ** 2
    return np.abs(ba.mean(0) - bb.mean(0)) / np.sqrt(var + 1e-12), ba.mean(0), bb.mean(0)
