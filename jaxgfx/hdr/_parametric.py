"""Parametric response fits by Levenberg–Marquardt (:func:`jaxgfx.optim.least_squares_solve`):
gamma, Mitsunaga–Nayar polynomial (with exposure ratios), and a monotone log-domain spline.

All three minimise the same log-domain, variable-projection objective: for each sampled
pixel ``i`` the per-frame estimates ``h_ij = ln base(z_ij) − ln t_j`` should agree; the pixel
log-irradiance ``u_i`` is eliminated in closed form (weighted mean, weights ``hat(z)²``), so
the unknowns are only the curve parameters (and, for the polynomial, the exposure times).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_nonnegative
from .._math import safe_log
from ..optim import least_squares_solve
from ._curves import base_to_linear, table_lookup
from ._model import CameraResponse, resolve_anchor
from ._sampling import select_samples
from .weighting import weight_hat

__all__ = ["recover_gamma", "recover_polynomial", "recover_spline", "vp_residuals"]


def vp_residuals(log_x, w, log_t):
    """Variable-projection residuals ``w_ij (h_ij − u_i) / sqrt(Σ w²)``, ``h = log_x − log_t``.

    ``log_x``/``w``: ``(..., P, N)``; ``log_t``: ``(N,)`` (or broadcastable). ``u_i`` is the
    ``w²``-weighted mean of ``h_i·``; pixels with all-zero weights contribute zeros.
    """
    h = log_x - log_t
    w2 = w * w
    den = jnp.sum(w2, axis=-1, keepdims=True)
    ok = den > 0
    u = jnp.sum(w2 * h, axis=-1, keepdims=True) / jnp.where(ok, den, 1.0)
    tot = jnp.maximum(jnp.sum(w2), jnp.finfo(w.dtype).tiny)
    return w * (h - u) / jnp.sqrt(tot)


def _tols(dtype):
    return (1e-9, 1e-9) if dtype == jnp.float64 else (1e-4, 1e-4)


def _prep(z, key, n_samples):
    if key is None:
        key = jax.random.key(0)
    samples, valid = select_samples(key, z, n_samples=n_samples)  # (C, P, N)
    w = weight_hat(samples) * valid[..., None].astype(z.dtype)
    return samples, w


def _solve(fn, y0, args, max_steps):
    rtol, atol = _tols(jax.tree_util.tree_leaves(y0)[0].dtype)
    return least_squares_solve(fn, y0, args, solver="lm", rtol=rtol, atol=atol,
                               max_steps=max_steps)  # fmt: skip


def _fit_gamma(samples, w, log_t, max_steps):
    def fn(gam, args):
        s, ww = args
        lx = gam[:, None, None] * safe_log(s, floor=1e-12)
        return vp_residuals(lx, ww, log_t)

    g0 = jnp.full((samples.shape[0],), 2.0, samples.dtype)
    sol = _solve(fn, g0, (samples, w), max_steps)
    res = fn(sol.value, (samples, w))
    return sol.value, sol, res


def recover_gamma(
    z, t, code_max, *, key=None, n_samples: int = 512, max_steps: int = 64, anchor="mid"
):
    """Power-law fit ``x = z^γ`` per channel (method ``"gamma"``), Levenberg–Marquardt.

    Exact for gamma-encoded data: a noise-free float stack of ``x = z^2.2`` returns
    ``γ = 2.2`` to solver tolerance. ``diagnostics``: ``residual_rms`` (per channel),
    ``steps`` (LM iterations), ``converged`` (bool).
    """
    anchor_z = resolve_anchor(anchor)
    samples, w = _prep(z, key, n_samples)
    gam, sol, res = _fit_gamma(samples, w, jnp.log(t), max_steps)
    diag = _diag(res, sol)
    return CameraResponse(gam, "gamma", "gamma", float(code_max), anchor_z, None, diag)


def _diag(res, sol):
    c = res.shape[0]
    rms = jnp.sqrt(jnp.sum(res.reshape(c, -1) ** 2, axis=1))
    return {
        "residual_rms": rms,
        "steps": sol.num_steps,
        "converged": sol.converged,
    }


def _poly_init(gam, degree, dtype):
    """Least-squares projection of ``z^γ`` on ``Σ c_k z^k`` with ``Σ c_k = 1`` per channel."""
    zg = jnp.linspace(0.0, 1.0, 64, dtype=dtype)
    basis = jnp.stack([zg**k - zg**degree for k in range(degree)], axis=1)  # (64, K)

    def one(g):
        target = zg**g - zg**degree
        c, *_ = jnp.linalg.lstsq(basis, target)
        return jnp.concatenate([c, 1.0 - jnp.sum(c, keepdims=True)])

    return jax.vmap(one, out_axes=1)(gam)  # (K+1, C)


def recover_polynomial(
    z,
    t,
    code_max,
    *,
    key=None,
    n_samples: int = 512,
    degree: int = 5,
    estimate_ratios: bool = True,
    ratio_prior: float = 0.1,
    max_steps: int = 128,
    anchor="mid",
):
    """Mitsunaga & Nayar (1999) polynomial response ``x = Σ_{k=0..K} c_k z^k`` with
    ``Σ c_k = 1`` (so ``x(1) = 1``), per channel (method ``"polynomial"``).

    With ``estimate_ratios`` the exposure times are unknowns too (shared by the channels,
    the shortest fixed, initialised from the nominal ``t``); a weak penalty
    ``ratio_prior · (ln t_j − ln t_j^nominal)`` resolves the residual scale ambiguity of the
    log objective. Initialised from a gamma fit projected on the polynomial basis, then
    solved jointly by Levenberg–Marquardt. ``exposure_ratios``: ``(N,)`` fitted ``t_j / t_0``
    (ascending order of the nominal times).
    """
    if isinstance(degree, bool) or not isinstance(degree, int) or not 1 <= degree <= 10:
        raise ValueError(f"degree: expected an integer in [1, 10], got {degree!r}")
    check_nonnegative(ratio_prior, "ratio_prior")
    anchor_z = resolve_anchor(anchor)
    samples, w = _prep(z, key, n_samples)
    log_t0 = jnp.log(t)
    gam, _, _ = _fit_gamma(samples, w, log_t0, max_steps)
    c0 = _poly_init(gam, degree, z.dtype)
    n = t.shape[0]

    def unpack(y):
        free, dlt = y
        c = jnp.concatenate([free, 1.0 - jnp.sum(free, axis=0, keepdims=True)], axis=0)
        log_t = log_t0 + jnp.concatenate([jnp.zeros((1,), dlt.dtype), dlt])
        return c, log_t

    def fn(y, args):
        s, ww = args
        c, log_t = unpack(y)
        x = base_to_linear("polynomial", c[:, :, None, None], s)  # params (K+1, C, 1, 1)
        lx = safe_log(x, floor=1e-8)
        r = vp_residuals(lx, ww, log_t)
        prior = ratio_prior * (log_t - log_t0)[1:]
        return r.reshape(-1), prior

    dlt0 = jnp.zeros((n - 1,), z.dtype)
    if not estimate_ratios:

        def fn_fixed(free, args):
            return fn((free, dlt0), args)

        sol = _solve(fn_fixed, c0[:-1], (samples, w), max_steps)
        y = (sol.value, dlt0)
        res = fn_fixed(sol.value, (samples, w))[0]
    else:
        sol = _solve(fn, (c0[:-1], dlt0), (samples, w), max_steps)
        y = sol.value
        res = fn(y, (samples, w))[0]
    c, log_t = unpack(y)
    ratios = jnp.exp(log_t - log_t[0]) if estimate_ratios else None
    diag = _diag(res.reshape(samples.shape[0], -1), sol)
    return CameraResponse(c, "polynomial", "polynomial", float(code_max), anchor_z, ratios, diag)


def _softplus_inv(y):
    return y + jnp.log(-jnp.expm1(-y))


def recover_spline(
    z,
    t,
    code_max,
    *,
    key=None,
    n_samples: int = 512,
    n_knots: int = 64,
    lam: float = 1e-6,
    max_steps: int = 64,
    anchor="mid",
):
    """Monotone-by-construction log-domain spline (method ``"spline"``).

    ``g = ln x`` on ``n_knots`` uniform knots over ``[0, 1]``, ``g_0 = 0`` and
    ``g_k = Σ_{m≤k} softplus(θ_m)`` (strictly increasing for any ``θ``), linear
    interpolation between knots; smoothness ``lam · mean_k (hat(z_k) g''(z_k))²`` as in
    ``"debevec"``. Exposure times are taken as given (a free-form curve and free times are
    not jointly identifiable). Initialised from a gamma fit; LM per channel. Returns a
    ``"table"`` :class:`CameraResponse` with ``n_knots`` knots.
    """
    if isinstance(n_knots, bool) or not isinstance(n_knots, int) or n_knots < 4:
        raise ValueError(f"n_knots: expected an integer >= 4, got {n_knots!r}")
    check_nonnegative(lam, "lam")
    anchor_z = resolve_anchor(anchor)
    samples, w = _prep(z, key, n_samples)
    log_t = jnp.log(t)
    gam, _, _ = _fit_gamma(samples, w, log_t, max_steps)
    dt = z.dtype
    zk = jnp.linspace(0.0, 1.0, n_knots, dtype=dt)
    kk = np.arange(1, n_knots - 1)
    hat = 2.0 * np.minimum(kk / (n_knots - 1), 1.0 - kk / (n_knots - 1))
    sw = jnp.asarray(hat * (n_knots - 1) ** 2 / np.sqrt(n_knots - 2), dt)

    def table_of(theta):
        return jnp.concatenate([jnp.zeros((1,), dt), jnp.cumsum(jax.nn.softplus(theta))])

    def fn(theta, args):
        s, ww = args
        g = table_of(theta)
        lx = table_lookup(s[..., None], g[:, None])[..., 0]
        r = vp_residuals(lx, ww, log_t)
        d2 = g[:-2] - 2.0 * g[1:-1] + g[2:]
        return r.reshape(-1), jnp.sqrt(lam) * sw * d2

    def one(s, ww, gm):
        g0 = gm * jnp.log(jnp.maximum(zk, 0.5 / (n_knots - 1)))
        theta0 = _softplus_inv(jnp.maximum(jnp.diff(g0), 1e-3))
        sol = _solve(fn, theta0, (s, ww), max_steps)
        res = fn(sol.value, (s, ww))[0]
        return (
            table_of(sol.value),
            res,
            sol.num_steps,
            sol.converged,
        )

    tab, res, steps, conv = jax.vmap(one)(samples, w, gam)
    rms = jnp.sqrt(jnp.sum(res**2, axis=1))
    diag = {"residual_rms": rms, "steps": steps, "converged": conv}
    return CameraResponse(tab.T, "table", "spline", float(code_max), anchor_z, None, diag)
