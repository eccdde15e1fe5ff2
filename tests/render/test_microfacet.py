"""Microfacet distributions: normalisation, Smith Λ vs closed forms, projected area, VNDF chi²."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy.special import erf

from jaxgfx.render.bsdf.microfacet import MicrofacetDistribution
from jaxgfx.testing import chi2_test


def _hemisphere_quadrature(n_theta=256, n_phi=128):
    """Gauss–Legendre in θ ∈ [0, π/2] × midpoint in φ: directions (N, 3) and weights dω."""
    x, w = np.polynomial.legendre.leggauss(n_theta)
    theta = 0.25 * math.pi * (x + 1.0)
    wt = 0.25 * math.pi * w * np.sin(theta)
    phi = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], axis=-1)
    weights = (wt[:, None] * np.full(n_phi, 2 * math.pi / n_phi)[None, :]).ravel()
    return dirs.reshape(-1, 3), weights


DIRS, DW = _hemisphere_quadrature()
CONFIGS = [("ggx", 0.1, None), ("ggx", 0.5, None), ("ggx", 1.0, None), ("ggx", 0.2, 0.6)]
CONFIGS += [("beckmann", 0.1, None), ("beckmann", 0.5, None), ("beckmann", 0.3, 0.8)]


@jax.jit
def _d_and_area(distr, m, v):
    d = distr.eval(m)
    proj = distr.smith_g1(v[:, None, :], m[None]) * jnp.maximum(m @ v.T, 0.0).T * d[None]
    return d, proj


@pytest.mark.parametrize("kind,au,av", CONFIGS)
def test_normalisation_and_projected_area(kind, au, av, x64):
    """∫ D cos θ_m dω = 1 and ∫ G1(v, m) max(0, v·m) D(m) dω_m = cos θ_v (Heitz 2014 eq. 2)."""
    distr = MicrofacetDistribution(kind, au, av)
    v = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.3, 0.5, math.sqrt(0.66)]])
    v = np.concatenate([v, [[math.sqrt(1 - 0.1**2), 0.0, 0.1]]])
    d, proj = _d_and_area(distr, jnp.asarray(DIRS), jnp.asarray(v))
    assert float(np.sum(np.asarray(d) * DIRS[:, 2] * DW)) == pytest.approx(1.0, abs=2e-4)
    np.testing.assert_allclose(np.asarray(proj) @ DW, v[:, 2], rtol=2e-3)


def test_lambda_closed_forms(x64):
    tan = np.array([0.05, 0.3, 1.0, 3.0, 30.0])
    v = np.stack([tan, 0 * tan, np.ones_like(tan)], -1) / np.sqrt(1 + tan**2)[:, None]
    lam = jax.jit(lambda d, v: d.smith_lambda(v))
    for alpha in [0.05, 0.3, 1.0]:
        ggx = lam(MicrofacetDistribution("ggx", alpha), jnp.asarray(v))
        np.testing.assert_allclose(ggx, 0.5 * (np.sqrt(1 + alpha**2 * tan**2) - 1), rtol=1e-10)
        a = 1 / (alpha * tan)
        ref = 0.5 * (erf(a) - 1) + np.exp(-(a**2)) / (2 * a * np.sqrt(np.pi))
        beck = lam(MicrofacetDistribution("beckmann", alpha), jnp.asarray(v))
        np.testing.assert_allclose(beck, ref, rtol=1e-6, atol=1e-12)
    # GGX α = 1 at the pole: D = 1/π; anisotropic GGX rotated axis uses α_u
    assert float(MicrofacetDistribution("ggx", 1.0).eval(jnp.array([0.0, 0, 1]))) == pytest.approx(
        1 / math.pi
    )
    # height-correlated G = 1 / (1 + Λo + Λi)
    d = MicrofacetDistribution("ggx", 0.5)
    wo, wi = jnp.asarray(v[1]), jnp.asarray(v[2] * np.array([-1, 1, 1]))
    m = (wo + wi) / jnp.linalg.norm(wo + wi)
    g = d.G(wo, wi, m, height_correlated=True)
    ref = 1 / (1 + float(d.smith_lambda(wo)) + float(d.smith_lambda(wi)))
    assert float(g) == pytest.approx(ref, rel=1e-12)


_sample = jax.jit(lambda d, wi, u: d.sample(wi, u)[0])
_pdf = jax.jit(lambda d, wi, m: d.pdf(wi, m))

CHI2 = [
    ("ggx", 0.3, None, 0.8, True),
    ("ggx", 1.0, None, 1.0, True),
    ("ggx", 0.05, None, 0.5, True),
    ("ggx", 0.3, None, 0.05, True),
    ("ggx", 0.2, 0.6, 0.6, True),
    ("ggx", 0.3, None, 0.7, False),
    ("beckmann", 0.3, None, 0.7, False),
    ("beckmann", 0.2, 0.6, 0.7, False),
]


@pytest.mark.parametrize("kind,au,av,cos_i,visible", CHI2)
def test_sample_chi2(kind, au, av, cos_i, visible):
    distr = MicrofacetDistribution(kind, au, av, sample_visible=visible)
    s = math.sqrt(1 - cos_i**2)
    wi = jnp.array([s * 0.8, s * 0.6, cos_i])
    ok, p, det = chi2_test(
        lambda u1, u2: _sample(distr, wi, u2),
        lambda m: _pdf(distr, wi, m),
        key=jax.random.key(11),
        n_samples=40_000,
        res_theta=16,
        res_phi=32,
        ires=10,
        test_count=len(CHI2),
    )
    assert ok, (p, det["message"])
    assert det["pdf_integral"] == pytest.approx(1.0, abs=0.02)


def test_grads_wrt_alpha(x64):
    m = jnp.array([[0.1, 0.2, 0.97467943], [0.5, -0.3, 0.81240384]])
    v = jnp.array([[0.6, 0.0, 0.8], [0.0, 0.28, 0.96]])

    @jax.jit
    def f(au, av, ab):
        g = MicrofacetDistribution("ggx", au, av)
        b = MicrofacetDistribution("beckmann", ab)
        return jnp.concatenate([g.eval(m), g.smith_g1(v, m), b.eval(m), b.smith_g1(v, m)])

    check_grads(f, (0.3, 0.5, 0.4), order=1, modes=["rev"])


@pytest.mark.slow
def test_hard_cases_finite():
    """α = 1e-4, grazing (cos θ = 0, 1e-7) and the pole: finite values and gradients."""
    m = jnp.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, 0.0, 0.8], [1.0, 0.0, 1e-7]])
    m = m / jnp.linalg.norm(m, axis=-1, keepdims=True)
    u = jnp.array([[0.5, 0.5], [0.0, 0.0], [0.999, 0.3], [0.2, 0.9]])

    @jax.jit
    def run(alpha):
        def f(a):
            out = []
            for kind in ("ggx", "beckmann"):
                d = MicrofacetDistribution(kind, a)
                mm, pdf = d.sample(m, u)
                out += [d.eval(m), d.smith_g1(m, m), d.G(m, m[::-1], m), pdf, mm]
            return out

        vals = f(alpha)
        grad = jax.grad(lambda a: sum(jnp.sum(jnp.where(jnp.isfinite(x), x, 0)) for x in f(a)))
        return vals, grad(alpha)

    for alpha in [1e-4, 1.0]:
        vals, g = run(alpha)
        for x in jax.tree_util.tree_leaves(vals) + [g]:
            assert np.all(np.isfinite(x)), alpha
    # α → 0: D concentrates at the pole (value 1/(π α²))
    vals, _ = run(1e-4)
    assert float(vals[0][0]) == pytest.approx(1 / (math.pi * 1e-8), rel=1e-4)


def test_bad_input():
    with pytest.raises(ValueError, match="type"):
        MicrofacetDistribution("phong", 0.1)
    with pytest.raises(ValueError, match="alpha"):
        MicrofacetDistribution("ggx", 0.0)
    with pytest.raises(ValueError, match="alpha_v"):
        MicrofacetDistribution("ggx", 0.1, -1.0)
