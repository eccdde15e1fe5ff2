"""Mitsuba 3's ``distant`` sensor (:class:`jaxgfx.render.camera.DistantSensor`): closed forms
for point, shape and disk targets, gradients, the XML reader / writer, and a same-run
comparison with Mitsuba 3."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.camera import DistantSensor
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import ad_fd_per_key
from tests.render._scenes import sensor_test_xml

RHO, E, THETA = 0.6, 2.0, math.radians(30)
_PLANE = {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0], "size": [4, 4],
          "material": "m"}  # fmt: skip
_SUN = {"type": "directional", "irradiance": E,
        "direction": [math.sin(THETA), -math.cos(THETA), 0]}  # fmt: skip
_D = [0.3, -1, 0.2]


def _scene(camera, emitters=(_SUN,)):
    return load_scene({"camera": camera, "shapes": [_PLANE], "emitters": list(emitters),
                       "materials": {"m": {"type": "diffuse", "reflectance": RHO}}})  # fmt: skip


_R = jax.jit(lambda s, k: render(s, k, spp=4, integrator="path", max_depth=2))


def test_distant_sensor_reads_a_lambertian_plane():
    """A Lambertian plane (albedo ``rho``) under a directional light (irradiance ``E`` at
    30 degrees) leaves ``rho E cos(theta) / pi`` in every direction: a point target on it reads
    that (float32 rounding); a target off the plane reads 0 (one program: the second is a
    ``Scene.replace`` of the first's target). Under ``jit``."""
    expect = RHO * E * math.cos(THETA) / math.pi
    s = _scene({"type": "distant", "direction": _D, "target": [0.2, 0, -0.1], "distance": 10.0})
    assert isinstance(s.camera, DistantSensor) and s.camera.lens_uniforms == 0
    assert (s.width, s.height) == (1, 1)
    np.testing.assert_allclose(_R(s, jax.random.key(0)), [[[expect] * 3]], rtol=1e-5)
    s = s.replace("camera.target", jnp.asarray([5.0, 0.0, 0.0]))
    np.testing.assert_array_equal(_R(s, jax.random.key(0)), np.zeros((1, 1, 3)))


def test_distant_sensor_reads_a_constant_environment():
    """A ray that misses every shape reads the constant environment's ``L`` exactly."""
    lv = [0.2, 0.3, 0.4]
    s = _scene({"type": "distant", "direction": [0, -1, 0], "target": [5, 0, 0], "distance": 3},
               [{"type": "constant", "radiance": lv}])  # fmt: skip
    np.testing.assert_allclose(_R(s, jax.random.key(0)), [[lv]], rtol=1e-6)


@pytest.mark.slow  # slow: ~3 s on 2 cores, load 3.8 (2 compiled renders)
def test_distant_sensor_shape_and_disk_targets_read_the_plane():
    """A rectangle target on the lit plane and a disk target about a point of it (every ray
    hits the uniformly lit plane) read ``rho E cos(theta) / pi`` too (float32 rounding)."""
    expect = RHO * E * math.cos(THETA) / math.pi
    cams = [
        {"type": "distant", "direction": _D, "distance": 10.0,
         "target": {"type": "rectangle", "center": [0.5, 0, 0], "normal": [0, 1, 0],
                    "size": [1, 0.5]}},
        {"type": "distant", "direction": _D, "target": [0, 0, 0], "radius": 1.0,
         "distance": 10.0},
    ]  # fmt: skip
    for cam in cams:
        s = _scene(cam)
        assert s.camera.lens_uniforms == 2
        np.testing.assert_allclose(_R(s, jax.random.key(0)), [[[expect] * 3]], rtol=1e-5)


def _loss_point(x, key, scene):
    s = scene.replace("camera.direction", x[:3]).replace("camera.target", x[3:6])
    s = s.replace("camera.distance", x[6])
    return jnp.sum(render(s, key, spp=1, integrator="aov"))


def _loss_shape(x, key, scene):
    s = scene.replace("camera.shape.centers", x[None])
    return jnp.sum(render(s, key, spp=2, integrator="aov"))


def test_distant_sensor_gradients_match_finite_differences(x64):
    """``aov`` channels (depth and position of the hit on the plane: smooth in the sensor's
    direction, target and distance) against central differences in float64 (same key)."""
    s = _scene({"type": "distant", "direction": _D, "target": [0.2, 0.1, -0.1], "distance": 5})
    c = s.camera
    x = jnp.concatenate([c.direction, c.target, c.distance[None]]).astype(jnp.float64)
    _, ad, fd = ad_fd_per_key(_loss_point, x, jax.random.split(jax.random.key(0), 1), 1e-6,
                              args=(s,))  # fmt: skip
    assert np.abs(ad).max() > 0
    np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


@pytest.mark.slow  # slow: ~2.5 s on 2 cores, load 3.8 (value + gradient, 6 perturbed renders)
def test_distant_sensor_shape_target_gradients_match_finite_differences(x64):
    """The same through a rectangle target's centre (its sampled points move with it)."""
    s = _scene({"type": "distant", "direction": _D, "distance": 5,
                "target": {"type": "rectangle", "center": [0.5, 0.3, 0], "normal": [0, 1, 0],
                           "size": [1, 0.5]}})  # fmt: skip
    x = s.camera.shape.centers[0].astype(jnp.float64)
    _, ad, fd = ad_fd_per_key(_loss_shape, x, jax.random.split(jax.random.key(1), 1), 1e-6,
                              args=(s,))  # fmt: skip
    assert np.abs(ad).max() > 0
    np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_bad_distant_sensors_are_refused_naming_the_field():
    with pytest.raises(ValueError, match=r"camera\.direction: expected a nonzero vector"):
        _scene({"type": "distant", "direction": [0, 0, 0], "target": [0, 0, 0], "distance": 1})
    with pytest.raises(ValueError, match=r"camera\.distance: expected a finite number > 0"):
        _scene({"type": "distant", "direction": _D, "target": [0, 0, 0], "distance": 0})
    with pytest.raises(ValueError, match=r"camera\.target: a distant sensor's target shape"):
        _scene({"type": "distant", "direction": _D, "distance": 1,
                "target": {"type": "sdf", "expr": {"op": "sphere", "center": [0, 0, 0],
                                                   "radius": 1}}})  # fmt: skip


_SENSOR = """<sensor type="distant">
        <vector name="direction" value="-0.3, -1, -0.2"/>{target}
        <film type="hdrfilm"><integer name="width" value="{w}"/>
            <integer name="height" value="1"/><rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    </sensor>
"""
_TARGETS = {
    "point": '<point name="target" value="1.0, 0.0, 0.8"/>',
    "shape": '<shape type="rectangle" name="target"><transform name="to_world"><scale value="0.5"/>'
    '<rotate x="1" angle="-90"/><translate value="0, 0.2, 0"/></transform></shape>',
    "none": "",
}


def _xml(kind, w=1, spp=64):
    return sensor_test_xml(_SENSOR.format(target=_TARGETS[kind], w=w, spp=spp))


def test_xml_reads_and_writes_the_distant_sensor(tmp_path):
    """Point, shape and no target; ``distance`` twice the bounding sphere's radius (the
    floor's half-diagonal 3 sqrt(2) and the spheres' heights: box [-3, 3] x [0, 2] x [-3, 3],
    radius sqrt(19)), the target shape not scene geometry, no target the disk across the
    sphere; the writer's ``distant`` reads back; films other than 1 x 1 and ``direction``
    with ``to_world`` refused with file and line."""
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    r = math.sqrt(19) * (1 + 1e-4)
    for kind in _TARGETS:
        p = tmp_path / f"{kind}.xml"
        p.write_text(_xml(kind))
        cam = read_xml(str(p)).desc["camera"]
        assert cam["type"] == "distant"
        np.testing.assert_allclose(cam["direction"], np.array([-0.3, -1, -0.2]) / math.sqrt(1.13))
        s = load_scene(read_xml(str(p)).desc)
        assert type(s.camera) is DistantSensor and len(s.shapes) == 3
        if kind == "none":
            np.testing.assert_allclose([cam["distance"], cam["radius"]], [r, r], rtol=1e-9)
            np.testing.assert_allclose(cam["target"], [0, 1, 0], atol=1e-12)
        else:
            np.testing.assert_allclose(cam["distance"], 2 * r, rtol=1e-9)
        if kind == "shape":
            np.testing.assert_allclose(s.camera.shape.centers[0], [0, 0.2, 0], atol=1e-6)
        y = read_xml(save_scene(s, str(tmp_path / f"w_{kind}.xml"))).desc["camera"]
        assert y.keys() == cam.keys()
        np.testing.assert_allclose(y["distance"], cam["distance"], rtol=1e-6)
    p = tmp_path / "bad.xml"
    p.write_text(_xml("point", w=2))
    with pytest.raises(ValueError, match=r"bad\.xml:\d+.*a distant sensor needs a 1 x 1 film, "
                                         r"got 2 x 1"):  # fmt: skip
        read_xml(str(p))
    p.write_text(_xml("point").replace("</sensor>", '<transform name="to_world"/></sensor>'))
    with pytest.raises(ValueError, match=r"bad\.xml:\d+.*direction or to_world, not both"):
        read_xml(str(p))


@pytest.mark.mitsuba
@pytest.mark.slow  # slow: ~5 s each on 2 cores, load 3.8 (3 x 8 renders x 1024 spp, 1 pixel)
@pytest.mark.parametrize("kind", list(_TARGETS))
def test_distant_sensor_matches_mitsuba_same_run(tmp_path, kind):
    """A point on the floor (lit by a sphere light and a constant environment, partly
    shadowed by a diffuse sphere), a rectangle target above the floor (rays through it hit
    the floor and the sphere), no target (the bounding-sphere disk: the environment too); path
    depth 3. The mean of 8 jaxgfx renders against 8 Mitsuba 3 (scalar_rgb) renders: |z| < 4
    (z from both spreads); and ``save_scene``'s file renders in Mitsuba as the original."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    spp = 1024
    p = tmp_path / "d.xml"
    p.write_text(_xml(kind, spp=spp))
    s = load_scene(read_xml(str(p)).desc)
    f = jax.jit(lambda s, k: render(s, k, spp=spp, integrator="path", max_depth=3))
    ours = np.stack([np.asarray(f(s, jax.random.key(i)), np.float64)[0, 0] for i in range(8)])

    def runs(path, seed):
        sc = mi.load_file(path)
        # seeds 2^20 apart: with seeds 0..23 Mitsuba's mean of the point file was low
        # (red 0.1750 +- 0.0003 against 0.1766 +- 0.0003 with seeds 1000..1063, and 0.1771
        # with seeds 0..15 and the constant emitter moved last); cause not established
        return np.stack([np.asarray(mi.render(sc, spp=spp, seed=(seed + i) << 20),
                                    np.float64)[0, 0, :3] for i in range(8)])  # fmt: skip

    theirs = runs(str(p), 0)
    written = runs(save_scene(s, str(tmp_path / "w.xml"), spp=spp, max_depth=3), 8)
    for a in (ours, written):
        z = (a.mean(0) - theirs.mean(0)) / np.sqrt(a.var(0, ddof=1) / 8 + theirs.var(0, ddof=1) / 8)
        print(kind, a.mean(0), theirs.mean(0), z)
        assert np.all(np.abs(z) < 4), z
    assert np.all(theirs.std(0) > 0)
