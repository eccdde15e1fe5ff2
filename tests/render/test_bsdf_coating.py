"""Rough plastic's internal diffuse reflectance ``R_int`` (bsdf/_coating.py): the precomputed
table's spline against the accurate quadrature, its derivatives, limits and the batched path."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.bsdf._coating import CoatingTerms, r_int, r_int_quadrature, r_int_table
from jaxgfx.render.bsdf.microfacet import MicrofacetDistribution

# (type, alpha, eta, R_int, dR/dalpha, dR/deta): R_int = 2 ∫ R(μ, 1/η) μ dμ by
# tools/make_coating_table.py's rule (384² nodes for R, 2 × 48-point Gauss–Legendre in μ split
# at the critical cosine; doubling both changes these by <= 8e-6), derivatives by central
# differences (h = 1e-3) of that quadrature; off the table's knots. Too slow for the test itself.
REFERENCE = [
    ("ggx", 0.2, 1.49, 0.487116676, -0.72165, 0.62214),
    ("ggx", 0.05, 1.5, 0.584730021, -0.38494, 0.60671),
    ("ggx", 0.2, 1.8, 0.632727829, -0.72977, 0.34971),
    ("beckmann", 0.3, 1.6, 0.594405997, -0.36069, 0.51287),
    ("ggx", 0.7, 3.1, 0.470656635, -0.61996, 0.05655),
    ("beckmann", 0.03, 1.2, 0.335574658, -0.04871, 1.22969),
]


@pytest.mark.parametrize("typ,alpha,eta,ref,da,de", REFERENCE)
def test_r_int_table_matches_quadrature_and_its_derivatives(x64, typ, alpha, eta, ref, da, de):
    f = jax.jit(lambda a, e: r_int_table(typ, a, e))
    assert float(f(alpha, eta)) == pytest.approx(ref, abs=2e-5)
    ga, ge = jax.grad(f, (0, 1))(alpha, eta)
    h = 1e-6  # AD is the derivative of the interpolant itself
    fd_a = (float(f(alpha + h, eta)) - float(f(alpha - h, eta))) / (2 * h)
    fd_e = (float(f(alpha, eta + h)) - float(f(alpha, eta - h))) / (2 * h)
    np.testing.assert_allclose([ga, ge], [fd_a, fd_e], rtol=1e-5)
    # ... and of the integral (1 %; 2 % at GGX α = 0.05, the spline's largest error in α)
    tol = 0.025 if alpha == 0.05 else 0.01
    assert float(ga) == pytest.approx(da, rel=tol, abs=1e-3)
    assert float(ge) == pytest.approx(de, rel=0.01, abs=1e-3)


def test_r_int_smooth_limit_is_f_dr(x64):
    # α → 0 (clamped to 1e-4): R_int → F_dr(1/η) = 2 ∫ F(μ, 1/η) μ dμ (TIR part analytic)
    eta = 1.49
    x, w = np.polynomial.legendre.leggauss(400)
    mu_c = math.sqrt(1 - 1 / eta**2)
    t = 0.5 * (1 - mu_c) * (x + 1) + mu_c
    s2 = (1 - t**2) * eta**2
    ct = np.sqrt(1 - s2)
    n = 1 / eta
    rs = (t - n * ct) / (t + n * ct)
    rp = (ct - n * t) / (ct + n * t)
    fdr = mu_c**2 + np.sum(0.5 * (1 - mu_c) * w * 2 * 0.5 * (rs**2 + rp**2) * t)
    for typ in ("ggx", "beckmann"):
        for a in (1e-6,):
            v = r_int(MicrofacetDistribution(typ, a), eta)
            assert float(v) == pytest.approx(fdr, abs=1e-5)


def test_r_int_batched_equals_scalar():
    alpha = jnp.array([0.05, 0.3, 0.9])
    eta = jnp.array([1.3, 1.49, 2.5])
    batched = CoatingTerms(MicrofacetDistribution("ggx", alpha), eta)
    assert batched.batched
    for k in range(3):
        scalar = r_int(MicrofacetDistribution("ggx", alpha[k]), eta[k])
        assert float(batched.r_int[k]) == pytest.approx(float(scalar), abs=1e-6)


# 12 s (compiles the quadratures): make test-slow
@pytest.mark.slow
def test_r_int_falls_back_to_quadrature_outside_the_table():
    # η < 1 (no total internal reflection), η > 4, α > 1, anisotropic: the quadrature
    for d, eta in [
        (MicrofacetDistribution("ggx", 0.3), 0.8),
        (MicrofacetDistribution("ggx", 0.3), 4.5),
        (MicrofacetDistribution("beckmann", 1.3), 1.5),
        (MicrofacetDistribution("ggx", 0.2, 0.4), 1.5),
    ]:
        assert float(r_int(d, eta)) == pytest.approx(float(r_int_quadrature(d, eta)), abs=1e-6)
    # mixed batch: each element by its own rule
    d = MicrofacetDistribution("ggx", jnp.array([0.3, 0.3]))
    v = r_int(d, jnp.array([1.5, 0.8]), nodes=8, n_mu=16)
    assert float(v[0]) == pytest.approx(float(r_int_table("ggx", 0.3, 1.5)), abs=1e-6)
    q = r_int_quadrature(MicrofacetDistribution("ggx", 0.3), 0.8, nodes=8, n_mu=16)
    assert float(v[1]) == pytest.approx(float(q), abs=1e-6)
