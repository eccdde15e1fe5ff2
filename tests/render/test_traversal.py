"""Traversal backends (Embree, Warp, pure-JAX BVH) against the brute-force JAX reference.

Each backend must return the reference's closest hits (same hit mask, ``t`` to 1e-5 relative,
same primitive wherever the two nearest candidates are distinguishable) on a mesh with
degenerate triangles, axis-aligned quads hit by rays parallel to them, random ``tmin``/``tmax``,
rays starting on surfaces and a transformed copy; gradients w.r.t. vertices must equal the
JAX BVH's (which tests/render/test_accel.py checks against finite differences).
Backends whose optional dependency is missing are skipped with the reason.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import geometry as S
from jaxgfx.render.geometry import accel as T
from jaxgfx.render.geometry import mesh_io as M
from jaxgfx.render.geometry.accel.bvh_sah import wavefront_trace

BACKENDS = [
    pytest.param(
        name,
        marks=pytest.mark.skipif(
            name not in T.available_backends(),
            reason=f"{name} backend not installed (pip install 'jaxgfx[{name}]')",
        ),
    )
    for name in ("embree", "warp")
]
# the JAX BVH itself is checked against brute force in tests/render/test_accel.py; here it is
# the reference of the gradient test


@jax.jit
def _isect(acc, o, d, tmin, tmax):
    h = acc.intersect(o, d, tmin=tmin, tmax=tmax)
    return h.t, h.prim_id


@jax.jit
def _occluded(acc, o, d, tmin, tmax):
    return acc.occluded(o, d, tmax, tmin=tmin)


@jax.jit
def _all_t(tri, o, d, tmin, tmax):
    return S.TRIANGLE_INTERSECTORS["MollerTrumbore1997"](tri, o, d, tmin[:, None], tmax[:, None])


def _mesh():
    """Soup, icosphere, two axis-aligned quads (one at z = 0.5, one at x = -0.25) and two
    degenerate triangles (collinear, a point) in one mesh."""
    soup = M.make_triangle_soup(300, size=0.15, seed=1)
    ico = M.make_icosphere(2, radius=0.4, center=(0.3, -0.2, 0.1))
    quad = np.array([[-1, -1, 0.5], [1, -1, 0.5], [1, 1, 0.5], [-1, 1, 0.5]], np.float32)
    wall = np.array([[-0.25, -1, -1], [-0.25, 1, -1], [-0.25, 1, 1], [-0.25, -1, 1]], np.float32)
    degen = np.array([[0, 0, 0], [0.5, 0, 0], [1, 0, 0], [0.2, 0.2, 0.2]], np.float32)
    quads = [[0, 1, 2], [0, 2, 3]]
    parts = [soup, ico, (quad, quads), (wall, quads), (degen, [[0, 1, 2], [3, 3, 3]])]
    vs, fs, off = [], [], 0
    for p in parts:
        v, f = (np.asarray(p.vertices), np.asarray(p.faces)) if hasattr(p, "vertices") else p
        vs.append(np.asarray(v, np.float32))
        fs.append(np.asarray(f) + off)
        off += len(v)
    return S.TriangleMesh(np.concatenate(vs), np.concatenate(fs))


def _rays(mesh, n=3000, seed=0):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-1.6, 1.6, (n, 3))
    d = rng.uniform(-0.8, 0.8, (n, 3)) - o
    d[::3] = rng.normal(size=d[::3].shape)
    d[: n // 8, 2] = 0.0  # parallel to the z = 0.5 quad
    d[n // 8 : n // 4, 0] = 0.0  # parallel to the x = -0.25 wall
    o[n // 8 : n // 6, 0] = -0.25  # ... and some inside its plane
    # rays starting on surfaces: points on random triangles
    k = slice(n // 4, n // 4 + n // 8)
    tri = np.asarray(mesh.triangles)[rng.integers(0, mesh.faces.shape[0] - 2, n // 8)]
    b = rng.dirichlet(np.ones(3), n // 8)
    o[k] = np.einsum("nk,nkc->nc", b, tri)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tmin = np.where(rng.uniform(size=n) < 0.3, rng.uniform(0, 1.0, n), 0.0)
    tmin[k] = 0.0
    tmax = np.where(rng.uniform(size=n) < 0.3, rng.uniform(0.5, 3.0, n), np.inf)
    f = np.float32
    return o.astype(f), d.astype(f), tmin.astype(f), tmax.astype(f), k


@pytest.fixture(scope="module")
def case():
    mesh = _mesh()
    o, d, tmin, tmax, on_surface = _rays(mesh)
    ts = np.asarray(_all_t(mesh.triangles, o, d, tmin, tmax))
    return mesh, (o, d, tmin, tmax), on_surface, ts


def _compare(t, pid, ts, tmin, tmax, skip, atol=0.0):
    """Assert the reference's hits, allowing disagreement only on ties and on ``skip`` rays."""
    srt = np.sort(ts, axis=1)
    t1, t2 = srt[:, 0], srt[:, 1]
    hit = np.isfinite(t1)
    tmax = np.where(np.isfinite(tmax), tmax, 1e30)
    # ties with the interval limits: a hit within 1e-5 relative of tmin or tmax
    t1f = np.where(hit, t1, -1.0)
    lim = hit & ((np.abs(t1f - tmin) <= 1e-5 * t1f) | (np.abs(t1f - tmax) <= 1e-5 * t1f))
    keep = ~skip & ~lim
    np.testing.assert_array_equal(np.isfinite(t)[keep], hit[keep])
    both = keep & hit
    np.testing.assert_allclose(t[both], t1[both], rtol=1e-5, atol=atol)
    gap = np.where(np.isfinite(t2), t2, 1e30) - np.where(hit, t1, 0.0)
    distinct = both & (gap > 1e-5 * np.abs(t1))
    assert distinct.sum() > 1000
    np.testing.assert_array_equal(pid[distinct], np.argmin(ts, axis=1)[distinct])
    return hit, keep


@pytest.mark.parametrize("name", BACKENDS)
def test_backend_matches_brute_force(case, name):
    mesh, (o, d, tmin, tmax), on_surface, ts = case
    acc = T.build_traversal(mesh, name)
    t, pid = (np.asarray(x) for x in _isect(acc, o, d, tmin, tmax))
    # rays starting on a surface: the self-intersection at t ~ 0 is a tie whichever way
    # rounding goes; beyond it, the hits must agree
    skip = np.zeros(len(o), bool)
    t_ref = np.min(ts, axis=1)
    skip[on_surface] = (t_ref[on_surface] < 1e-4) | (t[on_surface] < 1e-4)
    assert skip.sum() < 0.7 * (on_surface.stop - on_surface.start)
    hit, keep = _compare(t, pid, ts, tmin, tmax, skip)
    assert 1200 < hit.sum() < 2900 and keep.mean() > 0.9
    occ = np.asarray(_occluded(acc, o, d, tmin, tmax))
    # any-hit may also report the self-intersection of rays starting on a surface: not compared
    away = keep.copy()
    away[on_surface] = False
    np.testing.assert_array_equal(occ[away], hit[away])


@jax.jit
def _wavefront16(bvh, o, d, tmin, tmax):
    """The JAX BVH's wavefront traversal with a 16-slot pool: each slot is refilled ~150 times
    and the last steps run with a handful of live rays."""
    t, prim = wavefront_trace(bvh, o, d, tmin, tmax, width=16)
    return t, prim, wavefront_trace(bvh, o, d, tmin, tmax, any_hit=True, width=16)[1] >= 0


def test_jax_wavefront_matches_brute_force(case):
    """Issue 13: the wavefront traversal (ray slots refilled from a queue) finds brute force's
    closest hits on the hard cases (rays parallel to and inside a quad's plane, rays starting on
    surfaces, degenerate triangles, tmin/tmax), and any-hit agrees; a batch whose rays all miss
    the root box returns no hits and tmax; an empty batch returns empty arrays."""
    mesh, (o, d, tmin, tmax), on_surface, ts = case
    bvh = T.build_traversal(mesh, "jax")
    t, pid, occ = (np.asarray(x) for x in _wavefront16(bvh, o, d, tmin, tmax))
    skip = np.zeros(len(o), bool)
    t_ref = np.min(ts, axis=1)
    skip[on_surface] = (t_ref[on_surface] < 1e-4) | (t[on_surface] < 1e-4)
    assert skip.sum() < 0.7 * (on_surface.stop - on_surface.start)
    t = np.where(pid >= 0, t, np.inf)
    hit, keep = _compare(t, pid, ts, tmin, tmax, skip)
    assert 1200 < hit.sum() < 2900 and keep.mean() > 0.9
    away = keep.copy()
    away[on_surface] = False
    np.testing.assert_array_equal(occ[away], hit[away])
    # all rays start outside the scene's box and point away from it
    o_out = np.abs(o) + 5.0
    t, pid, occ = (np.asarray(x) for x in _wavefront16(bvh, o_out, np.abs(d), tmin, tmax))
    assert np.all(pid == -1) and not occ.any()
    np.testing.assert_array_equal(t, tmax)
    t, pid = wavefront_trace(bvh, o[:0], d[:0], tmin[:0], tmax[:0])  # an empty batch
    assert t.shape == pid.shape == (0,)


def test_jax_wavefront_float64(x64):
    """In float64 (x64 on: the pool's counters must stay int32) the wavefront's t equals brute
    force's to 1e-12 and the primitives match, rays from inside and outside a sphere."""
    ico = M.make_icosphere(1, radius=0.8)
    mesh = S.TriangleMesh(np.asarray(ico.vertices, np.float64), ico.faces)
    rng = np.random.default_rng(7)
    o = rng.uniform(-1.5, 1.5, (300, 3))
    d = rng.uniform(-0.5, 0.5, (300, 3)) - o  # aimed at the sphere
    d[::4] = rng.normal(size=d[::4].shape)  # and some in random directions
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    bvh = T.build_traversal(mesh, "jax")
    (t, pid), ref = jax.jit(lambda b, o, d: (b.closest_t(o, d), S.intersect(b.mesh, o, d)))(
        bvh, o, d
    )
    assert t.dtype == jnp.float64 and 150 < int(ref.valid.sum()) < 300
    np.testing.assert_array_equal(np.isfinite(t), np.asarray(ref.valid))
    hit = np.asarray(ref.valid)
    np.testing.assert_allclose(np.asarray(t)[hit], np.asarray(ref.t)[hit], rtol=1e-12)
    np.testing.assert_array_equal(np.asarray(pid)[hit], np.asarray(ref.prim_id)[hit])


@pytest.mark.parametrize("name", BACKENDS)
def test_backend_transformed_mesh(case, name):
    """Rotating, scaling (s) and translating mesh and rays together scales t by s (closed
    form) and keeps the primitive."""
    mesh, (o, d, tmin, tmax), on_surface, ts = case
    a = 0.7
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    s, shift = 2.5, np.array([3.0, -1.0, 0.5])
    moved = S.TriangleMesh(np.asarray(mesh.vertices) @ R.T * s + shift, mesh.faces)
    sel = np.ones(len(o), bool)
    sel[on_surface] = False
    sel[len(o) // 8 : len(o) // 6] = False  # in the wall's plane: rounding decides (a tie)
    o2 = (o[sel] @ R.T * s + shift).astype(np.float32)
    d2 = (d[sel] @ R.T).astype(np.float32)
    acc = T.build_traversal(moved, name)
    t, pid = (np.asarray(x) for x in _isect(acc, o2, d2, tmin[sel] * s, tmax[sel] * s))
    # atol: float32 rounding of the transformed origins (|o| ~ 4 -> ulp 4.8e-7, / s)
    _compare(t / s, pid, ts[sel], tmin[sel], tmax[sel], np.zeros(sel.sum(), bool), atol=1e-6)


def _grad_loss(acc, o, d, w):
    h = acc.intersect(o, d)
    return jnp.sum(jnp.where(h.valid, h.t, 0.0)) + jnp.sum(h.p * w) + jnp.sum(h.ng * w)


_grad = eqx.filter_jit(eqx.filter_grad(_grad_loss))


class _BruteForce(eqx.Module):
    """The brute-force JAX intersector in the backend interface (the gradient reference)."""

    mesh: S.TriangleMesh

    def intersect(self, o, d):
        return S.intersect(self.mesh, o, d)


@pytest.fixture(scope="module")
def grad_case(case):
    mesh, (o, d, _, _), _, _ = case
    o, d = jnp.asarray(o[:500]), jnp.asarray(d[:500])
    w = jnp.asarray(np.random.default_rng(3).normal(size=(500, 3)), jnp.float32)
    ref = _grad(_BruteForce(mesh), o, d, w).mesh.vertices
    return mesh, (o, d, w), np.asarray(ref)


# 5.8 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("name", BACKENDS)
def test_backend_gradients_equal_reference(grad_case, name):
    """d/d(vertices) of a loss over hit records (t, p, ng): identical to brute force's (the
    primitive is chosen by the backend, the record recomputed in JAX; the JAX BVH's gradients
    are checked against finite differences in tests/render/test_accel.py)."""
    mesh, args, ref = grad_case
    g = _grad(T.build_traversal(mesh, name), *args).mesh.vertices
    assert np.max(np.abs(ref)) > 1.0
    np.testing.assert_allclose(np.asarray(g), ref, rtol=1e-4, atol=1e-4)


# the JAX BVH's wavefront loop under vmap: ~13 s of compilation on a loaded 2-core machine
@pytest.mark.parametrize("name", [*BACKENDS, pytest.param("jax", marks=pytest.mark.slow)])
def test_backend_vmap_and_batch_shapes(case, name):
    mesh, (o, d, _, _), _, ts = case
    acc = T.build_traversal(mesh, name)
    lim = np.zeros(64, np.float32), np.full(64, np.inf, np.float32)
    t_ref = np.min(np.asarray(_all_t(mesh.triangles, o[:64], d[:64], *lim)), 1)
    o4, d4 = o[:64].reshape(4, 4, 4, 3), d[:64].reshape(4, 4, 4, 3)
    t_b = jax.jit(lambda a, o, d: a.closest_t(o, d)[0])(acc, o4, d4)
    t_v = jax.jit(jax.vmap(lambda o, d: acc.closest_t(o, d)[0]))(o4, d4)
    for t in (t_b, t_v):
        t = np.asarray(t).reshape(-1)
        assert np.array_equal(np.isfinite(t), np.isfinite(t_ref))
        np.testing.assert_allclose(t[np.isfinite(t)], t_ref[np.isfinite(t_ref)], rtol=1e-5)


def test_resolve_and_errors():
    assert T.resolve_backend("jax") == "jax"
    assert T.resolve_backend("auto") in T.available_backends()
    with pytest.raises(ValueError, match="accel"):
        T.resolve_backend("optix")
    with pytest.raises(TypeError, match="mesh"):
        T.build_traversal(S.Spheres(np.zeros(3), 1.0), T.resolve_backend("auto"))


# ---------------------------------------------------------------------------------------------
# renders and their gradients through each backend


def _mesh_scene():
    from jaxgfx.render.scene import load_scene

    ico = M.make_icosphere(3, radius=0.7, center=(0.0, 0.7, 0.0))  # 1280 triangles
    desc = {
        "camera": {
            "origin": [0, 1.5, 4],
            "target": [0, 0.6, 0],
            "fov": 40,
            "width": 20,
            "height": 20,
        },  # fmt: skip
        "shapes": [
            {
                "type": "mesh",
                "vertices": np.asarray(ico.vertices).tolist(),
                "faces": np.asarray(ico.faces).tolist(),
                "material": "red",
            },  # fmt: skip
            {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0], "size": [6, 6]},
        ],
        "materials": {"red": {"type": "diffuse", "reflectance": [0.8, 0.2, 0.2]}},
        "emitters": [
            {
                "type": "area",
                "radiance": [8, 8, 8],
                "shape": {
                    "type": "rectangle",
                    "center": [0.5, 3, 0.5],
                    "normal": [0, -1, 0],
                    "size": [1.5, 1.5],
                },
            },  # fmt: skip
            {"type": "constant", "radiance": [0.1, 0.1, 0.1]},
        ],
    }
    return load_scene(desc)


class _Plain(eqx.Module):
    """Brute-force JAX intersection of a mesh with the ``mesh`` attribute of the traversal
    objects: the reference."""

    mesh: S.TriangleMesh

    def closest_t(self, o, d, *, tmin, tmax):
        return S.closest_t(self.mesh, o, d, tmin, tmax)


def _with_plain_mesh(scene):
    idx = next(i for i, s in enumerate(scene.shapes) if hasattr(s, "mesh"))
    return eqx.tree_at(lambda s: s.shapes[idx], scene, _Plain(scene.shapes[idx].mesh)), idx


@eqx.filter_jit
def _scene_queries(scene):
    """Camera rays through the scene's two-phase intersection, then shadow rays towards the
    light (vertex gradients through full renders: the slow test below; through hit records:
    test_backend_gradients_equal_reference)."""
    h, w = scene.height, scene.width
    ij = jnp.stack(jnp.meshgrid(jnp.arange(w) + 0.5, jnp.arange(h) + 0.5), -1)
    o, d = scene.camera.generate_ray(ij)
    hit = S.intersect_scene(scene.shapes, o, d)
    light = jnp.asarray([0.5, 3.0, 0.5])
    so = jnp.where(hit.valid[..., None], hit.p + 1e-3 * hit.ng, o)
    sd = light - so
    dist = jnp.linalg.norm(sd, axis=-1)
    occ = S.occluded_scene(scene.shapes, so, sd / dist[..., None], dist)
    return hit, occ


@pytest.fixture(scope="module")
def scene_ref():
    scene = _mesh_scene()
    plain, idx = _with_plain_mesh(scene)
    hit, occ = _scene_queries(plain)
    return scene, idx, (hit, np.asarray(occ))


# issue 9: the Warp case is ~3 s of a loaded 2-core default run: slow (Warp's hits and
# gradients against the reference stay in the default run in the tests above and below)
@pytest.mark.parametrize(
    "name",
    [
        p
        if p.values[0] == "embree"
        else pytest.param(*p.values, marks=[*p.marks, pytest.mark.slow])
        for p in BACKENDS
    ],
)
# issue 9: ~10 s of a loaded 2-core default run; each backend's hits and gradients against the JAX
# reference stay in the default run
@pytest.mark.slow
def test_backend_scene_intersection_equal_reference(scene_ref, name):
    """Through the scene's two-phase intersection (mesh + analytic floor + light): the same hit
    records and shadow-ray visibility as brute force."""
    scene, idx, (h_ref, occ_ref) = scene_ref
    sc = T.scene_with_accel(scene, name)
    assert T.accel_of(sc.shapes[idx]) == name
    hit, occ = _scene_queries(sc)
    np.testing.assert_array_equal(np.asarray(hit.shape_id), np.asarray(h_ref.shape_id))
    assert 0.1 < np.mean(np.asarray(h_ref.shape_id) == idx) < 0.8
    np.testing.assert_allclose(np.asarray(hit.p), np.asarray(h_ref.p), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(np.asarray(hit.ns), np.asarray(h_ref.ns), atol=1e-5)
    np.testing.assert_array_equal(occ, occ_ref)
    assert 0.05 < occ_ref.mean() < 0.95


def _render_and_grad(scene):
    from jaxgfx.render.render import render

    idx = next(i for i, s in enumerate(scene.shapes) if hasattr(s, "mesh"))

    def loss(sc):
        img = render(sc, jax.random.key(1), spp=4, integrator="direct")
        return jnp.mean(img), img

    (_, img), g = eqx.filter_jit(eqx.filter_value_and_grad(loss, has_aux=True))(scene)
    return np.asarray(img), np.asarray(g.shapes[idx].mesh.vertices)


@pytest.fixture(scope="module")
def render_ref():
    scene = _mesh_scene()
    return scene, _render_and_grad(_with_plain_mesh(scene)[0])


@pytest.mark.slow  # three compilations of a differentiated render (~30 s each on 2 cores)
@pytest.mark.parametrize("name", BACKENDS)
def test_backend_render_and_gradient_equal_reference(render_ref, name):
    """Same key, same image and same d(mean image)/d(vertices) as brute force: per-pixel equal
    up to float rounding except on triangle-edge ties, image means within 5 standard errors."""
    scene, (img_ref, g_ref) = render_ref
    img, g = _render_and_grad(T.scene_with_accel(scene, name))
    se = img_ref.std() / np.sqrt(img_ref.size)
    assert abs(img.mean() - img_ref.mean()) < 5 * se
    close = np.isclose(img, img_ref, rtol=1e-4, atol=1e-5)
    assert close.mean() > 0.99
    assert np.abs(g_ref).max() > 1e-3
    np.testing.assert_allclose(g, g_ref, rtol=1e-3, atol=1e-3 * np.abs(g_ref).max())


# ---------------------------------------------------------------------------------------------
# scene loading, backend choice, procedural meshes


def test_load_scene_accel_choice_and_cache():
    from jaxgfx.render.scene import load_scene

    desc = {
        "camera": {"origin": [0, 0, 4], "target": [0, 0, 0], "fov": 30, "width": 4, "height": 4},
        "shapes": [{"type": "mesh", "generator": {"name": "icosphere", "level": 2}}],
    }
    jx = load_scene(desc, accel="jax")
    assert jx.accel == "jax" and jx.shapes[0].mesh.faces.shape == (320, 3)
    auto = load_scene(desc)
    assert auto.accel == T.resolve_backend("auto")
    for name in T.available_backends():
        a, b = jx.with_accel(name), jx.with_accel(name)
        assert a.accel == name
        # built once per mesh: the second conversion reuses the native scene / BVH
        assert jax.tree_util.tree_all(
            jax.tree_util.tree_map(lambda x, y: x is y, a.shapes[0], b.shapes[0])
        )
    with pytest.raises(ValueError, match="accel"):
        load_scene(desc, accel="optix")
    from jaxgfx.render.render import render

    with pytest.raises(ValueError, match="accel"):  # checked before anything is traced
        render(jx, jax.random.key(0), spp=1, accel="optix")
    bad = {**desc, "shapes": [{"type": "mesh", "generator": {"name": "bunny"}}]}
    with pytest.raises(ValueError, match=r"shapes\[0\]\.generator\.name"):
        load_scene(bad)
    bad = {**desc, "shapes": [{"type": "mesh", "generator": {"name": "blob", "levels": 2}}]}
    with pytest.raises(ValueError, match=r"shapes\[0\]\.generator"):
        load_scene(bad)


def test_make_blob_is_star_shaped_and_closed():
    """Rays from the centre through each face's centroid hit that face first, at the centroid's
    distance (a star-shaped, closed surface; brute-force JAX intersection), vertex normals point
    outwards, and the triangle count is 20 * 4**level."""
    c = np.array([0.2, -0.1, 0.3])
    blob = M.make_blob(2, seed=1, radius=0.7, center=c)
    assert blob.faces.shape == (320, 3)
    v = np.asarray(blob.vertices, np.float64)
    r = np.linalg.norm(v - c, axis=1)
    assert r.max() / r.min() > 1.3  # visibly bumpy, not a sphere
    cen = v[np.asarray(blob.faces)].mean(axis=1) - c
    dist = np.linalg.norm(cen, axis=1)
    d = (cen / dist[:, None]).astype(np.float32)
    o = np.broadcast_to(c, d.shape).astype(np.float32)
    h = jax.jit(lambda m, o, d: S.intersect(m, o, d))(blob, o, d)
    np.testing.assert_array_equal(np.asarray(h.prim_id), np.arange(320))
    np.testing.assert_allclose(np.asarray(h.t), dist, rtol=1e-5)
    assert np.all(np.sum(np.asarray(blob.normals) * (v - c), axis=1) > 0)
    np.testing.assert_array_equal(M.make_blob(2, seed=1).vertices, M.make_blob(2, seed=1).vertices)
