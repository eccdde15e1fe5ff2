"""Rough dielectric coatings: directional albedos of a rough interface and their tables.

A layered material (rough plastic) sees its base through the coat: light enters and leaves
with the coat's directional transmittance ``T(μ, η)`` (the albedo of the rough interface's
*transmission* lobe, ``< 1 - R`` where masking loses energy) and bounces inside with the
internal diffuse reflectance ``R_int = 2 mean_i R(μ_i, 1/η) μ_i`` over ``μ_i = i / 63``
(Mitsuba 3's 64-point rule, a rectangle-rule approximation of ``2 ∫ R(μ, 1/η) μ dμ``), ``R`` the
albedo of the *reflection* lobe. Mitsuba 3 (``roughplastic``, ``eval_transmittance`` /
``eval_reflectance``) tabulates both; the same tables are computed here, in JAX, as functions
of ``alpha`` and ``eta`` (so they follow ``Scene.replace`` and carry derivatives).

``R(μ, η) = E_m[F(wo·m, η) G1(wi, m)]`` and ``T(μ, η) = E_m[(1 - F(wo·m, η)) G1(wt, m)]`` with
``m`` drawn from the distribution's sampler for ``wo = (sqrt(1-μ²), 0, μ)``, ``wi`` the
reflection and ``wt`` the refraction of ``wo`` about ``m`` (the sampler's weights), by tensor
Gauss–Legendre quadrature over the sampler's unit square.

``R_int`` is *not* that quadrature where it can be avoided: total internal reflection puts a
square-root kink in ``F(wo·m, 1/η)`` (and masking kinks at the horizon), so a discrete sum over
the square is not smooth in ``(alpha, eta)`` and its AD derivative was off by 5–35 % (48² nodes;
GGX α = 0.2, η = 1.49: ``∂R_int/∂(α, η)`` (-0.718, 0.831) vs converged (-0.707, 0.608)). For
isotropic ``alpha`` in ``[1e-4, 1]`` and ``eta`` in ``[1, 4]``, :func:`r_int` interpolates a
precomputed table of Mitsuba's 64-point rule with ``R`` by an accurate (384²-node) quadrature
(``_coating_table.py``, made by ``tools/make_coating_table.py``) with a bicubic spline in
``(sqrt(alpha), 1/eta)``: value and derivative come from one C² function (below ``alpha = 0.02``
the value is the quadrature, :func:`small_alpha_weight`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import is_concrete
from jaxgfx._math import safe_div, safe_sqrt, sum_last
from jaxgfx.render.bsdf import _coating_table as _tab
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric
from jaxgfx.render.bsdf.microfacet import ALPHA_MIN, MicrofacetDistribution
from jaxgfx.render.geometry.frame import reflect

__all__ = [
    "rough_reflectance",
    "coating_tables",
    "lerp_table",
    "r_int",
    "r_int_table",
    "small_alpha_weight",
    "CoatingTerms",
    "TABLE_RES",
]

TABLE_RES = 64  # μ = i / 63 (Mitsuba 3 MTS_ROUGH_TRANSMITTANCE_RES)
_NODES_EXT = 24  # Gauss–Legendre nodes per axis for R(μ, η > 1) (smooth integrand)
_NODES_INT = 48  # ... for R(μ, 1/η) (total internal reflection makes F kink in m)


def _gl(n):
    x, w = np.polynomial.legendre.leggauss(n)
    return 0.5 * (x + 1.0), 0.5 * w


def rough_reflectance(
    distribution: MicrofacetDistribution, mu, eta, *, nodes: int = 24, transmission=False
):
    """Directional albedo ``R(μ, η)`` of the reflection lobe of a rough dielectric interface
    (``transmission=True``: ``T(μ, η)``, the albedo of its transmission lobe without the
    ``1/η²`` radiance scaling).

    ``mu`` (...) cosines in ``(0, 1]`` (clamped to >= 1e-6), ``eta`` relative IOR (broadcast
    against ``mu``; < 1 means seen from the denser side). ``distribution``'s ``alpha`` must be
    a scalar or broadcast against ``mu``. ``nodes`` Gauss–Legendre nodes per axis of the
    sampler's square. ``R → F(μ, η)`` as ``alpha → 0``.
    """
    mu = jnp.maximum(jnp.asarray(mu), 1e-6)
    dt = mu.dtype
    x, w = _gl(nodes)
    ux, uy = np.meshgrid(x, x, indexing="ij")
    u = jnp.asarray(np.stack([ux, uy], -1).reshape(-1, 2), dt)  # (n², 2)
    wq = jnp.asarray((w[:, None] * w[None, :]).reshape(-1), dt)
    wo = jnp.stack([safe_sqrt(1.0 - mu * mu), jnp.zeros_like(mu), mu], axis=-1)[..., None, :]
    d = _expand(distribution)
    m, _ = d.sample(wo, u)
    dot_om = sum_last(wo * m)
    fr = fresnel_dielectric(dot_om, jnp.asarray(eta, dt)[..., None])
    if transmission:
        wt = m * (dot_om * fr.eta_ti + fr.cos_theta_t)[..., None] - wo * fr.eta_ti[..., None]
        if d.type == "ggx" and d.sample_visible:
            g = d.smith_g1(wt, m)
        else:
            g = safe_div(d.G(wo, wt, m) * dot_om, wo[..., 2] * m[..., 2])
        val = jnp.where((wt[..., 2] < 0) & (dot_om > 0), (1.0 - fr.r) * g, 0.0)
        return jnp.sum(val * wq, axis=-1)
    wi = reflect(wo, m)
    f = fr.r
    if d.type == "ggx" and d.sample_visible:
        g = d.smith_g1(wi, m)
    else:
        g = safe_div(d.G(wo, wi, m) * dot_om, wo[..., 2] * m[..., 2])
    val = jnp.where((wi[..., 2] > 0) & (dot_om > 0), f * g, 0.0)
    return jnp.sum(val * wq, axis=-1)


def coating_tables(distribution: MicrofacetDistribution, eta):
    """``(T_ext (..., TABLE_RES), R_int (...))``: the rough coat's transmittance ``T(μ, η)`` at
    ``μ = i / (TABLE_RES - 1)`` (as Mitsuba 3's ``roughplastic``) and its internal diffuse
    reflectance :func:`r_int`.

    ``eta`` (and ``alpha``) scalars give one table; batch-shaped ones a table per element
    (``TABLE_RES × nodes²`` evaluations each: keep textured roughness small).
    """
    eta = jnp.asarray(eta)
    dt = jnp.result_type(eta, 1.0)
    mu = jnp.asarray(np.arange(TABLE_RES) / (TABLE_RES - 1), dt)
    e = eta[..., None] if eta.ndim else eta
    d = _expand(distribution)
    t_ext = rough_reflectance(d, mu, e, nodes=_NODES_EXT, transmission=True)
    return t_ext, r_int(distribution, eta)


def r_int_quadrature(distribution: MicrofacetDistribution, eta, *, nodes=_NODES_INT, n_mu=None):
    """``R_int`` by quadrature: Mitsuba 3's ``2 mean_i(R(μ_i, 1/η) μ_i)`` over ``μ_i = i / 63``
    with ``nodes``² nodes for ``R`` (``n_mu``: ``n_mu``-point Gauss–Legendre in μ instead).
    Not smooth in ``(alpha, eta)`` where ``eta > 1`` (see the module docstring); smooth for
    ``eta < 1`` (no total internal reflection)."""
    eta = jnp.asarray(eta)
    dt = jnp.result_type(eta, 1.0)
    e = eta[..., None] if eta.ndim else eta
    d = _expand(distribution)
    if n_mu is None:
        mu = jnp.asarray(np.arange(TABLE_RES) / (TABLE_RES - 1), dt)
        w = jnp.full((TABLE_RES,), 1.0 / TABLE_RES, dt)
    else:
        x, w = _gl(n_mu)
        mu, w = jnp.asarray(x, dt), jnp.asarray(w, dt)
    return 2.0 * jnp.sum(rough_reflectance(d, mu, 1.0 / e, nodes=nodes) * mu * w, axis=-1)


def _spline_slopes(f, axis):
    """Knot derivatives (grid units) of the not-a-knot cubic spline through ``f`` along
    ``axis`` (unit knot spacing), as SciPy's ``CubicSpline(..., bc_type="not-a-knot")``:
    second derivatives ``M`` from ``M[i-1] + 4 M[i] + M[i+1] = 6 Δ²f[i]`` with continuous third
    derivatives at the second and second-to-last knots, then the slopes of the cubic pieces."""
    f = np.moveaxis(np.asarray(f, np.float64), axis, 0)
    n = f.shape[0]
    a = np.zeros((n, n))
    rhs = np.zeros_like(f)
    a[0, :3] = a[-1, -3:] = (1.0, -2.0, 1.0)  # not-a-knot: M1 - M0 = M2 - M1 (both ends)
    for i in range(1, n - 1):
        a[i, i - 1 : i + 2] = (1.0, 4.0, 1.0)
        rhs[i] = 6.0 * (f[i + 1] - 2.0 * f[i] + f[i - 1])
    m = np.linalg.solve(a, rhs.reshape(n, -1)).reshape(f.shape)
    slopes = np.empty_like(f)
    slopes[:-1] = (f[1:] - f[:-1]) - (2.0 * m[:-1] + m[1:]) / 6.0
    slopes[-1] = (f[-1] - f[-2]) + (m[-2] + 2.0 * m[-1]) / 6.0
    return np.moveaxis(slopes, 0, axis)


@functools.cache
def _spline_coeffs(dist_type):
    """Knot values and derivatives ``(f, f_s, f_v, f_sv)`` (in grid units) of the tensor cubic
    spline (not-a-knot) through the table: bicubic Hermite on them is that spline. NumPy only
    (SciPy is not a runtime dependency)."""
    f = np.asarray(getattr(_tab, dist_type.upper()), np.float64)
    fs = _spline_slopes(f, 0)
    return np.stack([f, fs, _spline_slopes(f, 1), _spline_slopes(fs, 1)])  # (4, NS, NV)


def _hermite(t):
    t2, t3 = t * t, t * t * t
    return (2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t, -2 * t3 + 3 * t2, t3 - t2)


def r_int_table(dist_type, alpha, eta):
    """``R_int(alpha, eta)`` from the precomputed table (bicubic spline in ``s = sqrt(alpha)``,
    ``v = 1/eta``); ``alpha`` clamped to ``[1e-4, 1]``, ``eta`` to ``[1, 4]`` (:func:`r_int`
    falls back to the quadrature outside). Same shapes as ``broadcast(alpha, eta)``."""
    alpha, eta = jnp.broadcast_arrays(jnp.asarray(alpha), jnp.asarray(eta))
    dt = jnp.result_type(alpha, eta, 1.0)
    c = jnp.asarray(_spline_coeffs(dist_type), dt)
    a = jnp.clip(alpha, ALPHA_MIN, 1.0)
    v = jnp.clip(1.0 / jnp.where(eta > 0, eta, 1.0), _tab.V_MIN, _tab.V_MAX)
    xs = (jnp.sqrt(a) - _tab.S_MIN) * ((_tab.NS - 1) / (_tab.S_MAX - _tab.S_MIN))
    xv = (v - _tab.V_MIN) * ((_tab.NV - 1) / (_tab.V_MAX - _tab.V_MIN))
    xs = jnp.clip(xs, 0.0, _tab.NS - 1.0)
    xv = jnp.clip(xv, 0.0, _tab.NV - 1.0)
    i = jnp.clip(jnp.floor(xs).astype(jnp.int32), 0, _tab.NS - 2)
    j = jnp.clip(jnp.floor(xv).astype(jnp.int32), 0, _tab.NV - 2)
    t, u = xs - i, xv - j
    h0s, h1s, h2s, h3s = _hermite(t)
    h0v, h1v, h2v, h3v = _hermite(u)
    ws = ((h0s, 0, 0), (h1s, 0, 1), (h2s, 1, 0), (h3s, 1, 1))  # (basis, knot offset, s-deriv)
    wv = ((h0v, 0, 0), (h1v, 0, 1), (h2v, 1, 0), (h3v, 1, 1))
    out = jnp.zeros(xs.shape, dt)
    for bs, di, ds in ws:
        for bv, dj, dv in wv:
            out = out + bs * bv * c[2 * dv + ds, i + di, j + dj]
    return out


def _table_ok(distribution, eta):
    au, av = distribution.alpha_u, distribution.alpha_v
    return (au == av) & (au <= 1.0) & (eta >= 1.0) & (eta <= 1.0 / _tab.V_MIN)


def r_int(distribution: MicrofacetDistribution, eta, *, nodes=_NODES_INT, n_mu=None):
    """Internal diffuse reflectance ``R_int = 2 mean_i R(μ_i, 1/η) μ_i``, ``μ_i = i / 63``
    (Mitsuba 3's rule) of the rough coat (scalar or batch-shaped ``alpha``/``eta``, broadcast).

    Isotropic ``alpha <= 1`` (clamped below at 1e-4 as the distribution) and ``1 <= eta <= 4``:
    the table (:func:`r_int_table`; Mitsuba's rule with ``R`` by 384² nodes, interpolated by a
    smooth spline), with the spline's exact derivative. Elsewhere (``eta < 1``: no total
    internal reflection, the quadrature is smooth; ``eta > 4``, ``alpha > 1`` or anisotropic
    ``alpha``): :func:`r_int_quadrature`
    (``nodes``, ``n_mu``), whose AD derivative is that of a discrete sum. The fallback is
    computed only when some element needs it (``lax.cond``; under ``vmap`` both branches run).
    """
    eta = jnp.asarray(eta)
    d = distribution
    ok = _table_ok(d, eta)

    dt = jnp.result_type(d.alpha_u, eta, 1.0)

    def table():
        return r_int_table(d.type, jnp.broadcast_to(d.alpha_u, ok.shape), eta).astype(dt)

    def mixed():
        q = r_int_quadrature(d, eta, nodes=nodes, n_mu=n_mu)
        return jnp.where(ok, table(), jnp.broadcast_to(q, ok.shape)).astype(dt)

    out = _cond(jnp.all(ok), table, mixed)
    if jnp.ndim(d.alpha_u) == 0 and eta.ndim == 0:
        out = out + _small_alpha_correction(d, eta, ok, out)
    return out


# Below alpha ~ 0.02 Mitsuba's 64-point rule is not smooth in eta: as the critical cosine
# sqrt(1 - 1/eta^2) crosses a node i/63, R(i/63, 1/eta) turns from total internal reflection
# to Fresnel over a width ~ alpha, a feature the table's knots (1/eta every 0.031) cannot hold:
# the spline is off by up to 3e-3 in R_int there (0.7 % in the diffuse lobe, 1/(1 - R_int)).
# There the value is the quadrature's (48^2 nodes: within 1e-4 of 384^2 for alpha <= 0.02),
# blended in over sqrt(alpha) in [_S_LO, _S_HI]; the derivative stays the table's smooth one
# (plus the blend weight's): the rule's own derivative in eta jumps at every node crossing.
_S_LO, _S_HI = 0.1, 0.1414  # alpha 0.01 ... 0.02


def small_alpha_weight(alpha):
    """The quadrature's weight in :func:`r_int`: 1 for ``alpha <= 0.01``, 0 for ``alpha >=
    0.02``, a smoothstep in ``sqrt(alpha)`` between (C¹)."""
    s = jnp.sqrt(jnp.maximum(alpha, 0.0))
    t = jnp.clip((_S_HI - s) / (_S_HI - _S_LO), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _small_alpha_correction(d, eta, ok, spline):
    """``w(alpha) (q - spline)`` with the difference held constant; ``spline`` is the table's
    value (where ``ok``, which ``need`` implies)."""
    w = small_alpha_weight(d.alpha_u)
    need = ok & (d.alpha_u < _S_HI**2)

    def diff():
        q = r_int_quadrature(d, eta, nodes=_NODES_INT)
        return jax.lax.stop_gradient(q - spline)

    return w * _cond(need, diff, lambda: jnp.zeros((), w.dtype))


def _cond(pred, true_fn, false_fn):
    """``lax.cond``, decided in Python when ``pred`` is concrete (eager calls: a ``lax.cond``
    compiles both branches, the quadrature included, on every eager call)."""
    if is_concrete(pred):
        return true_fn() if bool(pred) else false_fn()
    return jax.lax.cond(pred, true_fn, false_fn)


def lerp_table(table, x):
    """Linear interpolation of ``table (..., N)`` sampled at ``i / (N - 1)`` at ``x`` (...)
    in ``[0, 1]`` (clamped)."""
    n = table.shape[-1]
    xs = jnp.clip(x, 0.0, 1.0) * (n - 1)
    i = jnp.minimum(jnp.floor(xs).astype(jnp.int32), n - 2)
    t = xs - i
    if table.ndim == 1:
        v0, v1 = table[i], table[i + 1]
    else:
        v0 = jnp.take_along_axis(table, i[..., None], axis=-1)[..., 0]
        v1 = jnp.take_along_axis(table, i[..., None] + 1, axis=-1)[..., 0]
    return (1.0 - t) * v0 + t * v1


_BATCH_NODES = 8  # per-element quadrature (batch-shaped alpha / eta, e.g. textured roughness)
_BATCH_MU = 16


class CoatingTerms:
    """The rough coat's ``T(cos)`` and ``R_int`` for one BSDF evaluation.

    ``R_int`` is :func:`r_int` (the precomputed table, or a quadrature outside its range).
    Scalar ``alpha`` and ``eta`` (the common case): ``T`` is Mitsuba 3's table
    (:func:`coating_tables`, a fixed cost per evaluation, independent of the batch).
    Batch-shaped ones (textured roughness): ``T`` at each ray's own cosine with
    ``_BATCH_NODES²`` nodes (the fallback ``R_int`` by ``_BATCH_MU``-point Gauss–Legendre in μ).
    """

    def __init__(self, distribution: MicrofacetDistribution, eta):
        self.d = distribution
        self.eta = jnp.asarray(eta)
        self.batched = bool(jnp.ndim(distribution.alpha_u) or jnp.ndim(distribution.alpha_v))
        self.batched = self.batched or bool(self.eta.ndim)
        if not self.batched:
            self.t_table, self.r_int = coating_tables(distribution, self.eta)
        else:
            self.r_int = r_int(distribution, self.eta, nodes=_BATCH_NODES, n_mu=_BATCH_MU)

    def T(self, cos):
        if not self.batched:
            return lerp_table(self.t_table, cos)
        return rough_reflectance(self.d, cos, self.eta, nodes=_BATCH_NODES, transmission=True)


def _expand(d):
    expand = lambda a: jnp.asarray(a)[..., None] if jnp.ndim(a) else a  # noqa: E731
    return MicrofacetDistribution(
        d.type, expand(d.alpha_u), expand(d.alpha_v), sample_visible=d.sample_visible
    )
