"""Mitsuba 3 XML ``directional`` / ``spot`` emitters, ``thindielectric`` / ``blendbsdf`` BSDFs
and the ``tent`` reconstruction filter: loaded from XML snippets, written back by ``save_scene``.

Fast unit tests (no rendering): the loaded lights and BSDFs are evaluated as the integrators
use them (``sample`` of the light at points of a diffuse plane, ``eval`` / ``sample`` of the
BSDF) and compared with closed forms written from Mitsuba 3's plugin definitions
(``src/emitters/{directional,spot}.cpp``, ``src/bsdfs/{thindielectric,blendbsdf}.cpp``,
``src/rfilters/tent.cpp``); XML -> description -> XML -> description and Scene -> XML give the
same parameters; each unsupported parameter is one error naming it, the object and file:line.
The rendered comparison with Mitsuba's reference image of mitsuba-data's ``floating_sphere``
(directional light) is in test_mitsuba_xml_render.py (slow).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import bsdf as B
from jaxgfx.render.emitters import DirectionalLight, SpotLight
from jaxgfx.render.film import TentFilter, make_filter
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba import scene_to_desc, to_mitsuba_dict
from jaxgfx.render.scene.mitsuba_conventions import IOR_TABLE
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene
from tests.render.test_mitsuba_xml_write import assert_same

SENSOR = """<sensor type="perspective">
  <float name="fov" value="40"/>
  <transform name="to_world"><lookat origin="0, 3, 0.01" target="0, 0, 0" up="0, 1, 0"/>
  </transform>
  <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/>
    <rfilter type="box"/></film>
</sensor>"""

RHO = 0.6
# the ground: Mitsuba's rectangle [-1, 1]^2 (normal +z) turned to y-up and scaled to 8 x 8
PLANE = (
    '<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/>'
    '<scale value="4"/></transform><bsdf type="diffuse"><rgb name="reflectance" '
    f'value="{RHO}"/></bsdf></shape>'
)


def scene_xml(body, *, film=None):
    sensor = SENSOR if film is None else SENSOR.replace('<rfilter type="box"/>', film)
    return f'<scene version="3.0.0">\n{sensor}\n{body}\n</scene>\n'


def write(tmp_path, text, name="scene.xml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


# points on the plane y = 0 (x, z) and the diffuse radiance leaving them upwards


PTS = np.array([[0.0, 0.0], [0.3, 0.1], [0.55, -0.2], [0.8, 0.4], [1.4, 0.0]])


def _plane_radiance(scene, light):
    """``rho / pi * Li * cos`` at PTS as the integrator computes direct light from ``light``:
    its ``sample`` at the points and the plane material's ``eval`` (normal +y, seen from
    above). The local frame: z = the normal, so cos = wi_y."""
    p = jnp.asarray(np.stack([PTS[:, 0], np.zeros(len(PTS)), PTS[:, 1]], -1), jnp.float32)
    wi, dist, li = light.sample(p)
    wi = np.asarray(wi, np.float64)
    local = np.stack([wi[:, 0], wi[:, 2], wi[:, 1]], -1)  # (x, z, y): z along the normal +y
    (mat,) = [
        m for n, m in zip(scene.material_names, scene.materials, strict=True) if n != "__black__"
    ]
    f = mat.eval(jnp.asarray([0.0, 0.0, 1.0]), jnp.asarray(local, jnp.float32))
    return np.asarray(f) * np.asarray(li), np.asarray(dist)


# ------------------------------------------------------------------------------- directional


def test_directional_from_xml_lights_a_diffuse_plane_as_the_closed_form(tmp_path):
    body = (
        PLANE + '<emitter type="directional"><vector name="direction" value="1.2, -1.6, 0"/>'
        '<rgb name="irradiance" value="2, 1, 0.5"/></emitter>'
    )
    p = write(tmp_path, scene_xml(body))
    (e,) = read_xml(p).desc["emitters"]
    assert e == {
        "type": "directional",
        "direction": pytest.approx([0.6, -0.8, 0.0]),
        "irradiance": [2.0, 1.0, 0.5],
    }
    scene = load_scene(p)
    (light,) = scene.delta_lights
    assert isinstance(light, DirectionalLight)
    L, dist = _plane_radiance(scene, light)
    # rho / pi * E * cos(theta), cos = 0.8 for light travelling along (0.6, -0.8, 0)
    want = RHO / math.pi * 0.8 * np.array([2.0, 1.0, 0.5])
    np.testing.assert_allclose(L, np.broadcast_to(want, L.shape), rtol=1e-6)
    assert np.all(np.isinf(dist))


def test_directional_by_to_world_and_by_default(tmp_path):
    # Mitsuba: the light travels along to_world's +z (a lookat's viewing direction) ...
    body = (
        PLANE + '<emitter type="directional"><transform name="to_world"><lookat '
        'origin="0, 0, 0" target="0, -0.8, 0.6" up="1, 0, 0"/></transform></emitter>'
    )
    (e,) = read_xml(write(tmp_path, scene_xml(body))).desc["emitters"]
    np.testing.assert_allclose(e["direction"], [0.0, -0.8, 0.6], atol=1e-12)
    assert e["irradiance"] == [1.0] * 3  # Mitsuba's default irradiance
    # ... and along +z without direction or to_world
    body = PLANE + '<emitter type="directional"/>'
    (e,) = read_xml(write(tmp_path, scene_xml(body))).desc["emitters"]
    assert e["direction"] == [0.0, 0.0, 1.0]


# -------------------------------------------------------------------------------------- spot


def _falloff(theta_deg, cutoff, beam):
    """Mitsuba 3 ``SpotLight::falloff_curve`` as a function of the angle to the axis."""
    th = np.radians(theta_deg)
    c, b = np.radians(cutoff), np.radians(beam)
    f = np.where(np.cos(th) >= np.cos(b), 1.0, (c - th) / (c - b))
    return np.where(np.cos(th) > np.cos(c), f, 0.0)


def test_spot_from_xml_on_axis_intensity_and_falloff(tmp_path):
    # 2 m above the plane, pointing down; beam_width omitted: Mitsuba's 3/4 of the cutoff
    body = (
        PLANE + '<emitter type="spot" id="lamp"><transform name="to_world">'
        '<lookat origin="0, 2, 0" target="0, 0, 0" up="1, 0, 0"/></transform>'
        '<rgb name="intensity" value="1, 2, 3"/><float name="cutoff_angle" value="30"/>'
        "</emitter>"
    )
    p = write(tmp_path, scene_xml(body))
    (e,) = read_xml(p).desc["emitters"]
    assert e == {
        "type": "spot",
        "position": [0.0, 2.0, 0.0],
        "direction": pytest.approx([0.0, -1.0, 0.0], abs=1e-12),
        "intensity": [1.0, 2.0, 3.0],
        "cutoff_angle": 30.0,
        "beam_width": 22.5,
        "id": "lamp",  # the XML id names the light's parameters (emitters.lamp.*)
    }
    scene = load_scene(p)
    (light,) = scene.delta_lights
    assert isinstance(light, SpotLight)
    L, dist = _plane_radiance(scene, light)
    r2 = PTS[:, 0] ** 2 + PTS[:, 1] ** 2 + 4.0
    cos = 2.0 / np.sqrt(r2)
    fall = _falloff(np.degrees(np.arccos(cos)), 30.0, 22.5)
    # the points: on the axis, in the beam, in the ramp, outside the cone
    assert fall[0] == 1 and fall[1] == 1 and 0 < fall[3] < 1 and fall[-1] == 0
    want = RHO / math.pi * np.array([1.0, 2.0, 3.0]) * (fall * cos / r2)[:, None]
    np.testing.assert_allclose(L, want, rtol=2e-5, atol=1e-8)
    np.testing.assert_allclose(dist, np.sqrt(r2), rtol=1e-6)
    # on the axis: the intensity over the squared distance, times rho / pi
    np.testing.assert_allclose(L[0], RHO / math.pi * np.array([1.0, 2.0, 3.0]) / 4, rtol=1e-6)


def test_spot_defaults_and_a_rotated_uniformly_scaled_to_world(tmp_path):
    # no lookat: the light points along to_world's +z; a uniform scale keeps the cone round
    body = (
        PLANE + '<emitter type="spot"><transform name="to_world"><scale value="3"/>'
        '<rotate x="1" angle="90"/><translate y="1.5"/></transform></emitter>'
    )
    (e,) = read_xml(write(tmp_path, scene_xml(body))).desc["emitters"]
    np.testing.assert_allclose(e["direction"], [0.0, -1.0, 0.0], atol=1e-12)
    assert e["position"] == pytest.approx([0.0, 1.5, 0.0])
    # Mitsuba's defaults: intensity 1, cutoff 20 degrees, beam width 3/4 of it
    assert (e["intensity"], e["cutoff_angle"], e["beam_width"]) == ([1.0] * 3, 20.0, 15.0)


# ---------------------------------------------------------------------------- thindielectric


def test_thindielectric_from_xml(tmp_path):
    body = (
        '<shape type="sphere"><bsdf type="thindielectric" id="pane">'
        '<float name="int_ior" value="1.6"/><string name="ext_ior" value="water"/>'
        '<rgb name="specular_transmittance" value="0.9, 0.8, 0.7"/></bsdf></shape>'
        '<shape type="sphere"><point name="center" x="3"/>'
        '<bsdf type="thindielectric" id="default"/></shape>'
    )
    p = write(tmp_path, scene_xml(body))
    m = read_xml(p).desc["materials"]
    assert m["pane"] == {
        "type": "thindielectric",
        "eta": pytest.approx(1.6 / IOR_TABLE["water"]),
        "specular_reflectance": [1.0] * 3,
        "specular_transmittance": [0.9, 0.8, 0.7],
    }
    # Mitsuba's defaults: bk7 inside, air outside
    assert m["default"]["eta"] == pytest.approx(IOR_TABLE["bk7"] / IOR_TABLE["air"])
    scene = load_scene(p)
    pane = scene.materials[scene.material_names.index("pane")]
    assert isinstance(pane, B.ThinDielectric)
    # at normal incidence: R = ((eta - 1) / (eta + 1))^2 per interface, R' = 2R / (1 + R) with
    # every internal bounce (Mitsuba's r *= 2 / (1 + r)); transmission goes straight through
    eta = 1.6 / IOR_TABLE["water"]
    r = ((eta - 1) / (eta + 1)) ** 2
    rt = 2 * r / (1 + r)
    wo = jnp.asarray([0.0, 0.0, 1.0])
    refl = pane.sample(wo, jnp.asarray(rt * 0.5), jnp.asarray([0.5, 0.5]))
    np.testing.assert_allclose(refl.wi, [0, 0, 1], atol=1e-7)
    np.testing.assert_allclose(refl.pdf, rt, rtol=1e-5)
    np.testing.assert_allclose(refl.weight, [1.0] * 3, rtol=1e-6)
    tr = pane.sample(wo, jnp.asarray(0.5 + rt * 0.5), jnp.asarray([0.5, 0.5]))
    np.testing.assert_allclose(tr.wi, [0, 0, -1], atol=1e-7)
    np.testing.assert_allclose(tr.pdf, 1 - rt, rtol=1e-5)
    np.testing.assert_allclose(tr.weight, [0.9, 0.8, 0.7], rtol=1e-6)


# ---------------------------------------------------------------------------------- blendbsdf


MIX = (
    '<bsdf type="blendbsdf" id="mix"><float name="weight" value="0.3"/>'
    '<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.6"/>'
    '</bsdf></bsdf><bsdf type="roughconductor"><string name="distribution" value="ggx"/>'
    '<float name="alpha" value="0.2"/></bsdf></bsdf>'
)
BSDF0 = {"type": "diffuse", "reflectance": [0.2, 0.4, 0.6]}
BSDF1 = {
    "type": "roughconductor",
    "distribution": "ggx",
    "alpha": 0.2,
    "sample_visible": True,
    "reflectance": [1.0] * 3,
    "fresnel": "none",
}


def test_blendbsdf_from_xml_is_the_weighted_sum_of_its_bsdfs(tmp_path):
    p = write(tmp_path, scene_xml(MIX + '<shape type="sphere"><ref id="mix"/></shape>'))
    m = read_xml(p).desc["materials"]["mix"]
    # the first nested BSDF gets 1 - weight (twosided unwrapped: jaxgfx shades both sides)
    assert m == {"type": "blendbsdf", "weight": 0.3, "bsdf0": BSDF0, "bsdf1": BSDF1}
    scene = load_scene(p)
    mix = scene.materials[scene.material_names.index("mix")]
    assert isinstance(mix, B.BlendBSDF)
    f0, f1 = B.make_bsdf(dict(BSDF0)), B.make_bsdf(dict(BSDF1))
    k = jax.random.split(jax.random.key(0))
    wo = jax.random.normal(k[0], (16, 3)) * jnp.asarray([1, 1, 0]) + jnp.asarray([0, 0, 1.5])
    wi = jax.random.normal(k[1], (16, 3)) * jnp.asarray([1, 1, 0]) + jnp.asarray([0, 0, 1.2])
    wo, wi = (v / jnp.linalg.norm(v, axis=-1, keepdims=True) for v in (wo, wi))
    # one jitted program (eager dispatch of the three BSDFs' ops costs seconds here)
    f, pdf, e0, p0, e1, p1 = jax.jit(
        lambda m, a, b: (
            m.eval(wo, wi),
            m.pdf(wo, wi),
            a.eval(wo, wi),
            a.pdf(wo, wi),
            b.eval(wo, wi),
            b.pdf(wo, wi),
        )
    )(mix, f0, f1)
    assert np.all(np.asarray(e1).max(-1) > 0)  # the conductor's lobe is not 0 for these pairs
    np.testing.assert_allclose(f, 0.7 * np.asarray(e0) + 0.3 * np.asarray(e1), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(
        pdf, 0.7 * np.asarray(p0) + 0.3 * np.asarray(p1), rtol=1e-5, atol=1e-7
    )


def test_blendbsdf_named_children_are_ordered_by_name_and_weight_can_be_a_texture(tmp_path):
    # Mitsuba orders nested BSDFs by name: "a_metal" is bsdf_0 although it comes second
    body = (
        '<bsdf type="blendbsdf" id="mix"><texture type="checkerboard" name="weight"/>'
        '<bsdf type="diffuse" name="b_matte"/><bsdf type="conductor" name="a_metal"/></bsdf>'
        '<shape type="sphere"><ref id="mix"/></shape>'
    )
    p = write(tmp_path, scene_xml(body))
    m = read_xml(p).desc["materials"]["mix"]
    assert m["bsdf0"]["type"] == "conductor" and m["bsdf1"]["type"] == "diffuse"
    # Mitsuba's defaults 0.4 / 0.2, swapped: a scalar parameter reads its checkerboard through
    # eval_1, the other pattern (swap_scalar_checkerboard)
    assert m["weight"] == {"type": "checkerboard", "color0": [0.2] * 3, "color1": [0.4] * 3}
    from jaxgfx.render.bsdf.textured import Textured

    scene = load_scene(p)
    mix = scene.materials[scene.material_names.index("mix")]
    assert isinstance(mix, Textured) and isinstance(mix.bsdf, B.BlendBSDF)
    # as Mitsuba's eval_1: colour1 (0.2) at uv (0.75, 0.75), colour0 (0.4) at (0.25, 0.75)
    assert float(mix.at(jnp.asarray([0.75, 0.75])).weight) == pytest.approx(0.2)
    assert float(mix.at(jnp.asarray([0.25, 0.75])).weight) == pytest.approx(0.4)


# ------------------------------------------------------------------------------ round trips


ALL = (
    PLANE
    + MIX
    + '<shape type="sphere"><point name="center" y="1"/><ref id="mix"/></shape>'
    + '<shape type="sphere"><point name="center" x="2"/><bsdf type="thindielectric" '
    'id="pane"><float name="int_ior" value="1.45"/><rgb name="specular_reflectance" '
    'value="0.5, 0.6, 0.7"/></bsdf></shape>'
    + '<emitter type="directional"><vector name="direction" value="0.6, -0.8, 0"/>'
    '<rgb name="irradiance" value="2, 1, 0.5"/></emitter>'
    + '<emitter type="spot"><transform name="to_world"><lookat origin="0.5, 2, 0.2" '
    'target="0, 0, 0" up="0, 1, 0"/></transform><rgb name="intensity" value="1, 2, 3"/>'
    '<float name="cutoff_angle" value="35"/><float name="beam_width" value="12"/></emitter>'
)


def test_save_scene_round_trips_the_four_plugins(tmp_path):
    first = read_xml(
        write(
            tmp_path,
            scene_xml(
                ALL, film='<rfilter type="tent"><float name="radius" value="1.5"/></rfilter>'
            ),
        )
    )
    out = save_scene(first.desc, str(tmp_path / "out" / "again.xml"))
    text = Path(out).read_text()
    assert '<bsdf type="blendbsdf" id="mix">' in text and '<bsdf type="thindielectric"' in text
    assert '<vector name="direction" value="0.6, -0.8, 0.0"/>' in text  # Mitsuba's <vector>
    assert '<emitter type="spot"' in text and '<rfilter type="tent">' in text
    second = read_xml(out)
    assert_same(first.desc, second.desc)
    assert second.desc["film"] == {"filter": "tent", "radius": 1.5}
    # a built Scene saves the same parameters (scene_to_desc reads the objects)
    scene = load_scene(first.desc)
    third = read_xml(save_scene(scene, str(tmp_path / "built.xml"))).desc
    s3 = load_scene(third)
    assert s3.material_names == scene.material_names
    for a, b in ((scene.materials, s3.materials), (scene.delta_lights, s3.delta_lights)):
        la, lb = jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)
        assert len(la) == len(lb)
        for x, y in zip(la, lb, strict=True):
            np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-6, atol=1e-7)
    assert isinstance(s3.rfilter, TentFilter) and s3.rfilter.radius == 1.5


def test_to_mitsuba_dict_writes_spot_directional_and_the_tent(tmp_path):
    desc = {
        "camera": {"origin": [0, 3, 1], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4},
        "film": {"filter": "tent"},
        "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1.0}],
        "emitters": [
            {"type": "directional", "direction": [0, 0, -2], "irradiance": 3.0},
            {"type": "spot", "position": [1, 2, 3], "direction": [0, -3, 4], "intensity": 5.0},
        ],
    }
    d = to_mitsuba_dict(desc, work_dir=str(tmp_path))
    assert d["sensor"]["film"]["rfilter"] == {"type": "tent", "radius": 1.0}
    assert d["sensor"]["film"]["sample_border"] is True
    assert d["emitter_0"] == {
        "type": "directional",
        "direction": [0.0, 0.0, -1.0],
        "irradiance": {"type": "rgb", "value": [3.0] * 3},
    }
    s = d["emitter_1"]
    m = np.asarray(s["to_world"])
    # Mitsuba's spot sits at to_world's origin and points along its +z (rigid: round cone)
    np.testing.assert_allclose(m[:3, 3], [1, 2, 3])
    np.testing.assert_allclose(m[:3, 2], [0, -0.6, 0.8], atol=1e-12)
    np.testing.assert_allclose(m[:3, :3].T @ m[:3, :3], np.eye(3), atol=1e-12)
    assert (s["cutoff_angle"], s["beam_width"]) == (20.0, 15.0)  # jaxgfx's = Mitsuba's defaults
    # a Scene's delta lights are kept by scene_to_desc
    back = scene_to_desc(load_scene(desc))["emitters"]
    assert [e["type"] for e in back] == ["directional", "spot"]


# ---------------------------------------------------------------------------------- errors


def rx(s):
    return re.escape(s)


@pytest.mark.parametrize(
    "body,msg",
    [
        (
            '<emitter type="spot" id="s">\n<rgb name="texture" value="1"/></emitter>',
            "<emitter type='spot' id='s'>: parameter 'texture': expected a bitmap texture "
            "(Mitsuba refuses a constant one)",
        ),
        (
            '<emitter type="spot" id="s">\n<transform name="to_world"><scale x="2"/>'
            "</transform></emitter>",
            "<emitter type='spot' id='s'>: parameter 'to_world': a spot light's to_world must be "
            "a rotation, uniform scale and translation",
        ),
        (
            '<emitter type="spot" id="s">\n<float name="beam_width" value="25"/></emitter>',
            "<emitter type='spot' id='s'>: parameter 'beam_width': expected degrees in "
            "[0, cutoff_angle], got 25.0",
        ),
        (
            '<emitter type="spot" id="s">\n<rgb name="radiance" value="1"/></emitter>',
            "<emitter type='spot' id='s'>: parameter 'radiance' is not supported",
        ),
        (
            '<emitter type="directional" id="d">\n<vector name="direction" value="0, 0, 1"/>'
            '<transform name="to_world"><rotate x="1" angle="10"/></transform></emitter>',
            "<emitter type='directional' id='d'>: parameter 'direction': give either direction "
            "or to_world",
        ),
        (
            '<emitter type="directional" id="d">\n<transform name="to_world"><scale value="2"/>'
            "</transform></emitter>",
            "<emitter type='directional' id='d'>: parameter 'to_world': a to_world that scales "
            "the light's +z axis is not supported",
        ),
        (
            '<bsdf type="thindielectric" id="t">\n<float name="alpha" value="0.1"/></bsdf>',
            "<bsdf type='thindielectric' id='t'>: parameter 'alpha' is not supported",
        ),
        (
            '<bsdf type="blendbsdf" id="b"><bsdf type="diffuse" id="inner">\n'
            '<texture type="checkerboard" name="reflectance"/></bsdf><bsdf type="diffuse"/></bsdf>',
            "<bsdf type='diffuse' id='inner'>: parameter 'reflectance': textures are not supported"
            " in a BSDF nested in a blendbsdf",
        ),
        (
            '\n<bsdf type="blendbsdf" id="b"><bsdf type="diffuse"/></bsdf>',
            "<bsdf type='blendbsdf' id='b'>: expected exactly two nested <bsdf>, got 1",
        ),
        (
            '<bsdf type="blendbsdf" id="b"><bsdf type="diffuse"/>\n<bsdf type="diffuse" '
            'name="x"/></bsdf>',
            "<bsdf type='blendbsdf' id='b'>: parameter 'x': give both nested BSDFs a name or "
            "neither",
        ),
    ],
)
def test_each_unsupported_parameter_names_itself_the_object_file_and_line(tmp_path, body, msg):
    p = write(tmp_path, scene_xml(PLANE + body))
    with pytest.raises(ValueError) as e:
        read_xml(p)
    # the parameter's line (the second line of the snippet: line 10 of the file)
    assert f"{p}:10: " in str(e.value) and msg in str(e.value), str(e.value)


def test_a_texture_weight_in_a_nested_blend_is_refused(tmp_path):
    body = (
        '<bsdf type="blendbsdf" id="outer"><bsdf type="blendbsdf" id="inner">\n'
        '<texture type="checkerboard" name="weight"/><bsdf type="diffuse"/>'
        '<bsdf type="diffuse"/></bsdf><bsdf type="diffuse"/></bsdf>'
    )
    p = write(tmp_path, scene_xml(PLANE + body))
    with pytest.raises(
        ValueError,
        match=rx(f"{p}:10: ")
        + ".*"
        + rx(
            "<bsdf type='blendbsdf' id='inner'>: parameter 'weight': a texture weight is "
            "supported for a top-level blendbsdf only"
        ),
    ):
        read_xml(p)


# --------------------------------------------------------------------------------------- tent


def _tent_cdf(x, r):
    """CDF of the normalised 1-D tent ``max(0, 1 - |x| / r) / r`` (Mitsuba's ``tent``)."""
    t = np.clip(x / r, -1, 1)
    return np.where(t < 0, 0.5 * (1 + t) ** 2, 1 - 0.5 * (1 - t) ** 2)


@pytest.mark.parametrize("radius", [1.0, 1.5])
def test_tent_filter_samples_the_closed_form_tent(radius):
    f = make_filter("tent", radius=radius)
    assert isinstance(f, TentFilter)
    # the inverse CDF: F(sample(u)) = u on a grid (exact), samples within the radius
    u = (np.arange(1001) + 0.5) / 1001
    x = np.asarray(f.sample(jnp.asarray(np.stack([u, u[::-1]], -1), jnp.float32)), np.float64)
    assert np.all(np.abs(x) <= radius)
    np.testing.assert_allclose(_tent_cdf(x[:, 0], radius), u, atol=2e-6)
    np.testing.assert_allclose(_tent_cdf(x[:, 1], radius), u[::-1], atol=2e-6)
    # the weights: a histogram of random offsets against the tent's bin integrals
    y = np.asarray(f.sample(jax.random.uniform(jax.random.key(3), (100_000, 2))))
    edges = np.linspace(-radius, radius, 9)
    p = np.diff(_tent_cdf(edges, radius))
    for k in range(2):
        n = np.histogram(y[:, k], edges)[0]
        # 5 binomial standard errors per bin
        assert np.all(np.abs(n - y.shape[0] * p) < 5 * np.sqrt(y.shape[0] * p * (1 - p))), n


def test_tent_rfilter_from_xml_defaults_to_mitsubas_radius(tmp_path):
    p = write(tmp_path, scene_xml(PLANE, film='<rfilter type="tent"/>'))
    assert read_xml(p).desc["film"] == {"filter": "tent", "radius": 1.0}
    assert load_scene(p).rfilter == TentFilter(1.0)
    bad = write(
        tmp_path,
        scene_xml(PLANE, film='<rfilter type="tent">\n<float name="stddev" value="1"/></rfilter>'),
        "b.xml",
    )
    with pytest.raises(
        ValueError, match=rx("<rfilter type='tent'>: parameter 'stddev' is not supported")
    ):
        read_xml(bad)
