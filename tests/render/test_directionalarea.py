"""Mitsuba 3's ``directionalarea`` emitter (:class:`jaxgfx.render.emitters.DirectionalAreaLight`):
a shape emitting only along its normal. As in Mitsuba, only the particle tracer sees its light;
camera paths (path, direct) see none of it. Closed form, gradients, readers / writers and a
same-run comparison with Mitsuba 3."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.emitters import DirectionalAreaLight
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import ad_fd_per_key

RHO = 0.5
L = [2.0, 1.0, 0.5]


def _desc(w=6, emitter_type="directionalarea"):
    """A white-ish floor (reflectance 0.5) under a 6 x 6 rectangle at height 1 emitting ``L``
    straight down; the camera, below the emitter, sees only floor inside the beam."""
    return {
        "camera": {
            "origin": [0, 0.8, 2],
            "target": [0, 0, 0],
            "fov": 20,
            "width": w,
            "height": w,
        },  # fmt: skip
        "shapes": [
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 1, 0],
                "size": [20, 20],
                "material": "m",
            }
        ],  # fmt: skip
        "materials": {"m": {"type": "diffuse", "reflectance": RHO}},
        "emitters": [
            {
                "type": emitter_type,
                "radiance": L,
                "shape": {
                    "type": "rectangle",
                    "center": [0, 1, 0],
                    "normal": [0, -1, 0],
                    "size": [6, 6],
                },
            }
        ],  # fmt: skip
    }


def _render(scene, integrator, spp, k, seed=0):
    f = jax.jit(lambda s, key: render(s, key, spp=spp, integrator=integrator, max_depth=3))
    return np.stack([np.asarray(f(scene, jax.random.key(seed + i)), np.float64)
                     for i in range(k)])  # fmt: skip


def test_loads_as_a_delta_light_on_its_shape():
    s = load_scene(_desc())
    (light,) = s.delta_lights
    assert isinstance(light, DirectionalAreaLight) and light.shape_index == 1
    assert not s.area_lights and len(s.shapes) == 2
    np.testing.assert_allclose(s.get("emitters.directionalarea.0.radiance"), L)
    with pytest.raises(ValueError, match=r"emitters\[0\]\.radiance"):
        load_scene({**_desc(), "emitters": [{**_desc()["emitters"][0], "radiance": [-1, 0, 0]}]})
    with pytest.raises(ValueError, match=r"emitters\[0\]: unknown key\(s\) \['direction'\]"):
        load_scene({**_desc(), "emitters": [{**_desc()["emitters"][0], "direction": [0, 1, 0]}]})


@pytest.mark.slow  # ~6.5 s process CPU measured under load 19 (2 compiles of a 6² render)
def test_particle_tracer_gives_the_collimated_beam_closed_form_and_path_sees_nothing():
    """The beam carries power ``L A`` through its cross-section ``A``: the floor's irradiance
    under it is ``L`` and its radiance ``rho L / pi`` in every pixel (the camera sees only lit
    floor): the ptracer's image mean within 4 standard errors of 8 renders. The path tracer
    (camera paths, light sampling) sees exactly 0, as Mitsuba's ``path`` does (its
    ``directionalarea`` ``eval`` and ``sample_direction`` return 0)."""
    s = load_scene(_desc())
    imgs = _render(s, "ptracer", 256, 8)
    m = imgs.mean((1, 2))
    se = m.std(0, ddof=1) / math.sqrt(8)
    expect = RHO * np.asarray(L) / math.pi
    print(m.mean(0), expect, se)
    assert np.all(np.abs(m.mean(0) - expect) < 4 * se), (m.mean(0), expect, se)
    assert np.all(se < 0.025 * expect)  # the test can tell a 10 % error
    assert np.all(_render(s, "path", 4, 1) == 0.0)


def _loss(x, key, scene):
    s = scene.replace("emitters.directionalarea.0.radiance", x)
    return jnp.mean(render(s, key, spp=2, integrator="ptracer", max_depth=2))


@pytest.mark.slow  # ~10 s process CPU, load 19 (value+gradient, 6 perturbed renders)
def test_radiance_gradient_matches_finite_differences(x64):
    scene = load_scene(_desc(w=4))
    x = jnp.asarray(L, jnp.float64)
    _, ad, fd = ad_fd_per_key(_loss, x, jax.random.split(jax.random.key(1), 2), 1e-4,
                              args=(scene,))  # fmt: skip
    assert np.all(np.abs(ad) > 0)
    np.testing.assert_allclose(ad, fd, rtol=1e-7)


_XML = """<scene version="3.0.0">
    <integrator type="{integrator}"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="20"/>
        <transform name="to_world"><lookat origin="0, 0.8, 2" target="0, 0, 0" up="0, 1, 0"/>
        </transform>
        <film type="hdrfilm"><integer name="width" value="{w}"/>
            <integer name="height" value="{w}"/><rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    </sensor>
    <shape type="rectangle">
        <transform name="to_world"><scale value="10"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.5"/></bsdf>
    </shape>
    <shape type="sphere">
        <point name="center" value="0.3, 0.25, 0"/><float name="radius" value="0.25"/>
        <bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf>
    </shape>
    <shape type="rectangle" id="beam">
        <transform name="to_world"><scale value="3"/><rotate x="1" angle="90"/>
            <translate y="1"/></transform>
        <emitter type="directionalarea"><rgb name="radiance" value="2, 1, 0.5"/></emitter>
    </shape>
</scene>
"""


def test_xml_reads_and_writes_it(tmp_path):
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    p = tmp_path / "d.xml"
    p.write_text(_XML.format(integrator="ptracer", w=4, spp=4))
    x = read_xml(str(p))
    (e,) = [e for e in x.desc["emitters"] if e["type"] == "directionalarea"]
    np.testing.assert_allclose(e["radiance"], L)
    assert e["shape"]["type"] == "rectangle"
    s = load_scene(x.desc)
    light = s.delta_lights[0]
    np.testing.assert_allclose(s.shapes[light.shape_index].centers[0], [0, 1, 0], atol=1e-6)
    out = save_scene(s, str(tmp_path / "w.xml"), integrator="ptracer")
    (e2,) = [e for e in read_xml(out).desc["emitters"] if e["type"] == "directionalarea"]
    np.testing.assert_allclose(e2["radiance"], L)
    p.write_text(_XML.format(integrator="ptracer", w=4, spp=4).replace(
        '<rgb name="radiance" value="2, 1, 0.5"/>',
        '<texture type="checkerboard" name="radiance"/>'))  # fmt: skip
    with pytest.raises(ValueError, match=r"d\.xml:\d+.*radiance"):
        read_xml(str(p))


@pytest.mark.mitsuba
@pytest.mark.slow  # ~5 s process CPU, load 19 (24², ptracer, 8 x 64 spp per renderer)
def test_matches_mitsuba_same_run(tmp_path):
    """The beam lighting a diffuse floor and a rough-conductor sphere (ptracer, depth 3):
    jaxgfx against Mitsuba 3 (scalar_rgb) in the same run, channel z and 4x4-block z from the
    spread of both sets of renders; Mitsuba's ``path`` renders the scene black, as jaxgfx's."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from tests.render.test_mitsuba_xml_render_projector import _ours, block_z

    p = tmp_path / "d.xml"
    p.write_text(_XML.format(integrator="ptracer", w=24, spp=64))
    ours = _ours(str(p), 64, 8)
    ms = mi.load_file(str(p))
    theirs = np.stack([np.asarray(mi.render(ms, spp=64, seed=s), np.float64)[..., :3]
                       for s in range(8)])  # fmt: skip
    c = block_z(ours, theirs)
    print(c, ours.mean((0, 1, 2)), theirs.mean((0, 1, 2)))
    assert np.all(np.abs(c["z_mean"]) < 4), c
    assert c["z_rms"] < 1.5 and c["frac_3_5"] >= 0.97, c
    p.write_text(_XML.format(integrator="path", w=8, spp=4))
    assert np.all(np.asarray(mi.render(mi.load_file(str(p)), spp=4)) == 0.0)
