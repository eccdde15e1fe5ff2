"""Mitsuba 3's ``cylinder`` shape loaded from XML as a triangle mesh (as ``disk`` is).

Mitsuba (``src/shapes/cylinder.cpp``): an open tube without caps, radius ``radius`` around the
segment ``p0`` -> ``p1``, i.e. the unit cylinder (radius 1, z in [0, 1]) placed by
``to_world . translate(p0) . to_frame(p1 - p0) . scale(r, r, |p1 - p0|)``, normals outward.
jaxgfx tessellates it into 256 segments (512 triangles) with radial vertex normals. Fast tests,
no rendering: the vertices lie on the closed-form surface, the faces face outwards, the area
converges to 2 pi r h as the tessellation is refined, and what the mesh cannot reproduce is
refused naming the parameter and file:line.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene import mitsuba_xml as MX
from jaxgfx.render.scene.mitsuba_xml import read_xml

SENSOR = """<sensor type="perspective">
  <float name="fov" value="40"/>
  <transform name="to_world"><lookat origin="0, 0, -30" target="0, 0, 0" up="0, 1, 0"/>
  </transform>
  <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/>
    <rfilter type="box"/></film>
</sensor>"""


def scene_xml(body):
    return f'<scene version="3.0.0">\n{SENSOR}\n{body}\n</scene>\n'


def write(tmp_path, text, name="scene.xml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def world_mesh(path):
    """The built scene's (only) mesh: world-space vertices, faces and vertex normals."""
    scene = load_scene(read_xml(path).desc)
    (shape,) = scene.shapes
    mesh = getattr(shape, "mesh", shape)
    return (np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces),
            np.asarray(mesh.normals, np.float64))  # fmt: skip


def area(v, f):
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    return 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1).sum()


PLACED = """<shape type="cylinder">
  <point name="p0" x="0.5" y="-1" z="0.25"/><point name="p1" x="1.5" y="1" z="2.25"/>
  <float name="radius" value="0.4"/>
  <transform name="to_world"><scale value="1.5"/><rotate x="0.70710678" y="0.70710678" angle="40"/>
    <translate x="-1" y="2" z="0.5"/></transform>
</shape>"""


def test_cylinder_vertices_lie_on_mitsubas_cylinder_and_face_outwards(tmp_path):
    v, f, n = world_mesh(write(tmp_path, scene_xml(PLACED)))
    # the closed form: to_world (uniform scale 1.5, rotation, translation) of the tube of
    # radius 0.4 around p0 -> p1
    ax = np.array([1.0, 1.0, 0.0]) / math.sqrt(2)
    c, s = math.cos(math.radians(40)), math.sin(math.radians(40))
    k = np.array([[0, -ax[2], ax[1]], [ax[2], 0, -ax[0]], [-ax[1], ax[0], 0]])
    rot = np.eye(3) * c + s * k + (1 - c) * np.outer(ax, ax)  # Rodrigues

    def world(p):
        return 1.5 * rot @ np.asarray(p, np.float64) + [-1.0, 2.0, 0.5]

    a, b, r = world([0.5, -1, 0.25]), world([1.5, 1, 2.25]), 1.5 * 0.4
    h = np.linalg.norm(b - a)
    d = (b - a) / h
    t = (v - a) @ d  # position along the axis
    radial = (v - a) - t[:, None] * d
    assert v.shape == (514, 3) and f.shape == (512, 3)  # two rings of 257 (the seam twice)
    np.testing.assert_allclose(np.linalg.norm(radial, axis=1), r, rtol=1e-5)
    np.testing.assert_allclose(np.sort(t)[[0, 256, 257, -1]], [0, 0, h, h], atol=1e-5)
    # unit radial vertex normals, pointing out
    rhat = radial / np.linalg.norm(radial, axis=1, keepdims=True)
    np.testing.assert_allclose(n, rhat, atol=1e-5)
    # faces counter-clockwise seen from outside: geometric normals point away from the axis
    e1, e2 = v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]
    gn = np.cross(e1, e2)
    centroid = v[f].mean(1)
    out = (centroid - a) - ((centroid - a) @ d)[:, None] * d
    assert np.all(np.sum(gn * out, 1) > 0)
    # open tube: every face spans both rings (no caps)
    assert np.all(np.ptp(t[f], axis=1) > 0.99 * h)
    # the area is the 256-gon tube's, within 3e-5 of 2 pi r h
    assert area(v, f) == pytest.approx(256 * 2 * math.sin(math.pi / 256) * r * h, rel=1e-5)
    assert area(v, f) / (2 * math.pi * r * h) == pytest.approx(1, abs=3e-5)


def test_cylinder_defaults_are_mitsubas_unit_cylinder(tmp_path):
    v, _, _ = world_mesh(write(tmp_path, scene_xml('<shape type="cylinder"/>')))
    np.testing.assert_allclose(np.hypot(v[:, 0], v[:, 1]), 1.0, rtol=1e-6)
    np.testing.assert_array_equal(np.unique(np.round(v[:, 2], 6)), [0.0, 1.0])


def test_cylinder_tessellation_area_converges_to_2_pi_r_h():
    errors = []
    for n_seg in (8, 32, 128, 256):
        v, f, _, _ = MX._cylinder(n_seg)
        errors.append(abs(area(v, f) / (2 * math.pi) - 1))  # unit radius and height
    # the n-gon's perimeter error pi^2 / (6 n^2): a quarter per doubling of n, twice
    for e, n_seg in zip(errors, (8, 32, 128, 256), strict=True):
        assert e == pytest.approx(math.pi**2 / (6 * n_seg**2), rel=0.03)
    assert errors[-1] < 3e-5 and errors[0] / errors[1] == pytest.approx(16, rel=0.05)


def test_a_length_scale_along_the_axis_is_accepted(tmp_path):
    """mitsuba-data's various_shapes scales its cylinder by (1.5, 1.5, 2): radius 1.5,
    length 2."""
    body = ('<shape type="cylinder"><transform name="to_world"><scale x="1.5" y="1.5" z="2"/>'
            "</transform></shape>")  # fmt: skip
    v, f, _ = world_mesh(write(tmp_path, scene_xml(body)))
    np.testing.assert_allclose(np.hypot(v[:, 0], v[:, 1]), 1.5, rtol=1e-6)
    assert v[:, 2].max() == pytest.approx(2.0)
    assert area(v, f) / (2 * math.pi * 1.5 * 2) == pytest.approx(1, abs=3e-5)


@pytest.mark.parametrize(
    "body,msg",
    [
        (
            '<shape type="cylinder">\n<transform name="to_world"><scale x="2"/></transform>'
            "</shape>",
            "<shape type='cylinder'>: parameter 'to_world': a cylinder's to_world must keep its "
            "cross-section a circle",
        ),
        (
            '<shape type="cylinder">\n<point name="p1" x="0" y="0" z="0"/></shape>',
            "<shape type='cylinder'>: parameter 'p1': p0 and p1 coincide",
        ),
        (
            '<shape type="cylinder">\n<float name="radius" value="-1"/></shape>',
            "<shape type='cylinder'>: parameter 'radius'",
        ),
    ],
)
def test_what_the_mesh_cannot_reproduce_is_refused(tmp_path, body, msg):
    p = write(tmp_path, scene_xml(body))
    with pytest.raises(ValueError) as e:
        read_xml(p)
    assert f"{p}:10: " in str(e.value) and msg in str(e.value), str(e.value)


def test_save_scene_writes_the_cylinder_back_as_the_same_mesh(tmp_path):
    first = write(tmp_path, scene_xml(PLACED))
    out = MX.save_scene(read_xml(first).desc, str(tmp_path / "out" / "again.xml"))
    for a, b in zip(world_mesh(first), world_mesh(out), strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
