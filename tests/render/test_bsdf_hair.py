"""Mitsuba 3's ``hair`` BSDF (Chiang et al. 2016) as :class:`jaxgfx.render.bsdf.Hair`: energy
conservation (white furnace by uniform-sphere Monte Carlo), chi² of the sampler, sample weights
against eval / pdf, the d'Eon longitudinal lobe against quadrature, reciprocity (what holds and
what does not), FD gradients of every continuous parameter, hard cases, errors and dispatch.
Against Mitsuba 3 itself: tests/render/test_bsdf_hair_mitsuba.py (``mitsuba`` marker)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.bsdf import BlendBSDF, Diffuse, Hair, Mask, make_bsdf
from jaxgfx.render.bsdf import _hair as H
from jaxgfx.testing import check_grads_fd, chi2_test


def _unit(n, seed):
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _fibre_dir(sin_theta, phi):
    """A direction with longitudinal sine ``sin_theta`` (fibre axis +y) and azimuth ``phi``."""
    c = math.sqrt(max(1 - sin_theta**2, 0.0))
    return jnp.array([c * math.cos(phi), sin_theta, c * math.sin(phi)])


_ev = jax.jit(lambda b, wo, wi: (b.eval(wo, wi), b.pdf(wo, wi)))
_mp = jax.jit(H._longitudinal)
_smp = jax.jit(lambda b, wo, u1, u2: b.sample(wo, u1, u2))

CASES = [  # (β_m, β_n, α°, η, wo): roughness, tilt, IOR and view (h = -wo_x / |wo_xz|)
    (0.3, 0.3, 2.0, 1.55, (0.3, 0.4, 0.866)),
    (0.15, 0.6, 0.0, 1.55, (-0.8, -0.2, 0.566)),
    (0.6, 0.2, 6.0, 1.33, (0.0, 0.7, 0.714)),
    (0.9, 0.9, -3.0, 1.8, (0.95, 0.1, -0.296)),  # seen from the back half (wo_z < 0)
]


@pytest.mark.parametrize("bm, bn, alpha, eta, wo", CASES)
def test_white_furnace_uniform_sphere(x64, bm, bn, alpha, eta, wo):
    """σ_a = 0: ``∫ eval(wo, wi) dω_i = 1`` (``eval`` already holds the cosine; Mitsuba's
    test_hair.py checks the same). Uniform-sphere Monte Carlo, independent of the sampler;
    |mean - 1| within 4 standard errors, and the standard error below 1 %."""
    b = Hair(sigma_a=0.0, longitudinal_roughness=bm, azimuthal_roughness=bn, scale_tilt=alpha,
             eta=eta)  # fmt: skip
    wo = jnp.asarray(wo) / np.linalg.norm(wo)
    n = 1 << 19
    u = jax.random.uniform(jax.random.key(1), (n, 2), jnp.float64)
    z = 1 - 2 * u[:, 0]
    r = jnp.sqrt(1 - z * z)
    wi = jnp.stack([r * jnp.cos(2 * jnp.pi * u[:, 1]), r * jnp.sin(2 * jnp.pi * u[:, 1]), z], -1)
    f = np.asarray(_ev(b, jnp.broadcast_to(wo, wi.shape), wi)[0][:, 0]) * 4 * math.pi
    mean, se = f.mean(), f.std(ddof=1) / math.sqrt(n)
    assert se < 0.01 and abs(mean - 1) < 4 * se, (mean, se)


@pytest.mark.slow  # slow: ~4 s CPU, 10 s wall on 2 cores at load 11 (compiles the sampler)
def test_absorption_loses_energy_as_the_attenuation_says(x64):
    """With absorption the albedo is ``Σ_p A_p`` < 1 (the lobes M_p, N_p integrate to 1), and
    the sampler's weight is exactly ``Σ A_p / Σ lum(A_p) · lum`` ... i.e. its mean equals the
    furnace integral: checked per channel against the closed-form ``Σ A_p``."""
    b = Hair(eumelanin=0.4, pheomelanin=0.3, longitudinal_roughness=0.4)
    wo = jnp.asarray([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93])
    g = b._geometry(wo)
    total = np.asarray(sum(g.a_p))
    assert np.all(total < 1) and np.all(total > 0.05)
    n = 1 << 17
    k1, k2 = jax.random.split(jax.random.key(4))
    s = _smp(b, jnp.broadcast_to(wo, (n, 3)), jax.random.uniform(k1, (n,), jnp.float64),
             jax.random.uniform(k2, (n, 2), jnp.float64))  # fmt: skip
    w = np.asarray(s.weight)
    se = w.std(0, ddof=1) / math.sqrt(n)
    assert np.all(np.abs(w.mean(0) - total) < 4 * se + 1e-12), (w.mean(0), total, se)


@pytest.mark.slow  # slow: ~6 s CPU, 15 s wall on 2 cores at load 11 (first case; the others 0.3 s)
@pytest.mark.parametrize("bm, bn, alpha, eta, wo", CASES)
def test_chi2_sampling_matches_pdf(bm, bn, alpha, eta, wo):
    b = Hair(eumelanin=0.3, pheomelanin=0.2, longitudinal_roughness=bm,
             azimuthal_roughness=bn, scale_tilt=alpha, eta=eta)  # fmt: skip
    wo = jnp.asarray(wo, jnp.float32) / np.linalg.norm(wo)

    def sample(u1, u2):
        s = _smp(b, jnp.broadcast_to(wo, (u1.shape[0], 3)), u1, u2)
        return jnp.where((s.pdf > 0)[:, None], s.wi, 0.0)

    def pdf(w):
        return _ev(b, jnp.broadcast_to(wo, w.shape), w)[1]

    ok, p, d = chi2_test(sample, pdf, key=jax.random.key(2), n_samples=200_000,
                         res_theta=24, res_phi=48, ires=8, test_count=len(CASES))  # fmt: skip
    assert ok, (p, d["message"], d["pdf_integral"])
    assert abs(d["pdf_integral"] - 1) < 2e-3


@pytest.mark.slow  # slow: ~4 s CPU, 10 s wall on 2 cores at load 11 (compiles the sampler)
def test_sample_pdf_and_weight_equal_eval_over_pdf(x64):
    b = Hair(eumelanin=0.8, pheomelanin=0.5, longitudinal_roughness=0.25, scale_tilt=3.0)
    wo = jnp.asarray(_unit(4096, 3))
    k1, k2 = jax.random.split(jax.random.key(5))
    s = _smp(b, wo, jax.random.uniform(k1, (4096,), jnp.float64),
             jax.random.uniform(k2, (4096, 2), jnp.float64))  # fmt: skip
    f, pdf = _ev(b, wo, s.wi)
    ok = np.asarray(s.pdf) > 0
    assert ok.mean() > 0.999
    np.testing.assert_allclose(np.linalg.norm(s.wi, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.asarray(s.pdf)[ok], np.asarray(pdf)[ok], rtol=1e-9)
    ratio = np.asarray(f) / np.asarray(pdf)[:, None]
    np.testing.assert_allclose(np.asarray(s.weight)[ok], ratio[ok], rtol=1e-9)
    assert not np.any(np.asarray(s.is_delta)) and np.all(np.asarray(s.eta) == 1)


def test_longitudinal_lobe_is_deons_normalised_density(x64):
    """``M_p`` (i0e form) against d'Eon et al. 2011 eq. 6 with SciPy's I0, and its integral
    over the sphere (``∫ M cos θ dθ dφ = 1``) by Gauss–Legendre quadrature in θ, for variances
    from 0.0001 (κ = 1e4, where ``I0`` and ``sinh`` overflow) to 2."""
    from scipy.special import i0

    xg, wg = np.polynomial.legendre.leggauss(400)
    for v in (1e-4, 0.01, 0.1, 0.5, 2.0):
        for th_o in (-1.2, -0.3, 0.0, 0.7, 1.5):
            th = 0.5 * math.pi * xg
            m = np.asarray(_mp(math.sin(th_o), math.cos(th_o), np.sin(th), np.cos(th), v))
            total = 2 * math.pi * np.sum(0.5 * math.pi * wg * m * np.cos(th))
            tol = 1e-6 if v >= 0.01 else 2e-3  # 400 nodes resolve a lobe of width 0.01 only
            assert abs(total - 1) < tol, (v, th_o, total)
            if v >= 0.01:
                k = 1 / v
                ref = (k / (2 * math.sinh(k)) * np.exp(-k * math.sin(th_o) * np.sin(th))
                       * i0(k * math.cos(th_o) * np.cos(th)) / (2 * math.pi))  # fmt: skip
                np.testing.assert_allclose(m, ref, rtol=1e-10, atol=1e-300)


def test_reciprocity_holds_for_the_lobe_shapes_only(x64):
    """Chiang's model is not reciprocal (Mitsuba flags it ``NonSymmetric``): ``h``, the
    attenuation ``A_p`` (Fresnel at ``θ_o``, ``γ_o``) and the azimuthal centres ``Φ_p`` depend on
    the viewing direction alone, and the tilt turns only ``θ_o``. What is symmetric: ``M_p``
    without tilt. Measured here: swapping the directions changes ``eval`` by > 10 % on most
    pairs even at α = 0."""
    a, c = _unit(256, 6), _unit(256, 7)
    sa, ca, sc, cc = a[:, 1], np.sqrt(1 - a[:, 1] ** 2), c[:, 1], np.sqrt(1 - c[:, 1] ** 2)
    m1 = np.asarray(_mp(sa, ca, sc, cc, 0.05))
    m2 = np.asarray(_mp(sc, cc, sa, ca, 0.05))
    np.testing.assert_allclose(m1, m2, rtol=1e-12)
    b = Hair(sigma_a=0.2, scale_tilt=0.0)
    f1 = np.asarray(_ev(b, jnp.asarray(a), jnp.asarray(c))[0])[:, 1]
    f2 = np.asarray(_ev(b, jnp.asarray(c), jnp.asarray(a))[0])[:, 1]
    rel = np.abs(f1 - f2) / np.maximum(f1, f2)
    assert np.mean(rel > 0.1) > 0.5


def test_melanin_gives_published_sigma_a_and_colours():
    b = Hair(eumelanin=2.0, pheomelanin=0.5)
    np.testing.assert_allclose(b.absorption, 2 * np.array([0.419, 0.697, 1.37])
                               + 0.5 * np.array([0.187, 0.4, 1.05]), rtol=1e-6)  # fmt: skip
    np.testing.assert_allclose(Hair(sigma_a=[0.2, 0.25, 0.7], scale=2.0).absorption,
                               [0.4, 0.5, 1.4], rtol=1e-6)  # fmt: skip
    np.testing.assert_allclose(Hair().absorption, 1.3 * np.array([0.419, 0.697, 1.37])
                               + 0.2 * np.array([0.187, 0.4, 1.05]), rtol=1e-6)  # fmt: skip
    # eumelanin darkens (blue most): the albedo exp(-2 σ_a)
    al = np.asarray(Hair(eumelanin=0.3, pheomelanin=0.0).albedo)
    assert al[0] > al[1] > al[2]


PARAMS = ("longitudinal_roughness", "azimuthal_roughness", "scale_tilt", "eta")


@pytest.mark.slow  # slow: ~5 s CPU, 13 s wall each on 2 cores at load 11 (two compiles)
@pytest.mark.parametrize("pigment", [False, True])
def test_gradients_match_finite_differences(x64, pigment):
    """d/dθ of a weighted sum of ``eval`` over 64 direction pairs, θ = (β_m, β_n, α, η,
    σ_a (RGB) | eumelanin, pheomelanin), float64 central differences (ε = 1e-6)."""
    wo, wi = jnp.asarray(_unit(64, 8)), jnp.asarray(_unit(64, 9))
    wt = jnp.asarray(np.random.default_rng(10).uniform(0.5, 1.5, (64, 3)))

    def build(x):
        kw = dict(zip(PARAMS, x[:4], strict=True))
        if pigment:
            return Hair(eumelanin=x[4], pheomelanin=x[5], **kw)
        return Hair(sigma_a=x[4:7], **kw)

    def f(x):
        b = build(x)
        return jnp.sum(wt * b.eval(wo, wi)) + jnp.sum(b.pdf(wo, wi))

    x = [0.35, 0.45, 3.0, 1.5] + ([0.7, 0.4] if pigment else [0.3, 0.5, 0.9])
    ok, ad, fd = check_grads_fd(f, jnp.asarray(x, jnp.float64), eps=1e-6, rtol=1e-6,
                                atol=1e-9, jit=True)  # fmt: skip
    assert ok, (ad, fd)
    assert np.all(np.abs(ad) > 1e-4)  # every parameter matters here


HARD = [
    ("grazing h = -1", (1.0, 0.3, 0.0)),
    ("grazing h = +1", (-1.0, 0.0, 0.0)),
    ("along the fibre +y", (0.0, 1.0, 0.0)),
    ("along the fibre -y", (0.0, -1.0, 0.0)),
    ("head-on h = 0", (0.0, 0.0, 1.0)),
]


HARD_PARAMS = [(0.0, 0.01, 0.01), (50.0, 0.01, 0.01), (0.0, 0.3, 0.5), (1e3, 1.0, 0.5)]


def _hard_loss(x, wo):
    """eval + pdf over 19 light directions (three along / across the fibre) and the weights and
    pdfs of 19 samples (u1 from 0 to 1), for ``x = (σ_a, β_m, β_n, α, η)``."""
    wis = jnp.asarray(np.concatenate([_unit(16, 11), [[0, 1, 0], [0, -1, 0], [1, 0, 0]]]))
    b = Hair(sigma_a=x[0], longitudinal_roughness=x[1], azimuthal_roughness=x[2],
             scale_tilt=x[3], eta=x[4])  # fmt: skip
    w = jnp.broadcast_to(wo, wis.shape)
    s = b.sample(w, jnp.linspace(0, 1, wis.shape[0]), jnp.full((wis.shape[0], 2), 0.5))
    return jnp.sum(b.eval(w, wis)) + jnp.sum(b.pdf(w, wis)) + jnp.sum(s.weight) + jnp.sum(s.pdf)


@pytest.mark.slow  # slow: ~9 s CPU, 22 s wall on 2 cores at load 11 (the sampler's gradient)
def test_hard_cases_values_and_gradients_finite(x64):
    """β_m = β_n = 0.01 (κ ≈ 1e4, a logistic of scale 0.002), σ_a = 0, 50 and 1000, grazing
    h = ±1, views along the fibre axis (sin θ = ±1, where h is undefined: 0 as Mitsuba) and
    head-on: values and gradients w.r.t. all five parameters finite (one vmapped program)."""
    xs, wos = [], []
    for sig, bm, bn in HARD_PARAMS:
        for _, wo in HARD:
            xs.append([sig, bm, bn, 2.0, 1.55])
            wos.append(np.asarray(wo) / np.linalg.norm(wo))
    v, d = jax.jit(jax.vmap(jax.value_and_grad(_hard_loss)))(jnp.asarray(xs), jnp.asarray(wos))
    assert np.all(np.isfinite(np.asarray(v))) and np.all(np.isfinite(np.asarray(d)))


@pytest.mark.slow  # slow: ~2.5 s CPU, 6 s wall on 2 cores at load 11
def test_sampling_with_extreme_uniforms_is_finite(x64):
    b = Hair(longitudinal_roughness=0.01, azimuthal_roughness=0.01)
    u = jnp.asarray([0.0, 1.0 - 1e-16, 0.5])
    uu = jnp.stack(jnp.meshgrid(u, u, u, indexing="ij"), -1).reshape(-1, 3)
    for wo, _ in ((w, n) for n, w in HARD):
        s = _smp(b, jnp.broadcast_to(jnp.asarray(wo) / np.linalg.norm(wo), (27, 3)),
                 uu[:, 0], uu[:, 1:])  # fmt: skip
        assert np.all(np.isfinite(np.asarray(s.wi))) and np.all(np.isfinite(np.asarray(s.weight)))


def test_errors_name_the_argument():
    with pytest.raises(ValueError, match="sigma_a: give either"):
        Hair(sigma_a=0.5, eumelanin=1.0)
    with pytest.raises(ValueError, match="longitudinal_roughness"):
        Hair(longitudinal_roughness=0.0)
    with pytest.raises(ValueError, match="azimuthal_roughness"):
        Hair(azimuthal_roughness=1.5)
    with pytest.raises(ValueError, match="eta"):
        Hair(eta=1.0)
    with pytest.raises(ValueError, match="eumelanin"):
        Hair(eumelanin=-1.0)
    with pytest.raises(ValueError, match="sigma_a"):
        Hair(sigma_a=[1.0, -1.0, 0.0])
    with pytest.raises(ValueError, match="unknown parameter for 'hair'"):
        make_bsdf({"type": "hair", "roughness": 0.3})
    with pytest.raises(TypeError, match="cannot be nested"):
        BlendBSDF(Hair(), Diffuse())
    with pytest.raises(TypeError, match="cannot be nested"):
        Mask(Hair())


def test_make_bsdf_and_jit_dispatch():
    b = make_bsdf({"type": "hair", "eumelanin": 0.2, "pheomelanin": 0.4,
                   "longitudinal_roughness": 0.25})  # fmt: skip
    assert isinstance(b, Hair) and b.is_transmissive and b.needs_tangents
    wo, wi = _fibre_dir(0.2, 1.3), _fibre_dir(-0.25, -1.0)
    f, p = _ev(b, wo, wi)
    assert np.all(np.asarray(f) > 0) and float(p) > 0
