"""Pearson chi² goodness-of-fit test for direction samplers (after Mitsuba 3's ``chi2.py``)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaincc

__all__ = ["chi2_test"]


def _chi2_sf(stat: float, dof: int) -> float:
    """Survival function of the chi² distribution (regularised upper incomplete gamma)."""
    if dof <= 0:
        return 1.0
    return float(gammaincc(jnp.float32(0.5 * dof), jnp.float32(0.5 * stat)))


def _pool_chi2(obs, exp, min_exp):
    """Chi² over cells sorted by expected count, pooling cells with ``exp < min_exp``."""
    order = np.argsort(exp, kind="stable")
    stat, dof = 0.0, 0
    pooled_obs = pooled_exp = 0.0
    for i in order:
        if exp[i] < min_exp:
            pooled_obs += obs[i]
            pooled_exp += exp[i]
            if pooled_exp >= min_exp:
                stat += (pooled_obs - pooled_exp) ** 2 / pooled_exp
                dof += 1
                pooled_obs = pooled_exp = 0.0
        else:
            stat += (obs[i] - exp[i]) ** 2 / exp[i]
            dof += 1
    if pooled_exp > 0:
        stat += (pooled_obs - pooled_exp) ** 2 / pooled_exp
        dof += 1
    return stat, dof - 1


def chi2_test(
    sample_fn,
    pdf_fn,
    *,
    key,
    n_samples: int = 100_000,
    res_theta: int = 16,
    res_phi: int = 32,
    sig_level: float = 0.01,
    test_count: int = 1,
    ires: int = 6,
    min_expected: float = 5.0,
):
    """Chi² test that ``sample_fn`` draws directions distributed as ``pdf_fn``.

    ``sample_fn(u1, u2)`` maps uniform numbers ``u1`` (n,) and ``u2`` (n, 2) to unit directions
    (n, 3); a failed sample is signalled by the zero vector (it is dropped: its probability mass
    is then simply missing from ``pdf_fn``'s integral). ``pdf_fn(w)`` (m, 3) -> (m,) is the
    solid-angle density. The sphere is split into ``res_theta × res_phi`` cells uniform in
    ``(cos θ, φ)`` (so each has solid angle ``4π / (res_theta res_phi)``); the expected count
    per cell is ``n_samples ∫_cell pdf dω`` by ``ires × ires`` Gauss–Legendre quadrature.
    Cells with expected count < ``min_expected`` are pooled; the statistic is compared with the
    chi² distribution with Šidák-corrected level ``1 - (1 - sig_level)^(1/test_count)``.

    Fails (``passed = False``) on non-finite or non-unit samples, samples in a cell whose
    integrated pdf is 0, or a pdf integral > 1.1. Returns ``(passed, p_value, details)`` with
    ``details`` a dict (``observed``, ``expected`` (res_theta, res_phi) arrays, ``pdf_integral``,
    ``chi2``, ``dof``, ``message``).

    Reference: Mitsuba 3 ``mitsuba/python/chi2.py`` (W. Jakob); pbrt-v4 tests.
    """
    if n_samples < 1 or res_theta < 1 or res_phi < 1 or ires < 1:
        raise ValueError("n_samples, res_theta, res_phi, ires: expected positive integers")
    if not 0 < sig_level < 1:
        raise ValueError(f"sig_level: expected a value in (0, 1), got {sig_level}")
    k1, k2 = jax.random.split(key)
    u1 = jax.random.uniform(k1, (n_samples,))
    u2 = jax.random.uniform(k2, (n_samples, 2))
    w = np.asarray(sample_fn(u1, u2), dtype=np.float64).reshape(n_samples, 3)

    # expected counts by quadrature
    xg, wg = np.polynomial.legendre.leggauss(ires)
    xg = 0.5 * (xg + 1.0)
    wg = 0.5 * wg
    dz = 2.0 / res_theta
    dphi = 2.0 * math.pi / res_phi
    # each cos θ cell [z0, z1] is integrated in θ (dω = sin θ dθ dφ), which clusters nodes
    # towards the poles where peaked lobes (small roughness) concentrate
    z_edges = np.clip(-1.0 + np.arange(res_theta + 1) * dz, -1.0, 1.0)
    th_edges = np.arccos(z_edges)  # decreasing
    th0, th1 = th_edges[1:], th_edges[:-1]  # per cell, th0 < th1
    theta = th0[:, None] + (th1 - th0)[:, None] * xg[None, :]  # (T, q)
    wth = (th1 - th0)[:, None] * wg[None, :] * np.sin(theta)  # (T, q)
    phi = (np.arange(res_phi)[:, None] + xg[None, :]) * dphi  # (P, q)
    st = np.sin(theta)[:, None, :, None]
    zz = np.cos(theta)[:, None, :, None]
    pp = phi[None, :, None, :]
    pts = np.stack(
        np.broadcast_arrays(st * np.cos(pp), st * np.sin(pp), zz + 0.0 * pp), axis=-1
    )  # (T, P, q, q, 3)
    pdf_vals = np.asarray(pdf_fn(jnp.asarray(pts.reshape(-1, 3), dtype=u1.dtype)), np.float64)
    pdf_vals = pdf_vals.reshape(res_theta, res_phi, ires, ires)
    integral = np.einsum("tpij,ti,j->tp", pdf_vals, wth, wg) * dphi
    expected = integral * n_samples
    details = {"pdf_integral": float(integral.sum()), "expected": expected}

    def fail(msg):
        details["message"] = msg
        return False, 0.0, details

    if not np.all(np.isfinite(pdf_vals)):
        return fail("pdf_fn returned non-finite values")
    if np.any(pdf_vals < 0):
        return fail("pdf_fn returned negative values")
    if not np.all(np.isfinite(w)):
        return fail("sample_fn returned non-finite samples")
    norm = np.linalg.norm(w, axis=-1)
    ok = norm > 0
    if np.any(np.abs(norm[ok] - 1.0) > 1e-3):
        return fail("sample_fn returned samples outside the domain (non-unit vectors)")
    if details["pdf_integral"] > 1.1:
        return fail(f"pdf integrates to {details['pdf_integral']:.4f} > 1.1")
    ws = w[ok] / norm[ok, None]
    ti = np.clip(((ws[:, 2] + 1.0) / dz).astype(np.int64), 0, res_theta - 1)
    ph = np.mod(np.arctan2(ws[:, 1], ws[:, 0]), 2.0 * math.pi)
    pi = np.clip((ph / dphi).astype(np.int64), 0, res_phi - 1)
    observed = np.zeros((res_theta, res_phi))
    np.add.at(observed, (ti, pi), 1.0)
    details["observed"] = observed
    bad = (expected == 0) & (observed > 0)
    if np.any(bad):
        return fail(f"{int(observed[bad].sum())} samples in cells with expected frequency 0")
    stat, dof = _pool_chi2(observed.ravel(), expected.ravel(), min_expected)
    p = _chi2_sf(stat, dof)
    alpha = 1.0 - (1.0 - sig_level) ** (1.0 / test_count)
    details.update(chi2=stat, dof=dof, message="ok" if p > alpha else "chi² rejected")
    return bool(p > alpha), p, details
