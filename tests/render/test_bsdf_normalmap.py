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
from jaxgfx.render.bsdf._normalmap import shadow_terminator
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
    """(0.5, 0.5, 1) is the unperturbed normal: an anisotropic rough conductor whose tangent
    space is turned about the normal by 0.7 rad gives the eval and pdf of the nested BSDF
    turned by the same angle, to 1e-12 (sampling through the wrapper: the closed-form test
    below; the render-level bit identity: the slow test below)."""
    inner = RoughConductor(0.3, alpha_v=0.1)
    nm = NormalMap(inner, jnp.array([0.5, 0.5, 1.0]))
    wo, wi = _dirs(rng, 64), _dirs(rng, 64)
    wo = wo.at[:, 2].set(jnp.abs(wo[:, 2]))
    c, s_ = math.cos(0.7), math.sin(0.7)
    rot = jnp.array([[c, s_, 0.0], [-s_, c, 0.0], [0.0, 0.0, 1.0]])  # world -> tangent frame

    @jax.jit
    def run(nm, tg):
        m = nm.at(UV, tg)
        wo_t, wi_t = wo @ rot.T, wi @ rot.T
        # the unturned eval in the same program: eagerly, its op-by-op compiles cost more
        turned = nm.bsdf.eval(wo_t, wi_t), nm.bsdf.pdf(wo_t, wi_t)
        return m.eval(wo, wi), m.pdf(wo, wi), *turned, nm.bsdf.eval(wo, wi)

    f2, p2, f0, p0, f_unturned = run(nm, _tangents(angle=0.7))
    assert np.abs(np.asarray(f0) - np.asarray(f_unturned)).max() > 1e-3  # anisotropic
    np.testing.assert_allclose(f2, f0, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(p2, p0, rtol=1e-12, atol=1e-15)


def _tan2(z):
    return (1.0 - z * z) / (z * z)


def _diffuse_tilted(rho, n, wo, wi, flip=True, shadow=True):
    """Diffuse shaded with the normal ``n`` (local, one per direction or shared) by Mitsuba 3's
    rules, written out in NumPy: leak rule, the flip of an invalid normal's tangential part
    (Schüssler et al. 2017) and Estevez et al.'s (2019) shadowing factor
    ``2 / (1 + sqrt(1 + min(tan²θ_n / 8, 1) tan²θ_i))``."""
    n = np.broadcast_to(np.asarray(n, np.float64), wo.shape).copy()
    if flip:
        bad = wo[:, 2] * np.sum(wo * n, -1) <= 0
        n[bad, :2] *= -1
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    co, ci = np.sum(wo * n, -1), np.sum(wi * n, -1)
    ok = (co > 0) & (ci > 0) & (wi[:, 2] > 0)
    g = 1.0
    if shadow:
        with np.errstate(divide="ignore", invalid="ignore"):
            a2 = np.minimum(_tan2(n[:, 2]) / 8, 1.0)
            g = 2 / (1 + np.sqrt(1 + a2 * _tan2(wi[:, 2])))
    return np.where(ok, rho / math.pi * ci * g, 0.0)


@pytest.mark.parametrize("sigma,flags", [(1.0, True), (-1.0, True), (1.0, False)])
def test_tilted_normal_map_diffuse_closed_form(x64, rng, sigma, flags):
    """A constant map of the unit normal ``n = (x, y, z)`` (tangent space) shades like a
    diffuse surface of normal ``x s + y t + z n`` (``t = sigma (+z x s)``: both sides), with
    Mitsuba 3's ``flip_invalid_normals`` and ``use_shadowing_function`` on (default) or off."""
    n_ts = np.array([0.4, -0.3, 0.8])
    n_ts /= np.linalg.norm(n_ts)
    tg = _tangents(angle=0.4, sigma=sigma)
    n_loc = n_ts[0] * np.asarray(tg.s) + n_ts[1] * np.asarray(tg.t) + n_ts[2] * np.eye(3)[2]
    wo, wi = _dirs(rng, 500), _dirs(rng, 500)
    kw = {"flip_invalid_normals": flags, "use_shadowing_function": flags}
    nm = NormalMap(Diffuse(0.7), jnp.asarray(_enc(n_ts)), **kw)
    u1, u2 = jnp.asarray(rng.uniform(size=500)), jnp.asarray(rng.uniform(size=(500, 2)))
    got, pdf, smp = _eval_pdf(nm, tg, wo, wi, u1, u2)
    wo, wi = np.asarray(wo), np.asarray(wi)
    ref = _diffuse_tilted(0.7, n_loc, wo, wi, flags, flags)
    np.testing.assert_allclose(got, np.repeat(ref[:, None], 3, 1), atol=1e-12)
    assert (ref > 0).mean() > 0.1  # the test sees lit directions
    flipped = wo[:, 2] * (wo @ n_loc) <= 0
    assert flipped.mean() > 0.05  # and viewers behind the mapped normal
    # pdf: cosine density about the (flipped) tilted normal, zero for leaking directions
    n = np.where(flipped[:, None] & flags, n_loc * [-1, -1, 1], n_loc)
    ok = (np.sum(wi * n, -1) > 0) & (wi[:, 2] > 0) & (np.sum(wo * n, -1) > 0)
    np.testing.assert_allclose(pdf, np.where(ok, np.sum(wi * n, -1) / math.pi, 0.0), atol=1e-12)
    # samples: kept ones have the closed-form pdf and weight eval / pdf; the discarded ones
    # (pdf 0, weight 0) are exactly those that cross a surface or whose viewer is below n'
    w, sp, sw = (np.asarray(x) for x in (smp.wi, smp.pdf, smp.weight))
    np.testing.assert_allclose(np.linalg.norm(w, axis=-1), 1.0, atol=1e-12)
    cos_n = np.sum(w * n, -1)
    valid = (np.sum(wo * n, -1) > 0) & (w[:, 2] > 0) & (cos_n > 0)
    kept = sp > 0
    assert np.array_equal(kept, valid) and 0.05 < kept.mean() < 0.95
    np.testing.assert_allclose(sp[kept], cos_n[kept] / math.pi, rtol=1e-12)
    ref_w = _diffuse_tilted(0.7, n_loc, wo, w, flags, flags)[kept] / sp[kept]
    np.testing.assert_allclose(sw[kept], np.repeat(ref_w[:, None], 3, 1), rtol=1e-12)
    assert np.all(sw[~kept] == 0)


@jax.jit
def _eval_pdf(m, tg, wo, wi, u1, u2):
    mm = m.at(UV, tg)
    return mm.eval(wo, wi), mm.pdf(wo, wi), mm.sample(wo, u1, u2)


def test_shadow_terminator_values_and_hard_cases(x64):
    """Estevez et al.'s factor at hand-computed points (normal tilted 45°: a² = 1/8; light at
    60°: tan² = 3 -> 2 / (1 + sqrt(1 + 3/8))), its limits (1 for an unperturbed normal or a
    light overhead, 0 at grazing light), a normal in the tangent plane (a² = 1), and finite
    gradients at the singular points ``n_z = 0``, ``w_z = 0``."""
    r = math.sqrt(0.5)
    n = jnp.array([[r, 0, r], [0, 0, 1.0], [r, 0, r], [1.0, 0, 0], [1.0, 0, 0], [r, 0, r]])
    w = jnp.array([[math.sin(math.pi / 3), 0, 0.5], [0.6, 0, 0.8], [0, 0, 1.0],
                   [0.6, 0, 0.8], [1.0, 0, 0], [0, 1.0, 0]])  # fmt: skip
    g = jax.jit(shadow_terminator)(n, w)
    want = [2 / (1 + math.sqrt(1 + 3 / 8)), 1.0, 1.0, 2 / (1 + math.sqrt(1 + 0.75**2)), 0, 0]
    np.testing.assert_allclose(g, want, atol=1e-13)
    grads = jax.jit(jax.grad(lambda n, w: jnp.sum(shadow_terminator(n, w)), (0, 1)))(n, w)
    assert all(np.all(np.isfinite(x)) for x in grads)


def test_bump_linear_ramp_is_the_tilted_normal(x64, rng):
    """Height ``h(u) = 4 u - 1/2`` (a 4-texel ramp, bilinear, interior u) times ``scale``: on a
    surface with ``|dp/du| = a``, ``|dp/dv| = b`` the normal is
    ``normalize(-scale 4 / a, 0, 1)``."""
    a, b, k = 2.0, 0.5, 0.3
    n = np.array([-k * 4 / a, 0.0, 1.0])
    n /= np.linalg.norm(n)
    nv = np.array([0.0, -k * 4 / b, 1.0])  # along v, with a rotated tangent: h_v = 4
    nv /= np.linalg.norm(nv)
    wo, wi = _dirs(rng, 300), _dirs(rng, 300)

    @jax.jit
    def run(k, enc_n):
        tex = Texture(jnp.array([[0.0, 1.0, 2.0, 3.0]]), wrap="clamp")
        bm = BumpMap(Diffuse(0.6), tex, k).at(jnp.array([0.45, 0.5]), _tangents(a, b))
        nm = NormalMap(Diffuse(0.6), enc_n).at(UV, _tangents(a, b))
        tex_v = Texture(jnp.array([[0.0], [1.0], [2.0], [3.0]]), wrap="clamp")
        bv = BumpMap(Diffuse(0.6), tex_v, k).at(jnp.array([0.5, 0.45]), _tangents(a, b, 1.0))
        return bm.frame.n, bm.eval(wo, wi), nm.eval(wo, wi), bv.frame.n

    bm_n, bm_f, nm_f, bv_n = run(k, jnp.asarray(_enc(n)))
    np.testing.assert_allclose(bm_n, n, atol=1e-14)
    np.testing.assert_allclose(bm_f, nm_f, atol=1e-12)
    ref = _diffuse_tilted(0.6, n, np.asarray(wo), np.asarray(wi))
    np.testing.assert_allclose(bm_f[:, 0], ref, atol=1e-12)
    tg1 = _tangents(angle=1.0)
    want = nv[0] * np.asarray(tg1.s) + nv[1] * np.asarray(tg1.t) + nv[2] * np.eye(3)[2]
    np.testing.assert_allclose(bv_n, want, atol=1e-14)


@pytest.mark.parametrize(
    "name,inner,n_ts,cos_o",
    [
        pytest.param(
            "diffuse tilt 35",
            Diffuse(0.5),
            [math.sin(0.6), 0.0, math.cos(0.6)],
            0.7,
            marks=pytest.mark.slow,  # slow: ~2.5 s CPU (the chi2 programs' compile)
        ),
        pytest.param(
            "ggx 0.3 tilt 50",
            RoughConductor(0.3),
            [0.0, math.sin(0.9), math.cos(0.9)],
            0.5,
            marks=pytest.mark.slow,  # slow: ~1.5 s CPU after the diffuse case, ~3 s alone
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

    n = 20_000
    ok, p, det = chi2_test(
        sample_fn,
        jax.jit(lambda w: m.pdf(jnp.broadcast_to(wo, w.shape), w)),
        key=jax.random.key(3),
        n_samples=n,
        ires=6,
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


_HARD_C = [
    [0.5, 0.5, 0.0],  # the map's normal points straight down (flips below the surface)
    [1.0, 0.5, 0.45],  # tilted past the horizon
    [0.5, 0.5, 0.5],  # the zero vector: the unperturbed frame
    [1.0, 0.5, 0.5],  # exactly in the tangent plane, along s
]


def _hard_inputs():
    rng = np.random.default_rng(1)
    wo = jnp.concatenate([_dirs(rng, 64), _GRAZE, _GRAZE])
    wi = jnp.concatenate([_dirs(rng, 64), _GRAZE, _GRAZE[::-1]])
    return wo, wi, jnp.asarray(rng.uniform(size=(wo.shape[0], 2)))


def _hard_eval(c, wo, wi):
    m = NormalMap(Diffuse(0.4), c).at(UV, _tangents(angle=0.3))
    return m.eval(wo, wi), m.pdf(wo, wi)


@jax.jit
def _hard(c, wo, wi, u2):
    val, pdf = _hard_eval(c, wo, wi)
    s = NormalMap(Diffuse(0.5), c).at(UV, _tangents()).sample(wo, jnp.full(wo.shape[0], 0.3), u2)
    return val, pdf, s


@pytest.mark.parametrize("c", _HARD_C)
def test_hard_normals_finite_values_and_samples(x64, c):
    wo, wi, u2 = _hard_inputs()
    val, pdf, s = _hard(jnp.asarray(c, jnp.float64), wo, wi, u2)
    assert np.all(np.isfinite(val)) and np.all(np.asarray(val) >= 0)
    assert np.all(np.isfinite(pdf)) and np.all(np.asarray(pdf) >= 0)
    for x in (s.wi, s.pdf, s.weight):
        assert np.all(np.isfinite(x))
    assert np.all(np.asarray(s.weight) >= 0)
    if c[2] == 0.0:  # a map normal below the surface: nothing leaks through, all black
        assert np.all(np.asarray(val) == 0) and np.all(np.asarray(s.weight) == 0)
    if c == [0.5, 0.5, 0.5]:  # zero vector -> unperturbed
        ref = Diffuse(0.4).eval(wo, wi)
        np.testing.assert_allclose(val, ref, rtol=1e-12, atol=1e-15)


@pytest.mark.slow  # slow: ~2.5 s CPU (the reverse-mode program's compile)
def test_hard_normals_finite_gradients(x64):
    """Reverse-mode derivatives of eval + pdf w.r.t. the map value are finite at every hard
    normal (all four in one batch: a (4, 3) texture, nearest lookup, one texel per ray group)."""
    wo, wi, _ = _hard_inputs()
    n = wo.shape[0]
    uv = jnp.stack([(jnp.arange(4 * n) // n + 0.5) / 4, jnp.full(4 * n, 0.5)], -1)
    wo4, wi4 = jnp.tile(wo, (4, 1)), jnp.tile(wi, (4, 1))

    def loss(img):
        m = NormalMap(Diffuse(0.4), Texture(img, filter="nearest")).at(uv, _tangents(angle=0.3))
        return jnp.sum(m.eval(wo4, wi4)) + jnp.sum(m.pdf(wo4, wi4))

    g = jax.jit(jax.grad(loss))(jnp.asarray(_HARD_C, jnp.float64)[None])
    assert np.all(np.isfinite(g))
    assert np.abs(g).max() > 0


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


def _hit_tangents(shapes, hit):
    return hit, surface_tangents(shapes, hit)


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
    hit, (du, dv) = jax.jit(lambda sh, o, d: _hit_tangents(sh, intersect_scene(sh, o, d)))(
        shapes, o, d
    )
    assert np.array_equal(hit.shape_id, [0, 0, 1, 2])
    du, dv = np.asarray(du), np.asarray(dv)
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
    with pytest.raises(TypeError, match="flip_invalid_normals: expected a bool"):
        NormalMap(Diffuse(0.5), jnp.array([0.5, 0.5, 1.0]), flip_invalid_normals="yes")
    with pytest.raises(ValueError, match=r"materials\.m: use_shadowing_function: expected a bool"):
        load_scene(_plane(_nm_desc() | {"use_shadowing_function": 1}))
    m = load_scene(_plane(_nm_desc() | {"use_shadowing_function": False})).materials[0]
    assert (m.flip_invalid_normals, m.use_shadowing_function) == (True, False)


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


@pytest.mark.slow  # slow: ~55-85 s on 2 shared cores (four scenes compiled, path and direct)
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


def _mapped_scene_desc(folder):
    """A rectangle with a normal map (inline image, clamp / nearest) on a diffuse BSDF and a
    sphere with a bump map (an EXR file, raw, options off) on a rough conductor."""
    from jaxgfx.io import write_exr

    rng = np.random.default_rng(0)
    img = rng.uniform(0.3, 0.7, (3, 4, 3))
    img[..., 2] = 0.9
    write_exr(str(folder / "h.exr"), rng.uniform(size=(5, 6, 1)).astype(np.float32))
    nm = {"type": "normalmap", "bsdf": {"type": "diffuse", "reflectance": [0.2, 0.5, 0.8]},
          "normalmap": {"type": "bitmap", "image": img.tolist(), "wrap": "clamp",
                        "filter": "nearest"}}  # fmt: skip
    bm = {"type": "bumpmap", "bsdf": {"type": "roughconductor", "alpha": 0.2}, "scale": 0.4,
          "height": {"type": "bitmap", "file": "h.exr", "raw": True},
          "flip_invalid_normals": False, "use_shadowing_function": False}  # fmt: skip
    desc = _plane(nm) | {"materials": {"m": nm, "b": bm}}
    desc["shapes"] = desc["shapes"] + [
        {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.3, "material": "b"}
    ]
    return desc


def _same_materials(a, b):
    assert type(a) is type(b)
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb  # the same classes, static options (wrap, filter, flags) and structure
    for x, y in zip(la, lb, strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("via", ["description", "scene"])
def test_mapped_materials_survive_save_and_load(tmp_path, via):
    """load -> save_scene (XML, the map images written next to it or referenced) -> load gives
    the same materials: classes, nested parameters, texels, wrap / filter, scale, options."""
    from jaxgfx.render.scene.mitsuba_xml import save_scene

    desc = _mapped_scene_desc(tmp_path)
    first = load_scene(desc, base_dir=str(tmp_path))
    xml = save_scene(first if via == "scene" else desc, tmp_path / "out" / "s.xml",
                     base_dir=str(tmp_path))  # fmt: skip
    again = load_scene(xml)
    names = dict(zip(again.material_names, again.materials, strict=True))
    for name, m in zip(first.material_names, first.materials, strict=True):
        _same_materials(m, names[name])
    assert isinstance(names["m"], NormalMap) and isinstance(names["b"], BumpMap)
    assert not names["b"].use_shadowing_function and names["m"].use_shadowing_function
    if via == "description":  # a textured nested BSDF is exported too: its texels come back
        desc["materials"]["m"]["bsdf"]["reflectance"] = {
            "type": "bitmap",
            "image": [[[0.25, 0.5, 0.75], [0.1, 0.2, 0.3]]],
        }
        built = load_scene(desc, base_dir=str(tmp_path))
        back = load_scene(save_scene(desc, tmp_path / "t" / "t.xml", base_dir=str(tmp_path)))
        m0 = dict(zip(built.material_names, built.materials, strict=True))["m"]
        m1 = dict(zip(back.material_names, back.materials, strict=True))["m"]
        _same_materials(m0, m1)


def test_parameters_of_a_mapped_material_with_a_textured_nested_bsdf(x64):
    """Scene.parameters() lists a mapped material's textured nested BSDF by field path
    (texels or checkerboard colours, then the fields no texture overrides: not the replaced
    constant, not the alias ``alpha``), then the map (and ``scale``). Every path is readable
    and replaceable, and a replaced nested texel changes the shading with the derivative a
    central difference gives."""
    tex = [[[0.2, 0.3, 0.4], [0.5, 0.6, 0.7]]]
    nm = {"type": "normalmap", "normalmap": {"type": "bitmap", "image": [[[0.6, 0.5, 0.9]]]},
          "bsdf": {"type": "diffuse", "reflectance": {"type": "bitmap", "image": tex}}}  # fmt: skip
    checker = {"type": "checkerboard", "color0": 0.1, "color1": 0.9}
    rough = {"type": "roughplastic", "alpha": 0.3, "diffuse_reflectance": checker}
    bm = {"type": "bumpmap", "scale": 0.5, "height": {"type": "bitmap", "image": [[0.0, 1.0]]},
          "bsdf": rough}  # fmt: skip
    desc = _plane(nm) | {"materials": {"m": nm, "b": bm}}
    desc["shapes"] = desc["shapes"] + [
        {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.3, "material": "b"}
    ]
    scene = load_scene(desc)
    params = {p.path: p for p in scene.parameters() if p.path.startswith("materials.")}
    assert list(params) == [
        "materials.m.bsdf.reflectance.image",
        "materials.m.normalmap.image",
        "materials.b.bsdf.diffuse_reflectance.color0",
        "materials.b.bsdf.diffuse_reflectance.color1",
        "materials.b.bsdf.distribution.alpha_u",
        "materials.b.bsdf.distribution.alpha_v",
        "materials.b.bsdf.specular_reflectance",
        "materials.b.bsdf.eta",
        "materials.b.height.image",
        "materials.b.scale",
    ]
    assert params["materials.m.bsdf.reflectance.image"].shape == (1, 2, 3)
    assert params["materials.m.bsdf.reflectance.image"].bounds == (0.0, 1.0)
    np.testing.assert_allclose(scene.get("materials.m.bsdf.reflectance.image"), tex)
    np.testing.assert_allclose(scene.get("materials.b.bsdf.diffuse_reflectance.color1"), [0.9] * 3)
    assert float(scene.get("materials.b.bsdf.alpha")) == pytest.approx(0.3)  # the alias works
    for path in params:  # every path round-trips through replace
        x = jnp.asarray(scene.get(path))
        assert np.array_equal(scene.replace(path, x * 0.5 + 0.1).get(path), x * 0.5 + 0.1)
    # a nested texel through the wrapper: d eval / d texel against a central difference
    path = "materials.m.bsdf.reflectance.image"
    wo = jnp.array([[0.3, 0.2, 0.93]])
    wi = jnp.array([[-0.2, 0.4, 0.89]])
    uv = jnp.array([[0.3, 0.5]])

    def f(x):
        m = scene.replace(path, x).materials[scene.material_names.index("m")]
        return jnp.sum(m.at(uv, _tangents()).eval(wo, wi))

    x0, e, h = jnp.asarray(tex), jnp.asarray(np.random.default_rng(2).normal(size=(1, 2, 3))), 1e-6
    g, fp, fm = jax.jit(lambda x: (jax.grad(f)(x), f(x + h * e), f(x - h * e)))(x0)
    fd = (fp - fm) / (2 * h)  # directional central difference
    assert abs(float(fd)) > 1e-3
    np.testing.assert_allclose(jnp.sum(g * e), fd, rtol=1e-6)
