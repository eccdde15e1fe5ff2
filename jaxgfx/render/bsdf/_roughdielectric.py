"""Rough dielectric: microfacet reflection and refraction (Walter et al. 2007)."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from jaxgfx._checks import as_float_array
from jaxgfx._math import safe_div, safe_normalize, sum_last
from jaxgfx.render.bsdf._base import (
    BSDF,
    BSDFSample,
    check_rgb,
    check_scalar,
    mask3,
    prep_dirs,
    sample_setup,
    to_rgb,
)
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric
from jaxgfx.render.bsdf.microfacet import DISTRIBUTION_ALIASES, MicrofacetDistribution
from jaxgfx.render.geometry.frame import reflect

__all__ = ["RoughDielectric"]


class RoughDielectric(BSDF):
    """Rough dielectric interface (Mitsuba ``roughdielectric``; Walter, Marschner, Li,
    Torrance, "Microfacet Models for Refraction through Rough Surfaces", EGSR 2007).

    Both sides usable (``wo.z < 0``: the viewer is inside). With ``η`` the IOR ratio across
    the interface as seen from ``wo`` (``eta`` from outside, ``1/eta`` from inside) and the
    generalised half vector ``m = ±normalize(wo + η' wi)`` (``η' = 1`` for reflection, ``η``
    for refraction; oriented to ``+z``):

    * reflection (``wo``, ``wi`` on one side): ``f cos θ_i = F D G / (4 |cos θ_o|)``;
    * refraction: ``f cos θ_i = (1 - F) D G |wo·m| |wi·m| / (|cos θ_o| (wo·m + η wi·m)²)``
      — Walter's eq. 21 with the radiance scaling ``1/η²`` (Mitsuba 3, radiance transport);

    ``F = F_dielectric(wo·m)``, separable Smith ``G``, ``alpha`` (``alpha_v``) the
    distribution's α (> 0; clamped at 1e-4), ``distribution`` static ``"ggx"``/``"beckmann"``.
    Sampling: ``m`` from the distribution's sampler for ``±wo`` (GGX: visible normals),
    reflection with probability ``F`` else refraction; weights ``G1(wi)`` (reflection) and
    ``G1(wi)/η²`` (refraction) for visible normals. ``eta == 1`` exactly: the index-matched
    interface passes light straight through (a delta event ``wi = -wo``, weight
    ``specular_transmittance``), as the limit ``eta → 1`` of the lobe.

    Example: ``RoughDielectric(0.1, eta=1.5)`` — frosted glass.
    """

    distribution: MicrofacetDistribution
    eta: jnp.ndarray
    specular_reflectance: jnp.ndarray
    specular_transmittance: jnp.ndarray

    is_transmissive = True
    PARAMETER_ALIASES: ClassVar[dict[str, tuple[str, ...]]] = DISTRIBUTION_ALIASES

    def __init__(
        self,
        alpha=0.1,
        *,
        alpha_v=None,
        eta=1.5046 / 1.000277,
        distribution="ggx",
        specular_reflectance=1.0,
        specular_transmittance=1.0,
        sample_visible=True,
    ):
        self.distribution = MicrofacetDistribution(
            distribution, alpha, alpha_v, sample_visible=sample_visible
        )
        self.eta = as_float_array(eta, "eta")
        self.specular_reflectance = to_rgb(specular_reflectance, "specular_reflectance")
        self.specular_transmittance = to_rgb(specular_transmittance, "specular_transmittance")

    def __check_init__(self):
        check_scalar(self.eta, "eta", positive=True)
        check_rgb(self.specular_reflectance, "specular_reflectance")
        check_rgb(self.specular_transmittance, "specular_transmittance")

    @property
    def albedo(self):
        return jnp.zeros_like(self.specular_reflectance)

    # -------------------------------------------------------------- shared geometry
    def _half(self, wo, wi):
        """``(m, eta_rel, reflect, ok)`` for the pair: the generalised half vector (``+z``
        side), the IOR ratio seen from ``wo``, the event and its validity."""
        co, ci = wo[..., 2], wi[..., 2]
        refl = co * ci > 0
        eta_rel = jnp.where(co > 0, self.eta, 1.0 / self.eta)
        m = safe_normalize(wo + wi * jnp.where(refl, 1.0, eta_rel)[..., None])
        m = m * jnp.where(m[..., 2] < 0, -1.0, 1.0)[..., None]
        dot_om, dot_im = sum_last(wo * m), sum_last(wi * m)
        # microfacets seen from the wrong side by either direction are discarded (Mitsuba)
        ok = (co != 0) & (ci != 0) & (dot_om * co > 0) & (dot_im * ci > 0) & (m[..., 2] > 0)
        ok = ok & (refl | (self.eta != 1.0))
        return m, eta_rel, refl, ok, dot_om, dot_im

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        m, eta_rel, refl, ok, dot_om, dot_im = self._half(wo, wi)
        d = self.distribution
        F = fresnel_dielectric(dot_om, self.eta).r
        dg = d.eval(m) * d.G(wo, wi, m)
        aco = jnp.abs(wo[..., 2])
        f_r = safe_div(F * dg, 4.0 * aco)
        denom = dot_om + eta_rel * dot_im
        f_t = safe_div((1.0 - F) * dg * jnp.abs(dot_om * dot_im), aco * denom * denom)
        val = jnp.where(
            refl[..., None],
            f_r[..., None] * self.specular_reflectance,
            f_t[..., None] * self.specular_transmittance,
        )
        return mask3(ok, val)

    def _pdf(self, wo, m, eta_rel, refl, dot_om, dot_im):
        d = self.distribution
        s = jnp.where(wo[..., 2] < 0, -1.0, 1.0)[..., None]
        p_m = d.pdf(wo * s, m)  # the sampler's density of m (for the upper-side wo)
        F = fresnel_dielectric(dot_om, self.eta).r
        denom = dot_om + eta_rel * dot_im
        jac_r = safe_div(1.0, 4.0 * jnp.abs(dot_im))
        jac_t = safe_div(eta_rel * eta_rel * jnp.abs(dot_im), denom * denom)
        return p_m * jnp.where(refl, F * jac_r, (1.0 - F) * jac_t)

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        m, eta_rel, refl, ok, dot_om, dot_im = self._half(wo, wi)
        return jnp.where(ok, self._pdf(wo, m, eta_rel, refl, dot_om, dot_im), 0.0)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        d = self.distribution
        co = wo[..., 2]
        s = jnp.where(co < 0, -1.0, 1.0)
        wo_up = wo * s[..., None]
        wo_up = jnp.where((co != 0)[..., None], wo_up, jnp.array([0.0, 0.0, 1.0], wo.dtype))
        m, _ = d.sample(wo_up, u2)
        dot_om = sum_last(wo * m)
        fr = fresnel_dielectric(dot_om, self.eta)
        refl = u1 <= fr.r
        wi_r = reflect(wo, m)
        wi_t = m * (dot_om * fr.eta_ti + fr.cos_theta_t)[..., None] - wo * fr.eta_ti[..., None]
        matched = self.eta == 1.0
        wi_t = jnp.where(jnp.broadcast_to(matched, shape)[..., None], -wo, wi_t)
        wi = safe_normalize(jnp.where(refl[..., None], wi_r, wi_t))
        dot_im = sum_last(wi * m)
        same_side = wi[..., 2] * co > 0
        ok = (co != 0) & (dot_om * co > 0) & jnp.where(refl, same_side, ~same_side)
        ok = ok & (dot_im * wi[..., 2] > 0)
        eta_rel = jnp.where(co > 0, self.eta, 1.0 / self.eta)
        pdf = self._pdf(wo, m, eta_rel, refl, dot_om, dot_im)
        if d.type == "ggx" and d.sample_visible:
            g = d.smith_g1(wi, m)
        else:
            g = safe_div(d.G(wo, wi, m) * jnp.abs(dot_om), jnp.abs(co) * m[..., 2])
        w_t = g * fr.eta_ti * fr.eta_ti
        # the lobe is chosen with probability F: value 1, derivative of F / F (SmoothDielectric)
        p_sel = jnp.where(refl, fr.r, 1.0 - fr.r)
        w_sel = safe_div(p_sel, jax.lax.stop_gradient(p_sel), fill=1.0)
        weight = jnp.where(
            refl[..., None],
            g[..., None] * self.specular_reflectance,
            w_t[..., None] * self.specular_transmittance,
        )
        # index-matched interface: a straight pass (delta), weight kt
        is_delta = jnp.broadcast_to(matched, shape) & ~refl
        weight = jnp.where(is_delta[..., None], self.specular_transmittance, weight)
        pdf = jnp.where(is_delta, 1.0, pdf)
        ok = ok | is_delta
        ok = ok & (pdf > 0)
        return BSDFSample(
            wi=wi,
            pdf=jnp.where(ok, pdf, 0.0),
            weight=mask3(ok, weight * w_sel[..., None]),
            is_delta=is_delta,
            eta=jnp.where(refl, 1.0, fr.eta_it),
        )
