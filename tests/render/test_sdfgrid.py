"""SDF grids (Mitsuba's ``sdfgrid``): the ``.vol`` reader, exact voxel intersection against
closed forms, normals, hard cases, instancing, gradients against finite differences and a
same-run comparison with Mitsuba 3's own ``sdfgrid``."""

from __future__ import annotations

import os
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.geometry import Instances, SDFGrid, SDFGridShape, read_vol, write_vol
from jaxgfx.render.geometry.intersect import intersect_scene
from jaxgfx.render.scene import load_scene

DATA = os.path.join(os.path.dirname(__file__), "..", "data", "mitsuba")
TORUS = os.path.join(DATA, "docs", "scenes", "sdfgrid", "torus_sdfgrid.vol")
C, R = np.array([0.5, 0.5, 0.5]), 0.3


def _grid_of(f, n):
    x = np.linspace(0.0, 1.0, n)
    z, y, xx = np.meshgrid(x, x, x, indexing="ij")
    return f(np.stack([xx, y, z], -1))


def _sphere_sdf(p):
    return np.linalg.norm(p - C, axis=-1) - R


def _rays(n, seed=0):
    rng = np.random.default_rng(seed)
    o = rng.normal(size=(n, 3))
    o = C + 2 * o / np.linalg.norm(o, axis=-1, keepdims=True)
    d = C + 0.2 * rng.normal(size=(n, 3)) - o
    return o, d / np.linalg.norm(d, axis=-1, keepdims=True)


def _sphere_t(o, d):
    """Analytic first hit with the sphere and |cos| at the hit."""
    oc = o - C
    b = np.sum(oc * d, -1)
    disc = b * b - (np.sum(oc * oc, -1) - R * R)
    t = np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    return t, np.sqrt(np.maximum(disc, 0)) / R


def test_vol_round_trip_and_errors(tmp_path):
    v = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4) - 5
    p = tmp_path / "g.vol"
    write_vol(p, v)
    assert np.array_equal(read_vol(p), v)
    t = read_vol(TORUS)  # mitsuba-data's torus: 40³, header bytes as Mitsuba writes them
    assert t.shape == (40, 40, 40) and t.min() < 0 < t.max()
    raw = p.read_bytes()
    cases = {
        b"XOL" + raw[3:]: "expected the magic 'VOL'",
        raw[:3] + bytes([2]) + raw[4:]: "version 2, only version 3",
        raw[:20] + np.int32(3).tobytes() + raw[24:]: "has 3 channels, an SDF grid needs 1",
        raw[:-4]: "92 data bytes, the header's size 4x3x2 needs 96",
    }
    for i, (bad, msg) in enumerate(cases.items()):
        q = tmp_path / f"bad{i}.vol"
        q.write_bytes(bad)
        with pytest.raises(ValueError, match=str(q).replace(".", r"\.") + ".*" + msg[:20]):
            read_vol(q)
    with pytest.raises(ValueError, match="values: expected a"):
        SDFGrid(np.zeros((1, 4, 4)))
    with pytest.raises(ValueError, match="normals"):
        SDFGridShape(SDFGrid(v), "flat")


def test_trilinear_values_are_exact_at_vertices_and_linear_between():
    v = _grid_of(lambda p: p[..., 0] + 2 * p[..., 1] - 3 * p[..., 2] + 0.1, 5)
    g = SDFGrid(v)
    p = np.random.default_rng(1).uniform(-0.2, 1.2, (100, 3))
    q = np.clip(p, 0, 1)  # clamped outside the cube, as Mitsuba's texture lookups
    # one compiled program for both (eager dispatch of the lookups cost ~4 s)
    val, grad = jax.jit(lambda g, p, q: (g(p), g.gradient(q)))(g, jnp.asarray(p), jnp.asarray(q))
    assert np.allclose(val, q[:, 0] + 2 * q[:, 1] - 3 * q[:, 2] + 0.1, atol=1e-5)
    # a linear function's gradient is exact in every voxel
    assert np.allclose(grad, [1, 2, -3], atol=1e-4)


@jax.jit
def _intersect(values, o, d):
    """Hits of the grid ``values`` (smooth shading normals ``ns``, analytic ``ng``): one
    compiled walk per grid and ray shape, shared by the tests."""
    return SDFGridShape(SDFGrid(values)).intersect(o, d)


@pytest.mark.slow  # slow: 40 s at load 10-17 on 2 cores (x64 walk compiled for 3 grid sizes)
def test_hit_distance_and_normals_converge(x64):
    """Hit distance: the trilinear interpolation error bound |f - I f| <= h²/8 Σ_i max|∂ii f|
    <= h²/8 · 2/(R - √3 h) for the sphere distance (Hessian eigenvalues 1/r, 1/r, 0), hence the
    hit distance error <= that / |cos| to first order (rays with |cos| > 0.3), order 2.
    Normals against the analytic sphere's: ``analytic`` (``ng``, the gradient of one voxel's
    trilinear function) first order in h, ``smooth`` (``ns``, Hansson-Söderlund et al. 2022:
    the blended voxel normals) second order."""
    o, d = _rays(400)
    ta, cos = _sphere_t(o, d)
    m = np.isfinite(ta) & (cos > 0.3)
    errs, err_n = [], {}
    for n in (9, 17, 33):
        h = _intersect(jnp.asarray(_grid_of(_sphere_sdf, n)), o, d)
        t = np.asarray(h.t)
        step = 1 / (n - 1)
        bound = step * step / 8 * 2 / (R - np.sqrt(3) * step) / cos[m]
        err = np.abs(t[m] - ta[m])
        assert np.all(err <= 1.05 * bound), (n, np.max(err / bound))
        errs.append(err.max())
        na = (np.asarray(h.p) - C) / np.linalg.norm(np.asarray(h.p) - C, axis=-1)[:, None]
        err_n[n, "analytic"] = np.abs(np.asarray(h.ng)[m] - na[m]).max()
        err_n[n, "smooth"] = np.abs(np.asarray(h.ns)[m] - na[m]).max()
    # measured max errors 0.0102, 0.0024 (17, 33 vertices): order 2
    assert errs[2] / errs[1] < 0.3 and errs[1] / errs[0] < 0.3, errs
    assert 0.3 < err_n[33, "analytic"] / err_n[17, "analytic"] < 0.7, err_n
    assert err_n[33, "smooth"] / err_n[17, "smooth"] < 0.35, err_n
    assert err_n[33, "smooth"] < 0.1 * err_n[33, "analytic"], err_n


@pytest.mark.slow  # slow: 20 s at load 10 on 2 cores (one x64 walk compile + its gradient)
def test_hard_cases(x64):
    # all ray tests through _intersect at one grid and ray shape: one compiled walk
    g17 = jnp.asarray(_grid_of(_sphere_sdf, 17))
    # axis-parallel rays (zero direction components), a ray from inside, a ray leaving the
    # cube, a ray missing it, a ray grazing the (grid) sphere's silhouette
    o = np.array([[0.5, 0.5, -1.0], [0.5, 0.5, 0.5], [0.5, 0.5, 0.5], [2.0, 2.0, 2.0],
                  [0.5 + R, 0.5, -1.0]])  # fmt: skip
    d = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 0, -1.0], [1.0, 0, 0], [0, 0, 1.0]])
    h = _intersect(g17, o, d)
    t = np.asarray(h.t)
    assert abs(t[0] - 1.2) < 2e-3 and abs(t[1] - R) < 2e-3 and abs(t[2] - R) < 2e-3
    assert np.isinf(t[3])
    assert all(np.all(np.isfinite(np.asarray(x)[h.valid])) for x in (h.p, h.ng, h.ns))
    # a ray starting inside hits from inside: outward normal along the direction (the
    # analytic normal tilts by ~0.1 here: the hit lies on two grid planes, and the voxel
    # above them is used, as Mitsuba's sdf_grad does)
    assert np.asarray(h.ng)[1] @ d[1] > 0.98
    # secondary rays spawned from hits do not re-hit their origin
    from jaxgfx.render.geometry import spawn_ray

    so, sd = spawn_ray(h.p, h.ng, -jnp.asarray(d))
    hs = _intersect(g17, so, sd)
    assert not bool(np.asarray(hs.valid)[0])
    # grazing rays near the silhouette: finite values and gradients
    xs = 0.5 + R + np.linspace(-0.01, 0.01, 41)
    og = np.stack([xs, np.full(41, 0.5), np.full(41, -1.0)], -1)
    dg = np.broadcast_to([0, 0, 1.0], og.shape)

    def loss(values, o):
        sh = SDFGridShape(SDFGrid(values))
        hh = sh.intersect(o, dg)
        return jnp.sum(jnp.where(hh.valid, hh.t + hh.ns[..., 0], 0.0))

    g = jax.jit(jax.grad(loss, argnums=(0, 1)))(g17, jnp.asarray(og))
    assert all(np.all(np.isfinite(np.asarray(x))) for x in g)
    # no surface: all values positive (Mitsuba refuses such a grid; jaxgfx misses)
    assert not np.asarray(_intersect(jnp.ones_like(g17), o, d).valid).any()


@pytest.mark.slow  # slow: ~21 s (36 s at load 10-17) on 2 cores (x64 compile of the walk)
def test_instanced_grid_matches_the_transformed_sphere(x64):
    """A grid sphere in an instance (rotation, non-uniform scale, translation) against the
    analytic ellipsoid's hits mapped back to the grid space; the singular transform is
    refused naming to_world."""
    s = SDFGridShape(SDFGrid(_grid_of(_sphere_sdf, 33)))
    a = np.diag([2.0, 1.0, 3.0]) @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = a, [1.0, -2.0, 0.5]
    inst = Instances(s, m[None])
    rng = np.random.default_rng(3)
    u = rng.normal(size=(200, 3))
    ow = a @ C + m[:3, 3] + 8 * u / np.linalg.norm(u, axis=-1, keepdims=True)
    dw = (a @ C + m[:3, 3] + 0.5 * rng.normal(size=(200, 3))) - ow
    dw = dw / np.linalg.norm(dw, axis=-1, keepdims=True)
    h = jax.jit(lambda o, d: intersect_scene([inst], o, d))(ow, dw)
    ai = np.linalg.inv(a)
    dl = dw @ ai.T
    dl = dl / np.linalg.norm(dl, axis=-1, keepdims=True)
    hl = jax.jit(lambda o, d: s.intersect(o, d))((ow - m[:3, 3]) @ ai.T, dl)
    v = np.asarray(h.valid)
    assert v.sum() > 50 and np.array_equal(v, np.asarray(hl.valid))
    pw = np.asarray(hl.p)[v] @ a.T + m[:3, 3]
    assert np.allclose(np.asarray(h.p)[v], pw, atol=1e-9)
    nw = np.asarray(hl.ng)[v] @ np.linalg.inv(a)
    nw /= np.linalg.norm(nw, axis=-1, keepdims=True)
    assert np.allclose(np.asarray(h.ng)[v], nw, atol=1e-9)
    bad = m.copy()
    bad[:3, 0] = 0
    with pytest.raises(ValueError, match=r"to_world\[0\]: the transform is singular"):
        Instances(s, bad[None])


@pytest.mark.slow  # slow: ~43 s (87 s at load 10-17) on 2 cores (x64 compile of the walk)
def test_gradients_match_finite_differences(x64):
    """dt/d(values) and d(shading normal)/d(values) of instanced hits, and d/d(to_world),
    against central differences in float64 (a few voxel values near the hits)."""
    g0 = _grid_of(_sphere_sdf, 9)
    m = np.eye(4)
    m[:3, :3] = [[1.5, 0.2, 0], [0, 1.2, 0], [0.1, 0, 1.0]]
    o = np.array([[0.75, 0.8, -2.0], [0.6, 0.55, -2.0], [0.9, 0.7, -2.0]])
    d = np.array([[0.0, 0.0, 1.0], [0.05, 0.0, 1.0], [0.0, 0.05, 1.0]])
    d /= np.linalg.norm(d, axis=-1, keepdims=True)

    @jax.jit
    def loss(values, mat):
        inst = Instances(SDFGridShape(SDFGrid(values)), mat[None])
        h = intersect_scene([inst], o, d)
        return jnp.sum(jnp.where(h.valid, h.t + 0.3 * h.ns[..., 0] - 0.2 * h.ng[..., 1], 0.0))

    ad_v, ad_m = jax.jit(jax.grad(loss, argnums=(0, 1)))(jnp.asarray(g0), jnp.asarray(m))
    assert np.all(np.asarray(intersect_scene(
        [Instances(SDFGridShape(SDFGrid(g0)), m[None])], o, d).valid))  # fmt: skip
    ad_v = np.asarray(ad_v)
    idx = np.argsort(-np.abs(ad_v).ravel())[:4]  # the voxels the hits depend on most
    eps = 1e-6
    for i in idx:
        e = np.zeros(g0.size)
        e[i] = eps
        e = e.reshape(g0.shape)
        fd = (loss(g0 + e, m) - loss(g0 - e, m)) / (2 * eps)
        assert abs(fd - ad_v.ravel()[i]) < 1e-6 * max(1, abs(fd)), (i, fd, ad_v.ravel()[i])
    for ij in [(0, 0), (1, 1), (0, 3), (2, 3)]:
        e = np.zeros((4, 4))
        e[ij] = eps
        fd = (loss(g0, m + e) - loss(g0, m - e)) / (2 * eps)
        assert abs(fd - float(ad_m[ij])) < 1e-6 * max(1, abs(fd)), (ij, fd, ad_m[ij])


def test_scene_dict_and_xml_reach_sdfgrid(tmp_path):
    from jaxgfx.render.scene import load_scene

    v = _grid_of(_sphere_sdf, 9).astype(np.float32)
    write_vol(tmp_path / "s.vol", v)
    base = {"camera": {"origin": [0.5, 0.5, -3], "target": [0.5] * 3,
                       "fov": 20, "width": 4, "height": 4},
            "materials": {"m": {"type": "diffuse", "reflectance": 0.5}}}  # fmt: skip
    for sd in ({"type": "sdfgrid", "filename": "s.vol", "material": "m"},
               {"type": "sdfgrid", "values": v.tolist(), "normals": "analytic", "material": "m",
                "to_world": np.diag([2.0, 2, 2, 1]).tolist()}):  # fmt: skip
        sc = load_scene({**base, "shapes": [sd]}, base_dir=str(tmp_path))
        assert len(sc.shapes) == 1
    with pytest.raises(ValueError, match=r"shapes\[0\]: give exactly one of 'filename'"):
        load_scene({**base, "shapes": [{"type": "sdfgrid", "material": "m"}]})
    with pytest.raises(ValueError, match=r"shapes\[0\]\.filename: .*nope\.vol"):
        load_scene({**base, "shapes": [{"type": "sdfgrid", "filename": "nope.vol"}]},
                   base_dir=str(tmp_path))  # fmt: skip


@pytest.mark.mitsuba
def test_ray_intersections_match_mitsuba_sdfgrid(x64):
    """mitsuba-data's torus grid (40³) in Mitsuba 3 (scalar_rgb, its own sdfgrid, exact cubic
    per voxel) and in jaxgfx: hit/miss, t, the analytic normal (si.n) and the smooth shading
    normal (si.sh_frame.n) at 400 rays through the cube."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(5)
    n = 400
    o = rng.uniform(-0.5, 1.5, (n, 3))
    o[:, 2] = -1.0
    tgt = rng.uniform(0.1, 0.9, (n, 3))
    d = tgt - o
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    scene = mi.load_dict({"type": "scene", "g": {"type": "sdfgrid", "filename": TORUS}})
    ts, ns, ss = [], [], []
    for i in range(n):
        si = scene.ray_intersect(mi.Ray3f(mi.Point3f(*o[i]), mi.Vector3f(*d[i])))
        ts.append(si.t if si.is_valid() else np.inf)
        ns.append(list(si.n))
        ss.append(list(si.sh_frame.n))
    tm, nm, sm = np.array(ts), np.array(ns), np.array(ss)
    s = SDFGridShape(SDFGrid(read_vol(TORUS).astype(np.float64)))
    h = jax.jit(lambda o, d: s.intersect(o, d))(o, d)
    v = np.asarray(h.valid)
    assert v.sum() > 100 and np.array_equal(v, np.isfinite(tm))
    # Mitsuba solves in float32 to |t_near - t_far| < 1e-5 (voxel units)
    assert np.abs(np.asarray(h.t)[v] - tm[v]).max() < 1e-4
    assert np.abs(np.asarray(h.ng)[v] - nm[v]).max() < 1e-3
    assert np.abs(np.asarray(h.ns)[v] - sm[v]).max() < 1e-3


def test_save_scene_writes_the_grid_back(tmp_path):
    """save_scene (Scene or description) writes an sdfgrid as a ``.vol`` in ``<stem>_files/``
    next to the XML (a file-given grid by its absolute path), and read_xml + load_scene give
    the same values, normals option and to_world back; a rotated sphere's frame round-trips."""
    from jaxgfx.render.scene import load_scene
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    v = _grid_of(_sphere_sdf, 6).astype(np.float32)
    write_vol(tmp_path / "s.vol", v)
    m = np.array([[0, -2.0, 0, 1], [2.0, 0, 0, -1], [0, 0, 2.0, 0.5], [0, 0, 0, 1]])
    f = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 1.0, 0]])
    desc = {"camera": {"origin": [0, 0, -6], "target": [0, 0, 0], "fov": 30, "width": 4,
                       "height": 4},
            "materials": {"m": {"type": "diffuse", "reflectance": 0.5}},
            "shapes": [{"type": "sdfgrid", "values": v.tolist(), "normals": "analytic",
                        "to_world": m.tolist(), "material": "m"},
                       {"type": "sdfgrid", "filename": "s.vol", "material": "m"},
                       {"type": "sphere", "center": [3.0, 0, 0], "radius": 0.5, "frame": f.tolist(),
                        "material": "m"}]}  # fmt: skip
    for k, scene in enumerate((desc, load_scene(desc, base_dir=str(tmp_path)))):
        out = save_scene(scene, str(tmp_path / f"out{k}" / "s.xml"), base_dir=str(tmp_path))
        text = pathlib.Path(out).read_text()
        assert 'type="sdfgrid"' in text
        vols = sorted(os.listdir(tmp_path / f"out{k}" / "s_files"))
        assert len(vols) == (2 if k else 1) and vols[0].endswith(".vol"), vols
        back = read_xml(out).desc["shapes"]
        grids = [s for s in back if s["type"] == "sdfgrid"]
        grids += [s for i in back if i["type"] == "instances" for s in i["shapes"]]
        assert len(grids) == 2
        vals = [read_vol(g["filename"]) for g in grids]
        assert all(np.array_equal(w, v) for w in vals)
        sc = load_scene(read_xml(out).desc)
        inst = [s for s in sc.shapes if isinstance(s, Instances)]
        mats = np.concatenate([np.asarray(i.to_world).reshape(-1, 4, 4) for i in inst])
        assert any(np.allclose(t, m, atol=1e-6) for t in mats)
        norms = sorted(getattr(i.shape, "normals", "") for i in inst)
        assert "analytic" in norms
        sph = [s for s in back if s["type"] == "sphere"][0]
        np.testing.assert_allclose(sph["frame"], f, atol=1e-6)
        np.testing.assert_allclose(sph["center"], [3.0, 0, 0], atol=1e-6)


def _grid_render_mean(x, key, scene, idx):
    """Mean image of ``scene`` with grid values ``idx`` (flat) set to ``x[:-1]`` and the red
    reflectance to ``x[-1]``."""
    v = scene.get("shapes.0.grid.values")
    v = v.reshape(-1).at[idx].set(x[:-1]).reshape(v.shape)
    s = scene.replace("shapes.0.grid.values", v)
    s = s.replace("materials.m.reflectance", jnp.stack([x[-1], 0.4, 0.2]))
    return jnp.mean(render(s, key, spp=1, integrator="direct"))


@pytest.mark.slow  # slow: 70 s at load 10-17 on 2 cores (float64 compile of value+grad, FD)
def test_render_gradient_wrt_grid_values_and_material_matches_finite_differences(x64):
    """d(mean image)/d(three grid values, red reflectance) of a 4×4 direct-lighting render of a
    grid sphere under a point light (the view inside the sphere's disk: no silhouette), reverse
    mode against central differences with the same keys (float64)."""
    from jaxgfx.testing import ad_fd_per_key

    v = _grid_of(_sphere_sdf, 9)
    desc = {"camera": {"origin": [0.5, 0.5, -3], "target": [0.5, 0.5, 0.5], "fov": 4,
                       "width": 4, "height": 4},
            "materials": {"m": {"type": "diffuse", "reflectance": [0.7, 0.4, 0.2]}},
            "shapes": [{"type": "sdfgrid", "values": v.tolist(), "material": "m"}],
            "emitters": [{"type": "point", "position": [2, 3, -4],
                          "intensity": [30, 30, 30]}]}  # fmt: skip
    scene = load_scene(desc, dtype=jnp.float64)
    # the vertices of the voxels the camera rays hit (front of the sphere, around (.5, .5, .2))
    idx = jnp.asarray(np.ravel_multi_index(([1, 2, 2], [4, 4, 5], [4, 5, 4]), v.shape))
    x0 = jnp.concatenate([jnp.asarray(v).reshape(-1)[idx], jnp.asarray([0.7])])
    keys = jax.random.split(jax.random.key(0), 2)
    _, ad, fd = ad_fd_per_key(_grid_render_mean, x0, keys, 1e-6, args=(scene, idx))
    assert np.all(np.abs(ad[:, -1]) > 1e-3) and np.abs(ad[:, :-1]).max() > 1e-2, ad
    np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-8)


@pytest.mark.mitsuba
def test_mitsuba_loads_the_written_grid_and_hits_it_as_jaxgfx(tmp_path):
    """The XML save_scene writes for an instanced inline grid loads in Mitsuba 3 (scalar_rgb),
    and its ray_intersect t agrees with jaxgfx's at rays through the placed sphere."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from jaxgfx.render.scene.mitsuba_xml import save_scene

    v = _grid_of(_sphere_sdf, 9).astype(np.float32)
    m = np.diag([2.0, 2.0, 2.0, 1.0])
    m[:3, 3] = [-1.0, -1.0, -1.0]  # the grid's cube [0, 1]³ -> [-1, 1]³
    desc = {"camera": {"origin": [0, 0, -6], "target": [0, 0, 0], "fov": 30, "width": 4,
                       "height": 4},
            "materials": {"m": {"type": "diffuse", "reflectance": 0.5}},
            "shapes": [{"type": "sdfgrid", "values": v.tolist(), "to_world": m.tolist(),
                        "material": "m"}]}  # fmt: skip
    out = save_scene(desc, str(tmp_path / "g.xml"))
    ms = mi.load_file(out)
    sc = load_scene(desc)
    o = np.stack([np.linspace(-0.4, 0.4, 9), np.linspace(0.3, -0.3, 9), np.full(9, -5.0)], 1)
    d = np.tile([0.0, 0.0, 1.0], (9, 1))
    tm = [ms.ray_intersect(mi.Ray3f(mi.Point3f(*a), mi.Vector3f(*b))).t
          for a, b in zip(o, d, strict=True)]  # fmt: skip
    h = jax.jit(lambda o, d: intersect_scene(sc.shapes, o, d))(o.astype(np.float32), d)
    assert np.all(np.asarray(h.valid))
    np.testing.assert_allclose(np.asarray(h.t), tm, atol=1e-4)
