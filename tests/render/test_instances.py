"""Instancing (jaxgfx.render.geometry.instance, ``{type: instances}``, Mitsuba ``shapegroup`` /
``instance``).

References: the same shapes flattened into world space (vertices / rectangle edges mapped by
the matrices, brute-force Möller–Trumbore), the closed-form ray-ellipsoid intersection for a
non-uniformly scaled sphere, finite differences for gradients, Mitsuba 3's reference image of
mitsuba-data's ``instancing`` scene (slow) and Mitsuba 3 itself (``mitsuba`` marker).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import jax.test_util
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jaxgfx.render import render
from jaxgfx.render.geometry import Instances, Rectangles, Spheres, intersect
from jaxgfx.render.geometry.accel import available_backends, build_traversal
from jaxgfx.render.geometry.mesh_io import make_icosphere
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba_xml import read_xml
from jaxgfx.testing import ad_fd_per_key
from tests.render.test_mitsuba_xml_render import compare, data_dir, refs, render_xml  # noqa: F401


def _mats(k, seed=0, uniform=False):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(k):
        m = np.eye(4)
        s = np.full(3, rng.uniform(0.5, 2)) if uniform else rng.uniform(0.5, 2, 3)
        m[:3, :3] = Rotation.random(random_state=seed * 100 + i).as_matrix() @ np.diag(s)
        m[:3, 3] = rng.uniform(-3, 3, 3)
        out.append(m)
    return np.array(out)


def _rays(n, seed=1):
    rng = np.random.default_rng(seed)
    o = rng.normal(size=(n, 3)) * 6
    d = rng.normal(size=(n, 3)) * 2 - o
    return o, d / np.linalg.norm(d, axis=-1, keepdims=True)


@jax.jit
def _hit(inst, o, d):
    return inst.intersect(o, d)


@jax.jit
def _against_flat(inst, flat, o, d):
    """Instanced and flattened hits, any-hit with tmax = inf and just before the hits."""
    h1, h2 = inst.intersect(o, d), intersect(flat, o, d)
    occ = inst.occluded(o, d, jnp.full(o.shape[:-1], jnp.inf))
    occ_short = inst.occluded(o, d, jnp.where(h2.valid, h2.t * 0.999, 1e3))
    return h1, h2, occ, occ_short


def _mesh64():
    m = make_icosphere(1)
    return type(m)(np.asarray(m.vertices, np.float64), m.faces)


@pytest.mark.parametrize(
    "backend",
    # slow: ~8.5 s on 2 cores at load 9.5 (compiling the wavefront BVH for K x N rays)
    # embree slow too: ~3 s of the default run (2026-12-06, quiet); brute stays in it
    ["brute", pytest.param("jax", marks=pytest.mark.slow),
     pytest.param("embree", marks=pytest.mark.slow)],
)
def test_instances_equal_the_flattened_mesh(backend, x64):
    """Rotated, non-uniformly scaled and translated copies of an 80-triangle icosphere: same
    hits, t, p, ng and prim ids (k * 80 + j) as the flattened mesh, any-hit = hit mask."""
    if backend == "embree" and "embree" not in available_backends():
        pytest.skip("embreex not installed")
    mesh = _mesh64()
    shape = mesh if backend == "brute" else build_traversal(mesh, backend)
    inst = Instances(shape, _mats(5))
    flat = inst.flatten()
    o, d = _rays(300)
    h1, h2, occ, occ_short = _against_flat(inst, flat, o, d)
    assert int(h2.valid.sum()) > 60
    np.testing.assert_array_equal(h1.valid, h2.valid)
    v = np.asarray(h2.valid)
    np.testing.assert_array_equal(np.asarray(h1.prim_id)[v], np.asarray(h2.prim_id)[v])
    tol = 1e-9 if backend == "brute" else 1e-5  # host engines search in float32
    np.testing.assert_allclose(np.asarray(h1.t)[v], np.asarray(h2.t)[v], rtol=tol)
    np.testing.assert_allclose(np.asarray(h1.p)[v], np.asarray(h2.p)[v], atol=tol * 10)
    np.testing.assert_allclose(np.asarray(h1.ng)[v], np.asarray(h2.ng)[v], atol=tol * 10)
    np.testing.assert_array_equal(occ, h2.valid)
    assert not bool(jnp.any(occ_short))  # a shorter tmax: the hits beyond it are gone


def test_instanced_rectangles_and_non_uniformly_scaled_sphere(x64):
    """Rectangles map to rectangles (edges by A); a sphere under diag(1, 2, 0.5) is the
    ellipsoid x² + y²/4 + 4z² = 1: t from the closed-form quadratic, normal ∝ (x, y/4, 4z)."""
    rect = Rectangles(np.zeros((1, 3)), np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    inst = Instances(rect, _mats(3, seed=4))
    o, d = _rays(400, seed=5)
    h1, h2, _, _ = _against_flat(inst, inst.flatten(), o, d)
    np.testing.assert_array_equal(h1.valid, h2.valid)
    v = np.asarray(h2.valid)
    assert v.sum() > 10
    np.testing.assert_allclose(np.asarray(h1.t)[v], np.asarray(h2.t)[v], rtol=1e-10)

    sph = Spheres(np.zeros((1, 3)), np.ones(1))
    m = np.diag([1.0, 2.0, 0.5, 1.0])
    m[:3, 3] = [0.3, -0.2, 0.1]
    inst = Instances(sph, m)
    o, d = _rays(400, seed=6)
    h = _hit(inst, o, d)
    q = o - m[:3, 3]
    w = np.array([1.0, 0.25, 4.0])  # x²/a² weights
    a = (d * d * w).sum(-1)
    b = 2 * (q * d * w).sum(-1)
    c = (q * q * w).sum(-1) - 1
    disc = b * b - 4 * a * c
    hit = disc > 0
    t0 = (-b - np.sqrt(np.where(hit, disc, 0))) / (2 * a)
    hit &= t0 > 0  # all origins lie outside
    assert hit.sum() > 40
    np.testing.assert_array_equal(h.valid, hit)
    np.testing.assert_allclose(np.asarray(h.t)[hit], t0[hit], rtol=1e-9)
    p = o + t0[:, None] * d
    n = (p - m[:3, 3]) * w
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    np.testing.assert_allclose(np.asarray(h.ng)[hit], n[hit], atol=1e-9)


@pytest.mark.slow  # slow: ~13 s on 2 cores at load 9.5 (check_grads compiles value, jvp, vjp)
def test_hit_gradients_match_finite_differences(x64):
    """d(sum of t, p, ng)/d(to_world) and d/d(vertices) through an instance, float64 FD."""
    mesh = _mesh64()
    mats = _mats(2, seed=7)
    o, d = _rays(24, seed=8)
    inst = Instances(mesh, mats)
    h = _hit(inst, o, d)
    assert int(h.valid.sum()) > 3

    def loss(tw, verts):
        i = Instances(type(mesh)(verts, mesh.faces), tw)
        pid = jnp.asarray(h.prim_id)
        r = i.hit(pid, jnp.asarray(o), jnp.asarray(d), pid >= 0)
        w = jnp.where(r.valid[:, None], 1.0, 0.0)
        return jnp.sum(jnp.where(r.valid, r.t, 0.0)) + jnp.sum(w * (r.p + r.ng) * 0.3)

    jax.test_util.check_grads(
        jax.jit(loss), (jnp.asarray(mats), mesh.vertices), order=1, modes=["rev"], eps=1e-6
    )


def _desc(instanced: bool):
    mats = _mats(3, seed=2, uniform=False)
    mats[:, :3, 3] *= 0.4
    ico = make_icosphere(1)  # inline, without vertex normals (see below)
    mesh = {"type": "mesh", "vertices": np.asarray(ico.vertices).tolist(),
            "faces": np.asarray(ico.faces).tolist(), "material": "m"}  # fmt: skip
    rect = {"type": "rectangle", "center": [0, 0, 0], "edge_u": [1.2, 0, 0],
            "edge_v": [0, 0, 1.2], "material": "r"}  # fmt: skip
    if instanced:
        shapes = [{"type": "instances", "shapes": [mesh, rect], "to_world": mats.tolist()}]
    else:
        shapes = []
        for m in mats:
            shapes.append({**mesh, "to_world": m.tolist()})
            c = m[:3, 3]
            shapes.append({"type": "rectangle", "center": c.tolist(), "material": "r",
                           "edge_u": (m[:3, :3] @ [1.2, 0, 0]).tolist(),
                           "edge_v": (m[:3, :3] @ [0, 0, 1.2]).tolist()})  # fmt: skip
    return {
        "camera": {
            "origin": [0, 1, 9],
            "target": [0, 0, 0],
            "fov": 40,
            "width": 16,
            "height": 16,
        },  # fmt: skip
        "materials": {
            "m": {"type": "diffuse", "reflectance": [0.7, 0.4, 0.2]},
            "r": {"type": "diffuse", "reflectance": 0.5},
        },  # fmt: skip
        "shapes": shapes,
        "emitters": [
            {"type": "point", "position": [3, 5, 6], "intensity": [60, 60, 60]},
            {"type": "constant", "radiance": [0.2, 0.2, 0.2]},
        ],  # fmt: skip
    }


@pytest.mark.slow  # slow: ~20-33 s on 2 loaded cores (two scenes' compiles)
def test_instanced_scene_renders_like_the_flattened_one():
    """Same image (same key, direct lighting) as the scene with each copy written out; the only
    difference is rounding in the hit records. (The mesh has no vertex normals: an instance
    interpolates its normals in local space and then maps them, as Mitsuba 3 does, which is
    not the same as interpolating mapped normals under a non-uniform scale.)"""
    a = load_scene(_desc(True))
    b = load_scene(_desc(False))
    assert sum(isinstance(s, Instances) for s in a.shapes) == 2
    key = jax.random.key(3)
    ia = render(a, key, spp=2, integrator="direct")
    ib = render(b, key, spp=2, integrator="direct")
    assert float(jnp.mean(ib)) > 0.05
    # a path may pick another triangle at a shared edge: compare pixels robustly
    diff = np.abs(np.asarray(ia) - np.asarray(ib))
    assert np.mean(diff < 1e-4) > 0.97
    np.testing.assert_allclose(np.mean(ia, (0, 1)), np.mean(ib, (0, 1)), rtol=2e-3)


def _mean_image(x, key, scene):
    s = scene.replace("materials.m.reflectance", jnp.stack([x, 0.4, 0.2]))
    return jnp.mean(render(s, key, spp=1, integrator="direct"))


@pytest.mark.slow  # slow: ~50 s on 2 loaded cores (float64 compile of value+grad and FD)
def test_material_gradient_through_instances_matches_finite_differences(x64):
    """d(mean image)/d(red reflectance of the instanced mesh's material): reverse mode against
    central differences with the same keys (float64; linear in the reflectance, so the two
    agree to rounding per key)."""
    scene = load_scene(_desc(True), dtype=jnp.float64)
    keys = jax.random.split(jax.random.key(0), 2)
    x0 = jnp.asarray(0.7)
    _, ad, fd = ad_fd_per_key(_mean_image, x0, keys, 1e-4, args=(scene,))
    assert np.all(np.abs(ad) > 1e-4)
    np.testing.assert_allclose(ad, fd, rtol=1e-6)


def test_bad_instances_are_refused_with_the_field_named():
    d = _desc(True)
    d["shapes"][0]["to_world"][1] = np.diag([1.0, 0.0, 1.0, 1.0]).tolist()
    with pytest.raises(ValueError, match=r"shapes\[0\]\.to_world\[1\]: .*singular"):
        load_scene(d)
    d = _desc(True)
    d["shapes"][0]["shapes"].append({"type": "instances", "shapes": [], "to_world": []})
    with pytest.raises(ValueError, match=r"shapes\[0\]\.shapes\[2\]: nested instancing"):
        load_scene(d)
    # an empty group and an empty list of matrices add nothing
    d = _desc(True)
    d["shapes"].append({"type": "instances", "shapes": [], "to_world": [np.eye(4).tolist()]})
    d["shapes"].append({"type": "instances", "shapes": d["shapes"][0]["shapes"], "to_world": []})
    assert len(load_scene(d).shapes) == 2


_XML = """<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 9" target="0, 0, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/>
      <rfilter type="box"/></film>
    <sampler type="independent"><integer name="sample_count" value="16"/></sampler>
  </sensor>
  <integrator type="path"><integer name="max_depth" value="3"/></integrator>
  <emitter type="point"><point name="position" x="3" y="5" z="6"/>
    <rgb name="intensity" value="60"/></emitter>
  <emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>
  <shape type="shapegroup" id="g">
    <shape type="sphere"><float name="radius" value="0.8"/>
      <bsdf type="diffuse"><rgb name="reflectance" value="0.8 0.3 0.2"/></bsdf></shape>
    <shape type="rectangle">
      <transform name="to_world"><translate z="-1"/></transform>
      <bsdf type="diffuse"><rgb name="reflectance" value="0.2 0.6 0.3"/></bsdf></shape>
    EXTRA
  </shape>
  <shape type="instance" id="a"><ref id="g"/>
    <transform name="to_world"><scale x="1.5" y="0.6" z="1"/><rotate y="1" angle="30"/>
      <translate x="-1.5"/></transform></shape>
  <shape type="instance" id="b"><ref id="g"/>
    <transform name="to_world"><rotate x="1" angle="-40"/><scale x="0.7" y="1.4" z="0.9"/>
      <translate x="1.6" y="0.3"/></transform></shape>
</scene>
"""


def _write(tmp_path, text):
    p = tmp_path / "inst.xml"
    p.write_text(text)
    return str(p)


def test_xml_shapegroup_and_instances(tmp_path):
    x = read_xml(_write(tmp_path, _XML.replace("EXTRA", "")))
    (entry,) = x.desc["shapes"]
    assert entry["type"] == "instances" and len(entry["to_world"]) == 2
    assert [s["type"] for s in entry["shapes"]] == ["sphere", "rectangle"]
    m = np.asarray(entry["to_world"][0])  # scale, then rotate about y, then translate
    r = Rotation.from_euler("y", 30, degrees=True).as_matrix()
    np.testing.assert_allclose(m[:3, :3], r @ np.diag([1.5, 0.6, 1.0]), atol=1e-12)
    scene = load_scene(x.desc)
    assert [type(s).__name__ for s in scene.shapes] == ["Instances", "Instances"]


def test_xml_instancing_errors_name_the_object_and_line(tmp_path):
    bad = _XML.replace("EXTRA", "").replace('<scale x="0.7" y="1.4" z="0.9"/>',
                                            '<scale x="0.7" y="0" z="0.9"/>')  # fmt: skip
    with pytest.raises(ValueError, match=r"xml:\d+: <transform>: .*singular.*id='b'.*to_world"):
        read_xml(_write(tmp_path, bad))
    bad = bad.replace('y="0"', 'y="1e-20"')  # det 6e-21: invertible in float64, not usable
    with pytest.raises(ValueError, match=r"xml:\d+: .*id='b'.*'to_world': .*singular"):
        read_xml(_write(tmp_path, bad))
    nested = '<shape type="shapegroup" id="h"><shape type="sphere"/></shape>'
    with pytest.raises(ValueError, match=r"inst\.xml:\d+: .*nested instancing is not permitted"):
        read_xml(_write(tmp_path, _XML.replace("EXTRA", nested)))
    em = '<shape type="sphere"><emitter type="area"/></shape>'
    with pytest.raises(ValueError, match=r"inst\.xml:\d+: .*instancing of emitters"):
        read_xml(_write(tmp_path, _XML.replace("EXTRA", em)))


@pytest.mark.mitsuba
@pytest.mark.slow  # slow: ~40 s on 2 cores (Mitsuba 256 spp + jaxgfx 256 spp, 32²)
def test_instanced_scene_matches_mitsuba(tmp_path):
    """The XML scene above (two instances, rotation + non-uniform scale, a sphere becoming an
    ellipsoid) rendered by Mitsuba 3 and jaxgfx: channel means within 4 standard errors, 4x4
    block means within a z RMS of 1.5 (standard errors from both renders' sample variance)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    path = _write(tmp_path, _XML.replace("EXTRA", ""))
    spp = 256
    ref = np.asarray(mi.render(mi.load_file(path), spp=spp, seed=1), np.float64)[..., :3]
    x = read_xml(path)
    scene = load_scene(x.desc)
    keys = jax.random.split(jax.random.key(5), 8)
    imgs = np.stack([np.asarray(render(scene, k, spp=spp // 8, max_depth=x.max_depth))
                     for k in keys])  # fmt: skip
    img = imgs.mean(0)
    # per-pixel standard error of jaxgfx's mean from its 8 independent batches; Mitsuba's
    # is of the same size (same spp, same estimator), hence the factor 2 in the variance
    var = imgs.var(0, ddof=1) / 8 * 2
    h = w = 32
    z_mean = (img.mean((0, 1)) - ref.mean((0, 1))) / np.sqrt(var.sum((0, 1)) / (h * w) ** 2)
    assert np.all(np.abs(z_mean) < 4), z_mean

    def blocks(a):
        return a.reshape(8, 4, 8, 4, 3).mean((1, 3))

    se = np.sqrt(blocks(var) / 16)
    ok = se > 0
    z = (blocks(img) - blocks(ref))[ok] / se[ok]
    assert np.sqrt(np.mean(z**2)) < 1.5, np.sqrt(np.mean(z**2))


@pytest.mark.slow  # slow: 15-28 s on 2 cores at load 10-15 (OBJ sphere, 32 512 triangles; 64²)
def test_instancing_scene_matches_mitsubas_reference(data_dir):  # noqa: F811
    """mitsuba-data's ``instancing`` scene (a group of an OBJ sphere, a sphere and a rectangle,
    three instances with rotations and scales): channel means |z| < 4, 4x4 blocks' z RMS < 1.5
    and 97 % |z| < 3.5 against the reference's variance image."""
    scene = data_dir / "tests" / "scenes" / "instancing"
    spp = 16
    img = render_xml(str(scene / "test_instancing_path.xml"), spp)
    ref, var = refs(str(scene / "refs" / "test_instancing_ref_rgb.exr"))
    c = compare(img, ref, var, spp)
    assert np.all(np.abs(c["z_mean"]) < 4), c
    assert c["z_rms"] < 1.5 and c["frac_3_5"] > 0.97, c


def test_instances_round_trip_through_save_scene_and_to_mitsuba_dict(tmp_path):
    """scene -> save_scene (Mitsuba XML: a shapegroup and one instance per matrix) -> read back:
    the same members, matrices and materials; to_mitsuba_dict of the
    description gives group_0 and instance_0_K referring to it."""
    from jaxgfx.render.scene.mitsuba import to_mitsuba_dict
    from jaxgfx.render.scene.mitsuba_xml import save_scene

    desc = _desc(True)
    md = to_mitsuba_dict(desc)
    assert md["group_0"]["type"] == "shapegroup" and len(md["group_0"]) == 3
    for k in range(3):
        inst = md[f"instance_0_{k}"]
        assert inst["shapegroup"] == {"type": "ref", "id": "group_0"}
        np.testing.assert_allclose(inst["to_world"], desc["shapes"][0]["to_world"][k])
    scene = load_scene(desc)
    path = tmp_path / "saved.xml"
    save_scene(scene, str(path), spp=4)
    text = path.read_text()
    assert text.count('type="instance"') == 6  # 3 matrices x 2 members (mesh, rectangle)
    back = read_xml(str(path))
    ents = [s for s in back.desc["shapes"] if s["type"] == "instances"]
    assert len(ents) == 2
    for e in ents:
        np.testing.assert_allclose(e["to_world"], desc["shapes"][0]["to_world"], atol=1e-6)
    s2 = load_scene(back.desc)
    got = [s for s in s2.shapes if isinstance(s, Instances)]
    want = [s for s in scene.shapes if isinstance(s, Instances)]
    assert len(got) == len(want) == 2
    for g, w in zip(got, want, strict=True):  # the same members, matrices and materials
        np.testing.assert_allclose(g.to_world, w.to_world, atol=1e-6)
        gb, wb = getattr(g.shape, "mesh", g.shape), getattr(w.shape, "mesh", w.shape)
        assert type(gb) is type(wb) and g.n_prims == w.n_prims
        for f in ("vertices", "centers", "edge_u", "edge_v"):
            if hasattr(wb, f):
                np.testing.assert_allclose(getattr(gb, f), getattr(wb, f), atol=1e-6)
    for a, b in zip(s2.shape_materials, scene.shape_materials, strict=True):
        ma = s2.materials[int(a[0])].reflectance
        mb = scene.materials[int(b[0])].reflectance
        np.testing.assert_allclose(ma, mb, atol=1e-6)


def test_with_accel_rebuilds_the_one_shared_structure():
    """Scene.accel reports the instanced mesh's backend; with_accel swaps the shared structure
    (same mesh leaves, same matrices)."""
    if "embree" not in available_backends():
        pytest.skip("embreex not installed")
    d = _desc(True)
    d["shapes"][0]["shapes"][0] = {"type": "mesh", "generator": {"name": "icosphere", "level": 2},
                                   "material": "m"}  # fmt: skip
    scene = load_scene(d, accel="jax")
    assert scene.accel == "jax"
    s2 = scene.with_accel("embree")
    assert s2.accel == "embree"
    a, b = scene.shapes[0], s2.shapes[0]
    assert type(b.shape).__name__ == "EmbreeMesh" and b.shape.mesh.vertices is a.shape.mesh.vertices
    np.testing.assert_array_equal(a.to_world, b.to_world)


def _boxes_and_rays(k=60, n=400, seed=11):
    """Overlapping random boxes; rays from random origins (some inside boxes), a quarter of
    them along the axes (zero direction components) and some with short intervals."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(-2.5, 2.5, (k, 3))
    h = rng.uniform(0.3, 1.5, (k, 3))
    boxes = np.stack([c - h, c + h], 1)
    o = rng.uniform(-6, 6, (n, 3))
    d = rng.normal(size=(n, 3)) - o / 3  # mostly towards the cluster
    d[: n // 4] = np.eye(3)[rng.integers(0, 3, n // 4)] * rng.choice([-1, 1], (n // 4, 1))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t0 = np.where(rng.uniform(size=n) < 0.2, rng.uniform(0, 3, n), 0.0)
    t1 = np.where(rng.uniform(size=n) < 0.3, t0 + rng.uniform(0, 4, n), np.inf)
    return boxes, o, d, t0, t1


def _brute_pairs(boxes, o, d, t0, t1):
    """Reference: every (ray, box) slab test separately, ``(entry t, hit)`` of shape (n, k)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (boxes[None, :, 0] - o[:, None]) / d[:, None]
        tb = (boxes[None, :, 1] - o[:, None]) / d[:, None]
    # a zero direction component: inside the slab (any t) or never
    inside = (o[:, None] >= boxes[None, :, 0]) & (o[:, None] <= boxes[None, :, 1])
    zero = d[:, None] == 0
    lo = np.where(zero, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
    hi = np.where(zero, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
    tn = np.maximum(lo.max(-1), t0[:, None])
    tf = np.minimum(hi.min(-1), t1[:, None])
    return tn, tn <= tf


def test_top_level_finds_exactly_the_boxes_each_ray_meets():
    """build_tlas + tlas_candidates (host) and tlas_collect (jitted) against a slab test of
    every (ray, box) pair: the same pairs (no margin case within 1e-4 of a box face taken as
    a difference), collect's list the nearest 8 by entry t, its count the number met."""
    from jaxgfx.render.geometry.accel.tlas import build_tlas, tlas_candidates, tlas_collect

    boxes, o, d, t0, t1 = _boxes_and_rays()
    tn, hit = _brute_pairs(boxes, o, d, t0, t1)
    # pairs whose decision is within rounding of a face (the boxes are widened to float32)
    tn_w, hit_w = _brute_pairs(boxes + [[-1e-4], [1e-4]], o, d, t0 - 1e-4, t1 + 1e-4)
    assert 800 < hit.sum() < 0.5 * hit.size  # overlapping boxes, mostly misses
    top = build_tlas(boxes)
    assert top.bounds.shape[0] == 2 * len(boxes) - 1 and int(top.leaf.sum()) == len(boxes)
    r, k, te = tlas_candidates(top.bounds, top.offset, top.leaf, o, d, t0, t1)
    got = np.zeros_like(hit)
    got[r, k] = True
    assert len(r) == got.sum()  # no pair twice
    assert np.all(got[hit]) and np.all(hit_w[got])
    np.testing.assert_allclose(te, tn[r, k], atol=1e-5)
    ck, ct, cnt = jax.jit(tlas_collect)(top, *(jnp.asarray(x, jnp.float32) for x in (o, d, t0, t1)))
    ck, ct, cnt = np.asarray(ck), np.asarray(ct), np.asarray(cnt)
    np.testing.assert_array_equal(cnt, got.sum(1))
    assert cnt.max() > 8  # some lists overflowed: they keep the 8 nearest
    for i in range(len(o)):
        want = np.sort(np.where(got[i], tn[i], np.inf))[:8]
        np.testing.assert_allclose(ct[i], want, atol=1e-5)
        assert set(ck[i][ck[i] >= 0]) <= set(np.flatnonzero(got[i]))


def test_closed_form_inverse_and_its_gradient(x64):
    """inv3 against numpy's LAPACK inverse (random and near-singular-but-valid matrices) and
    its reverse-mode derivative against float64 central differences (check_grads)."""
    from jaxgfx.render.geometry.accel.tlas import inv3

    rng = np.random.default_rng(3)
    a = rng.normal(size=(50, 3, 3))
    a[0] = np.diag([1e-3, 1.0, 1e3])  # badly scaled but invertible
    np.testing.assert_allclose(jax.jit(inv3)(a), np.linalg.inv(a), rtol=1e-9, atol=1e-12)
    jax.test_util.check_grads(inv3, (jnp.asarray(a[1:3]),), order=1, modes=["rev"], eps=1e-6)


# slow: 6-14 s each on 2 cores at load 13-18 (float64 compiles of the search, hit and any-hit)
@pytest.mark.slow
@pytest.mark.parametrize("backend", ["jax", "embree"])
def test_many_overlapping_instances_equal_the_flattened_mesh(backend, x64):
    """60 instances of a 20-triangle icosahedron on top of each other (rays meet up to ~25
    boxes, beyond the 8 the Embree top level lists per ray: the host completes those), rays
    along the axes included: the two-level traversal finds the flattened mesh's hits (brute
    force in float64): same mask, prim ids and t; any-hit equal to the mask."""
    if backend not in available_backends():
        pytest.skip(f"{backend} not available")
    m = make_icosphere(0)
    mesh = type(m)(np.asarray(m.vertices, np.float64), m.faces)
    mats = _mats(60, seed=12)
    mats[:, :3, 3] *= 0.5
    inst = Instances(build_traversal(mesh, backend), mats)
    boxes, o, d, t0, t1 = _boxes_and_rays(seed=13)
    h1, h2, occ, _ = _against_flat(inst, inst.flatten(), o, d)
    v = np.asarray(h2.valid)
    assert v.sum() > 100
    np.testing.assert_array_equal(h1.valid, v)
    np.testing.assert_array_equal(np.asarray(h1.prim_id)[v], np.asarray(h2.prim_id)[v])
    np.testing.assert_allclose(np.asarray(h1.t)[v], np.asarray(h2.t)[v], rtol=1e-9)
    np.testing.assert_array_equal(occ, v)


@pytest.mark.parametrize("backend", ["brute", "jax"])
def test_instanced_queries_call_no_lapack(backend):
    """Regression (issue 24, the -m mitsuba hang): the instanced search and hit record lower
    to no LAPACK custom call. jnp.linalg.inv's batched getrf waits, inside XLA's 2-thread CPU
    pool, on tasks it queues to the same pool; two such calls at once blocked forever (4 of 6
    runs of two 20 000-matrix inverses in one jitted program hung on this machine, 0 of 6
    with the closed form)."""
    mesh = make_icosphere(0)
    shape = mesh if backend == "brute" else build_traversal(mesh, backend)
    inst = Instances(shape, _mats(3))
    o, d = (jnp.asarray(x, jnp.float32) for x in _rays(8))

    def f(inst, o, d):
        return inst.intersect(o, d).p, inst.occluded(o, d, jnp.full(8, 5.0))

    text = jax.jit(f).lower(inst, o, d).as_text()
    assert "custom_call" not in text or "lapack" not in text.lower()
    assert "lapack" in jax.jit(jnp.linalg.inv).lower(o[:3, None] * d[:3]).as_text().lower()
