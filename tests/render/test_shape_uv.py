"""Mitsuba 3's uv layouts of its analytic shapes as the XML loader builds them: the rotated
sphere's local frame (``Spheres.frames``), the cube mesh's per-face uvs, the disk's polar and
the cylinder's ``(φ/2π, z)`` uvs — closed forms at known points, and a same-run comparison of
``uv`` with Mitsuba 3's ``scene.ray_intersect`` at random rays."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.geometry import Spheres
from jaxgfx.render.geometry.intersect import intersect_scene
from jaxgfx.render.geometry.tangent import shape_tangents
from jaxgfx.render.scene import load_scene

HEAD = """<scene version="3.0.0">
<sensor type="perspective"><transform name="to_world"><lookat origin="0, 0, 40"
 target="0, 0, 0" up="0, 1, 0"/></transform>
<film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/>
</film></sensor>
"""


def _rot(axis, deg):
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = math.radians(deg)
    return np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * k @ k


def _load(tmp_path, body, name="s.xml"):
    p = tmp_path / name
    p.write_text(HEAD + body + "</scene>")
    return str(p), load_scene(str(p))


def _hits(scene, o, d):
    return jax.jit(lambda o, d: intersect_scene(scene.shapes, o, d))(
        jnp.asarray(o, jnp.float32), jnp.asarray(d, jnp.float32)
    )


def test_rotated_sphere_uv_and_tangents_in_its_frame():
    """Rays at the centre from local directions (φ, θ): uv = (φ/2π, θ/π) and
    dp/du = 2π r F (-sin θ sin φ, sin θ cos φ, 0) in world space (F: the sphere's frame)."""
    f = _rot([1.0, 2.0, -0.5], 70.0)
    c, r = np.array([0.5, -1.0, 2.0]), 1.5
    s = Spheres(c, r, f)
    phi = np.array([0.3, 1.7, 3.0, 4.4, 5.9])
    theta = np.array([0.4, 1.2, 1.6, 2.3, 2.9])
    loc = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], 1)
    n = loc @ f.T
    o, d = c + 4 * n, -n
    h = jax.jit(lambda o, d: intersect_scene([s], o, d))(o, d)
    np.testing.assert_allclose(np.asarray(h.uv), np.stack([phi / (2 * np.pi), theta / np.pi], 1),
                               atol=2e-6)  # fmt: skip
    dpdu, dpdv = shape_tangents(s, jnp.zeros(5, jnp.int32), h.p, h.ng)
    want = 2 * np.pi * r * np.stack([-loc[:, 1], loc[:, 0], 0 * phi], 1) @ f.T
    np.testing.assert_allclose(np.asarray(dpdu), want, atol=1e-4)
    # dp/dv: the derivative of the point along θ, π r (cos θ cos φ, cos θ sin φ, -sin θ)
    wv = np.pi * r * np.stack([np.cos(theta) * np.cos(phi), np.cos(theta) * np.sin(phi),
                               -np.sin(theta)], 1) @ f.T  # fmt: skip
    np.testing.assert_allclose(np.asarray(dpdv), wv, atol=1e-4)
    # without a frame: world axes (unchanged behaviour)
    h0 = jax.jit(lambda o, d: intersect_scene([Spheres(c, r)], o, d))(c + 4 * loc, -loc)
    np.testing.assert_allclose(np.asarray(h0.uv), np.asarray(h.uv), atol=2e-6)


@pytest.mark.slow  # slow: 3-5 s at load 10 on 2 cores (two compiled intersections)
def test_instanced_rotated_sphere_uv_equals_the_flattened_one():
    """An instance turns the sphere's frame: the instanced hit's uv (local space) and that of
    ``Instances.flatten()`` (frame = the instance's rotation after the sphere's own) agree."""
    from jaxgfx.render.geometry import Instances

    f = _rot([1.0, 2.0, -0.5], 70.0)
    c, r = np.array([0.5, -1.0, 2.0]), 1.5
    s = Spheres(c, r, f)
    u = np.random.default_rng(1).normal(size=(6, 3))
    n = u / np.linalg.norm(u, axis=1, keepdims=True)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = 2.0 * _rot([0.0, 1.0, 1.0], 40.0), [1.0, 0.0, -1.0]
    inst = Instances(s, m[None])
    cw = m[:3, :3] @ c + m[:3, 3]
    both = jax.jit(lambda a, b, o, d: (intersect_scene([a], o, d), intersect_scene([b], o, d)))
    hi, hf = both(inst, inst.flatten(), cw + 8 * n, -n)
    assert np.all(np.asarray(hi.valid))
    np.testing.assert_allclose(np.asarray(hi.uv), np.asarray(hf.uv), atol=2e-6)


def test_rotated_sphere_uv_gradient_matches_finite_differences(x64):
    """d uv / d(frame angle) at a fixed ray, against central differences (float64)."""
    o, d = np.array([0.3, -0.2, 5.0]), np.array([0.0, 0.0, -1.0])

    def uv(a):
        ca, sa = jnp.cos(a), jnp.sin(a)
        f = jnp.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]]) @ jnp.asarray(
            _rot([1.0, 0.0, 0.0], 50.0)
        )
        return intersect_scene([Spheres(jnp.zeros(3), 1.0, f)], o[None], d[None]).uv[0]

    a0, eps = 0.4, 1e-6
    g = jax.jit(jax.jacfwd(uv))(a0)
    fd = (uv(a0 + eps) - uv(a0 - eps)) / (2 * eps)
    np.testing.assert_allclose(np.asarray(g), np.asarray(fd), rtol=1e-7, atol=1e-9)
    assert abs(float(g[0])) > 0.01  # the frame's turn moves u


def test_cube_disk_cylinder_vertex_uvs_are_mitsubas():
    """The meshes' vertex uvs are the closed forms at the vertices: cube face +z (vertices
    12-15) ((y+1)/2, (x+1)/2); disk (r, φ/2π) with the seam's rim vertex at v = 1 and the
    centre at r = 0; cylinder (φ/2π, z) with the seam's vertices at u = 0 and u = 1."""
    from jaxgfx.render.scene import mitsuba_xml as MX

    v, f, _, uv = MX._cube()
    assert v.shape == (24, 3) and f.shape == (12, 3)
    top = slice(12, 16)
    np.testing.assert_array_equal(v[top, 2], 1.0)
    np.testing.assert_allclose(uv[top], np.stack([(v[top, 1] + 1) / 2, (v[top, 0] + 1) / 2], 1))
    v, f, _, uv = MX._disk(16)
    r = np.linalg.norm(v[:, :2], axis=1)
    np.testing.assert_allclose(uv[:, 0], r, atol=1e-12)
    rim = r > 0.5
    phi = np.arctan2(v[rim, 1], v[rim, 0]) % (2 * np.pi) / (2 * np.pi)
    dv = uv[rim, 1] - phi  # the seam's last rim vertex: v = 1 (φ computed as 0 or ~1)
    assert np.all((np.abs(dv) < 1e-12) | (np.abs(dv - 1) < 1e-12)) and uv[rim, 1].max() == 1.0
    v, f, _, uv = MX._cylinder(16)
    phi = np.arctan2(v[:, 1], v[:, 0]) % (2 * np.pi) / (2 * np.pi)
    du = uv[:, 0] - phi
    assert np.all((np.abs(du) < 1e-12) | (np.abs(du - 1) < 1e-12)) and np.any(
        np.abs(du - 1) < 1e-12
    )
    np.testing.assert_array_equal(uv[:, 1], v[:, 2])
    # each triangle's uvs span less than one segment: no triangle wraps around the seam
    assert np.ptp(uv[f][..., 0], axis=1).max() <= 1 / 16 + 1e-12


@pytest.mark.slow  # slow: 5-11 s at load 10 on 2 cores (three scenes, three compiles)
def test_cube_disk_cylinder_uv_closed_forms(tmp_path):
    """Cube (scaled 2, 3, 0.5, moved): on its +z face uv = ((y+1)/2, (x+1)/2) in local units
    (Mitsuba's face 3, corners (1,-1,1), (1,1,1), (-1,1,1), (-1,-1,1) with uv (0,1), (1,1),
    (1,0), (0,0)). Disk (scaled 2, 3): uv = (r, φ/2π) of the local point. Cylinder
    (radius 2, length 3 along z, moved): uv = (φ/2π, z/3)."""
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-0.9, 0.9, (2, 8))
    cube = ('<shape type="cube"><transform name="to_world"><scale x="2" y="3" z="0.5"/>'
            '<translate x="1" y="-2" z="0.5"/></transform></shape>')  # fmt: skip
    _, sc = _load(tmp_path, cube)
    o = np.stack([1 + 2 * x, -2 + 3 * y, 10 + 0 * x], 1)
    h = _hits(sc, o, np.tile([0.0, 0.0, -1.0], (8, 1)))
    np.testing.assert_allclose(np.asarray(h.t), 9.0, atol=1e-5)
    np.testing.assert_allclose(np.asarray(h.uv), np.stack([(y + 1) / 2, (x + 1) / 2], 1),
                               atol=1e-6)  # fmt: skip

    r = rng.uniform(0.05, 0.95, 8)
    phi = rng.uniform(0.0, 2 * np.pi, 8)
    _, sc = _load(tmp_path, '<shape type="disk"><transform name="to_world"><scale x="2" y="3"/>'
                            "</transform></shape>")  # fmt: skip
    o = np.stack([2 * r * np.cos(phi), 3 * r * np.sin(phi), 10 + 0 * r], 1)
    h = _hits(sc, o, np.tile([0.0, 0.0, -1.0], (8, 1)))
    uv = np.asarray(h.uv)
    np.testing.assert_allclose(uv[:, 0], r, atol=1e-4)  # chords: 1 - cos(π/256) = 7.5e-5
    dv = (uv[:, 1] - phi / (2 * np.pi) + 0.5) % 1.0 - 0.5
    assert np.all(np.abs(dv) <= (1 - r) / 512 + 1e-6), dv  # centre vertex: 1/2n at r = 0

    z = rng.uniform(0.05, 2.95, 8)
    _, sc = _load(tmp_path, '<shape type="cylinder"><float name="radius" value="2"/>'
                            '<point name="p1" x="0" y="0" z="3"/><transform name="to_world">'
                            '<translate x="1"/></transform></shape>')  # fmt: skip
    n = np.stack([np.cos(phi), np.sin(phi), 0 * phi], 1)
    p = np.array([1.0, 0.0, 0.0]) + 2 * n + np.stack([0 * z, 0 * z, z], 1)
    h = _hits(sc, p + 5 * n, -n)
    uv = np.asarray(h.uv)
    du = (uv[:, 0] - phi / (2 * np.pi) + 0.5) % 1.0 - 0.5
    assert np.abs(du).max() < 1e-6 and np.abs(uv[:, 1] - z / 3).max() < 1e-5, (du, uv)


SHAPES = {  # transforms with rotations, non-uniform scales and an oblique cylinder axis
    "sphere": '<shape type="sphere"><float name="radius" value="0.7"/><transform '
    'name="to_world"><scale value="1.5"/><rotate x="1" angle="-35"/><rotate y="1" '
    'angle="-25"/><translate x="0.3" y="-0.5" z="-2"/></transform></shape>',
    "cube": '<shape type="cube"><transform name="to_world"><scale x="1.5" y="1.5" z="0.2"/>'
    '<translate y="2.5" z="-5"/><rotate y="1" angle="25"/><rotate z="1" angle="35"/>'
    "</transform></shape>",
    "disk": '<shape type="disk"><transform name="to_world"><scale x="1.5" y="2.5"/><rotate '
    'x="1" angle="-35"/><rotate y="1" angle="-25"/><translate y="2.5" z="-2"/>'
    "</transform></shape>",
    "cylinder": '<shape type="cylinder"><point name="p0" x="0.2" y="-0.3" z="0.1"/><point '
    'name="p1" x="1.0" y="0.6" z="-0.5"/><float name="radius" value="0.8"/>'
    '<transform name="to_world"><rotate x="1" angle="-35"/><translate y="-2"/>'
    "</transform></shape>",
}


@pytest.mark.mitsuba
@pytest.mark.parametrize("kind", sorted(SHAPES))
def test_uv_matches_mitsuba_at_random_rays(tmp_path, kind):
    """300 rays from a sphere of radius 8 around the shape's box centre, aimed at random points
    of its box: the same hits as Mitsuba 3 (scalar_rgb) and the same uv, away from the seams
    (u or v within 2e-3 of 0 or 1 of a periodic coordinate) and, for the disk, its
    tessellation's centre error (1/2n of a turn at r = 0)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path, sc = _load(tmp_path, SHAPES[kind])
    ms = mi.load_file(path)
    lo, hi = np.asarray(ms.bbox().min), np.asarray(ms.bbox().max)
    rng = np.random.default_rng(3)
    n = 300
    u = rng.normal(size=(n, 3))
    o = (lo + hi) / 2 + 8 * u / np.linalg.norm(u, axis=1, keepdims=True)
    d = rng.uniform(lo, hi, (n, 3)) - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ts, uvs = [], []
    for i in range(n):
        si = ms.ray_intersect(mi.Ray3f(mi.Point3f(*o[i]), mi.Vector3f(*d[i])))
        ts.append(si.t if si.is_valid() else np.inf)
        uvs.append(list(si.uv))
    tm, um = np.array(ts), np.array(uvs)
    h = _hits(sc, o, d)
    v = np.asarray(h.valid) & np.isfinite(tm)
    tj = np.asarray(h.t)
    # the tessellated silhouettes (disk, cylinder) may differ by a hair at grazing rays
    assert (np.asarray(h.valid) != np.isfinite(tm)).sum() <= 3 and v.sum() > 60
    assert np.abs(tj[v] - tm[v]).max() < 2e-2 * (1 if kind in ("disk", "cylinder") else 1e-2)
    uj = np.asarray(h.uv)[v]
    um = um[v]
    periodic = {"sphere": [0], "cube": [], "disk": [1], "cylinder": [0]}[kind]
    keep = np.ones(len(uj), bool)
    for k in periodic:
        keep &= np.minimum(um[:, k], 1 - um[:, k]) > 2e-3
    diff = np.abs(uj - um)[keep]
    tol = {"sphere": 1e-5, "cube": 1e-5, "disk": 2e-3, "cylinder": 5e-4}[kind]
    assert keep.sum() > 50 and diff.max() < tol, (kind, diff.max(axis=0))
