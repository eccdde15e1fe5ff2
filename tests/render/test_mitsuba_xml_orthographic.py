"""Mitsuba 3's ``orthographic`` sensor loaded from XML as a jaxgfx ``MatrixCamera`` and written
back by ``save_scene``.

Fast unit tests (no rendering): the loaded camera's rays against the closed form written from
Mitsuba 3's ``orthographic_projection`` (include/mitsuba/render/sensor.h) and
``sensors/orthographic.cpp``: film position ``(s_x, s_y)`` in ``[0, 1]^2`` from the top left ->
camera-space point ``(1 - 2 s_x, (1 - 2 s_y) h / w, near_clip)``, ray origin ``to_world`` of it,
direction ``normalize(to_world (0, 0, 1))``. The rendered comparison with Mitsuba's reference
image of mitsuba-data's ``orthographic_sensor`` scene is in test_mitsuba_xml_render.py (slow).
"""

from __future__ import annotations

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.camera import MatrixCamera, look_at_matrix, perspective_matrix
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba import to_mitsuba_dict
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

SMALL = (
    '<shape type="sphere"><point name="center" value="0, 0, 3"/>'
    '<float name="radius" value="0.1"/></shape>'
)


def ortho_xml(sensor_body, body=SMALL, *, w=8, h=4):
    return (
        '<scene version="3.0.0">\n<sensor type="orthographic">\n'
        f"{sensor_body}\n"
        f'<film type="hdrfilm"><integer name="width" value="{w}"/>'
        f'<integer name="height" value="{h}"/><rfilter type="box"/></film>\n'
        f"</sensor>\n{body}\n</scene>\n"
    )


def write(tmp_path, text, name="scene.xml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def mitsuba_look_at(origin, target, up):
    """Mitsuba's Transform4f.look_at, written out: columns (left, up', dir, origin)."""
    o, t, u = (np.asarray(v, np.float64) for v in (origin, target, up))
    d = (t - o) / np.linalg.norm(t - o)
    left = np.cross(u, d)
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(d, left), d, o
    return m


def mitsuba_rays(to_world, near, w, h, px):
    """Mitsuba's orthographic rays at continuous pixel positions ``px (n, 2)``."""
    sx, sy = px[:, 0] / w, px[:, 1] / h
    p_cam = np.stack([1 - 2 * sx, (1 - 2 * sy) * h / w, np.full_like(sx, near)], -1)
    o = p_cam @ to_world[:3, :3].T + to_world[:3, 3]
    d = to_world[:3, 2] / np.linalg.norm(to_world[:3, 2])
    return o, np.broadcast_to(d, o.shape)


PIXELS = np.array([[0.0, 0.0], [8.0, 4.0], [8.0, 0.0], [0.0, 4.0], [4.0, 2.0], [0.5, 3.5],
                   [6.25, 1.75]])  # fmt: skip


def test_orthographic_rays_are_mitsubas_closed_form(tmp_path):
    # a sensor plane scaled (non-uniformly, also along z: the direction is normalised and the
    # near plane moves with the scale, as in Mitsuba), turned about its axis, then placed
    sensor = (
        '<float name="near_clip" value="0.5"/><float name="far_clip" value="50"/>'
        '<transform name="to_world"><scale x="2" y="3" z="1.5"/><rotate z="1" angle="30"/>'
        '<lookat origin="1, 2, 5" target="1, 2, 0" up="0, 1, 0"/></transform>'
    )
    x = read_xml(write(tmp_path, ortho_xml(sensor)))
    cam = load_scene(x.desc).camera
    assert isinstance(cam, MatrixCamera) and (cam.width, cam.height) == (8, 4)
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    rot = np.eye(4)
    rot[:2, :2] = [[c, -s], [s, c]]
    to_world = mitsuba_look_at([1, 2, 5], [1, 2, 0], [0, 1, 0]) @ rot @ np.diag([2, 3, 1.5, 1])
    o, d = cam.generate_ray(jnp.asarray(PIXELS, jnp.float32))
    o_ref, d_ref = mitsuba_rays(to_world, 0.5, 8, 4, PIXELS)
    np.testing.assert_allclose(np.asarray(o), o_ref, atol=2e-5)
    np.testing.assert_allclose(np.asarray(d), d_ref, atol=1e-6)
    # looking down -z from z = 5, the origins lie on the plane z = 5 - 1.5 * 0.5
    np.testing.assert_allclose(np.asarray(o)[:, 2], 4.25, atol=1e-5)
    np.testing.assert_allclose(d_ref[0], [0, 0, -1], atol=1e-12)


def test_orthographic_defaults_film_width_spans_minus_one_to_one(tmp_path):
    """Identity to_world, default near_clip 0.01: the film's width maps to camera x in
    [1, -1] (image left = +x, the ``left`` axis of Mitsuba's look_at), its height to
    [h/w, -h/w], rays along +z."""
    cam = load_scene(read_xml(write(tmp_path, ortho_xml("", w=8, h=4))).desc).camera
    o, d = cam.generate_ray(jnp.asarray([[0.0, 0.0], [8.0, 4.0], [4.0, 2.0]]))
    np.testing.assert_allclose(np.asarray(o), [[1, 0.5, 0.01], [-1, -0.5, 0.01], [0, 0, 0.01]],
                               atol=1e-6)  # fmt: skip
    np.testing.assert_allclose(np.asarray(d), np.tile([0.0, 0.0, 1.0], (3, 1)), atol=1e-7)


def test_orthographic_far_clip_is_checked_and_the_near_plane_is_where_rays_start(tmp_path):
    sensor = (
        '<float name="near_clip" value="2"/><float name="far_clip" value="6"/>'
        '<transform name="to_world"><lookat origin="0, 0, 0" target="0, 0, 1" up="0, 1, 0"/>'
        "</transform>"
    )
    # a unit sphere reaching z = 8: beyond the far plane (rays end at z = 6); one reaching
    # z = 5.5 loads
    far = '<shape type="sphere" id="far"><point name="center" value="0, 0, 7"/></shape>'
    with pytest.raises(ValueError) as e:
        read_xml(write(tmp_path, ortho_xml(sensor, far)))
    assert "<sensor type='orthographic'>: far_clip=6.0: " in str(e.value), e.value
    assert "<shape type='sphere' id='far'> reaches beyond it" in str(e.value), e.value
    read_xml(write(tmp_path, ortho_xml(sensor, far.replace("0, 0, 7", "0, 0, 4.5"))))
    # a sphere between the sensor's origin and its near plane (z in [0.2, 1.8]) loads: the
    # rays start at z = 2, past it, so it is clipped in jaxgfx as in Mitsuba
    near = ('<shape type="sphere"><point name="center" value="0, 0, 1"/>'
            '<float name="radius" value="0.8"/></shape>')  # fmt: skip
    cam = load_scene(read_xml(write(tmp_path, ortho_xml(sensor, near))).desc).camera
    o, _ = cam.generate_ray(jnp.asarray([[4.0, 2.0]]))
    np.testing.assert_allclose(np.asarray(o), [[0, 0, 2]], atol=1e-6)


@pytest.mark.parametrize(
    "sensor,msg",
    [
        ('\n<float name="fov" value="40"/>', "parameter 'fov' is not supported"),
        (
            '\n<transform name="to_world"><scale z="1e-13"/></transform>',  # nearly singular
            "parameter 'to_world': the orthographic sensor's to_world must be invertible",
        ),
        (
            '\n<float name="near_clip" value="5"/><float name="far_clip" value="2"/>',
            "parameter 'far_clip': expected far_clip > near_clip",
        ),
    ],
)
def test_orthographic_parameters_it_cannot_reproduce_are_refused(tmp_path, sensor, msg):
    p = write(tmp_path, ortho_xml(sensor))
    with pytest.raises(ValueError) as e:
        read_xml(p)
    # the parameter's line, then the sensor's
    assert str(e.value).startswith(f"{p}:4: {p}:2: <sensor type='orthographic'>: {msg}"), e.value


def test_save_scene_writes_an_orthographic_sensor_with_the_same_rays(tmp_path):
    sensor = (
        '<float name="near_clip" value="0.5"/>'
        '<transform name="to_world"><scale x="2" y="3"/>'
        '<lookat origin="1, 2, 5" target="0, 0, 0" up="0, 1, 0"/></transform>'
    )
    body = '<shape type="sphere"><float name="radius" value="0.5"/></shape>'
    first = read_xml(write(tmp_path, ortho_xml(sensor, body)))
    scene = load_scene(first.desc)
    out = save_scene(scene, str(tmp_path / "out.xml"))  # from the built Scene
    assert '<sensor type="orthographic"' in Path(out).read_text()
    again = load_scene(read_xml(out).desc).camera
    px = jnp.asarray(PIXELS, jnp.float32)
    for a, b in zip(scene.camera.generate_ray(px), again.generate_ray(px), strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), atol=2e-5)
    # the description's matrix camera is exported the same way
    d = to_mitsuba_dict(first.desc)
    assert d["sensor"]["type"] == "orthographic" and "fov" not in d["sensor"]


def test_a_projective_matrix_camera_is_not_exported():
    vp = perspective_matrix(40.0, 1.0, 0.1, 10.0) @ look_at_matrix([0, 0, 3], [0, 0, 0],
                                                                    [0, 1, 0])  # fmt: skip
    desc = {"camera": {"view_proj_inverse": np.linalg.inv(vp).tolist(), "width": 4, "height": 4},
            "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1.0}]}  # fmt: skip
    with pytest.raises(NotImplementedError, match="a projective matrix camera has no Mitsuba"):
        to_mitsuba_dict(desc)
