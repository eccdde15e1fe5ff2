"""Normal mapping and bump mapping (Mitsuba 3 ``normalmap`` / ``bumpmap``): closed forms at the
BSDF level, the sampler against its pdf, hard cases, surface tangents, the loaders' errors, and
(slow) renders: bit-identity, texel / scale gradients against finite differences."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import load_scene, render
from jaxgfx.render.bsdf import (
    BumpMap,
    Diffuse,
    NormalMap,
    RoughConductor,
    TangentSpace,
    make_bsdf,
)
from jaxgfx.render.bsdf.texture import Texture
from jaxgfx.render.geometry import Rectangles, Spheres, TriangleMesh, intersect_scene
from jaxgfx.render.geometry.tangent import surface_tangents
from jaxgfx.testing import ad_fd_per_key, chi2_test

UV = np.array([0.3, 0.6])  # NumPy: float64 under the x64 fixture


def _tangents(a=1.0, b=1.0, angle=0.0, sigma=1.0, dtype=jnp.float64):
    """Tangent space of a parallelogram-free rectangle whose dp/du has length ``a`` along
    ``s`` (rotated by ``angle`` about +z) and dp/dv length ``b`` along ``t``."""
    c, s_ = math.cos(angle), math.sin(angle)
    s = jnp.array([c, s_, 0.0], dtype)
    t = sigma * jnp.array([-s_, c, 0.0], dtype)
    return TangentSpace(s=s, t=t, du=jnp.array([a, 0.0], dtype), dv=jnp.array([0.0, b], dtype))


def _enc(n):
    n = np.asarray(n, np.float64)
    return (n / np.linalg.norm(n) + 1.0) / 2.0


def _dirs(rng, n, dtype=np.float64):
    w = rng.normal(size=(n, 3))
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    return jnp.asarray(w, dtype)


def test_flat_normal_map_is_the_nested_bsdf(x64, rng):
    """(0.5, 0.5, 1) is the unperturbed normal: a rough conductor in a frame turned about the
    normal (tangent at 0.7 rad) gives its eval, pdf and samples to 1e-12 (the render-level
    bit identity is in the slow test below)."""
    inner = RoughConductor(0.3)
    nm = NormalMap(inner, jnp.array([0.5, 0.5, 1.0]))
    wo, wi = _dirs(rng, 64), _dirs(rng, 64)
    wo = wo.at[:, 2].set(jnp.abs(wo[:, 2]))
    u1, u2 = jnp.asarray(rng.uniform(size=64)), jnp.asarray(rng.uniform(size=(64, 2)))

    @jax.jit
    def run(b, tg):
        m = b.at(UV, tg) if tg is not None else b
        return m.eval(wo, wi), m.pdf(wo, wi), m.sample(wo, u1, u2)

    f0, p0, s0 = run(inner, None)
    f2, p2, s2 = run(nm, _tangents(angle=0.7))
    np.testing.assert_allclose(f2, f0, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(p2, p0, rtol=1e-12, atol=1e-15)
    a, b = s2, s0
    np.testing.assert_allclose(a.wi, b.wi, atol=1e-12)
    np.testing.assert_allclose(a.weight, b.weight, rtol=1e-10, atol=1e-14)


def _diffuse_tilted(rho, n, wo, wi):
    """Diffuse shaded with the normal ``n`` and Mitsuba's leak rule, in closed form."""
    co, ci = wo @ n, wi @ n
    ok = (co > 0) & (ci > 0) & (wi[:, 2] > 0)
    return np.where(ok, rho / math.pi * ci, 0.0)


@pytest.mark.parametrize("sigma", [1.0, -1.0])
def test_tilted_normal_map_diffuse_closed_form(x64, rng, sigma):
    """A constant map of the unit normal ``n = (x, y, z)`` (tangent space) shades like a
    diffuse surface of normal ``x s + y t + z n`` (``t = sigma (+z x s)``: both sides)."""
    n_ts = np.array([0.4, -0.3, 0.8])
    n_ts /= np.linalg.norm(n_ts)
    tg = _tangents(angle=0.4, sigma=sigma)
    n_loc = n_ts[0] * np.asarray(tg.s) + n_ts[1] * np.asarray(tg.t) + n_ts[2] * np.eye(3)[2]
    wo, wi = _dirs(rng, 500), _dirs(rng, 500)
    nm = NormalMap(Diffuse(0.7), jnp.asarray(_enc(n_ts)))
    got, pdf = jax.jit(lambda nm, tg: (nm.at(UV, tg).eval(wo, wi), nm.at(UV, tg).pdf(wo, wi)))(
        nm, tg
    )
    ref = _diffuse_tilted(0.7, n_loc, np.asarray(wo), np.asarray(wi))
    np.testing.assert_allclose(got, np.repeat(ref[:, None], 3, 1), atol=1e-12)
    assert (ref > 0).mean() > 0.1  # the test sees lit directions
    # pdf: cosine density about the tilted normal, zero for leaking directions
    ok = (np.asarray(wi) @ n_loc > 0) & (np.asarray(wi)[:, 2] > 0) & (np.asarray(wo) @ n_loc > 0)
    np.testing.assert_allclose(pdf, np.where(ok, np.asarray(wi) @ n_loc / math.pi, 0.0), atol=1e-12)


def test_bump_linear_ramp_is_the_tilted_normal(x64, rng):
    """Height ``h(u) = 4 u - 1/2`` (a 4-texel ramp, bilinear, interior u) times ``scale``: on a
    surface with ``|dp/du| = a``, ``|dp/dv| = b`` the normal is
    ``normalize(-scale 4 / a, 0, 1)``."""
    a, b, k = 2.0, 0.5, 0.3
    tex = Texture(jnp.array([[0.0, 1.0, 2.0, 3.0]]), wrap="clamp")
    bm = BumpMap(Diffuse(0.6), tex, k).at(jnp.array([0.45, 0.5]), _tangents(a, b))
    n = np.array([-k * 4 / a, 0.0, 1.0])
    n /= np.linalg.norm(n)
    np.testing.assert_allclose(bm.frame.n, n, atol=1e-14)
    nm = NormalMap(Diffuse(0.6), jnp.asarray(_enc(n))).at(UV, _tangents(a, b))
    wo, wi = _dirs(rng, 300), _dirs(rng, 300)
    np.testing.assert_allclose(bm.eval(wo, wi), nm.eval(wo, wi), atol=1e-12)
    ref = _diffuse_tilted(0.6, n, np.asarray(wo), np.asarray(wi))
    np.testing.assert_allclose(bm.eval(wo, wi)[:, 0], ref, atol=1e-12)
    # along v, with a rotated tangent: h_v = 4 on a (b along t) surface
    tex_v = Texture(jnp.array([[0.0], [1.0], [2.0], [3.0]]), wrap="clamp")
    bv = BumpMap(Diffuse(0.6), tex_v, k).at(jnp.array([0.5, 0.45]), _tangents(a, b, angle=1.0))
    nv = np.array([0.0, -k * 4 / b, 1.0])
    nv /= np.linalg.norm(nv)
    want = nv[0] * np.asarray(_tangents(angle=1.0).s) + nv[1] * np.asarray(_tangents(angle=1.0).t)
    np.testing.assert_allclose(bv.frame.n, want + nv[2] * np.eye(3)[2], atol=1e-14)


@pytest.mark.parametrize(
    "name,inner,n_ts,cos_o",
    [
        ("diffuse tilt 35", Diffuse(0.5), [math.sin(0.6), 0.0, math.cos(0.6)], 0.7),
        pytest.param(
            "ggx 0.3 tilt 50",
            RoughConductor(0.3),
            [0.0, math.sin(0.9), math.cos(0.9)],
            0.5,
            marks=pytest.mark.slow,  # slow: ~3 s on 2 cores (loaded)
        ),
    ],
)
def test_wrapped_sampling_matches_pdf(name, inner, n_ts, cos_o):
    """Chi² of the perturbed sampler against the wrapper's pdf (leaking samples are dropped:
    their mass is missing from both), and weight == eval / pdf on the kept samples."""
    m = NormalMap(inner, jnp.asarray(_enc(n_ts), jnp.float32)).at(
        jnp.array([0.5, 0.5], jnp.float32), _tangents(dtype=jnp.float32)
    )
    wo = jnp.array([math.sqrt(1 - cos_o**2), 0.0, cos_o], jnp.float32)
    store = {}

    @jax.jit
    def sample(u1, u2):
        return m.sample(jnp.broadcast_to(wo, u2.shape[:-1] + (3,)), u1, u2)

    def sample_fn(u1, u2):
        s = sample(u1, u2)
        store["s"] = s
        return jnp.where((s.pdf > 0)[:, None], s.wi, 0.0)

    n = 40_000
    ok, p, det = chi2_test(
        sample_fn,
        jax.jit(lambda w: m.pdf(jnp.broadcast_to(wo, w.shape), w)),
        key=jax.random.key(3),
        n_samples=n,
        ires=10,
        test_count=2,
    )
    assert ok, (p, det["message"])
    frac = float(det["observed"].sum()) / n
    tol = 4 * math.sqrt(max(frac * (1 - frac), 1e-4) / n) + 3e-3
    assert det["pdf_integral"] == pytest.approx(frac, abs=tol)
    assert frac < 0.999  # the tilt makes some samples leak
    s = store["s"]
    kept = np.asarray(s.pdf) > 0
    f = np.asarray(m.eval(jnp.broadcast_to(wo, s.wi.shape), s.wi))
    np.testing.assert_allclose(
        np.asarray(s.weight)[kept], f[kept] / np.asarray(s.pdf)[kept, None], rtol=2e-3
    )


_GRAZE = jnp.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])


@jax.jit
def _hard(c, wo, wi, u2):
    def f(cc):
        m = NormalMap(Diffuse(0.4), cc).at(UV, _tangents(angle=0.3))
        return m.eval(wo, wi), m.pdf(wo, wi)

    val, pdf = f(c)
    g = jax.grad(lambda cc: jnp.sum(f(cc)[0]) + jnp.sum(f(cc)[1]))(c)
    s = NormalMap(Diffuse(0.5), c).at(UV, _tangents()).sample(wo, jnp.full(wo.shape[0], 0.3), u2)
    return val, pdf, g, s


@pytest.mark.parametrize(
    "c",
    [
        [0.5, 0.5, 0.0],  # the map's normal points straight down (flips below the surface)
        [1.0, 0.5, 0.45],  # tilted past the horizon
        [0.5, 0.5, 0.5],  # the zero vector: the unperturbed frame
        [1.0, 0.5, 0.5],  # exactly in the tangent plane, along s
    ],
)
def test_hard_normals_finite_values_and_gradients(x64, c):
    rng = np.random.default_rng(1)
    wo = jnp.concatenate([_dirs(rng, 64), _GRAZE, _GRAZE])
    wi = jnp.concatenate([_dirs(rng, 64), _GRAZE, _GRAZE[::-1]])
    u2 = jnp.asarray(rng.uniform(size=(wo.shape[0], 2)))
    val, pdf, g, s = _hard(jnp.asarray(c, jnp.float64), wo, wi, u2)
    assert np.all(np.isfinite(val)) and np.all(np.asarray(val) >= 0)
    assert np.all(np.isfinite(pdf)) and np.all(np.asarray(pdf) >= 0)
    assert np.all(np.isfinite(g))
    for x in (s.wi, s.pdf, s.weight):
        assert np.all(np.isfinite(x))
    assert np.all(np.asarray(s.weight) >= 0)
    if c[2] == 0.0:  # a map normal below the surface: nothing leaks through, all black
        assert np.all(np.asarray(val) == 0) and np.all(np.asarray(s.weight) == 0)
    if c == [0.5, 0.5, 0.5]:  # zero vector -> unperturbed
        ref = Diffuse(0.4).eval(wo, wi)
        np.testing.assert_allclose(val, ref, rtol=1e-12, atol=1e-15)


_WO = np.array([[0.3, 0.2, 0.93], [-0.5, 0.1, 0.86]])
_WI = np.array([[-0.2, 0.4, 0.89], [0.6, -0.3, 0.74]])
_UVS = np.array([[0.3, 0.6], [0.7, 0.2]])


def _nm_eval(im):
    m = NormalMap(Diffuse(0.5), Texture(im)).at(_UVS, _tangents())
    return jnp.sum(m.eval(_WO, _WI) * jnp.array([0.5, 1.0, 1.5]))


def _bm_eval(x):  # x = (scale, 9 heights)
    tex = Texture(x[1:].reshape(3, 3, 1))
    m = BumpMap(Diffuse(0.5), tex, x[0]).at(_UVS, _tangents(2.0, 0.5))
    return jnp.sum(m.eval(_WO, _WI))


def _fd(f, x, h=1e-6):
    e = h * jnp.eye(x.size).reshape((x.size,) + x.shape)
    vals = jax.jit(jax.vmap(f))(jnp.concatenate([x + e, x - e]))
    return ((vals[: x.size] - vals[x.size :]) / (2 * h)).reshape(x.shape)


@pytest.mark.slow  # slow: ~8 s on 2 loaded cores (the vmapped FD programs' compile)
def test_texel_and_scale_gradients_of_eval(x64, rng):
    """Reverse-mode derivatives of the wrapped eval w.r.t. normal-map texels and bump ``scale``
    and heights against central differences (float64, step 1e-6)."""
    img = jnp.asarray(rng.uniform(0.3, 0.7, size=(2, 2, 3))).at[..., 2].set(0.9)
    g = jax.jit(jax.grad(_nm_eval))(img)
    fd = _fd(_nm_eval, img)
    assert np.abs(fd).max() > 1e-3
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)
    x = jnp.concatenate([jnp.array([0.2]), jnp.asarray(rng.uniform(size=9))])
    g = jax.jit(jax.grad(_bm_eval))(x)
    fd = _fd(_bm_eval, x)
    assert abs(float(fd[0])) > 1e-3
    np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)


def _sphere_param(u, v, c, r):
    th, ph = math.pi * v, 2 * math.pi * u
    return c + r * np.array(
        [math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)]
    )


def test_surface_tangents_are_the_uv_derivatives(x64):
    """dp/du, dp/dv of spheres, rectangles and UV meshes against central differences of the
    parameterisations that give the hit's uv."""
    c, r = np.array([0.1, -0.2, 0.3]), 1.5
    mesh = TriangleMesh(
        jnp.array([[10.0, 0, 0], [12.0, 0.2, 0], [10.3, 1.5, 0.4]]),
        jnp.array([[0, 1, 2]]),
        uvs=jnp.array([[0.1, 0.2], [0.9, 0.3], [0.2, 0.8]]),
    )
    shapes = [
        Spheres(jnp.asarray(c)[None], jnp.array([r])),
        Rectangles(jnp.array([5.0, 0, 0]), jnp.array([0.0, 2, 0]), jnp.array([0.0, 0, 3])),
        mesh,
    ]
    o = jnp.array([[0.1, -0.2, -3.0], [0.1, -3.0, 0.9], [2.0, 0.5, 0.4], [10.7, 0.5, 3.0]])
    d = jnp.array([[0.0, 0, 1], [0.0, 1, 0], [1.0, 0, 0], [0.0, 0, -1]])
    o = o.at[1].set([0.6, -3.0, 0.9])
    hit = jax.jit(intersect_scene)(shapes, o, d)
    assert np.array_equal(hit.shape_id, [0, 0, 1, 2])
    du, dv = (np.asarray(x) for x in jax.jit(surface_tangents)(shapes, hit))
    e = 1e-6
    for i in (0, 1):
        u, v = np.asarray(hit.uv[i])
        fu = (_sphere_param(u + e, v, c, r) - _sphere_param(u - e, v, c, r)) / (2 * e)
        fv = (_sphere_param(u, v + e, c, r) - _sphere_param(u, v - e, c, r)) / (2 * e)
        np.testing.assert_allclose(du[i], fu, atol=1e-6)
        np.testing.assert_allclose(dv[i], fv, atol=1e-6)
    np.testing.assert_allclose(du[2], [0, 2, 0], atol=1e-12)
    np.testing.assert_allclose(dv[2], [0, 0, 3], atol=1e-12)
    # mesh: the affine map uv -> p sends each vertex's uv difference to its position difference
    vv, tt = np.asarray(mesh.vertices), np.asarray(mesh.uvs)
    for k in (1, 2):
        dt = tt[k] - tt[0]
        np.testing.assert_allclose(dt[0] * du[3] + dt[1] * dv[3], vv[k] - vv[0], atol=1e-12)


def test_bad_inputs_are_named():
    with pytest.raises(ValueError, match="normalmap: expected a texture with 3 channel"):
        NormalMap(Diffuse(0.5), Texture(jnp.ones((2, 2, 1))))
    with pytest.raises(ValueError, match="bsdf: missing nested BSDF"):
        NormalMap(None, jnp.array([0.5, 0.5, 1.0]))
    with pytest.raises(TypeError, match="bsdf: expected a BSDF"):
        NormalMap("diffuse", jnp.array([0.5, 0.5, 1.0]))
    with pytest.raises(ValueError, match="normalmap: missing texture"):
        make_bsdf({"type": "normalmap", "bsdf": {"type": "diffuse"}})
    with pytest.raises(TypeError, match="height: expected a bitmap texture"):
        BumpMap(Diffuse(0.5), 0.3)
    with pytest.raises(ValueError, match="scale"):
        BumpMap(Diffuse(0.5), Texture(jnp.ones((2, 2))), float("nan"))
    with pytest.raises(TypeError, match="cannot wrap another one"):
        NormalMap(NormalMap(Diffuse(0.5), jnp.array([0.5, 0.5, 1.0])), jnp.array([0.5, 0.5, 1]))
    base = _plane({"type": "normalmap", "bsdf": {"type": "diffuse"},
                   "normalmap": {"type": "bitmap", "image": [[0.5, 0.5]]}})  # fmt: skip
    with pytest.raises(ValueError, match=r"materials\.m: normalmap: expected a texture with 3"):
        load_scene(base)
    with pytest.raises(ValueError, match=r"materials\.m: bsdf: 'normalmap' needs a nested"):
        load_scene(_plane({"type": "normalmap", "normalmap": {"type": "bitmap", "image": [[1]]}}))
    with pytest.raises(ValueError, match=r"materials\.m: scale: unknown key for 'normalmap'"):
        load_scene(_plane(_nm_desc() | {"scale": 2.0}))
    with pytest.raises(ValueError, match=r"materials\.m: height: 'bumpmap' needs a texture"):
        load_scene(_plane({"type": "bumpmap", "bsdf": {"type": "diffuse"}}))


def _nm_desc(img=((0.5, 0.5, 1.0),), inner=None):
    return {
        "type": "normalmap",
        "bsdf": inner or {"type": "diffuse", "reflectance": 0.5},
        "normalmap": {"type": "bitmap", "image": [list(map(list, img))]},
    }


def _plane(material, width=4):
    return {
        "camera": {"origin": [0, 3, 0.01], "target": [0, 0, 0], "up": [0, 0, -1], "fov": 30,
                   "width": width, "height": width},
        "shapes": [{"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0],
                    "size": [2, 2], "material": "m"}],
        "materials": {"m": material},
        "emitters": [{"type": "point", "position": [0.3, 2.0, 0.2], "intensity": 10}],
    }  # fmt: skip


KEY = jax.random.key(5)


def _loss(x, key, scene, path, w):
    img = render(scene.replace(path, x), key, spp=2, integrator="direct")
    return jnp.sum(jnp.mean(img, (0, 1)) * w)


@pytest.mark.slow  # slow: ~53 s on 2 loaded cores (four scenes compiled, path and direct)
def test_render_flat_map_bit_identical_and_gradients_match_fd(x64):
    """A flat normal map renders bit for bit like its nested material (path tracer, so BSDF
    sampling and NEE both run through the wrapper); d loss / d texels and d loss / d scale
    match same-key central differences (a point light, no sampled emitter: the image is a
    smooth deterministic function of the parameters per key)."""
    plain = render(load_scene(_plane({"type": "diffuse", "reflectance": 0.5})), KEY, spp=2)
    flat = render(load_scene(_plane(_nm_desc())), KEY, spp=2)
    assert float(plain.mean()) > 0.05
    assert np.array_equal(np.asarray(plain), np.asarray(flat))
    w = jnp.array([0.5, 1.0, 1.5])
    keys = jax.random.split(KEY, 2)
    img = [[[0.55, 0.45, 0.9], [0.4, 0.5, 0.95]], [[0.5, 0.6, 0.92], [0.62, 0.38, 0.9]]]
    sc = load_scene(_plane(_nm_desc() | {"normalmap": {"type": "bitmap", "image": img}}))
    x = jnp.asarray(img)
    _, ad, fd = ad_fd_per_key(_loss, x, keys, 1e-5, args=(sc, "materials.m.normalmap.image", w))
    assert np.abs(fd).max() > 1e-3
    np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-8)
    bump = {"type": "bumpmap", "bsdf": {"type": "diffuse", "reflectance": 0.5}, "scale": 0.05,
            "height": {"type": "bitmap", "image": [[0.0, 1.0, 0.3], [0.5, 0.2, 0.9]]}}  # fmt: skip
    sb = load_scene(_plane(bump))
    _, ad, fd = ad_fd_per_key(
        _loss, jnp.asarray(0.05), keys, 1e-6, args=(sb, "materials.m.scale", w)
    )
    assert np.abs(fd).max() > 1e-3
    np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-8)
