"""``mesh_attribute`` textures (Mitsuba 3's ``vertex_*`` / ``face_*`` mesh attributes).

References: closed forms (barycentric interpolation of vertex values, the face's own value),
the PLY grouping rules of Mitsuba's documentation, finite differences (float64) for the
gradient w.r.t. attribute values, and Mitsuba's reference images of mitsuba-data's three
``mesh_attributes`` scenes (slow).
"""

from __future__ import annotations

import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.bsdf.texture import MeshAttribute
from jaxgfx.render.geometry import TriangleMesh, intersect
from jaxgfx.render.geometry.mesh_io import load_ply, ply_attributes
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import ad_fd_per_key
from tests.render.test_mitsuba_xml_render import compare, refs, render_xml

DATA = os.path.join(os.path.dirname(__file__), "..", "data", "mitsuba")
SCENES = os.path.join(DATA, "tests", "scenes", "mesh_attributes")


def _quad():
    v = np.array([[-1.0, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    f = np.array([[0, 1, 2], [0, 2, 3]])
    return v, f


def test_hit_carries_interpolated_vertex_and_constant_face_values():
    """uv[..., 2:] = b0 a(v0) + b1 a(v1) + b2 a(v2) + face value (closed form at random
    points of both triangles), jitted."""
    v, f = _quad()
    va = np.array([[1.0, 0, 0], [0, 2, 0], [0, 0, 3], [4, 4, 4]])
    fa = np.array([[10.0, 20, 30], [-1, -2, -3]])
    mesh = TriangleMesh(v, f, vertex_attributes=va, face_attributes=fa)
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.95, 0.95, (200, 2))
    o = np.concatenate([xy, np.ones((200, 1))], 1)
    d = np.tile([0.0, 0, -1], (200, 1))
    h = jax.jit(lambda m, o, d: intersect(m, o, d))(mesh, o, d)
    assert bool(h.valid.all()) and h.uv.shape == (200, 5)
    first = xy[:, 1] <= xy[:, 0]  # triangle 0: (0, 1, 2) below the diagonal y = x
    want = np.zeros((200, 3))
    for i, (x, y) in enumerate(xy):
        tri = f[0] if first[i] else f[1]
        a, b, c = v[tri][:, :2]
        m = np.array([b - a, c - a]).T
        b1, b2 = np.linalg.solve(m, [x, y] - a)
        want[i] = (1 - b1 - b2) * va[tri[0]] + b1 * va[tri[1]] + b2 * va[tri[2]]
        want[i] += fa[0 if first[i] else 1]
    np.testing.assert_allclose(np.asarray(h.uv[:, 2:]), want, rtol=1e-5, atol=1e-5)
    # the texture reads its slot (columns 2..4 for slot 0), times its scale
    tex = MeshAttribute("vertex_color", jnp.asarray(0.5), 0)
    np.testing.assert_allclose(np.asarray(tex(h.uv)), 0.5 * want, rtol=1e-5, atol=1e-5)


def test_ply_attributes_follow_mitsubas_naming():
    """{p}_0 {p}_1 {p}_2 -> {prefix}{p} (3 channels), r g b -> color, a lone name -> itself."""
    props = {"color_0": [1.0], "color_1": [2.0], "color_2": [3.0], "weight_0": [4.0],
             "n_x": [8.0], "n_y": [9.0], "q": [1.5]}  # fmt: skip
    out = ply_attributes("vertex_", props)
    assert {k: v.tolist() for k, v in out.items()} == {
        "vertex_color": [[1.0, 2.0, 3.0]],
        "vertex_weight": [[4.0]],
        "vertex_n": [[8.0, 9.0]],
        "vertex_q": [[1.5]],
    }
    out = ply_attributes("face_", {"red": [0.5], "green": [0.25], "blue": [1.0]})
    assert {k: v.tolist() for k, v in out.items()} == {"face_color": [[0.5, 0.25, 1.0]]}
    mesh, attrs = load_ply(os.path.join(SCENES, "meshes", "sphere_attribute.ply"), attributes=True)
    assert {k: v.shape for k, v in attrs.items()} == {
        "vertex_color": (1192, 3), "face_color": (528, 3), "face_weight": (528, 1)}  # fmt: skip
    assert mesh.faces.shape == (528, 3)


def _desc(attr_values):
    v, f = _quad()
    return {
        "camera": {
            "origin": [0, 0, 3],
            "target": [0, 0, 0],
            "fov": 50,
            "width": 8,
            "height": 8,
        },  # fmt: skip
        "materials": {
            "m": {
                "type": "diffuse",
                "reflectance": {"type": "mesh_attribute", "name": "vertex_color"},
            }
        },
        "shapes": [
            {
                "type": "mesh",
                "vertices": v.tolist(),
                "faces": f.tolist(),
                "material": "m",
                "attributes": {"vertex_color": attr_values},
            }
        ],  # fmt: skip
        "emitters": [{"type": "directional", "direction": [0, 0, -1], "irradiance": [1, 1, 1]}],
    }


def _loss(x, key, scene):
    s = eqx.tree_at(lambda sc: sc.shapes[0].vertex_attributes, scene, x)
    return jnp.mean(render(s, key, spp=1, integrator="direct"))


@pytest.mark.slow  # slow: ~23 s on 2 loaded cores (float64 compile of value+grad and FD)
def test_gradient_wrt_vertex_attribute_values_matches_finite_differences(x64):
    """d(mean image)/d(vertex colours): reverse mode = central differences (same keys;
    the image is linear in the values, so they agree to rounding)."""
    vals = [[0.2, 0.4, 0.6], [0.8, 0.1, 0.3], [0.5, 0.5, 0.5], [0.9, 0.7, 0.1]]
    scene = load_scene(_desc(vals), dtype=jnp.float64)
    x0 = scene.shapes[0].vertex_attributes
    assert x0.shape == (4, 3)
    keys = jax.random.split(jax.random.key(0), 2)
    _, ad, fd = ad_fd_per_key(_loss, x0, keys, 1e-4, args=(scene,))
    assert np.abs(ad).max() > 1e-3
    np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-9)


def test_missing_or_bad_attributes_are_refused():
    with pytest.raises(ValueError, match=r"shapes\[0\]\.attributes: attribute 'vertex_color'"):
        load_scene(_desc([[0.1, 0.2, 0.3]] * 3))
    d = _desc([[0.1, 0.2, 0.3]] * 4)
    d["materials"]["m"]["reflectance"]["name"] = "color"
    with pytest.raises(ValueError, match=r"materials\.m: reflectance\.name: expected 'vertex_"):
        load_scene(d)


@pytest.mark.slow  # slow: ~9-13 s each on 2 loaded cores (48², 16 spp, direct)
@pytest.mark.parametrize("name", ["3_vertex", "1_face", "3_face"])
def test_mesh_attribute_scenes_match_mitsubas_reference(name):
    """mitsuba-data's mesh_attributes scenes (vertex colour as reflectance, face colour as
    reflectance, face weight of a blendbsdf): channel means |z| < 4, 4x4 blocks' z RMS < 1.5,
    97 % of blocks |z| < 3.5 against the reference's variance image."""
    spp = 16
    img = render_xml(os.path.join(SCENES, f"test_mesh_attributes_{name}_direct.xml"), spp)
    ref, var = refs(os.path.join(SCENES, "refs", f"test_mesh_attributes_{name}_ref_rgb.exr"))
    c = compare(img, ref, var, spp)
    assert np.all(np.abs(c["z_mean"]) < 4), c
    assert c["z_rms"] < 1.5 and c["frac_3_5"] > 0.97, c
