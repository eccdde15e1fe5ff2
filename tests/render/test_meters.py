"""Mitsuba 3's ``radiancemeter`` and ``irradiancemeter`` sensors
(:class:`jaxgfx.render.camera.RadianceMeter`, :class:`~jaxgfx.render.camera.IrradianceMeter`):
1 x 1 images, closed forms, gradients, XML readers / writers, same-run Mitsuba comparison."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.camera import IrradianceMeter, RadianceMeter
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import ad_fd_per_key
from tests.render._scenes import sensor_test_xml

L = [1.0, 2.0, 3.0]


def _scene(camera, emitters=None, shapes=None):
    return load_scene({
        "camera": camera,
        "shapes": shapes if shapes is not None else [
            {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0], "size": [4, 4],
             "material": "m"}],
        "materials": {"m": {"type": "diffuse", "reflectance": 0.5}},
        "emitters": emitters if emitters is not None else [{"type": "constant", "radiance": L}],
    })  # fmt: skip


_R = jax.jit(lambda s, k: render(s, k, spp=4, integrator="path", max_depth=1))


def test_radiance_meter_reads_the_radiance_along_its_ray():
    """Looking at an area light of radiance ``L_a``: ``L_a`` exactly; looking past the floor
    into a constant environment ``L``: ``L`` (one program: the second meter is a
    ``Scene.replace`` of the first's direction); a 1 x 1 image under ``jit``."""
    la = [4.0, 5.0, 6.0]
    light = {"type": "area", "radiance": la, "shape": {"type": "rectangle", "center": [0, 3, 0],
             "normal": [0, -1, 0], "size": [1, 1]}}  # fmt: skip
    env = {"type": "constant", "radiance": L}
    s = _scene({"type": "radiancemeter", "origin": [0.1, 1, 0.2], "direction": [0, 2, 0]},
               [light, env])  # fmt: skip
    assert isinstance(s.camera, RadianceMeter) and (s.width, s.height) == (1, 1)
    np.testing.assert_allclose(s.camera.direction, [0, 1, 0])  # stored unit
    np.testing.assert_allclose(_R(s, jax.random.key(0)), [[la]], rtol=1e-6)
    s = s.replace("camera.direction", jnp.asarray([0.6, 0.8, 0.0]))
    np.testing.assert_allclose(_R(s, jax.random.key(0)), [[L]], rtol=1e-6)


def test_irradiance_meter_in_a_constant_environment_reads_pi_l():
    """Mitsuba's definition: ``pi`` times the mean radiance of cosine-weighted directions, the
    irradiance ``E = pi L`` under a constant environment (the meter's sphere, also the scene's
    only geometry, is convex: every sample sees ``L``, exact)."""
    ball = {"type": "sphere", "center": [0, 2, 0], "radius": 0.5}
    s = _scene({"type": "irradiancemeter", "shape": ball}, shapes=[{**ball, "material": "m"}])
    assert isinstance(s.camera, IrradianceMeter)
    np.testing.assert_allclose(_R(s, jax.random.key(0)), [[np.pi * np.asarray(L)]], rtol=1e-6)


def _sphere_light_scene(a=0.5, h=1.0, r=0.5):
    light = {"type": "area", "radiance": L,
             "shape": {"type": "sphere", "center": [0, h, 0], "radius": r}}  # fmt: skip
    meter = {"type": "irradiancemeter", "shape": {"type": "rectangle", "center": [0, 0, 0],
             "normal": [0, 1, 0], "size": [2 * a, 2 * a]}}  # fmt: skip
    return _scene(meter, [light])


@pytest.mark.slow  # ~11 s process CPU measured under load 19 (8 renders x 4096 samples)
def test_irradiance_meter_averages_over_its_surface():
    """A square meter of half-size ``a`` under a sphere light (radius ``R``, radiance ``L``,
    centre at height ``h > R`` above the square's centre): the irradiance at a point is
    ``pi L R² cos / d²`` (a sphere wholly above the horizon acts as a point in irradiance), so
    its mean over the square is ``pi L R² Omega / (4 a²)`` with ``Omega = 4 atan(a² / (h
    sqrt(2 a² + h²)))`` the solid angle of the square seen from the centre. 8 renders x 4096
    samples: within 4 standard errors (from their spread)."""
    a, h, r = 0.5, 1.0, 0.5
    s = _sphere_light_scene(a, h, r)
    f = jax.jit(lambda s, k: render(s, k, spp=4096, integrator="path", max_depth=1))
    v = np.stack([np.asarray(f(s, jax.random.key(i)), np.float64)[0, 0] for i in range(8)])
    omega = 4 * math.atan(a * a / (h * math.sqrt(2 * a * a + h * h)))
    expect = math.pi * np.asarray(L) * r * r * omega / (4 * a * a)
    se = v.std(0, ddof=1) / math.sqrt(8)
    print(v.mean(0), expect, se)
    assert np.all(np.abs(v.mean(0) - expect) < 4 * se), (v.mean(0), expect, se)
    assert np.all(se < 0.025 * expect)


def _grad_scene():
    """A diffuse floor, a point light and an environment map."""
    return {"shapes": [{"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0],
                        "size": [8, 8], "material": "m"}],
            "materials": {"m": {"type": "diffuse", "reflectance": 0.5}},
            "emitters": [{"type": "point", "position": [0.5, 2, 0.3], "intensity": 3.0},
                         {"type": "envmap", "image": np.random.default_rng(0).random((4, 8, 3))
                          + 0.1}]}  # fmt: skip


def _loss_radiance(x, key, scene):
    """The meter ray's first-hit depth and albedo (``aov``: the path tracer does not carry
    derivatives through a camera ray's hit point)."""
    s = scene.replace("camera.origin", x[:3]).replace("camera.direction", x[3:])
    return jnp.sum(render(s, key, spp=1, integrator="aov"))


def _loss_irradiance(x, key, scene):
    s = scene.replace("camera.shape.edge_u", x[None, :3]).replace("camera.shape.edge_v",
                                                                  x[None, 3:])  # fmt: skip
    return jnp.sum(render(s, key, spp=4, integrator="path", max_depth=1))


@pytest.mark.slow  # ~8.4 s process CPU, load 19 (2 value+gradient, 24 perturbed renders)
def test_meter_gradients_match_finite_differences(x64):
    """Radiance meter: ``origin`` and ``direction`` (the ``aov`` depth of its ray's hit on the
    floor, smooth in both); irradiance meter: its rectangle's edges (turning the meter turns
    its cosine-weighted directions through a bilinear environment map with no occluder; the
    floor is below it; ``path``). Per key, AD against central differences in float64."""
    sc = load_scene({**_grad_scene(), "camera": {"type": "radiancemeter", "origin": [0, 1, 2],
                                                 "direction": [0.1, -0.6, -1]}})  # fmt: skip
    x = jnp.concatenate([sc.camera.origin, sc.camera.direction]).astype(jnp.float64)
    _, ad, fd = ad_fd_per_key(_loss_radiance, x, jax.random.split(jax.random.key(0), 2), 1e-6,
                              args=(sc,))  # fmt: skip
    assert np.abs(ad).max() > 0
    np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())
    meter = {"type": "irradiancemeter", "shape": {"type": "rectangle", "center": [0, 1, 0],
             "edge_u": [0.5, 0.1, 0], "edge_v": [0, 0.2, -0.5]}}  # fmt: skip
    sc = load_scene({**_grad_scene(), "camera": meter})
    x = jnp.concatenate([sc.camera.shape.edge_u[0], sc.camera.shape.edge_v[0]])
    _, ad, fd = ad_fd_per_key(_loss_irradiance, x.astype(jnp.float64),
                              jax.random.split(jax.random.key(1), 2), 1e-6,
                              args=(sc,))  # fmt: skip
    assert np.abs(ad).max() > 0
    np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_bad_meters_are_refused_naming_the_field():
    with pytest.raises(ValueError, match=r"camera\.direction: expected a nonzero vector"):
        _scene({"type": "radiancemeter", "origin": [0, 1, 0], "direction": [0, 0, 0]})
    with pytest.raises(ValueError, match=r"camera\.shape: an irradiance meter needs"):
        _scene(
            {
                "type": "irradiancemeter",
                "shape": {
                    "type": "sdf",
                    "expr": {"op": "sphere", "center": [0, 0, 0], "radius": 1},
                },
            }
        )
    with pytest.raises(ValueError, match=r"camera.type"):
        _scene({"type": "fisheye"})


_FILM = """<film type="hdrfilm"><integer name="width" value="{w}"/>
    <integer name="height" value="1"/><rfilter type="box"/></film>
    <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>"""
_RADIANCE = ('<sensor type="radiancemeter"><point name="origin" value="1.5, 0.6, 1.2"/>'
             '<vector name="direction" value="-1.5, -0.2, -1.2"/>{film}</sensor>')  # fmt: skip
_IRRADIANCE = '<sensor type="irradiancemeter">{film}</sensor>'


def _xml(kind, w=1, spp=64):
    film = _FILM.format(w=w, spp=spp)
    if kind == "radiancemeter":
        return sensor_test_xml(_RADIANCE.format(film=film))
    return sensor_test_xml(meter=_IRRADIANCE.format(film=film))


def test_xml_reads_and_writes_the_meters(tmp_path):
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    for kind, cls in (("radiancemeter", RadianceMeter), ("irradiancemeter", IrradianceMeter)):
        p = tmp_path / f"{kind}.xml"
        p.write_text(_xml(kind))
        x = read_xml(str(p))
        assert x.desc["camera"]["type"] == kind and x.spp == 64
        s = load_scene(x.desc)
        assert type(s.camera) is cls
        if kind == "irradiancemeter":  # the meter's sphere is also scene geometry (Mitsuba)
            np.testing.assert_allclose(s.camera.shape.centers[0], [0, 0.5, 0])
            assert len(s.shapes) == 3
        out = save_scene(s, str(tmp_path / f"w_{kind}.xml"))
        y = read_xml(out)
        assert y.desc["camera"]["type"] == kind
        p.write_text(_xml(kind, w=2))
        with pytest.raises(ValueError, match=rf"{kind}\.xml:\d+.*needs a 1 x 1 film, got 2 x 1"):
            read_xml(str(p))


@pytest.mark.mitsuba
@pytest.mark.slow  # ~6 / 14 s process CPU, load 19 (8 x 1024 / 4096 spp per renderer)
@pytest.mark.parametrize("kind", ["radiancemeter", "irradiancemeter"])
def test_meters_match_mitsuba_same_run(tmp_path, kind):
    """The radiance meter looking at the diffuse sphere / the irradiance meter on it, lit by a
    sphere light and a constant environment over a diffuse floor (path, depth 3): the mean of
    8 jaxgfx renders against 8 Mitsuba 3 (scalar_rgb) renders, z from both spreads."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from jaxgfx.render.scene.mitsuba_xml import read_xml

    p = tmp_path / "m.xml"
    spp = 1024 if kind == "radiancemeter" else 4096
    p.write_text(_xml(kind, spp=spp))
    x = read_xml(str(p))
    s = load_scene(x.desc)
    f = jax.jit(lambda s, k: render(s, k, spp=spp, integrator="path", max_depth=3))
    ours = np.stack([np.asarray(f(s, jax.random.key(i)), np.float64)[0, 0] for i in range(8)])
    ms = mi.load_file(str(p))
    theirs = np.stack([np.asarray(mi.render(ms, spp=spp, seed=i), np.float64)[0, 0, :3]
                       for i in range(8)])  # fmt: skip
    se = np.sqrt(ours.var(0, ddof=1) / 8 + theirs.var(0, ddof=1) / 8)
    z = (ours.mean(0) - theirs.mean(0)) / se
    print(kind, ours.mean(0), theirs.mean(0), z)
    assert np.all(np.abs(z) < 4), (ours.mean(0), theirs.mean(0), z)
    assert np.all(se < 0.03 * theirs.mean(0))


@pytest.mark.mitsuba  # ~1 s measured (Mitsuba only, 2 x 8 renders x 256 spp of one pixel)
@pytest.mark.parametrize("kind", ["radiancemeter", "irradiancemeter"])
def test_written_meters_render_the_same_in_mitsuba(tmp_path, kind):
    """``save_scene`` of the loaded meter scene (the irradiance meter nested in a null-BSDF
    copy of its sphere) renders in Mitsuba 3 as the original file does: z of the means of 8
    renders each."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    p = tmp_path / "m.xml"
    p.write_text(_xml(kind, spp=256))
    out = save_scene(load_scene(read_xml(str(p)).desc), str(tmp_path / "w.xml"), spp=256,
                     max_depth=3)  # fmt: skip

    def runs(path):
        sc = mi.load_file(path)
        return np.stack([np.asarray(mi.render(sc, spp=256, seed=i), np.float64)[0, 0, :3]
                         for i in range(8)])  # fmt: skip

    a, b = runs(str(p)), runs(out)
    z = (a.mean(0) - b.mean(0)) / np.sqrt(a.var(0, ddof=1) / 8 + b.var(0, ddof=1) / 8)
    print(kind, a.mean(0), b.mean(0), z)
    assert np.all(np.abs(z) < 4), z
