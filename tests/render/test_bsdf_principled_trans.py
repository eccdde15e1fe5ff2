"""Principled BSDF transmission (``spec_trans``) and the thin principled BSDF (Mitsuba 3's
``principled`` / ``principledthin``): closed forms (the rough dielectric and rough conductor they
reduce to, Lambertian transmission), reciprocity, chi² of the samplers, furnace, FD gradients,
hard cases, scene loading. Against Mitsuba 3 itself: test_bsdf_principled_mitsuba.py."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.bsdf import (
    Principled,
    PrincipledThin,
    RoughConductor,
    RoughDielectric,
    make_bsdf,
)
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import chi2_test


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _sphere_dirs(n, seed):
    return _unit(np.random.default_rng(seed).normal(size=(n, 3)))


def _dir(cos, phi=0.7):
    s = math.sqrt(max(1 - cos * cos, 0.0))
    return jnp.array([s * math.cos(phi), s * math.sin(phi), cos])


_ev = jax.jit(lambda b, wo, wi: (b.eval(wo, wi), b.pdf(wo, wi)))


@jax.jit
def _sample(b, wo, u1, u2):
    s = b.sample(wo, u1, u2)
    return jnp.where((s.pdf > 0)[:, None], s.wi, 0.0), s


FULL = dict(base_color=[0.8, 0.45, 0.2], roughness=0.35, metallic=0.3, specular=0.6,
            spec_tint=0.4, sheen=0.7, sheen_tint=0.5, flatness=0.25, clearcoat=0.8,
            clearcoat_gloss=0.6, spec_trans=0.6)  # fmt: skip
THIN = dict(base_color=[0.7, 0.3, 0.1], roughness=0.35, spec_tint=0.3, spec_trans=0.6,
            diff_trans=0.8, eta=1.33, sheen=0.5, sheen_tint=0.4, flatness=0.3)  # fmt: skip


# ------------------------------------------------------------------ closed forms


# slow: ~5.3 s on the loaded 2-core box (compiles eval/pdf of two BSDFs in float64)
@pytest.mark.slow
@pytest.mark.parametrize("eta", [1.5, 1 / 1.3])
def test_spec_trans_one_is_the_rough_dielectric(x64, eta):
    """base 1, metallic 0, spec_trans 1: eval and pdf equal ``RoughDielectric(α = r², η)`` on
    the whole sphere (both sides: the diffuse lobe's weight and the tints vanish, the main
    lobe's probabilities become ``F`` and ``1 - F``)."""
    wo, wi = (jnp.asarray(_sphere_dirs(400, s)) for s in (0, 1))
    ours = Principled(1.0, 0.4, eta=eta, spec_trans=1.0)
    f, p = _ev(ours, wo, wi)
    g, q = _ev(RoughDielectric(0.16, eta=eta), wo, wi)
    assert np.sum(np.asarray(g)[:, 0] > 1e-3) > 100
    np.testing.assert_allclose(np.asarray(f), np.asarray(g), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(np.asarray(p), np.asarray(q), rtol=1e-10, atol=1e-14)


# slow: ~5 s on the loaded 2-core box (compiles eval/pdf of four BSDFs)
@pytest.mark.slow
def test_spec_trans_lobe_weights(x64):
    """Every lobe on, spec_trans s, metallic m, ``b = (1 - m) s``: front reflection is the
    reflection-only BSDF minus ``s (1 - m)`` of its diffuse lobe; refraction is ``sqrt(base) b``
    times the rough dielectric's; back reflection ``b`` times the rough dielectric's."""
    p = dict(FULL, anisotropic=0.0)
    s, m = p.pop("spec_trans"), p["metallic"]
    b = (1 - m) * s
    eta = 2 / (1 - math.sqrt(0.08 * p["specular"])) - 1
    wo, wi = _sphere_dirs(400, 2), _sphere_dirs(400, 3)
    f = np.asarray(_ev(Principled(**p, spec_trans=s), jnp.asarray(wo), jnp.asarray(wi))[0])
    f0 = np.asarray(_ev(Principled(**p), jnp.asarray(wo), jnp.asarray(wi))[0])
    diff = dict(p, metallic=0.0, specular=0.0, sheen=0.0, clearcoat=0.0)
    fd = np.asarray(_ev(Principled(**diff), jnp.asarray(wo), jnp.asarray(wi))[0])
    rd = RoughDielectric(p["roughness"] ** 2, eta=eta)
    fr = np.asarray(_ev(rd, jnp.asarray(wo), jnp.asarray(wi))[0])
    co, ci = wo[:, 2], wi[:, 2]
    front, back, refr = (co > 0) & (ci > 0), (co < 0) & (ci < 0), co * ci < 0
    np.testing.assert_allclose(f[front], (f0 - s * (1 - m) * fd)[front], rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(f[back], b * fr[back], rtol=1e-10, atol=1e-14)
    sq = np.sqrt(np.asarray(p["base_color"]))
    np.testing.assert_allclose(f[refr], b * sq * fr[refr], rtol=1e-10, atol=1e-14)
    assert min(front.sum(), back.sum(), refr.sum()) > 50 and np.all(f0[back] == 0)


# slow: ~7 s on the loaded 2-core box (compiles two principled programs)
@pytest.mark.slow
def test_spec_trans_absent_or_zero_traces_nothing():
    """``spec_trans`` absent or a plain 0: no lobe (``None``), reflection-only; an array 0
    keeps the lobe (transmissive), whose values are then the reflection-only ones in front and
    0 elsewhere."""
    assert Principled().spec_trans is None and Principled(spec_trans=0).spec_trans is None
    assert not Principled().is_transmissive and Principled(spec_trans=0.3).is_transmissive
    b = Principled(**dict(FULL, spec_trans=jnp.zeros(())))
    assert b.is_transmissive
    wo, wi = (jnp.asarray(_sphere_dirs(64, s), jnp.float32) for s in (4, 5))
    f, p = _ev(b, wo, wi)
    f0, p0 = _ev(Principled(**dict(FULL, spec_trans=0.0)), wo, wi)
    np.testing.assert_allclose(np.asarray(f), np.asarray(f0), rtol=1e-6, atol=1e-7)
    front = (np.asarray(wo)[:, 2] > 0) & (np.asarray(wi)[:, 2] > 0)
    np.testing.assert_allclose(np.asarray(p)[front], np.asarray(p0)[front], rtol=1e-6)
    thin = PrincipledThin()
    assert thin.spec_trans is None and thin.diff_trans is None and not thin.is_transmissive
    assert PrincipledThin(diff_trans=0.5).is_transmissive


# slow: ~5.4 s on the loaded 2-core box (compiles eval of three BSDFs)
@pytest.mark.slow
def test_thin_specular_pair_is_two_rough_conductors(x64):
    """Thin, base 1, spec_trans 1, spec_tint 0: reflection is the rough conductor with the
    dielectric Fresnel (``k = 0``) of α = r²; transmission towards the mirror image of a
    reflected direction is ``(1 - F) D' G' / (4 c_o)`` with α' = ((0.65 η - 0.35) r)²: the
    Fresnel-free conductor minus the ``k = 0`` one."""
    eta, r = 1.45, 0.4
    wo, wi = _sphere_dirs(300, 6), _sphere_dirs(300, 7)
    wo[:, 2], wi[:, 2] = np.abs(wo[:, 2]), np.abs(wi[:, 2])
    thin = PrincipledThin(1.0, r, eta=eta, spec_trans=1.0)
    flip = wi * np.array([1, 1, -1])
    f_r = np.asarray(_ev(thin, jnp.asarray(wo), jnp.asarray(wi))[0])
    f_t = np.asarray(_ev(thin, jnp.asarray(wo), jnp.asarray(flip))[0])
    a_t = ((0.65 * eta - 0.35) * r) ** 2

    def cond(alpha, **kw):
        return np.asarray(_ev(RoughConductor(alpha, **kw), jnp.asarray(wo), jnp.asarray(wi))[0])

    np.testing.assert_allclose(f_r, cond(r * r, eta=eta, k=0.0), rtol=1e-10, atol=1e-14)
    # mirrored pairs that pass Mitsuba's side test (-wi·h > 0 for the unmirrored wi)
    h = _unit(wo + wi)
    ok = np.sum(flip * h, 1) < 0
    ref = cond(a_t, fresnel="none") - cond(a_t, eta=eta, k=0.0)
    np.testing.assert_allclose(f_t[ok], ref[ok], rtol=1e-9, atol=1e-14)
    assert ok.sum() > 100 and np.all(f_t[~ok] == 0)


# slow: ~5.5 s on the loaded 2-core box (compiles the thin sampler)
@pytest.mark.slow
def test_thin_diffuse_transmission_is_lambertian():
    """diff_trans = 2 (all of the diffuse energy transmitted), spec_trans 0: ``eval = base
    |cos θ_i| / π`` below, 0 above; every sample lands below with weight ``base``."""
    base = jnp.array([0.8, 0.5, 0.2])
    thin = PrincipledThin(base, 0.5, diff_trans=2.0)
    for cos in (0.9, -0.3):
        wo = jnp.broadcast_to(_dir(cos), (4096, 3))
        k1, k2 = jax.random.split(jax.random.key(1))
        _, s = _sample(thin, wo, jax.random.uniform(k1, (4096,)), jax.random.uniform(k2, (4096, 2)))
        wi = np.asarray(s.wi)
        assert np.all(wi[:, 2] * cos < 0)
        np.testing.assert_allclose(np.asarray(s.weight), np.broadcast_to(base, wi.shape),
                                   rtol=1e-5)  # fmt: skip
        f = np.asarray(_ev(thin, wo, s.wi)[0])
        np.testing.assert_allclose(f, np.abs(wi[:, 2:]) * np.asarray(base) / np.pi, rtol=1e-5)
        assert not np.any(np.asarray(_ev(thin, wo, s.wi * jnp.array([1, 1, -1.0]))[0]))


# ------------------------------------------------------------------ reciprocity


# slow: 2.4-7.8 s on the loaded 2-core box (compiles eval of both BSDFs in float64)
@pytest.mark.slow
def test_reciprocity(x64):
    """Principled with spec_trans: reflection is reciprocal; refraction in radiance units obeys
    ``f(wo, wi) η'(wo)² = f(wi, wo)`` (Veach 1997 §5.2). Thin: reflection and diffuse
    transmission are reciprocal."""
    wo, wi = _sphere_dirs(400, 8), _sphere_dirs(400, 9)
    co, ci = np.abs(wo[:, 2:]), np.abs(wi[:, 2:])
    eta = 2 / (1 - math.sqrt(0.08 * FULL["specular"])) - 1
    b = Principled(**FULL)
    f1 = np.asarray(_ev(b, jnp.asarray(wo), jnp.asarray(wi))[0]) / ci
    f2 = np.asarray(_ev(b, jnp.asarray(wi), jnp.asarray(wo))[0]) / co
    refr = wo[:, 2] * wi[:, 2] < 0
    eta_o = np.where(wo[:, 2] > 0, eta, 1 / eta)[:, None]
    np.testing.assert_allclose(f1[~refr], f2[~refr], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose((f1 * eta_o**2)[refr], f2[refr], rtol=1e-9, atol=1e-12)
    assert np.sum(f1[refr][:, 0] > 1e-3) > 20
    # thin: reflection everywhere; transmission without the specular lobe, whose side test
    # (Mitsuba's, on the unmirrored wi) is not symmetric in wo and wi
    for desc, pairs in ((THIN, ~refr), (dict(THIN, spec_trans=0.0), refr | ~refr)):
        t = PrincipledThin(**desc)
        g1 = np.asarray(_ev(t, jnp.asarray(wo), jnp.asarray(wi))[0]) / ci
        g2 = np.asarray(_ev(t, jnp.asarray(wi), jnp.asarray(wo))[0]) / co
        np.testing.assert_allclose(g1[pairs], g2[pairs], rtol=1e-9, atol=1e-12)


# ------------------------------------------------------------------ sampling

CHI2_CASES = [
    ("principled front", Principled(**FULL), 0.7),
    ("principled inside", Principled(**dict(FULL, roughness=0.5)), -0.6),
    ("principled grazing eta<1", Principled(**dict(FULL, specular=None, eta=0.8)), 0.1),
    ("thin front", PrincipledThin(**THIN), 0.6),
    ("thin back glossy", PrincipledThin(**dict(THIN, roughness=0.2, eta=1.6)), -0.4),
]


# slow: ~50 s for the five cases on the loaded 2-core box (two samplers compiled, 40 000
# samples and a 40² quadrature per cell for the peaked ones)
@pytest.mark.slow
@pytest.mark.parametrize("name,bsdf,cos_o", CHI2_CASES, ids=[c[0] for c in CHI2_CASES])
def test_chi2_weights_and_mass(name, bsdf, cos_o):
    """The samplers draw their ``pdf`` over the whole sphere (chi², Šidák over the cases); the
    pdf integrates to the fraction of successful samples; on the samples ``weight == eval /
    pdf`` and ``pdf == pdf(wo, wi)``; both hemispheres are reached."""
    wo = _dir(cos_o)
    n = 40_000
    won = jnp.broadcast_to(wo, (n, 3))
    store = {}

    def sample_fn(u1, u2):
        w, store["s"] = _sample(bsdf, won, u1, u2)
        return w

    def pdf_fn(w):  # in chunks of n rows: one compiled _ev for the quadrature and the samples
        k = -(-w.shape[0] // n)
        wp = jnp.concatenate([w, jnp.tile(wo, (k * n - w.shape[0], 1))])
        return jnp.concatenate([_ev(bsdf, won, c)[1] for c in jnp.split(wp, k)])[: w.shape[0]]

    # peaked lobes (grazing, the thin's IOR-scaled α = 0.019) need a finer quadrature
    ires = 40 if ("grazing" in name or "glossy" in name) else 10
    ok, p, det = chi2_test(sample_fn, pdf_fn, key=jax.random.key(3), n_samples=n, ires=ires,
                           test_count=len(CHI2_CASES))  # fmt: skip
    assert ok, (p, det["message"])
    frac = float(det["observed"].sum()) / n
    assert det["pdf_integral"] == pytest.approx(
        frac, abs=4 * math.sqrt(frac * (1 - frac) / n) + 3e-3
    )
    s = store["s"]
    valid = np.asarray(s.pdf) > 0
    assert valid.mean() > 0.7
    wz = np.asarray(s.wi)[:, 2]
    assert np.any(wz[valid] * cos_o < 0) and np.any(wz[valid] * cos_o > 0)
    f, pdf = (np.asarray(x) for x in _ev(bsdf, won, s.wi))
    np.testing.assert_allclose(np.asarray(s.pdf)[valid], pdf[valid], rtol=1e-5)
    np.testing.assert_allclose(np.asarray(s.weight)[valid], f[valid] / pdf[valid][:, None],
                               rtol=1e-4, atol=1e-7)  # fmt: skip


def test_lobe_probabilities_are_mitsubas():
    """Thin: ∝ ``s r_sr / 2``, ``s r_st / 2``, ``(1 - s)(1 - t) r_dr``, ``(1 - s) t r_dt``
    (``t = diff_trans / 2``); principled: the diffuse lobe's ∝ ``(1 - m)(1 - s) r_d``."""
    t = PrincipledThin(spec_trans=0.4, diff_trans=0.5, specular_transmittance_sampling_rate=2.0)
    got = [float(x) for x in t._probs()]
    raw = [0.2, 0.4, 0.6 * 0.75, 0.6 * 0.25]
    assert got == pytest.approx([x / sum(raw) for x in raw])
    b = Principled(metallic=0.4, clearcoat=0.8, spec_trans=0.5)
    tot = 0.3 + 0.2 + 1.0
    assert [float(x) for x in b._probs()] == pytest.approx([0.3 / tot, 0.2 / tot, 1 / tot])


# ------------------------------------------------------------------ energy


_furnace_w = jax.jit(lambda b, wo, u1, u2: (lambda s: (s.weight, s.eta))(b.sample(wo, u1, u2)))


def _albedo(bsdf, cos, n=40_000, energy=False):
    k1, k2 = jax.random.split(jax.random.key(11))
    wo = jnp.broadcast_to(_dir(cos), (n, 3))
    w, eta = _furnace_w(bsdf, wo, jax.random.uniform(k1, (n,)), jax.random.uniform(k2, (n, 2)))
    w = np.asarray(w, np.float64)[:, 0] * (np.asarray(eta) ** 2 if energy else 1.0)
    return w.mean(), w.std() / math.sqrt(n)


# slow: ~14 s on the loaded 2-core box (compiles both samplers, 12 x 40 000 samples)
@pytest.mark.slow
def test_furnace():
    """Energy (albedo with the radiance scaling ``1/η'²`` of refraction undone) of the white
    transmissive principled (spec_trans 1) is ≤ 1 on both sides, ≈ 1 when nearly smooth (R + T
    = 1); the white thin sheet with spec_trans 1 is ≤ 1, and ≈ 1 when nearly smooth (its
    reflection F and unbent transmission 1 - F; the GGX at α = 1e-3 loses < 1e-3)."""
    for r in (0.02, 0.5):
        b = Principled(1.0, r, eta=1.5, spec_trans=1.0)
        t = PrincipledThin(1.0, r, eta=1.5, spec_trans=1.0)
        for cos in (0.9, -0.5, 0.2):
            a, se = _albedo(b, cos, energy=True)
            assert a <= 1 + 4 * se, (r, cos, a, se)
            if r < 0.1:
                assert a == pytest.approx(1.0, abs=4 * se + 2e-3), (r, cos, a)
            a, se = _albedo(t, cos)
            assert a <= 1 + 4 * se, (r, cos, a, se)
            if r < 0.1:
                assert a == pytest.approx(1.0, abs=4 * se + 2e-3), (r, cos, a)


# ------------------------------------------------------------------ gradients, hard cases

_GW = _unit(np.random.default_rng(12).normal(size=(8, 3)))
_GI = _unit(np.random.default_rng(13).normal(size=(8, 3)))
_GU1 = np.linspace(0.03, 0.97, 8)
_GU2 = np.random.default_rng(14).uniform(0.05, 0.95, (8, 2))


def _ad_fd(f, args, eps=1e-6):
    """Per argument, the AD and the central-difference derivative of ``u · f`` along a random
    direction of that argument (float64, jitted)."""
    args = [jnp.asarray(a, jnp.float64) for a in args]
    rng = np.random.default_rng(0)
    u = jnp.asarray(rng.standard_normal(jax.eval_shape(f, *args).shape))
    scalar = jax.jit(lambda *a: jnp.vdot(u, f(*a)))
    grads = jax.jit(jax.grad(scalar, argnums=tuple(range(len(args)))))(*args)
    out = []
    for i, a in enumerate(args):
        d = jnp.asarray(rng.standard_normal(a.shape))
        hi = [x + eps * d if j == i else x for j, x in enumerate(args)]
        lo = [x - eps * d if j == i else x for j, x in enumerate(args)]
        out.append((float(jnp.vdot(grads[i], d)), float((scalar(*hi) - scalar(*lo)) / (2 * eps))))
    return out


def _principled_fn(base, r, st, eta):
    b = Principled(base, r, eta=eta, spec_trans=st, metallic=0.2, clearcoat=0.5, sheen=0.4,
                   flatness=0.3, spec_tint=0.2)  # fmt: skip
    wo, wi = jnp.asarray(_GW), jnp.asarray(_GI)
    s = b.sample(wo, jnp.asarray(_GU1), jnp.asarray(_GU2))
    return jnp.concatenate([b.eval(wo, wi).ravel(), b.pdf(wo, wi), s.weight.ravel()])


def _thin_fn(base, r, st, eta, dt, flat):
    b = PrincipledThin(base, r, eta=eta, spec_trans=st, diff_trans=dt, flatness=flat,
                       sheen=0.4, spec_tint=0.3)  # fmt: skip
    wo, wi = jnp.asarray(_GW), jnp.asarray(_GI)
    s = b.sample(wo, jnp.asarray(_GU1), jnp.asarray(_GU2))
    return jnp.concatenate([b.eval(wo, wi).ravel(), b.pdf(wo, wi), s.weight.ravel()])


@pytest.mark.parametrize(
    "fn,args,names",
    [(_principled_fn, ([0.7, 0.4, 0.2], 0.45, 0.6, 1.4), "base roughness spec_trans eta"),
     (_thin_fn, ([0.7, 0.4, 0.2], 0.45, 0.6, 1.4, 0.7, 0.3),
      "base roughness spec_trans eta diff_trans flatness")],
    ids=["principled", "thin"],
)  # fmt: skip
# slow: ~43 s (principled) and ~24 s (thin) on the loaded 2-core box (grad through sample)
@pytest.mark.slow
def test_grads_vs_fd(x64, fn, args, names):
    """d(eval, pdf, sample weight) / d(each parameter) against central differences (float64,
    jitted, a random direction per parameter; measured max relative difference 3.4e-9)."""
    for name, (ad, fd) in zip(names.split(), _ad_fd(fn, args), strict=True):
        assert abs(fd) > 1e-3, name  # the parameter matters
        assert ad == pytest.approx(fd, rel=1e-6), name


_HARD = _unit([[0, 0, 1.0], [1, 0, 1e-7], [0.6, 0, 0.8], [0, 0, -1.0], [0.3, 0.2, -1e-7],
               [0.6, 0, -0.8]])  # fmt: skip
_HARD_ARGS = [  # (roughness, spec_trans, eta)
    (0.0, 1.0, 1.5), (1e-4, 0.5, 1.0), (0.5, 0.0, 1.0 + 1e-7), (1.0, 1.0, 0.7), (0.3, 0.5, 1.0)
]  # fmt: skip


# slow: ~29 s (principled) and ~19 s (thin) on the loaded 2-core box (grad through sample)
@pytest.mark.slow
@pytest.mark.parametrize("thin", [False, True], ids=["principled", "thin"])
def test_hard_cases_finite(x64, thin):
    """roughness 0 and 1e-4 (α clamps to 1e-3), eta exactly 1 (principled: read as 1.001, as
    Mitsuba) and 1 + 1e-7, spec_trans 0 (array) and 1, grazing (cos ±1e-7), normal, both sides:
    eval, pdf, sample weights and their gradients w.r.t. (roughness, spec_trans, eta) finite."""
    wo, wi = jnp.asarray(np.repeat(_HARD, 6, axis=0)), jnp.asarray(np.tile(_HARD, (6, 1)))
    u1 = jnp.linspace(0.01, 0.99, 36)
    u2 = jnp.stack([jnp.linspace(0.02, 0.98, 36), jnp.linspace(0.9, 0.1, 36)], -1)

    def total(r, st, eta):
        if thin:
            b = PrincipledThin([0.5, 0.2, 0.9], r, eta=eta, spec_trans=st, diff_trans=0.5,
                               sheen=1.0, flatness=0.5, spec_tint=0.5)  # fmt: skip
        else:
            b = Principled([0.5, 0.2, 0.9], r, eta=eta, spec_trans=st, clearcoat=1.0,
                           sheen=1.0, flatness=0.5, spec_tint=0.5)  # fmt: skip
        return (jnp.sum(b.eval(wo, wi)) + 1e-6 * jnp.sum(b.pdf(wo, wi))
                + jnp.sum(b.sample(wo, u1, u2).weight))  # fmt: skip

    grad = jax.jit(jax.value_and_grad(total, argnums=(0, 1, 2)))
    for args in _HARD_ARGS:
        v, g = grad(*(jnp.float64(a) for a in args))
        assert np.isfinite(float(v)) and all(np.isfinite(float(x)) for x in g), args


# slow: ~5 s on the loaded 2-core box (compiles vmapped eval/pdf of both BSDFs)
@pytest.mark.slow
def test_jit_batched_parameters():
    """Per-ray parameters (as textures give) equal one BSDF per ray, under jit and vmap."""
    wo, wi = (jnp.asarray(_sphere_dirs(4, s), jnp.float32) for s in (15, 16))
    st = jnp.asarray([0.0, 0.3, 0.7, 1.0])
    dt = jnp.asarray([0.0, 0.5, 1.5, 2.0])

    def one(st, dt, wo, wi):
        a = _ev(Principled(**dict(FULL, spec_trans=st)), wo, wi)
        b = _ev(PrincipledThin(**dict(THIN, spec_trans=st, diff_trans=dt)), wo, wi)
        return a + b

    batched = one(st, dt, wo, wi)
    per_ray = jax.jit(jax.vmap(one))(st, dt, wo, wi)
    for x, y in zip(batched, per_ray, strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-5, atol=1e-7)


# ------------------------------------------------------------------ descriptions, scenes


def test_make_bsdf_and_refusals():
    t = make_bsdf({"type": "principledthin"})
    assert isinstance(t, PrincipledThin) and float(t.eta) == 1.5  # Mitsuba's default
    for desc, msg in [
        ({"type": "principledthin", "diff_trans": 2.5}, r"diff_trans: expected values in \[0, 2\]"),
        ({"type": "principledthin", "spec_trans": -0.1}, r"spec_trans: expected values in"),
        ({"type": "principledthin", "eta": 0.0}, "eta: expected a finite value > 0"),
        ({"type": "principledthin", "specular": 0.5}, r"desc\['specular'\]: unknown parameter"),
        ({"type": "principled", "spec_trans": 1.2}, r"spec_trans: expected values in"),
    ]:  # fmt: skip
        with pytest.raises(ValueError, match=msg):
            make_bsdf(desc)


def test_yaml_scene(tmp_path):
    yaml = tmp_path / "s.yaml"
    yaml.write_text(
        "camera: {origin: [0, 0, 3], target: [0, 0, 0], fov: 40, width: 4, height: 4}\n"
        "materials:\n  g: {type: principled, base_color: [0.9, 0.8, 0.7], spec_trans: 0.8,\n"
        "      eta: 1.4, roughness: 0.2}\n"
        "  t: {type: principledthin, diff_trans: 1.2, spec_trans: {type: checkerboard,\n"
        "      color0: 0.2, color1: 0.6}}\n"
        "shapes:\n  - {type: sphere, center: [0, 0, 0], radius: 1, material: g}\n"
        "  - {type: sphere, center: [2, 0, 0], radius: 1, material: t}\n"
    )
    scene = load_scene(str(yaml))
    m = dict(zip(scene.material_names, scene.materials, strict=True))
    assert isinstance(m["g"], Principled) and m["g"].is_transmissive
    assert type(m["t"]).__name__ == "Textured" and m["t"].is_transmissive
    at = m["t"].at(jnp.array([[0.25, 0.25], [0.75, 0.25]]))
    np.testing.assert_allclose(np.asarray(at.spec_trans), [0.2, 0.6])
