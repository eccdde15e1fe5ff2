"""Fresnel terms vs closed forms (complex Snell/Fresnel in NumPy), textbook values."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from scipy.integrate import quad

from jaxgfx.render.bsdf.fresnel import (
    fresnel_conductor,
    fresnel_dielectric,
    fresnel_dielectric_polarized,
    fresnel_diffuse_reflectance,
    fresnel_schlick,
)


def np_fresnel(cos_i, n):
    """Unpolarised Fresnel reflectance for relative complex IOR n, from Snell's law (NumPy)."""
    cos_i = np.asarray(cos_i, np.complex128)
    n = np.asarray(n, np.complex128)
    sin2_t = (1 - cos_i**2) / n**2
    cos_t = np.sqrt(1 - sin2_t)
    cos_t = np.where(cos_t.imag < 0, -cos_t, cos_t)  # decaying branch
    rs = (cos_i - n * cos_t) / (cos_i + n * cos_t)
    rp = (n * cos_i - cos_t) / (n * cos_i + cos_t)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2), np.abs(rs) ** 2, np.abs(rp) ** 2


COS = np.array([1.0, 0.95, 0.8, 0.6, 0.4, 0.25, 0.1, 0.03])
_fd = jax.jit(fresnel_dielectric)
_fc = jax.jit(fresnel_conductor)


@pytest.mark.parametrize("eta", [1.5, 1.0 / 1.5, 2.4, 1.333])
def test_dielectric_matches_closed_form(eta, x64):
    res = _fd(jnp.asarray(COS), eta)
    ref, _, _ = np_fresnel(COS, eta)
    # total internal reflection where sin θ_i > eta
    ref = np.where(1 - COS**2 > eta**2, 1.0, ref)
    np.testing.assert_allclose(res.r, ref, rtol=1e-10, atol=1e-12)
    # Snell's law and sign convention of cos θ_t
    sin_t = np.sqrt(1 - COS**2) / eta
    exp_cos_t = -np.sqrt(np.maximum(1 - sin_t**2, 0))
    np.testing.assert_allclose(res.cos_theta_t, exp_cos_t, atol=1e-10)
    # arriving from inside: same as 1/eta from outside, cos_t positive
    inside = _fd(-jnp.asarray(COS), eta)
    outside_inv = _fd(jnp.asarray(COS), 1.0 / eta)
    np.testing.assert_allclose(inside.r, outside_inv.r, rtol=1e-12)
    np.testing.assert_allclose(inside.cos_theta_t, -outside_inv.cos_theta_t, atol=1e-12)


def test_textbook_values():
    assert float(fresnel_dielectric(1.0, 1.5).r) == pytest.approx(0.04, abs=1e-7)
    assert float(fresnel_dielectric(-1.0, 1.5).r) == pytest.approx(0.04, abs=1e-7)
    # Brewster's angle tan θ_B = 1.5: R_p = 0, R_s = sin²(θ_i - θ_t)
    tb = math.atan(1.5)
    rs, rp = fresnel_dielectric_polarized(math.cos(tb), 1.5)
    assert float(rp) == pytest.approx(0.0, abs=1e-7)
    tt = math.asin(math.sin(tb) / 1.5)
    assert float(rs) == pytest.approx(math.sin(tb - tt) ** 2, rel=1e-5)  # 0.1479
    # grazing incidence reflects everything; index-matched interface reflects nothing
    assert float(fresnel_dielectric(0.0, 1.5).r) == pytest.approx(1.0)
    assert float(fresnel_dielectric(0.3, 1.0).r) == 0.0
    # critical angle of glass -> air: sin θ_c = 1/1.5
    cos_c = math.sqrt(1 - (1 / 1.5) ** 2)
    assert float(fresnel_dielectric(-(cos_c - 1e-3), 1.5).r) == 1.0
    assert float(fresnel_dielectric(-(cos_c + 1e-2), 1.5).r) < 1.0


def test_conductor_matches_closed_form(x64):
    eta = jnp.array([0.2004, 0.9240, 1.1022])  # Au at ~(650, 550, 450) nm
    k = jnp.array([3.5328, 2.4519, 1.9271])
    res = _fc(jnp.asarray(COS)[:, None], eta, k)
    ref, _, _ = np_fresnel(COS[:, None], np.asarray(eta) + 1j * np.asarray(k))
    np.testing.assert_allclose(res, ref, rtol=1e-10)
    # normal incidence closed form
    n0 = ((eta - 1) ** 2 + k**2) / ((eta + 1) ** 2 + k**2)
    np.testing.assert_allclose(res[0], n0, rtol=1e-10)
    # k = 0 reduces to the dielectric
    np.testing.assert_allclose(_fc(jnp.asarray(COS), 1.5, 0.0), _fd(jnp.asarray(COS), 1.5).r)


def test_schlick():
    c = jnp.asarray(COS)
    np.testing.assert_allclose(fresnel_schlick(0.04, c), 0.04 + 0.96 * (1 - COS) ** 5, rtol=1e-6)
    assert float(fresnel_schlick(0.04, 0.0)) == pytest.approx(1.0)
    # Schlick's approximation stays within 0.04 of the exact glass curve (max 0.035 here)
    err = np.abs(np.asarray(fresnel_schlick(0.04, c)) - np_fresnel(COS, 1.5)[0])
    assert 0.03 < np.max(err) < 0.04


@pytest.mark.parametrize("eta", [1.5, 1.0 / 1.5, 1.333])
def test_diffuse_reflectance_quadrature(eta, x64):
    def f(mu):
        r, _, _ = np_fresnel(mu, eta)
        return (1.0 if 1 - mu**2 > eta**2 else float(r)) * 2 * mu

    crit = math.sqrt(max(1 - eta**2, 0.0))
    ref = quad(f, 0, 1, points=[crit] if crit > 0 else None, epsabs=1e-13, limit=200)[0]
    assert float(fresnel_diffuse_reflectance(eta)) == pytest.approx(ref, abs=1e-9)


@pytest.mark.slow
def test_diffuse_reflectance_reciprocity_identity(x64):
    # 1 - F_dr(1/η) = (1 - F_dr(η)) / η²  (energy balance through the interface)
    eta = jnp.array([1.2, 1.5, 2.0])
    lhs = 1 - fresnel_diffuse_reflectance(1 / eta)
    rhs = (1 - fresnel_diffuse_reflectance(eta)) / eta**2
    np.testing.assert_allclose(lhs, rhs, rtol=1e-9)


# 3.3 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_fresnel_grads(x64):
    c = jnp.array([0.9, 0.5, 0.2])

    @jax.jit
    def f(e_out, e_in, eta_c, k_c, e_dr, e_dr_inv):
        return jnp.concatenate(
            [
                fresnel_dielectric(c, e_out).r,
                fresnel_dielectric(-c, e_in).r,
                fresnel_conductor(c, eta_c, k_c),
                fresnel_diffuse_reflectance(jnp.stack([e_dr, e_dr_inv])),
            ]
        )

    check_grads(f, (1.5, 1.3, 0.4, 2.5, 1.5, 0.7), order=1, modes=["rev"])


def test_fresnel_hard_cases_finite():
    cs = jnp.array([0.0, 1.0, -1.0, 1e-8, -1e-8])

    @jax.jit
    def run(c, e, k):
        vals = (fresnel_dielectric(c, e).r, fresnel_conductor(jnp.abs(c), e, k))
        g = jax.grad(lambda c, e, k: jnp.sum(fresnel_dielectric(c, e).r), argnums=(0, 1))(c, e, k)
        g2 = jax.grad(lambda c, e, k: jnp.sum(fresnel_conductor(jnp.abs(c), e, k)), (0, 1, 2))(
            c, e, k
        )
        return vals, g, g2

    for e, k in [(1.5, 0.0), (1.0, 0.0), (0.5, 0.0), (0.2, 3.0)]:
        out = run(cs, e, k)
        for leaf in jax.tree_util.tree_leaves(out):
            assert np.all(np.isfinite(leaf)), (e, k)
        r = np.asarray(out[0][0])
        assert np.all((r >= 0) & (r <= 1))
