"""Ellipsoids (Mitsuba 3's ``ellipsoids``; ``jaxgfx/render/geometry/ellipsoids.py``): hits and
normals against the implicit quadric solved independently (NumPy roots), Mitsuba's conventions
(extent 3, culled backs, flat ellipsoids never hit), the hard cases (grazing rays, a scale of 0,
rays from inside, many overlapping ellipsoids: BVH = brute force), gradients of the hit record
against central differences (float64), the PLY format, scene dict / XML / writer, "model only
what a scene needs", and, with the ``mitsuba`` marker, hits, t and normals against Mitsuba
3.9.1 (scalar_rgb) and a render in the same run."""

from __future__ import annotations

import math
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.geometry import Ellipsoids, read_ellipsoids_ply, write_ellipsoids_ply
from jaxgfx.render.geometry import ellipsoids as E


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _axis_angle(axis, angle):
    """``(R, q)``: Rodrigues' matrix and the quaternion ``(x, y, z, w)`` of a rotation (built
    independently of the code under test)."""
    a = _unit(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    R = np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K
    return R, np.r_[a * math.sin(angle / 2), math.cos(angle / 2)]


def _axis_angle_matrix(q):
    """The rotation of a unit quaternion ``(x, y, z, w)`` by Rodrigues' formula."""
    angle = 2 * math.atan2(np.linalg.norm(q[:3]), q[3])
    return _axis_angle(q[:3] if np.any(q[:3]) else [0, 0, 1], angle)[0]


def _random_ellipsoids(rng, n, spread=1.0):
    c = rng.uniform(-spread, spread, (n, 3))
    s = rng.uniform(0.05, 0.4, (n, 3))
    Rq = [_axis_angle(rng.normal(size=3), rng.uniform(0, 2 * math.pi)) for _ in range(n)]
    return c, s, np.stack([r for r, _ in Rq]), np.stack([q for _, q in Rq])


def _reference(c, s, R, o, d):
    """Near root of ``(x - c)ᵀ R S⁻² Rᵀ (x - c) = 1`` along ``o + t d`` (NumPy polynomial
    roots), and the gradient normal ``∝ R S⁻² Rᵀ (p - c)`` there."""
    M = R @ np.diag(1 / s**2) @ R.T
    f = o - c
    roots = np.roots([d @ M @ d, 2 * f @ M @ d, f @ M @ f - 1])
    roots = roots[np.abs(roots.imag) < 1e-9].real
    if roots.size == 0:
        return np.inf, None
    t = roots.min()
    return t, _unit(M @ (o + t * d - c))


def _hit(shape, o, d, **kw):
    o, d = jnp.asarray(o, jnp.float64), jnp.asarray(d, jnp.float64)
    return jax.jit(lambda o, d: shape.intersect(o, d, **kw))(o, d)


def test_hits_match_the_implicit_quadric(x64):
    """Six rotated anisotropic ellipsoids (extent 1), 60 rays from outside aimed near their
    centres: the hit record's t and normal against the quadric's roots (NumPy) to 1e-9; the
    documented example (4.75); Mitsuba's default extent 3 (measured there: t = 4.25 for the
    same ray)."""
    rng = np.random.default_rng(0)
    c, s, R, q = _random_ellipsoids(rng, 6, spread=3.0)
    shape = Ellipsoids(c, s, q, extent=1.0)
    k = np.repeat(np.arange(6), 10)
    o = c[k] + 2.5 * _unit(rng.normal(size=(60, 3)))
    d = _unit(c[k] + rng.normal(0, 0.02, (60, 3)) - o)
    ref = [_reference(c[i], s[i], R[i], o[j], d[j]) for j, i in enumerate(k)]
    t_ref = np.array([t for t, _ in ref])
    assert np.all(np.isfinite(t_ref))
    hit = jax.jit(lambda sh, k, o, d: sh.hit(k, o, d, True))
    h = hit(shape, jnp.asarray(k), jnp.asarray(o), jnp.asarray(d))
    assert np.all(np.asarray(h.valid))
    np.testing.assert_allclose(np.asarray(h.t), t_ref, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(h.ng), np.stack([n for _, n in ref]), atol=1e-9)
    assert np.all(np.asarray(h.ns) == np.asarray(h.ng)) and np.all(np.asarray(h.uv) == 0)
    # the example: a ray along +z hits (1, .5, .25) at t = 5 - extent / 4
    c1, s1 = np.zeros((6, 3)), np.tile([1, 0.5, 0.25], (6, 1))
    q1 = np.tile([0.0, 0, 0, 1], (6, 1))
    o1, d1 = np.tile([0.0, 0, -5], (60, 1)), np.tile([0.0, 0, 1], (60, 1))
    for extent, t in ((1.0, 4.75), (3.0, 4.25)):
        h = hit(Ellipsoids(c1, s1, q1, extent=extent), jnp.asarray(k), jnp.asarray(o1),
                jnp.asarray(d1))  # fmt: skip
        assert np.all(np.abs(np.asarray(h.t) - t) < 1e-12)
        assert np.allclose(np.asarray(h.ng), [0, 0, -1])


_INTERSECT = jax.jit(lambda sh, o, d, tmax: sh.intersect(o, d, tmax=tmax))


def test_hard_cases_are_as_documented(x64):
    """Rays from inside and ellipsoids behind the ray miss (culled back faces, Mitsuba); a
    tangent ray hits once; a flat ellipsoid (a scale of 0) is never hit; a negative scale acts
    as its absolute value; tmax clips (one compiled search; the gradients at these cases:
    :func:`test_hit_gradients_match_finite_differences`)."""
    o = jnp.asarray([[0, 0, 0], [0, 0, 5], [1, 0, -5], [0, 0, -5], [0.2, 0.1, 0],
                     [0, -5, 0], [0.1, -5, -5], [-5, 0, 0]], jnp.float64)  # fmt: skip
    d = jnp.asarray(_unit([[0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, -1], [0, 1, 0],
                           [0, 1, 1], [1, 0, 0]]))  # fmt: skip
    tmax = jnp.asarray([9, 9, 9, 4.7, 9, 9, 9, 9.0])

    def run(scales):
        return _INTERSECT(Ellipsoids([[0, 0, 0]], [scales], [[0, 0, 0, 1]], extent=1.0), o, d,
                          tmax)  # fmt: skip

    h = run([1, 0.5, 0.25])
    valid = np.asarray(h.valid)
    np.testing.assert_array_equal(valid, [False, False, True, False, False, True, True, True])
    assert float(h.t[2]) == 5.0 and np.allclose(np.asarray(h.ng[2]), [1, 0, 0])  # tangent
    assert float(h.t[7]) == 4.0
    assert not np.any(np.asarray(run([1, 0, 0.25]).valid))  # flat: never hit
    h2 = run([-1, 0.5, 0.25])  # Mitsuba 3.9.1: t = 4.0 along x (measured)
    np.testing.assert_array_equal(np.asarray(h2.t), np.asarray(h.t))


def test_bvh_equals_brute_force_on_overlapping_ellipsoids(x64):
    """300 ellipsoids overlapping in a unit box (each ray crosses many), 400 rays from outside
    and 100 from inside the cloud: the BVH's nearest (t, ellipsoid) equals the brute-force
    minimum of the per-ellipsoid near roots (tmin = 0), and its any-hit query (shadow rays)
    is True exactly where that minimum is below tmax."""
    rng = np.random.default_rng(2)
    c, s, _, q = _random_ellipsoids(rng, 300, spread=0.6)
    shape = Ellipsoids(c, s, q, extent=1.0)
    o = np.concatenate([3 * _unit(rng.normal(size=(400, 3))), rng.uniform(-0.3, 0.3, (100, 3))])
    d = _unit(rng.normal(0, 0.4, (500, 3)) - o)
    # shadow rays: tmax of 3 for the first half, 1.8 for the rest (some nearest hits beyond)
    tmax = np.where(np.arange(500) < 250, 3.0, 1.8)
    t, k, occ = jax.jit(lambda o, d, tm: (*shape.closest_t(o, d), shape.occluded(o, d, tm)))(
        jnp.asarray(o), jnp.asarray(d), jnp.asarray(tmax)
    )
    # brute force in NumPy: the near root of every (ray, ellipsoid) quadric
    R = np.stack([_axis_angle_matrix(qq) for qq in q])
    M = np.einsum("kij,kj,klj->kil", R, 1 / s**2, R)  # R S⁻² Rᵀ
    f = o[:, None] - c[None]
    A = np.einsum("ni,kij,nj->nk", d, M, d)
    B = np.einsum("nki,kij,nj->nk", f, M, d)
    C = np.einsum("nki,kij,nkj->nk", f, M, f) - 1
    disc = B * B - A * C
    tb = np.where(disc >= 0, (-B - np.sqrt(np.maximum(disc, 0))) / A, np.inf)
    tb = np.where(tb > 0, tb, np.inf)
    assert np.isfinite(tb.min(1)).sum() > 450
    np.testing.assert_allclose(np.asarray(t), tb.min(1), rtol=1e-9)
    hit = np.isfinite(tb.min(1))
    np.testing.assert_array_equal(np.asarray(k)[hit], tb.argmin(1)[hit])
    blocked = tb.min(1) < tmax
    assert 0 < np.sum(hit & ~blocked) and np.array_equal(np.asarray(occ), blocked)


def test_hit_gradients_match_finite_differences(x64):
    """d(t, n) / d(a centre, a scale, two quaternion components) of hits on two rotated
    ellipsoids: reverse mode against central differences (float64, rtol 1e-6; one compiled
    value and gradient); the quaternion's derivative is that of the normalised rotation. The
    same function's value and gradient are finite at the hard cases: a grazing ray, a flat
    ellipsoid, a ray from inside, the zero quaternion."""
    rng = np.random.default_rng(5)
    c, s, _, q = _random_ellipsoids(rng, 2, spread=0.5)
    shape = Ellipsoids(c, s, q, extent=1.5)
    o = np.array([[0.1, 0.2, -4.0], [3.0, 0.1, 0.3]])
    d = _unit(np.asarray(c) - o + [[0.02, 0.03, 0], [0, 0.1, 0.05]])
    k = jnp.asarray([0, 1])
    w = jnp.asarray(rng.normal(size=(2, 4)))
    # (field, row, column): a centre, a scale, a quaternion component of each ellipsoid
    at = (("centers", 0, 1), ("scales", 1, 2), ("quaternions", 0, 0), ("quaternions", 1, 3))
    flat = np.concatenate([c.ravel(), s.ravel(), q.ravel()])
    idx = [{"centers": 0, "scales": 6, "quaternions": 12}[fl] + r * (4 if fl[0] == "q" else 3)
           + col for fl, r, col in at]  # fmt: skip

    def f(x, o, d):
        sh = eqx.tree_at(
            lambda e: (e.centers, e.scales, e.quaternions),
            shape,
            (x[:6].reshape(2, 3), x[6:12].reshape(2, 3), x[12:].reshape(2, 4)),
        )
        h = sh.hit(k, o, d, True)
        rec = jnp.concatenate([h.t[:, None], h.ng], -1)
        return jnp.sum(w * jnp.where(h.valid[:, None], rec, 0.0))

    vg = jax.jit(jax.value_and_grad(f))  # one compile for AD, the differences, the hard cases
    x0 = jnp.asarray(flat)
    ad = np.asarray(vg(x0, o, d)[1])[idx]
    eps = 1e-6
    fd = np.array([(float(vg(x0.at[i].add(eps), o, d)[0]) -
                    float(vg(x0.at[i].add(-eps), o, d)[0])) / (2 * eps) for i in idx])  # fmt: skip
    assert np.all(np.abs(ad) > 1e-3), ad
    np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-9)
    # hard cases: ellipsoid 0 grazed (tangent along its first axis), made flat, the ray
    # starting at its centre; ellipsoid 1 with the zero quaternion
    R0 = E._np_quaternion_matrix(q[:1])[0]
    semi = 1.5 * s[0]
    graze = (np.r_[[c[0] + semi[0] * R0[:, 0] - 5 * R0[:, 1]], o[1:]], np.r_[[R0[:, 1]], d[1:]])
    for x, (oo, dd) in (
        (flat, graze),
        (np.r_[flat[:6], 0, flat[7:]], (o, d)),
        (flat, (np.r_[c[:1], o[1:]], d)),
        (np.r_[flat[:16], 0, 0, 0, 0], (o, d)),
    ):
        val, g = vg(jnp.asarray(x), jnp.asarray(oo), jnp.asarray(dd))
        assert np.isfinite(float(val)) and np.all(np.isfinite(np.asarray(g))), (x, g)


def test_ply_round_trip_and_errors(tmp_path):
    """write → read gives the ellipsoids back (scales through ln / exp: 1e-6 relative); the
    reader's to_world (rotation 30° about z, uniform scale 2, translation) equals the
    ellipsoids placed by hand; bad files are refused naming the file (attributes: volumetric)."""
    rng = np.random.default_rng(3)
    c, s, R, q = _random_ellipsoids(rng, 5)
    write_ellipsoids_ply(tmp_path / "e.ply", c, s, q)
    c2, s2, q2 = read_ellipsoids_ply(tmp_path / "e.ply")
    np.testing.assert_allclose(c2, c, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(s2, s, rtol=1e-6)
    np.testing.assert_allclose(q2, q, atol=1e-6)
    Rz, _ = _axis_angle([0, 0, 1], math.pi / 6)
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = 2 * Rz, [1, 2, 3]
    c3, s3, q3 = read_ellipsoids_ply(tmp_path / "e.ply", scale_factor=0.5, to_world=m)
    np.testing.assert_allclose(c3, c @ (2 * Rz).T + [1, 2, 3], rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(s3, s, rtol=1e-6)  # 0.5 x 2
    R3 = E._np_quaternion_matrix(q3.astype(np.float64))
    np.testing.assert_allclose(R3, Rz @ R, atol=1e-6)
    head = "ply\nformat ascii 1.0\nelement vertex 1\n"
    props = "".join(f"property float {f}\n" for f in E.PLY_FIELDS)
    bad = {
        "attr": (head + props.replace("property float scale_0", "property float opacity\n"
                                      "property float scale_0") + "end_header\n" + "0 " * 14,
                 "per-ellipsoid attributes \\['opacity'\\] are not supported"),
        "order": (head + props.replace("nx", "qq") + "end_header\n" + "0 " * 13,
                  "expected the vertex properties"),
        "short": (head + props + "end_header\n" + "0 " * 12, "expected 13 numbers, got 12"),
        "type": (head + props.replace("float x", "double x") + "end_header\n", "float properties"),
    }  # fmt: skip
    for name, (text, msg) in bad.items():
        (tmp_path / f"{name}.ply").write_text(text)
        with pytest.raises(ValueError, match=rf"{name}\.ply.*{msg}"):
            read_ellipsoids_ply(tmp_path / f"{name}.ply")
    with pytest.raises(ValueError, match="a scale of 0 cannot be written"):
        write_ellipsoids_ply(tmp_path / "z.ply", c, np.zeros_like(s), q)


BASE = {
    "camera": {"origin": [0, 0, -5], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4},
    "materials": {"m": {"type": "diffuse", "reflectance": 0.5}},
    "emitters": [{"type": "point", "position": [0, 0, -5], "intensity": [9, 9, 9]}],
}
CENTERS = [[0, 0, 0], [0.8, 0.3, 0.2]]
SCALES = [[0.3, 0.2, 0.1], [0.1, 0.2, 0.15]]
QUATS = [[0, 0, 0, 1], [0.6, 0, 0, 0.8]]


def _inline(**kw):
    return {"type": "ellipsoids", "centers": CENTERS, "scales": SCALES, "quaternions": QUATS,
            "material": "m", **kw}  # fmt: skip


def test_scene_dict_and_refusals(tmp_path):
    """``{type: ellipsoids, centers/scales/quaternions | data | filename (+ scale_factor,
    to_world), extent}`` loads the same ellipsoids each way; the parameters are the three
    leaves; attributes, adaptive clamping, two sources, to_world without a file, non-unit
    quaternions, emitters, instancing and edge sampling are refused naming the field."""
    from jaxgfx.render import render
    from jaxgfx.render.scene import load_scene

    sc = load_scene({**BASE, "shapes": [_inline(extent=2.0)]})
    (e,) = sc.shapes
    assert isinstance(e, Ellipsoids) and e.extent == 2.0
    assert [p.path for p in sc.parameters() if p.path.startswith("shapes")] == [
        "shapes.0.centers", "shapes.0.scales", "shapes.0.quaternions"]  # fmt: skip
    data = np.concatenate([CENTERS, SCALES, QUATS], 1)
    e2 = load_scene({**BASE, "shapes": [{"type": "ellipsoids", "data": data.ravel().tolist(),
                                          "material": "m"}]}).shapes[0]  # fmt: skip
    write_ellipsoids_ply(tmp_path / "e.ply", CENTERS, np.asarray(SCALES) / 2, QUATS)
    e3 = load_scene({**BASE, "shapes": [{"type": "ellipsoids", "filename": "e.ply",
                                          "scale_factor": 2.0, "material": "m"}]},
                    base_dir=str(tmp_path)).shapes[0]  # fmt: skip
    assert e2.extent == e3.extent == 3.0
    for x in (e2, e3):
        for f in ("centers", "scales", "quaternions"):
            np.testing.assert_allclose(np.asarray(getattr(x, f)), np.asarray(getattr(e, f)),
                                       rtol=1e-6, atol=1e-7)  # fmt: skip
    bad = [
        (_inline(opacities=[[1.0], [1.0]]), r"shapes\[0\]\.opacities: per-ellipsoid attributes"),
        (_inline(extent_adaptive_clamping=True), "extent_adaptive_clamping: only false"),
        (_inline(data=data.tolist()), "give exactly one of 'filename', 'centers'"),
        (_inline(to_world=np.eye(4).tolist()), r"to_world: only with 'filename'"),
        (_inline(quaternions=[[0, 0, 0, 1], [1, 0, 0, 1]]),
         r"shapes\[0\]\.quaternions: expected unit quaternions .* row 1 has length 1\.41421"),
        (_inline(scales=SCALES[:1]), "same number of rows"),
        (_inline(extent=0), "extent: expected a positive number"),
        ({"type": "ellipsoids", "data": [1, 2, 3], "material": "m"}, r"data: expected shape"),
        ({"type": "ellipsoids", "filename": "e.ply", "to_world": np.diag([-1.0, 1, 1, 1]).tolist(),
          "material": "m"}, "a mirroring or singular transform"),
    ]  # fmt: skip
    for sd, msg in bad:
        with pytest.raises(ValueError, match=msg):
            load_scene({**BASE, "shapes": [sd]}, base_dir=str(tmp_path))
    area = {"type": "area", "radiance": 1.0, "shape": {k: v for k, v in _inline().items()
                                                        if k != "material"}}  # fmt: skip
    with pytest.raises(ValueError, match=r"emitters\[0\]\.shape: ellipsoids cannot be area"):
        load_scene({**BASE, "emitters": [area], "shapes": [_inline()]})
    inst = {"type": "instances", "to_world": [np.eye(4).tolist()], "shapes": [_inline()]}
    with pytest.raises(ValueError, match=r"shapes\[0\]\.shapes\[0\]: instanced ellipsoids"):
        load_scene({**BASE, "shapes": [inst]})
    with pytest.raises(ValueError, match="edge sampling does not cover the silhouettes of ell"):
        render(sc, jax.random.key(0), spp=1, integrator="direct", visibility="edge")


SENSOR = ('<sensor type="perspective"><transform name="to_world"><lookat origin="0,0,-5" '
          'target="0,0,0" up="0,1,0"/></transform><film type="hdrfilm"><integer '
          'name="width" value="4"/><integer name="height" value="4"/></film></sensor>')  # fmt: skip


def test_xml_and_writer_round_trip(tmp_path):
    """XML ``<shape type="ellipsoids">`` with ``filename``, ``extent``, ``scale_factor`` and
    ``to_world`` loads as the dict does; bad files are refused with the XML line and the PLY's
    error, emitters and adaptive clamping too; save_scene writes a PLY and load → save → load
    gives the same ellipsoids (1e-6 relative) and extent."""
    from jaxgfx.render.scene import load_scene
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    write_ellipsoids_ply(tmp_path / "e.ply", CENTERS, SCALES, QUATS)

    def xml(body):
        (tmp_path / "s.xml").write_text(f'<scene version="3.0.0">{SENSOR}\n{body}</scene>')
        return str(tmp_path / "s.xml")

    x = read_xml(xml('<shape type="ellipsoids"><string name="filename" value="e.ply"/>'
                     '<float name="extent" value="2"/><float name="scale_factor" value="1.5"/>'
                     '<transform name="to_world"><rotate y="1" angle="40"/>'
                     '<translate x="0.5"/></transform></shape>'))  # fmt: skip
    (sd,) = x.desc["shapes"]
    assert sd["extent"] == 2.0 and sd["scale_factor"] == 1.5 and "to_world" in sd
    sc = load_scene(x.desc)
    (e,) = sc.shapes
    np.testing.assert_allclose(np.asarray(e.scales), 1.5 * np.asarray(SCALES), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(e.centers)[0], [0.5, 0, 0], atol=1e-6)
    (tmp_path / "bad.ply").write_text("ply\nformat ascii 1.0\nelement vertex 1\n"
                                      "property float x\nend_header\n0\n")  # fmt: skip
    for body, msg in (
        ('<shape type="ellipsoids"><string name="filename" value="bad.ply"/></shape>',
         r"s\.xml:2: .*'filename': .*bad\.ply: expected the vertex properties"),
        ('<shape type="ellipsoids"><string name="filename" value="e.ply"/><emitter '
         'type="area"><rgb name="radiance" value="1"/></emitter></shape>',
         r"s\.xml:2.*ellipsoids cannot be an area emitter"),
        ('<shape type="ellipsoids"><string name="filename" value="e.ply"/><boolean '
         'name="extent_adaptive_clamping" value="true"/></shape>', "only false is supported"),
        ('<shape type="ellipsoids"/>', "missing parameter 'filename'"),
    ):  # fmt: skip
        with pytest.raises(ValueError, match=msg):
            read_xml(xml(body))
    out = save_scene(sc, str(tmp_path / "out" / "w.xml"))
    text = Path(out).read_text()
    assert '<shape type="ellipsoids"' in text and 'name="extent" value="2.0"' in text
    (b,) = load_scene(read_xml(out).desc).shapes
    assert b.extent == 2.0
    for f in ("centers", "scales", "quaternions"):
        np.testing.assert_allclose(np.asarray(getattr(b, f)), np.asarray(getattr(e, f)),
                                   rtol=1e-6, atol=1e-7)  # fmt: skip


def test_scenes_without_ellipsoids_trace_no_ellipsoid_code(monkeypatch):
    """ "Model only what a scene needs": tracing a render of a sphere scene calls no ellipsoid
    code (the shape's kernel is never traced); the same scene with ellipsoids calls it."""
    from jaxgfx.render import render
    from jaxgfx.render.scene import load_scene

    calls = []
    orig = E._unit_sphere_entry  # the quadratic of the search and of the hit record
    monkeypatch.setattr(E, "_unit_sphere_entry", lambda *a: calls.append(1) or orig(*a))
    sphere = {"type": "sphere", "center": [0, 0, 0], "radius": 0.5, "material": "m"}

    def trace(shapes):
        scene = load_scene({**BASE, "shapes": shapes})
        jax.make_jaxpr(lambda k: render(scene, k, spp=1, max_depth=2))(jax.random.key(0))

    trace([sphere])
    assert not calls
    trace([sphere, _inline()])
    assert calls


def _render_mean(x, key, scene):
    from jaxgfx.render import render

    s = scene.replace("materials.m.reflectance", jnp.stack([x[0], x[1], 0.2]))
    return jnp.mean(render(s, key, spp=2, integrator="direct"))


@pytest.mark.slow  # slow: 13-17 s CPU, 27-33 s wall at load 6-7 on 2 cores (float64 render, grad)
def test_material_on_ellipsoids_differentiates(x64):
    """d(mean image)/d(red, green reflectance) of a 4×4 direct render of two diffuse
    ellipsoids under a point light: reverse mode against central differences with the same
    keys (float64)."""
    from jaxgfx.render.scene import load_scene
    from jaxgfx.testing import ad_fd_per_key

    desc = {**BASE, "shapes": [_inline()],
            "materials": {"m": {"type": "diffuse", "reflectance": [0.7, 0.4, 0.2]}}}  # fmt: skip
    scene = load_scene(desc, dtype=jnp.float64)
    keys = jax.random.split(jax.random.key(0), 2)
    _, ad, fd = ad_fd_per_key(_render_mean, jnp.asarray([0.7, 0.4]), keys, 1e-6,
                              args=(scene,))  # fmt: skip
    assert np.all(np.abs(ad) > 1e-3), ad
    np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-10)


# ---------------------------------------------------------------------------------------------
# against Mitsuba 3


@pytest.fixture(scope="module")
def mi():
    mitsuba = pytest.importorskip("mitsuba")
    mitsuba.set_variant("scalar_rgb")
    return mitsuba


def _mitsuba_hits(mi, scene, o, d):
    out = {"t": [], "n": [], "prim": []}
    for a, b in zip(o, d, strict=True):
        si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*a), mi.Vector3f(*b)))
        out["t"].append(si.t if si.is_valid() else np.inf)
        out["n"].append(list(si.n))
        out["prim"].append(si.prim_index)
    return {k: np.array(v) for k, v in out.items()}


@pytest.mark.mitsuba
def test_ray_intersections_match_mitsuba(mi, tmp_path, x64):
    """40 rotated anisotropic ellipsoids (scales 0.05-0.4, overlapping) in a PLY file placed by
    a to_world with a rotation, a non-uniform scale (1.2, 1, 0.9: Mitsuba's mean-scale rule)
    and a translation, default extent 3; 400 rays from a sphere around them aimed near the
    centres, 40 of them starting inside an ellipsoid, and 20 grazing ones: identical hit/miss
    and ellipsoid, t and normals against Mitsuba 3.9.1 (scalar_rgb)."""
    from jaxgfx.render.scene._ellipsoids import ellipsoids_from_desc
    from jaxgfx.render.scene.schema import _read_shape_file

    rng = np.random.default_rng(1)
    c, s, _, q = _random_ellipsoids(rng, 40, spread=1.0)
    s = s / 3
    write_ellipsoids_ply(tmp_path / "e.ply", c, s, q)
    M = mi.ScalarTransform4f().translate([0.2, 0, 0]).rotate([1, 1, 0], 30).scale([1.2, 1, 0.9])
    ms = mi.load_dict({"type": "scene", "e": {"type": "ellipsoids", "to_world": M,
                                              "filename": str(tmp_path / "e.ply")}})  # fmt: skip
    m = np.array(M.matrix, np.float64)
    shape = ellipsoids_from_desc({"type": "ellipsoids", "filename": str(tmp_path / "e.ply"),
                                  "to_world": m.tolist()}, "e", None,
                                 _read_shape_file)  # fmt: skip
    cw = np.asarray(shape.centers, np.float64)
    n = 400
    o = _unit(rng.normal(size=(n, 3))) * 4 + cw.mean(0)
    d = _unit(cw[rng.integers(0, 40, n)] + rng.normal(0, 0.15, (n, 3)) - o)
    o[:40] = cw[:40] + rng.normal(0, 0.01, (40, 3))  # inside: Mitsuba culls
    # grazing: tangent to an ellipsoid, offset outwards by 1e-3 of its size
    sw = np.asarray(shape.scales, np.float64) * shape.extent
    R = E._np_quaternion_matrix(np.asarray(shape.quaternions, np.float64))
    ax = R[:20, :, 0] * sw[:20, :1] * 1.001
    o[40:60] = cw[:20] + ax - 5 * R[:20, :, 1]
    d[40:60] = R[:20, :, 1]
    ref = _mitsuba_hits(mi, ms, o, d)
    h = _hit(shape, o, d)
    v = np.asarray(h.valid)
    assert v.sum() > 200 and np.array_equal(v, np.isfinite(ref["t"]))
    np.testing.assert_array_equal(np.asarray(h.prim_id)[v], ref["prim"][v])
    t = np.asarray(h.t)[v]
    # Mitsuba's float32 t is off by up to 1.1e-3 relative here (measured; 2.1e-3 in another
    # draw): its "robust" shift of the origin to dot(-o', d') / |d'| along the unit-sphere-frame
    # ray puts it |d'| = 1 / semi-axis times too far, and |o'|² - 1 cancels there. jaxgfx in
    # float32 is within 2e-6 of its float64 (below), which matches the quadric to 1e-9.
    np.testing.assert_allclose(ref["t"][v], t, rtol=4e-3)
    h32 = _hit(jax.tree_util.tree_map(lambda a: a.astype(jnp.float32)
                                      if jnp.issubdtype(a.dtype, jnp.floating) else a, shape),
               o.astype(np.float32), d.astype(np.float32))  # fmt: skip
    assert np.array_equal(np.asarray(h32.valid), v)
    np.testing.assert_allclose(np.asarray(h32.t)[v], t, rtol=5e-6)  # measured 1.9e-6
    # the normal convention at Mitsuba's own hit points: n ∝ R S⁻² Rᵀ (p - c)
    k = np.asarray(h.prim_id)[v]
    p = o[v] + ref["t"][v, None] * d[v]
    Mq = E._np_quaternion_matrix(np.asarray(shape.quaternions, np.float64)[k])
    local = np.einsum("nji,nj->ni", Mq, p - cw[k]) / sw[k] ** 2
    n_ref = _unit(np.einsum("nij,nj->ni", Mq, local))
    np.testing.assert_allclose(ref["n"][v], n_ref, atol=5e-5)  # measured 4.3e-6


RENDER_XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="2"/></integrator>
  <sensor type="perspective"><float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0, 1.6, -3.2" target="0, 0.1, 0" up="0, 1, 0"/>
    </transform>
    <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
    <film type="hdrfilm"><integer name="width" value="{w}"/><integer name="height" value="{h}"/>
      <rfilter type="box"/></film></sensor>
  <shape type="ellipsoids"><string name="filename" value="{ply}"/>
    <float name="extent" value="1"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.45, 0.2"/></bsdf></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="3"/>
    <rotate x="1" angle="-90"/><translate y="-0.3"/></transform>
    <bsdf type="roughconductor"><float name="alpha" value="0.3"/></bsdf></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="1"/>
    <rotate x="1" angle="90"/><translate x="0.8" y="2.5" z="-0.5"/></transform>
    <emitter type="area"><rgb name="radiance" value="4"/></emitter></shape>
</scene>"""


def _render_scene(tmp_path, scale=1.0, w=32, h=24):
    rng = np.random.default_rng(7)
    c = np.c_[rng.uniform(-1.2, 1.2, 6), rng.uniform(-0.2, 0.6, 6), rng.uniform(-0.8, 0.8, 6)]
    s = rng.uniform(0.15, 0.45, (6, 3))
    q = np.stack([_axis_angle(rng.normal(size=3), rng.uniform(0, math.pi))[1] for _ in range(6)])
    name = f"e{scale}.ply"
    write_ellipsoids_ply(tmp_path / name, c, s * scale, q)
    p = tmp_path / f"r{scale}.xml"
    p.write_text(RENDER_XML.format(ply=name, w=w, h=h))
    return str(p)


@pytest.mark.mitsuba  # 18 s CPU, 41 s wall at load 7 on 2 cores (one jaxgfx compile: 15 s CPU)
def test_render_matches_mitsuba_in_the_same_run(mi, tmp_path):
    """Six diffuse ellipsoids on a rough-conductor floor under a rectangular area light, path
    max_depth 2, 32×24 at 64 spp, K = 4 renders each by jaxgfx and Mitsuba 3.9.1 of one XML
    file: every 8×8 block mean within 5 standard errors (:func:`replicate_block_z`). Power:
    jaxgfx's render of the ellipsoids with scales 5 % larger is rejected (block max |z| > 5)."""
    from jaxgfx.render import render
    from jaxgfx.render.scene import load_scene
    from jaxgfx.render.scene.mitsuba_xml import read_xml
    from tests.render._scenes import replicate_block_z

    k = 4
    p = _render_scene(tmp_path)
    ms = mi.load_file(p)
    b = np.stack([np.array(mi.render(ms, spp=64, seed=s))[..., :3] for s in range(k)])
    b = b.astype(np.float64)

    x = read_xml(p)
    f = jax.jit(lambda scene, key: render(scene, key, spp=x.spp, integrator=x.integrator,
                                          max_depth=x.max_depth))  # fmt: skip
    keys = jax.random.split(jax.random.key(3), k)

    def ours(path):  # one compile: the 5 % larger scene has the same structure
        scene = load_scene(read_xml(path).desc)
        return np.stack([np.asarray(f(scene, key), np.float64) for key in keys])

    a = ours(p)
    assert np.all(np.isfinite(a)) and a.mean() > 0.02
    z, ma, mb = replicate_block_z(a, b)
    print("z max", z.max(), "means", a.mean(), b.mean())
    # measured: block max |z| 3.08, image means 0.0889 / 0.0883
    assert z.max() < 5, z.max()
    big = ours(_render_scene(tmp_path, 1.05))
    zb = replicate_block_z(big, b)[0]
    print("5 % larger: z max", zb.max())
    # measured: 5 % larger scales: block max |z| 12.1
    assert zb.max() > 5, zb.max()
