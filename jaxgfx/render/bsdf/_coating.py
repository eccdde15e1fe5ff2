"""Rough dielectric coatings: directional albedos of a rough interface and their tables.

A layered material (rough plastic) sees its base through the coat: light enters and leaves
with the coat's directional transmittance ``T(μ, η)`` (the albedo of the rough interface's
*transmission* lobe, ``< 1 - R`` where masking loses energy) and bounces inside with the
internal diffuse reflectance ``R_int = 2 ∫ R(μ, 1/η) μ dμ``, ``R`` the albedo of the
*reflection* lobe. Mitsuba 3 (``roughplastic``, ``eval_transmittance`` /
``eval_reflectance``) tabulates both; the same tables are computed here, in JAX, as functions
of ``alpha`` and ``eta`` (so they follow ``Scene.replace`` and carry derivatives).

``R(μ, η) = E_m[F(wo·m, η) G1(wi, m)]`` and ``T(μ, η) = E_m[(1 - F(wo·m, η)) G1(wt, m)]`` with
``m`` drawn from the distribution's sampler for ``wo = (sqrt(1-μ²), 0, μ)``, ``wi`` the
reflection and ``wt`` the refraction of ``wo`` about ``m`` (the sampler's weights), by tensor
Gauss–Legendre quadrature over the sampler's unit square.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jaxgfx._math import safe_div, safe_sqrt, sum_last
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric
from jaxgfx.render.bsdf.microfacet import MicrofacetDistribution
from jaxgfx.render.geometry.frame import reflect

__all__ = ["rough_reflectance", "coating_tables", "lerp_table", "CoatingTerms", "TABLE_RES"]

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
    ``μ = i / (TABLE_RES - 1)`` and its internal diffuse reflectance, as Mitsuba 3's
    ``roughplastic`` defines them (``R_int = 2 mean_i(R(μ_i, 1/η) μ_i)`` over the same grid).

    ``eta`` (and ``alpha``) scalars give one table; batch-shaped ones a table per element
    (``TABLE_RES × nodes²`` evaluations each: keep textured roughness small).
    """
    eta = jnp.asarray(eta)
    dt = jnp.result_type(eta, 1.0)
    mu = jnp.asarray(np.arange(TABLE_RES) / (TABLE_RES - 1), dt)
    e = eta[..., None] if eta.ndim else eta
    d = _expand(distribution)
    t_ext = rough_reflectance(d, mu, e, nodes=_NODES_EXT, transmission=True)
    r_int = 2.0 * jnp.mean(rough_reflectance(d, mu, 1.0 / e, nodes=_NODES_INT) * mu, axis=-1)
    return t_ext, r_int


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

    Scalar ``alpha`` and ``eta`` (the common case): Mitsuba 3's tables
    (:func:`coating_tables`, a fixed cost per evaluation, independent of the batch).
    Batch-shaped ones (textured roughness): ``T`` at each ray's own cosine with
    ``_BATCH_NODES²`` nodes and ``R_int`` by ``_BATCH_MU``-point Gauss–Legendre in μ
    (about 1.2k sampler evaluations per ray; docs/render_bsdf.md gives the measured accuracy).
    """

    def __init__(self, distribution: MicrofacetDistribution, eta):
        self.d = distribution
        self.eta = jnp.asarray(eta)
        self.batched = bool(jnp.ndim(distribution.alpha_u) or jnp.ndim(distribution.alpha_v))
        self.batched = self.batched or bool(self.eta.ndim)
        if not self.batched:
            self.t_table, self.r_int = coating_tables(distribution, self.eta)
        else:
            x, w = _gl(_BATCH_MU)
            dt = jnp.result_type(self.eta, 1.0)
            mu = jnp.asarray(x, dt)
            e = self.eta[..., None] if self.eta.ndim else self.eta
            d = _expand(distribution)
            r = rough_reflectance(d, mu, 1.0 / e, nodes=_BATCH_NODES)
            self.r_int = 2.0 * jnp.sum(r * mu * jnp.asarray(w, dt), axis=-1)

    def T(self, cos):
        if not self.batched:
            return lerp_table(self.t_table, cos)
        return rough_reflectance(self.d, cos, self.eta, nodes=_BATCH_NODES, transmission=True)


def _expand(d):
    expand = lambda a: jnp.asarray(a)[..., None] if jnp.ndim(a) else a  # noqa: E731
    return MicrofacetDistribution(
        d.type, expand(d.alpha_u), expand(d.alpha_v), sample_visible=d.sample_visible
    )
