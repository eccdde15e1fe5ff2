"""Mitsuba 3's ``pplastic``, ``polarizer``, ``circular`` and ``retarder`` in their unpolarised
(RGB-variant) form (issue 24): :class:`PolarizedPlastic` against an independent NumPy
transcription of its formula (Walter et al. 2007 microfacet terms, the unpolarised Fresnel
equations), its albedo against the closed form ``kd (1 - F(cos θ_o)) (1 - F_dr(η))``, sampling
(weights = eval / pdf, chi²), FD gradients of every continuous parameter in float64, hard
cases; the pass-throughs' lobes, gradients and a closed-form render; errors. Against Mitsuba 3
itself: tests/render/test_bsdf_polarized_mitsuba.py (``mitsuba`` marker)."""

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import erf

from jaxgfx.render.bsdf import (
    CircularPolarizer,
    PolarizedPlastic,
    Polarizer,
    Retarder,
    make_bsdf,
)
from jaxgfx.render.bsdf.fresnel import fresnel_diffuse_reflectance
from jaxgfx.testing import check_grads_fd, chi2_test

_ev = jax.jit(lambda b, wo, wi: (b.eval(wo, wi), b.pdf(wo, wi)))
_smp = jax.jit(lambda b, wo, u1, u2: b.sample(wo, u1, u2))


def _upper(n, seed):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


# ---------------------------------------------------------------- independent reference


def _fresnel(c, eta):
    """Unpolarised dielectric reflectance for ``cos θ = c > 0`` arriving from outside (n=1)."""
    s2 = (1 - c * c) / (eta * eta)
    ct = np.sqrt(np.maximum(1 - s2, 0.0))
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return np.where(s2 >= 1, 1.0, 0.5 * (rs * rs + rp * rp))


def _d(m, au, av, kind):
    e = (m[..., 0] / au) ** 2 + (m[..., 1] / av) ** 2
    z2 = m[..., 2] ** 2
    if kind == "beckmann":
        return np.exp(-e / z2) / (math.pi * au * av * z2 * z2)
    return 1.0 / (math.pi * au * av * (e + z2) ** 2)


def _g1(v, m, au, av, kind):
    t = np.sqrt((au * v[..., 0]) ** 2 + (av * v[..., 1]) ** 2) / v[..., 2]  # α tan θ
    if kind == "beckmann":
        a = 1.0 / t
        lam = 0.5 * (erf(a) - 1) + np.exp(-a * a) / (2 * a * math.sqrt(math.pi))
    else:
        lam = 0.5 * (np.sqrt(1 + t * t) - 1)
    return np.where(np.sum(v * m, -1) > 0, 1.0 / (1.0 + lam), 0.0)


def _reference(wo, wi, kd, ks, au, av, eta, kind):
    """Mitsuba's unpolarised pplastic ``eval`` written from the formulas."""
    h = wo + wi
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    co, ci = wo[..., 2], wi[..., 2]
    spec = (_fresnel(np.sum(wo * h, -1), eta) * _d(h, au, av, kind)
            * _g1(wo, h, au, av, kind) * _g1(wi, h, au, av, kind) / (4 * co))  # fmt: skip
    diff = (1 - _fresnel(co, eta)) * (1 - _fresnel(ci, eta)) * ci / math.pi
    return spec[:, None] * np.asarray(ks) + diff[:, None] * np.asarray(kd)


# One batch size for every float64 program below, so that the tests share their compiles
# (eval + pdf and the sampler per distribution, one value-and-gradient program).
N = 8192


@pytest.mark.parametrize("kind, au, av, eta", [
    ("ggx", 0.3, 0.3, 1.5), ("beckmann", 0.1, 0.1, 1.49 / 1.000277),
    ("ggx", 0.1, 0.4, 1.7), ("beckmann", 0.5, 0.2, 1.2),
])  # fmt: skip
def test_eval_equals_the_formula(x64, kind, au, av, eta):
    """``eval`` against the NumPy transcription (float64, to 1e-10 relative) on 8192 pairs of
    upper-hemisphere directions, isotropic and anisotropic, GGX and Beckmann; 0 below the
    surface (Mitsuba's FrontSide-only lobes). Power: the mutants ``render.pplastic.*`` of
    tools/mutants.py (one Fresnel transmission dropped, the lobe's Fresnel at ``cos θ_o``) fail
    it; so does an IOR 0.1 % off (checked here)."""
    kd, ks = [0.2, 0.5, 0.9], [1.0, 0.7, 0.4]
    wo, wi = _upper(N, 1), _upper(N, 2)
    b = PolarizedPlastic(kd, au, alpha_v=av, eta=eta, specular_reflectance=ks, distribution=kind)
    f = np.asarray(_ev(b, jnp.asarray(wo), jnp.asarray(wi))[0])
    want = _reference(wo, wi, kd, ks, au, av, eta, kind)
    np.testing.assert_allclose(f, want, rtol=1e-10, atol=1e-300)
    off = PolarizedPlastic(kd, au, alpha_v=av, eta=eta * 1.001, specular_reflectance=ks,
                           distribution=kind)  # fmt: skip
    assert not np.allclose(np.asarray(_ev(off, jnp.asarray(wo), jnp.asarray(wi))[0]), want,
                           rtol=1e-10, atol=1e-300)  # fmt: skip
    wb = wi * np.array([1, 1, -1])
    assert np.all(np.asarray(_ev(b, jnp.asarray(wo), jnp.asarray(wb))[0]) == 0)
    assert np.all(np.asarray(_ev(b, jnp.asarray(wb), jnp.asarray(wo))[1]) == 0)


def _uniforms(seed):
    k1, k2 = jax.random.split(jax.random.key(seed))
    return jax.random.uniform(k1, (N,), jnp.float64), jax.random.uniform(k2, (N, 2), jnp.float64)


@pytest.mark.parametrize("kind", ["ggx", "beckmann"])
def test_sample_weight_is_eval_over_pdf_and_lobe_choice(x64, kind):
    """Sampled directions (under jit): ``pdf`` equals ``pdf(wo, wi)``, ``weight`` equals
    eval / pdf, never delta, eta 1; the specular lobe is chosen with probability ``w_s =
    mean(ks) / (mean(kd) + mean(ks))`` exactly (``u1 < w_s``: the diffuse choices are the
    cosine-hemisphere directions of ``u2``, whatever the view), as Mitsuba."""
    b = PolarizedPlastic([0.1, 0.3, 0.5], 0.25, distribution=kind)
    wo = jnp.asarray(_upper(N, 3))
    u1, u2 = _uniforms(1)
    s = _smp(b, wo, u1, u2)
    f, p = _ev(b, wo, s.wi)
    ok = np.asarray(s.pdf) > 0
    assert ok.mean() > 0.85  # the rest: microfacet reflections below the horizon
    np.testing.assert_allclose(np.asarray(s.pdf)[ok], np.asarray(p)[ok], rtol=1e-12)
    ratio = np.asarray(f)[ok] / np.asarray(p)[ok][:, None]
    np.testing.assert_allclose(np.asarray(s.weight)[ok], ratio, rtol=1e-10)
    assert not np.any(np.asarray(s.is_delta)) and np.all(np.asarray(s.eta) == 1)
    assert float(b._spec_weight()) == pytest.approx(1 / (1 + 0.3), rel=1e-12)
    d = np.asarray(u1) >= float(b._spec_weight())
    s2 = _smp(b, -wo * jnp.array([1, 1, -1]), u1, u2)  # another view, same numbers
    np.testing.assert_allclose(np.asarray(s.wi)[d], np.asarray(s2.wi)[d], atol=1e-12)


@pytest.mark.slow  # slow: ~6 s on 2 cores (two float32 sampler compiles, 2 x 200k samples)
@pytest.mark.parametrize("kind, alpha", [("ggx", 0.3), ("beckmann", 0.15)])
def test_chi2_sampling_matches_pdf(kind, alpha):
    b = PolarizedPlastic([0.4, 0.3, 0.2], alpha, distribution=kind, eta=1.6)
    wo = jnp.asarray([0.5, 0.2, 0.84], jnp.float32)
    wo = wo / jnp.linalg.norm(wo)

    def sample(u1, u2):
        s = _smp(b, jnp.broadcast_to(wo, (u1.shape[0], 3)), u1, u2)
        return jnp.where((s.pdf > 0)[:, None], s.wi, 0.0)

    def pdf(w):
        return _ev(b, jnp.broadcast_to(wo, w.shape), w)[1]

    n, key = 200_000, jax.random.key(4)
    ok, p, d = chi2_test(sample, pdf, key=key, n_samples=n, res_theta=24, res_phi=48, ires=8,
                         test_count=2)  # fmt: skip
    assert ok, (p, d["message"])
    # the pdf's integral is the fraction of samples that do not fail (microfacet reflections
    # below the horizon), drawn from the same numbers as chi2_test draws them
    k1, k2 = jax.random.split(key)
    lost = np.mean(np.all(np.asarray(sample(jax.random.uniform(k1, (n,)),
                                            jax.random.uniform(k2, (n, 2)))) == 0, -1))
    print(f"{kind}: p = {p:.3f}, pdf integral {d['pdf_integral']:.4f}, failed samples {lost:.4f}")
    assert abs(d["pdf_integral"] - (1 - lost)) < 4 * math.sqrt(lost / n) + 2e-3, (d, lost)


def test_albedo_closed_form_and_energy(x64):
    """With ``ks = 0`` every sample is diffuse and the albedo is exactly
    ``kd (1 - F(cos θ_o)) (1 - F_dr(η))`` (``F_dr = 2∫F(μ)μ dμ``); the sampler's mean weight
    agrees within 4 standard errors (8192 samples per view). With ``kd = ks = 1`` the albedo
    stays below 1 at every view (energy is lost to the coat, never created)."""
    eta = 1.5
    u1, u2 = _uniforms(7)
    fdr = float(fresnel_diffuse_reflectance(jnp.float64(eta)))
    for c in (0.95, 0.5, 0.1):
        wo = jnp.broadcast_to(jnp.asarray([math.sqrt(1 - c * c), 0.0, c]), (N, 3))
        b = PolarizedPlastic([0.3, 0.6, 0.9], 0.2, eta=eta, specular_reflectance=0.0)
        w = np.asarray(_smp(b, wo, u1, u2).weight)
        want = np.array([0.3, 0.6, 0.9]) * (1 - _fresnel(c, eta)) * (1 - fdr)
        se = w.std(0, ddof=1) / math.sqrt(N)
        assert np.all(np.abs(w.mean(0) - want) < 4 * se + 1e-12), (w.mean(0), want, se)
        white = PolarizedPlastic(1.0, 0.2, eta=eta, specular_reflectance=1.0)
        w = np.asarray(_smp(white, wo, u1, u2).weight)
        se = w.std(0, ddof=1) / math.sqrt(N)
        assert np.all(w.mean(0) + 4 * se < 1.0) and np.all(w.mean(0) > 0.4), w.mean(0)


# directions of the gradient checks: head-on, two grazing (cos 1e-9), one generic
_DIRS = np.array([(0.0, 0.0, 1.0), (1.0, 0.0, 1e-9), (0.6, 0.8, 1e-9), (0.3, -0.2, 0.93)])
_WO = _DIRS / np.linalg.norm(_DIRS, axis=1, keepdims=True)
_WI = _WO[::-1] * np.array([-1.0, 1.0, 1.0])
_WI[0] = np.array([-0.25, 0.3, 0.92]) / np.linalg.norm([-0.25, 0.3, 0.92])  # generic pair


def _total(x, kind):
    """eval + pdf summed over the four direction pairs of a pplastic with ``x = (kd (3),
    ks (3), α_u, α_v, η)``."""
    wo, wi = jnp.asarray(_WO), jnp.asarray(_WI)
    b = PolarizedPlastic(x[0:3], x[6], alpha_v=x[7], eta=x[8], specular_reflectance=x[3:6],
                         distribution=kind)  # fmt: skip
    return jnp.sum(b.eval(wo, wi) * jnp.array([1.0, 2.0, 3.0])) + jnp.sum(b.pdf(wo, wi))


@functools.cache
def _programs(kind):
    """The value and gradient programs of :func:`_total` (shared by the two tests below)."""
    f = functools.partial(_total, kind=kind)
    return jax.jit(f), jax.jit(jax.grad(f))


@pytest.mark.parametrize("kind", ["beckmann", pytest.param("ggx", marks=pytest.mark.slow)])
def test_gradients_match_finite_differences(x64, kind):
    """d/d(kd, ks, α_u, α_v, η) of ``eval + pdf`` (four direction pairs, both lobes live;
    anisotropic) against central differences in float64 (h = 1e-6, rtol 1e-6). Beckmann is
    Mitsuba's default; the GGX variant (its own compile, ~3 s) runs with the slow tests."""
    f, g = _programs(kind)
    x = np.array([0.2, 0.5, 0.7, 0.9, 0.6, 0.3, 0.3, 0.2, 1.45])
    h = 1e-6
    fd = [(float(f(jnp.asarray(x + h * e))) - float(f(jnp.asarray(x - h * e)))) / (2 * h)
          for e in np.eye(9)]  # fmt: skip
    ad = np.asarray(g(jnp.asarray(x)))
    np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-9)
    assert np.all(np.abs(ad) > 1e-4)  # every parameter matters here


def test_hard_cases_values_and_gradients_finite(x64):
    """α → 0 (1e-7: below Mitsuba's 1e-4 clamp), grazing views and lights (cos 1e-9), η → 1
    (F = 0: the lobe vanishes and the diffuse term is exactly ``kd cos θ_i / π``), head-on,
    black: values and gradients w.r.t. all parameters finite; samples finite at extreme
    uniforms."""
    f, g = _programs("beckmann")
    for x in ([0.5] * 3 + [1.0] * 3 + [1e-7, 1e-7, 1.5],
              [0.5] * 3 + [1.0] * 3 + [0.2, 0.2, 1.0],
              [0.5] * 3 + [1.0] * 3 + [0.2, 0.3, 1.0 + 1e-7],
              [0.0] * 3 + [0.0] * 3 + [1.0, 1.0, 1.5]):  # fmt: skip
        x = jnp.asarray(x)
        assert np.isfinite(float(f(x))) and np.all(np.isfinite(np.asarray(g(x)))), x
    b = PolarizedPlastic(0.5, 0.2, eta=1.0)
    wo = jnp.asarray(np.resize(_WO, (N, 3)))
    wi = jnp.asarray(np.resize(_WI, (N, 3)))
    fe = np.asarray(_ev(b, wo, wi)[0])
    want = 0.5 * np.maximum(np.asarray(wi[:, 2]), 0)[:, None] / math.pi * np.ones(3)
    np.testing.assert_allclose(fe, want, rtol=1e-12, atol=1e-300)
    for u in (0.0, 1.0 - 1e-16):
        s = _smp(PolarizedPlastic(0.5, 1e-7), wo, jnp.full(N, u), jnp.full((N, 2), u))
        assert np.all(np.isfinite(np.asarray(s.wi))) and np.all(np.isfinite(np.asarray(s.weight)))


def test_errors_name_the_argument():
    with pytest.raises(ValueError, match="alpha"):
        PolarizedPlastic(0.5, 0.0)
    with pytest.raises(ValueError, match="eta"):
        PolarizedPlastic(eta=-1.5)
    with pytest.raises(ValueError, match="diffuse_reflectance"):
        PolarizedPlastic([0.1, -0.2, 0.3])
    with pytest.raises(ValueError, match="type"):
        PolarizedPlastic(distribution="phong")
    with pytest.raises(ValueError, match="unknown parameter for 'pplastic'"):
        make_bsdf({"type": "pplastic", "nonlinear": True})
    with pytest.raises(ValueError, match="transmittance"):
        Polarizer(transmittance=[1.0, -0.1, 0.5])
    with pytest.raises(ValueError, match="theta"):
        Polarizer(theta=float("nan"))
    with pytest.raises(ValueError, match="polarizing"):
        Polarizer(polarizing="yes")
    with pytest.raises(ValueError, match="delta"):
        Retarder(delta=float("inf"))
    with pytest.raises(ValueError, match="left_handed"):
        CircularPolarizer(left_handed=1)
    with pytest.raises(ValueError, match="unknown parameter for 'circular'"):
        make_bsdf({"type": "circular", "theta": 3.0})
    with pytest.raises(ValueError, match="unknown parameter for 'retarder'"):
        make_bsdf({"type": "retarder", "polarizing": False})


# ---------------------------------------------------------------- polarizer / retarder


_OPTIONS = {  # what each pass-through takes besides transmittance (no effect on the light)
    "polarizer": ({}, {"theta": 37.0}, {"theta": -90.0, "polarizing": False}),
    "circular": ({}, {"left_handed": True}),
    "retarder": ({}, {"theta": 37.0}, {"theta": -90.0, "delta": 10.0}),
}


@pytest.mark.parametrize("kind, factor", [("polarizer", 0.5), ("circular", 0.5),
                                          ("retarder", 1.0)])  # fmt: skip
def test_pass_through_lobes(kind, factor):
    """Under jit, from either side and at grazing: ``sample`` continues straight on
    (``wi = -wo``) with ``pdf`` 1, delta, ``eta`` 1 and weight ``factor · transmittance``
    (0.5 for the polarizers, 1 for the retarder, Mitsuba's RGB branches) whatever the angles
    and handedness; ``eval`` and ``pdf`` are 0."""
    t = [0.9, 0.5, 0.2]
    wo = jnp.asarray(_upper(6, 5) * np.array([1, 1, -1]) ** np.arange(6)[:, None])
    wo = wo.at[0].set(jnp.array([1.0, 0.0, 1e-9]))
    for opts in _OPTIONS[kind]:
        b = make_bsdf({"type": kind, "transmittance": t, **opts})
        s = _smp(b, wo, jnp.full(6, 0.3), jnp.full((6, 2), 0.7))
        np.testing.assert_array_equal(np.asarray(s.wi), -np.asarray(wo))
        np.testing.assert_allclose(np.asarray(s.weight), factor * np.tile(t, (6, 1)), rtol=1e-7)
        assert np.all(np.asarray(s.pdf) == 1) and np.all(np.asarray(s.is_delta))
        assert np.all(np.asarray(s.eta) == 1)
        f, p = _ev(b, wo, -wo)
        assert np.all(np.asarray(f) == 0) and np.all(np.asarray(p) == 0)
        assert b.has_delta and not b.is_transmissive
    # power: a retarder is not a polarizer
    assert not np.allclose(factor, 1.5 - factor)


def test_pass_through_gradients(x64):
    """d weight / d transmittance = 0.5 (polarizer) resp. 1 (retarder), against central
    differences in float64; the angles' derivatives are exactly 0 (no effect on unpolarised
    light)."""
    wo = jnp.asarray([0.3, 0.2, 0.93])
    for cls, factor in ((Polarizer, 0.5), (Retarder, 1.0)):

        def f(x, cls=cls):
            b = cls(transmittance=x[:3], theta=x[3])
            return jnp.sum(b.sample(wo, 0.5, jnp.array([0.5, 0.5])).weight * jnp.arange(1, 4))

        x = jnp.asarray([0.7, 0.4, 0.2, 30.0])
        ok, ad, fd = check_grads_fd(f, x, eps=1e-6, rtol=1e-9, atol=1e-12, jit=True)
        assert ok, (ad, fd)
        np.testing.assert_allclose(ad, [factor, 2 * factor, 3 * factor, 0.0], rtol=1e-12)


def _pass_through_scene(mat, le):
    """Camera -> a pass-through rectangle filling the view -> an area light behind it."""
    from jaxgfx.render import load_scene

    return load_scene({
        "camera": {"origin": [0, 0, 0], "target": [0, 0, 1], "fov": 20, "width": 4,
                   "height": 4},
        "shapes": [{"type": "rectangle", "center": [0, 0, 1], "edge_u": [2, 0, 0],
                    "edge_v": [0, 2, 0], "material": "f"}],
        "materials": {"f": mat},
        "emitters": [{"type": "area", "radiance": list(le), "shape": {
            "type": "rectangle", "center": [0, 0, 2], "normal": [0, 0, -1], "size": [4, 4]}}],
    })  # fmt: skip


_LE, _T = np.array([2.0, 3.0, 4.0]), np.array([0.8, 0.5, 0.25])


@pytest.mark.slow  # slow: ~10-16 s at load 6-7 on 2 cores (one path program with its vjp)
def test_polarizer_in_front_of_a_light_closed_form():
    """Camera -> polarizer rectangle -> area light, ``path`` of depth 2: every pixel sees the
    light through the polarizer, radiance ``0.5 T L_e`` exactly (a delta pass-through and then
    an emitter hit, MIS weight 1), and d pixel / d T = 0.5 L_e (reverse mode through the
    renderer, one program). Power: not the light alone (``L_e``). The retarder shares the
    pass-through (its factor 1 is checked by ``test_pass_through_lobes``)."""
    from jaxgfx.render import render

    key = jax.random.key(0)
    scene = _pass_through_scene({"type": "polarizer", "transmittance": _T.tolist(),
                                 "theta": 45.0}, _LE)  # fmt: skip

    @jax.jit
    def image_and_grad(tr):
        def f(tr):
            sc = scene.replace("materials.f.transmittance", tr)
            return render(sc, key, spp=2, integrator="path", max_depth=2)

        img, vjp = jax.vjp(f, tr)
        return img, vjp(jnp.zeros_like(img).at[1, 2].set(1.0))[0]

    img, g = (np.asarray(a) for a in image_and_grad(jnp.asarray(_T, jnp.float32)))
    np.testing.assert_allclose(img, np.broadcast_to(0.5 * _T * _LE, (4, 4, 3)), rtol=1e-6)
    assert not np.allclose(img, _LE)
    np.testing.assert_allclose(g, 0.5 * _LE, rtol=1e-6)
