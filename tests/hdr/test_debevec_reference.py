"""``debevec_solve`` against a dense NumPy least-squares solve of the full system.

The solver eliminates the P per-pixel unknowns (Schur complement) and solves an L × L system;
the reference stacks all P + L unknowns in one dense matrix, one row per equation of Debevec &
Malik (1997), eq. (3) — data rows ``W_ij (g[Z_ij] − u_i − ln t_j)``, smoothness rows
``√λ · hat(z_k) · g''(z_k)``, the anchor ``g[m] = 0`` and the solver's 1e-7 relative ridge on
``g`` — and calls ``numpy.linalg.lstsq``.
"""

import jax
import numpy as np
import pytest

from jaxgfx.hdr._debevec import debevec_solve


def _problem(seed, p=80, n=5, n_levels=32):
    rng = np.random.default_rng(seed)
    log_t = np.log(4.0 ** np.arange(n))
    u = rng.uniform(-7.0, 0.5, p)
    z = np.clip(np.exp((u[:, None] + log_t[None, :]) / 2.2), 0.0, 1.0)
    lev = np.clip(np.round(z * (n_levels - 1) + rng.normal(0, 0.7, z.shape)), 0, n_levels - 1)
    lev = lev.astype(np.int32)
    zq = lev / (n_levels - 1)
    w = np.minimum(zq, 1.0 - zq) * 2.0 + 0.01 * rng.random(z.shape)  # hat, not all equal
    w[lev == 0] = 0.0
    w[lev == n_levels - 1] = 0.0
    return lev, w, log_t


def _dense_reference(lev, w, log_t, n_levels, lam, m):
    p, n = lev.shape
    rows, rhs = [], []
    scale = 1.0 / np.sqrt(np.sum(w * w))  # the data term is normalised by sum W^2
    for i in range(p):
        for j in range(n):
            r = np.zeros(n_levels + p)
            r[lev[i, j]] = 1.0
            r[n_levels + i] = -1.0
            rows.append(scale * w[i, j] * r)
            rhs.append(scale * w[i, j] * log_t[j])
    h = 1.0 / (n_levels - 1)
    for k in range(1, n_levels - 1):
        zk = k * h
        r = np.zeros(n_levels + p)
        r[k - 1 : k + 2] = np.array([1.0, -2.0, 1.0]) / h**2
        # mean over the L - 2 interior knots of (hat(z) g'')^2
        rows.append(np.sqrt(lam / (n_levels - 2)) * 2.0 * min(zk, 1.0 - zk) * r)
        rhs.append(0.0)
    r = np.zeros(n_levels + p)
    r[m] = 1.0
    rows.append(r)
    rhs.append(0.0)
    a, b = np.array(rows), np.array(rhs)
    # the solver's conditioning ridge: 1e-7 x the mean diagonal of the normal matrix of g
    # once the u_i are eliminated (the Schur complement, here computed densely)
    nm = a.T @ a
    reduced = (
        nm[:n_levels, :n_levels]
        - nm[:n_levels, n_levels:]
        @ np.linalg.pinv(nm[n_levels:, n_levels:])
        @ nm[n_levels:, :n_levels]
    )
    ridge = np.sqrt(1e-7 * np.mean(np.diag(reduced)))
    a = np.vstack([a, np.hstack([ridge * np.eye(n_levels), np.zeros((n_levels, p))])])
    b = np.concatenate([b, np.zeros(n_levels)])
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    return sol[:n_levels]


@pytest.mark.parametrize("lam", [1e-6, 1e-3])
def test_debevec_solve_matches_dense_lstsq(x64, lam):
    n_levels, m = 32, 15
    lev, w, log_t = _problem(0)
    ref = _dense_reference(lev, w, log_t, n_levels, lam, m)
    solve = jax.jit(debevec_solve, static_argnums=(3,))
    g = np.asarray(solve(lev, w, log_t, n_levels, lam, m))
    assert np.unique(lev[w > 0]).size > 20  # most levels are constrained by data
    # same equations, same minimiser: equal to rounding (measured 3e-13); a weight not squared
    # moves g by 0.3 to 0.6, lambda off by 5 % by 1e-2
    np.testing.assert_allclose(g, ref, rtol=0, atol=1e-9)
