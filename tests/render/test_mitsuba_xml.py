"""Mitsuba 3 XML -> jaxgfx description translation (jaxgfx/render/scene/mitsuba_xml.py).

Fast unit tests: no rendering. References: closed-form matrices built here with NumPy, values
Mitsuba 3.9.1 reports for the same XML (recorded numbers; ``test_mitsuba_xml_vs_mitsuba.py``
recomputes them live with the ``mitsuba`` marker), and the exact error messages.
"""

from __future__ import annotations

import math
import os
import re

import numpy as np
import pytest

from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba_xml import (
    IOR_TABLE,
    envmap_from_mitsuba,
    read_xml,
    spectrum_to_rgb,
)

SENSOR = """<sensor type="perspective">
  <float name="fov" value="40"/>
  <transform name="to_world"><lookat origin="0, 0, -5" target="0, 0, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/>
    <rfilter type="box"/></film>
  <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
</sensor>"""


def scene_xml(body, *, spp_default="4", sensor=SENSOR):
    return (
        f'<scene version="3.0.0">\n<default name="spp" value="{spp_default}"/>\n{sensor}\n'
        f"{body}\n</scene>\n"
    )


def write(tmp_path, text, name="scene.xml"):
    p = tmp_path / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(text)
    return str(p)


def rx(s):
    return re.escape(s)


SPHERE = '<shape type="sphere"><float name="radius" value="0.5"/></shape>'


# ---------------------------------------------------------------------------- transforms


def rot_x(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])


def rot_y(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0, s, 0], [0, 1, 0, 0], [-s, 0, c, 0], [0, 0, 0, 1.0]])


def rot_z(deg):
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])


def trans(x, y, z):
    m = np.eye(4)
    m[:3, 3] = x, y, z
    return m


def mesh_to_world(tmp_path, ops):
    """The to_world matrix the translator gives a cube under ``ops`` (transform body)."""
    x = read_xml(
        write(
            tmp_path,
            scene_xml(f'<shape type="cube"><transform name="to_world">{ops}</transform></shape>'),
        )  # fmt: skip
    )
    return np.asarray(x.desc["shapes"][0]["to_world"])


def test_transform_elements_compose_like_numpy(tmp_path):
    ops = (
        '<scale x="2" y="3"/><rotate x="1" angle="30"/><rotate y="1" angle="-45"/>'
        '<rotate z="1" angle="60"/><translate x="1" y="-2" z="0.5"/>'
    )
    want = trans(1, -2, 0.5) @ rot_z(60) @ rot_y(-45) @ rot_x(30) @ np.diag([2, 3, 1, 1.0])
    np.testing.assert_allclose(mesh_to_world(tmp_path, ops), want, atol=1e-12)


def test_rotate_about_an_arbitrary_axis_and_matrix_and_scale_value(tmp_path):
    # rotation by 120 degrees about (1, 1, 1) permutes the axes: x -> y -> z -> x
    perm = np.array([[0, 0, 1, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1.0]])
    got = mesh_to_world(tmp_path, '<rotate value="0.57735, 0.57735, 0.57735" angle="120"/>')
    np.testing.assert_allclose(got, perm, atol=2e-5)
    mat = "1 2 0 4  0 1 0 5  0 0 3 6  0 0 0 1"
    got = mesh_to_world(tmp_path, f'<scale value="2"/><matrix value="{mat}"/>')
    want = np.array([[1, 2, 0, 4], [0, 1, 0, 5], [0, 0, 3, 6], [0, 0, 0, 1.0]]) @ np.diag(
        [2, 2, 2, 1.0]
    )
    np.testing.assert_allclose(got, want, atol=1e-12)
    got = mesh_to_world(tmp_path, '<translate value="1 2 3"/><scale value="1, 2, 4"/>')
    np.testing.assert_allclose(got, np.diag([1, 2, 4, 1.0]) @ trans(1, 2, 3), atol=1e-12)


def test_a_rotate_axis_of_another_length_is_refused_as_mitsuba_would_not_rotate(tmp_path):
    # Mitsuba 3.9.1 does not normalise the axis: rotate((1, 1, 1), 120) is a matrix with entries
    # 2.37 and 0.63 there (mi.ScalarTransform4f().rotate), not the axis permutation; an axis
    # within 1e-3 of unit length is normalised (above), a longer one is refused with its line
    p = write(
        tmp_path,
        scene_xml(
            '<shape type="cube"><transform name="to_world">'
            '<rotate value="1, 1, 1" angle="120"/></transform></shape>'
        ),
    )
    msg = r"scene\.xml:\d+: .*axis \(1\.0, 1\.0, 1\.0\) has length 1\.73205, not 1: Mitsuba 3 does"
    with pytest.raises(ValueError, match=msg):
        read_xml(p)
    ok = write(tmp_path, scene_xml('<shape type="cube"><transform name="to_world">'
                                   '<rotate x="1.0009" angle="30"/></transform></shape>'), "b.xml")
    np.testing.assert_allclose(read_xml(ok).desc["shapes"][0]["to_world"], rot_x(30), atol=1e-12)


def test_lookat_sensor_becomes_the_jaxgfx_camera(tmp_path):
    sensor = SENSOR.replace("0, 0, -5", "1, 2, 3").replace("0, 1, 0", "0, 0, 1")
    x = read_xml(write(tmp_path, scene_xml(SPHERE, sensor=sensor)))
    cam = x.desc["camera"]
    np.testing.assert_allclose(cam["origin"], [1, 2, 3])
    d = -np.array([1, 2, 3.0]) / math.sqrt(14)
    np.testing.assert_allclose(np.subtract(cam["target"], cam["origin"]), d, atol=1e-12)
    # up is re-orthogonalised (Mitsuba's look_at): z minus its component along d
    up = np.array([0, 0, 1.0]) - d[2] * d
    np.testing.assert_allclose(cam["up"], up / np.linalg.norm(up), atol=1e-12)
    assert (cam["fov"], cam["fov_axis"], cam["width"], cam["height"]) == (40.0, "x", 8, 6)
    assert x.desc["film"] == {"filter": "box"}


# ---------------------------------------------------------------------------- sensor


@pytest.mark.parametrize(
    "axis,want",
    [
        ("x", (50.0, "x")),
        ("y", (50.0, "y")),
        ("smaller", (50.0, "y")),  # 8x6: the smaller side is y
        ("larger", (50.0, "x")),
        # diagonal: tan(fx/2) = tan(50/2) * 8 / 10
        ("diagonal", (2 * math.degrees(math.atan(math.tan(math.radians(25)) * 0.8)), "x")),
    ],
)
def test_fov_axis(tmp_path, axis, want):
    sensor = SENSOR.replace(
        '<float name="fov" value="40"/>',
        f'<float name="fov" value="50"/><string name="fov_axis" value="{axis}"/>',
    )
    cam = read_xml(write(tmp_path, scene_xml(SPHERE, sensor=sensor))).desc["camera"]
    assert cam["fov"] == pytest.approx(want[0], abs=1e-10)
    assert cam["fov_axis"] == want[1]


def test_focal_length_default_matches_mitsuba(tmp_path):
    # Mitsuba 3.9.1 reports x_fov 38.18484 (default 50mm) and 52.62254 (35mm) for a 64x48 film
    sensor = SENSOR.replace('<float name="fov" value="40"/>', "").replace(
        '"width" value="8"/><integer name="height" value="6"', '"width" value="64"/><integer '
        'name="height" value="48"'
    )  # fmt: skip
    cam = read_xml(write(tmp_path, scene_xml(SPHERE, sensor=sensor))).desc["camera"]
    assert cam["fov"] == pytest.approx(38.18484, abs=1e-4) and cam["fov_axis"] == "x"
    s35 = sensor.replace("<transform", '<string name="focal_length" value="35mm"/><transform')
    cam = read_xml(write(tmp_path, scene_xml(SPHERE, sensor=s35))).desc["camera"]
    assert cam["fov"] == pytest.approx(52.62254, abs=1e-4)


def test_default_rfilter_is_mitsubas_gaussian(tmp_path):
    sensor = SENSOR.replace('<rfilter type="box"/>', "")
    x = read_xml(write(tmp_path, scene_xml(SPHERE, sensor=sensor)))
    assert x.desc["film"] == {"filter": "gaussian", "stddev": 0.5, "radius": 2.0}


def test_near_clip_that_would_clip_geometry_is_refused(tmp_path):
    sensor = SENSOR.replace("<transform", '<float name="near_clip" value="4.8"/><transform')
    p = write(tmp_path, scene_xml(SPHERE, sensor=sensor))
    msg = f"{p}:3: <sensor type='perspective'>: near_clip=4.8: {p}:10: <shape type='sphere'> comes"
    with pytest.raises(ValueError, match=rx(msg + " closer than")):
        read_xml(p)
    # far away enough: accepted (sphere at distance 4.5, frustum-corner factor ~1.07)
    ok = SENSOR.replace("<transform", '<float name="near_clip" value="4"/><transform')
    read_xml(write(tmp_path, scene_xml(SPHERE, sensor=ok)))
    far = SENSOR.replace("<transform", '<float name="far_clip" value="5"/><transform')
    with pytest.raises(ValueError, match=r"far_clip=5.0: .*reaches beyond it"):
        read_xml(write(tmp_path, scene_xml(SPHERE, sensor=far)))


# ---------------------------------------------------------------------------- parameters


def test_defaults_substitution_and_keyword_override(tmp_path):
    body = SPHERE.replace('value="0.5"', 'value="$r"')
    p = write(tmp_path, scene_xml('<default name="r" value="0.25"/>' + body))
    x = read_xml(p)
    assert x.spp == 4 and x.desc["shapes"][0]["radius"] == 0.25
    x = read_xml(p, spp=32, r=0.75)
    assert x.spp == 32 and x.desc["shapes"][0]["radius"] == 0.75
    with pytest.raises(ValueError, match=rx(f"{p}: parameter(s) ['typo'] are neither declared")):
        read_xml(p, typo=1)
    q = write(tmp_path, scene_xml(SPHERE.replace('value="0.5"', 'value="$nope"')), "q.xml")
    with pytest.raises(ValueError, match=rx(f"{q}:10: <float> attribute value='$nope': undefined "
                                            "parameter $nope")):  # fmt: skip
        read_xml(q)


def test_include_path_and_refs(tmp_path):
    (tmp_path / "lib" / "meshes").mkdir(parents=True)
    (tmp_path / "lib" / "meshes" / "tri.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0.25\nvt 1 0.25\nvt 0 1\nf 1/1 2/2 3/3\n"
    )
    write(
        tmp_path,
        '<scene version="3.0.0"><bsdf type="diffuse" id="red"><rgb name="reflectance" '
        'value="0.8, 0.1, 0.1"/></bsdf></scene>',
        "frag/materials.xml",
    )
    body = (
        '<path value="lib"/><include filename="frag/materials.xml"/>'
        '<shape type="obj"><string name="filename" value="meshes/tri.obj"/><ref id="red"/>'
        "</shape>" + SPHERE.replace("</shape>", '<ref id="red"/></shape>')
    )
    x = read_xml(write(tmp_path, scene_xml(body)))
    assert x.files == (str(tmp_path / "scene.xml"), str(tmp_path / "frag" / "materials.xml"))
    mesh, sphere = x.desc["shapes"]
    assert mesh["material"] == sphere["material"] == "red"
    # Mitsuba's diffuse outside twosided: black from behind (one_sided)
    red = {"type": "diffuse", "reflectance": [0.8, 0.1, 0.1], "one_sided": True}
    assert x.desc["materials"] == {"red": red}
    # OBJ texture coordinates are flipped (Mitsuba's flip_tex_coords), normals smooth
    np.testing.assert_allclose(mesh["uvs"], [[0, 0.75], [1, 0.75], [0, 0]])
    np.testing.assert_allclose(mesh["normals"], [[0, 0, 1]] * 3)


def test_values_rgb_spectrum_float(tmp_path):
    body = (
        '<shape type="sphere"><bsdf type="roughplastic"><spectrum name="diffuse_reflectance" '
        'value="0.3"/><rgb name="specular_reflectance" value="0.9"/><float name="alpha" '
        'value="0.2"/><string name="int_ior" value="bk7"/><float name="ext_ior" value="1.25"/>'
        "</bsdf></shape>"
    )
    m = read_xml(write(tmp_path, scene_xml(body))).desc["materials"]["bsdf_0"]
    assert m == {
        "type": "roughplastic",
        "distribution": "beckmann",  # Mitsuba's default
        "alpha": 0.2,
        "sample_visible": True,
        "eta": 1.5046 / 1.25,
        "diffuse_reflectance": [0.3] * 3,
        "specular_reflectance": [0.9] * 3,
        "nonlinear": False,
        "one_sided": True,  # not in twosided
    }


@pytest.mark.parametrize(
    "spec,emission,mitsuba",
    [  # values Mitsuba 3.9.1 (scalar_rgb) gives the same <spectrum> on an area light / BSDF
        ("400:0, 500:8, 600:15.6, 700:18.4", True, [20.7108, 10.8546, 2.77115]),
        ("400:1, 700:1", True, [1.19969, 0.94952, 0.903443]),
        ("400:0.78, 500:0.78, 600:0.78, 700:0.78", False, [0.776367, 0.77981, 0.776029]),
    ],
)
def test_wavelength_spectra_to_rgb_match_mitsuba(spec, emission, mitsuba):
    pairs = [p.split(":") for p in spec.split(", ")]
    rgb = spectrum_to_rgb([float(a) for a, _ in pairs], [float(b) for _, b in pairs],
                          emission=emission)  # fmt: skip
    np.testing.assert_allclose(rgb, mitsuba, rtol=2e-3)


def test_named_iors_and_their_eta(tmp_path):
    body = (
        '<shape type="sphere"><bsdf type="dielectric"><string name="int_ior" value="diamond"/>'
        '<string name="ext_ior" value="water"/></bsdf></shape>'
    )
    m = read_xml(write(tmp_path, scene_xml(body))).desc["materials"]["bsdf_0"]
    assert m["eta"] == pytest.approx(2.419 / 1.3330)
    assert IOR_TABLE["bk7"] == 1.5046 and IOR_TABLE["air"] == 1.000277


# ---------------------------------------------------------------------------- BSDFs, emitters


def test_bsdf_mappings(tmp_path):
    body = "".join(
        f'<shape type="sphere"><point name="center" x="{i}" y="0" z="0"/>'
        f'<float name="radius" value="0.1"/>{b}</shape>'
        for i, b in enumerate(
            [
                '<bsdf type="twosided"><bsdf type="diffuse"/></bsdf>',
                '<bsdf type="conductor"/>',
                '<bsdf type="conductor"><spectrum name="eta" value="0.2"/>'
                '<rgb name="k" value="3, 2, 1"/></bsdf>',
                '<bsdf type="roughconductor"><string name="distribution" value="ggx"/>'
                '<float name="alpha_u" value="0.3"/><float name="alpha_v" value="0.3"/></bsdf>',
                '<bsdf type="diffuse"><texture type="checkerboard" name="reflectance">'
                '<transform name="to_uv"><scale x="5" y="5"/></transform></texture></bsdf>',
            ]
        )
    )
    mats = read_xml(write(tmp_path, scene_xml(body))).desc["materials"]
    # only the first is in twosided: the others are Mitsuba's one-sided plugins
    assert list(mats.values()) == [
        {"type": "diffuse", "reflectance": [0.5] * 3},
        {"type": "conductor", "reflectance": [1.0] * 3, "fresnel": "none", "one_sided": True},
        {
            "type": "conductor",
            "reflectance": [1.0] * 3,
            "fresnel": "conductor",
            "eta": [0.2] * 3,
            "k": [3.0, 2.0, 1.0],
            "one_sided": True,
        },  # fmt: skip
        {
            "type": "roughconductor",
            "distribution": "ggx",
            "alpha": 0.3,
            "sample_visible": True,
            "reflectance": [1.0] * 3,
            "fresnel": "none",
            "one_sided": True,
        },  # fmt: skip
        {
            "type": "diffuse",
            "reflectance": {
                "type": "checkerboard",
                "color0": [0.4] * 3,
                "color1": [0.2] * 3,
                "scale": 5.0,
            },
            "one_sided": True,
        },  # fmt: skip
    ]


def test_emitters_and_integrator(tmp_path):
    body = (
        '<integrator type="moment"><integrator type="path"><integer name="max_depth" '
        'value="4"/></integrator></integrator>'
        '<emitter type="point"><transform name="to_world"><translate z="10"/></transform>'
        '<rgb name="intensity" value="100"/></emitter>'
        '<emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>'
        '<shape type="rectangle"><emitter type="area"><rgb name="radiance" value="2"/></emitter>'
        "</shape>"
    )
    x = read_xml(write(tmp_path, scene_xml(body)))
    assert (x.integrator, x.max_depth, x.rr_depth) == ("path", 4, 5)
    pt, const, area = x.desc["emitters"]
    assert pt == {"type": "point", "position": [0.0, 0.0, 10.0], "intensity": [100.0] * 3}
    assert const == {"type": "constant", "radiance": [0.5] * 3}
    # an emitter shape without a BSDF gets Mitsuba's default for emitters, a black diffuse
    # (mi.traverse of such a rectangle: bsdf.reflectance.value 0.0; 0.5 without the emitter)
    assert area["material"] == "mitsuba_default_emitter" and area["radiance"] == [2.0] * 3
    assert x.desc["materials"]["mitsuba_default_emitter"]["reflectance"] == [0.0] * 3
    assert area["shape"] == {"type": "rectangle", "center": [0.0, 0.0, 0.0],
                             "edge_u": [2.0, 0.0, 0.0], "edge_v": [0.0, 2.0, 0.0]}  # fmt: skip
    x = read_xml(write(tmp_path, scene_xml(SPHERE + '<integrator type="path"/>')))
    assert (x.integrator, x.max_depth) == ("path", None)  # Mitsuba's -1: unbounded
    x = read_xml(write(tmp_path, scene_xml(SPHERE + '<integrator type="direct"/>')))
    assert (x.integrator, x.max_depth) == ("direct", 2)


def test_envmap_resampling_follows_mitsubas_rows():
    img = np.zeros((3, 4, 3))
    img[:, :, 0] = np.array([0.0, 1.0, 4.0])[:, None]  # rows at v = 0, 1/2, 1
    out = envmap_from_mitsuba(img, factor=2)  # 6 rows at v = (i + 1/2) / 6
    v = (np.arange(6) + 0.5) / 6
    want = np.interp(v, [0, 0.5, 1], [0.0, 1.0, 4.0])
    np.testing.assert_allclose(out[:, 0, 0], want, rtol=1e-6)
    assert out.shape == (6, 4, 3)


# ---------------------------------------------------------------------------- shapes + schema


def test_sheared_rectangle_and_rotated_mesh_load_as_matrices(tmp_path):
    ops = '<matrix value="1 0.5 0 1  0 2 0 2  0 0 1 3  0 0 0 1"/>'
    body = (
        f'<shape type="rectangle"><transform name="to_world">{ops}</transform></shape>'
        f'<shape type="cube"><transform name="to_world"><rotate z="1" angle="90"/>'
        '<scale value="2"/></transform></shape>'
    )
    p = write(tmp_path, scene_xml(body))
    x = read_xml(p)
    rect = x.desc["shapes"][0]
    assert rect["edge_u"] == [2.0, 0.0, 0.0] and rect["edge_v"] == [1.0, 4.0, 0.0]
    scene = load_scene(p)
    r = scene.shapes[0]
    np.testing.assert_allclose(np.asarray(r.centers)[0], [1, 2, 3])
    np.testing.assert_allclose(np.asarray(r.edge_v)[0], [1, 4, 0])
    mesh = scene.shapes[1]
    v = np.asarray(mesh.vertices)
    m = 2 * rot_z(90)[:3, :3]
    from jaxgfx.render.scene.mitsuba_xml import _cube

    cv = _cube()[0]
    np.testing.assert_allclose(v, cv @ m.T, atol=1e-6)
    assert v.min() == pytest.approx(-2) and v.max() == pytest.approx(2)


def test_schema_mesh_to_world_transforms_vertices_and_normals():
    from jaxgfx.render.scene.schema import mesh_from_desc

    mat = np.diag([2.0, 1.0, 1.0, 1.0])
    mat[:3, 3] = [0, 0, 1]
    d = {"vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "faces": [[0, 1, 2]],
         "normals": [[1, 0, 1]] * 3, "to_world": mat.tolist()}  # fmt: skip
    m = mesh_from_desc(d, "shapes[0]", None)
    np.testing.assert_allclose(np.asarray(m.vertices), [[0, 0, 1], [2, 0, 1], [0, 1, 1]])
    # inverse transpose: (1, 0, 1) -> (1/2, 0, 1), normalised
    n = np.array([0.5, 0, 1]) / np.linalg.norm([0.5, 0, 1])
    np.testing.assert_allclose(np.asarray(m.normals), [n] * 3, rtol=1e-6)
    with pytest.raises(ValueError, match=rx("shapes[0].to_world: expected a 4x4 affine")):
        mesh_from_desc({**d, "to_world": np.ones((4, 4)).tolist()}, "shapes[0]", None)


def test_disk_is_a_fan_of_256_triangles(tmp_path):
    x = read_xml(write(tmp_path, scene_xml('<shape type="disk"/>')))
    s = x.desc["shapes"][0]
    v, f = np.asarray(s["vertices"]), np.asarray(s["faces"])
    assert f.shape == (256, 3)
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum()
    assert area == pytest.approx(256 / 2 * math.sin(2 * math.pi / 256), rel=1e-12)
    assert area / math.pi == pytest.approx(1, abs=1.1e-4)  # the tessellation's area error
    assert np.all(np.cross(e1, e2)[:, 2] > 0)  # counter-clockwise: normal +z like Mitsuba's


# ---------------------------------------------------------------------------- errors


@pytest.mark.parametrize(
    "body,line,msg",
    [
        (
            '<shape type="sdfgrid"/>',
            10,
            "<shape type='sdfgrid'>: missing parameter 'filename'",
        ),  # fmt: skip
        (
            '<bsdf type="measured_polarized" id="p"/>',
            10,
            "<bsdf type='measured_polarized' id='p'>: bsdf plugin 'measured_polarized' is not "
            "supported (unknown plugin; supported: diffuse,",
        ),  # fmt: skip
        (
            '<emitter type="sunsky"><float name="turbidity" value="12"/></emitter>',
            10,
            "<emitter type='sunsky'>: parameter 'turbidity': expected a number in [1.0, 10.0]",
        ),  # fmt: skip
        (
            '<shape type="sphere" id="s">\n<float name="foo" value="1"/></shape>',
            11,
            "<shape type='sphere' id='s'>: parameter 'foo' is not supported",
        ),  # fmt: skip
        (
            '<shape type="sphere" colour="red"/>',
            10,
            "<shape>: unsupported attribute(s) ['colour']",
        ),  # fmt: skip
        ('<medium type="homogeneous"/>', 10, "<medium>: not supported"),
        ('<shape type="sphere"><ref id="nope"/></shape>', 10, "<ref id='nope'>: unknown id"),
        (
            '<shape type="obj"><string name="filename" value="no.obj"/></shape>',
            10,
            "<shape type='obj'> filename 'no.obj': no such file",
        ),  # fmt: skip
        (
            '<shape type="sphere"><bsdf type="roughdielectric"><float name="alpha_u" value="0.1"/>'
            '<float name="alpha_v" value="0.2"/></bsdf></shape>',
            10,
            "parameter 'alpha_u': anisotropic roughness is not supported",
        ),  # fmt: skip
        (
            '<shape type="sphere"><bsdf type="conductor"><string name="material" value="Xx"/>'
            "</bsdf></shape>",
            10,
            "parameter 'material': unknown conductor 'Xx'; expected 'none' or one of ['Ag', ",
        ),
        (
            '<shape type="sphere"><transform name="to_world"><scale x="2"/></transform></shape>',
            10,
            "parameter 'to_world': a sphere's to_world must be a rotation",
        ),  # fmt: skip
        (
            '<integrator type="volpath"/>',
            10,
            "<integrator type='volpath'>: integrator plugin 'volpath' is not supported",
        ),  # fmt: skip
        (
            '<shape type="sphere"><float name="radius" value="abc"/></shape>',
            10,
            "<float name='radius'>: expected numbers, got 'abc'",
        ),  # fmt: skip
    ],
)
def test_each_unsupported_thing_names_itself_file_and_line(tmp_path, body, line, msg):
    p = write(tmp_path, scene_xml(body))
    with pytest.raises(ValueError) as e:
        read_xml(p)
    assert f"{p}:{line}: " in str(e.value) and msg in str(e.value), str(e.value)
    with pytest.raises(ValueError, match=rx(msg)):  # load_scene raises the same error
        load_scene(p)


def test_xml_syntax_error_and_include_cycle(tmp_path):
    p = write(tmp_path, '<scene version="3.0.0">\n<shape type="sphere">\n</scene>\n')
    with pytest.raises(ValueError, match=rx(f"{p}:3: XML syntax error: mismatched tag")):
        read_xml(p)
    q = write(tmp_path, '<scene version="3.0.0">\n<include filename="scene.xml"/></scene>')
    with pytest.raises(ValueError, match=rx(f"{q}:2: <include filename='scene.xml'>: include "
                                            "cycle")):  # fmt: skip
        read_xml(q)
    old = write(tmp_path, '<scene version="0.5.0"></scene>', "old.xml")
    with pytest.raises(ValueError, match=rx(f"{old}:1: <scene version='0.5.0'>: Mitsuba 0.x")):
        read_xml(old)


def test_load_scene_dispatches_on_xml_and_checks_parameters(tmp_path):
    p = write(tmp_path, scene_xml(SPHERE))
    scene = load_scene(p, spp=8)
    assert scene.camera.width == 8 and scene.camera.height == 6
    with pytest.raises(TypeError, match=rx("load_scene: parameters ['spp'] are for .xml")):
        load_scene(os.path.join(os.path.dirname(p), "x.yaml"), spp=8)


# ---------------------------------------------------------------------------- plugin registry


def test_docs_plugin_table_is_the_registry():
    from jaxgfx.render.scene.mitsuba_conventions import PLUGINS

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with open(os.path.join(root, "docs", "render_scenes.md"), encoding="utf-8") as f:
        text = f.read()
    body = text.split("<!-- plugin-table -->\n", 1)[1].split("<!-- /plugin-table -->", 1)[0]
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in body.splitlines()[2:]]
    assert [(t, p.strip("`"), s) for t, p, s in rows] == [(t, p, s) for (t, p), s in
                                                          PLUGINS.items()]  # fmt: skip


def _refused():
    from jaxgfx.render.scene.mitsuba_conventions import PLUGINS

    return [(t, p, s.split(": ", 1)[1]) for (t, p), s in PLUGINS.items() if s.startswith("ref")]


@pytest.mark.parametrize("tag,plugin,why", _refused())
def test_every_refused_plugin_is_refused_with_its_reason(tmp_path, tag, plugin, why):
    p = write(tmp_path, scene_xml(f'<{tag} type="{plugin}"/>'))
    msg = f"{p}:10: <{tag} type='{plugin}'>: {tag} plugin '{plugin}' is not supported ({why})"
    with pytest.raises(ValueError, match=rx(msg)):
        read_xml(p)


def test_unknown_plugin_names_the_supported_ones(tmp_path):
    p = write(tmp_path, scene_xml('<shape type="teapot"/>'))
    with pytest.raises(
        ValueError,
        match=rx(
            "shape plugin 'teapot' is not supported (unknown "
            "plugin; supported: obj, ply, serialized, sphere, "
            "rectangle"
        ),
    ):
        read_xml(p)
