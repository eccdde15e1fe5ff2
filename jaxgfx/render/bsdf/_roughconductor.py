"""Rough conductor: Cook–Torrance microfacet reflection with GGX or Beckmann normals."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from jaxgfx._math import safe_div, safe_normalize, vdot
from jaxgfx.render.bsdf._base import (
    BSDF,
    check_rgb,
    glossy_sample,
    mask3,
    prep_dirs,
    sample_setup,
    to_rgb,
)
from jaxgfx.render.bsdf._conductor import check_fresnel, fresnel_factor, resolve_fresnel
from jaxgfx.render.bsdf.microfacet import (
    DISTRIBUTION_ALIASES,
    MicrofacetDistribution,
    reflection_pdf,
)
from jaxgfx.render.geometry.frame import reflect

__all__ = ["RoughConductor"]


class RoughConductor(BSDF):
    """Cook & Torrance (1982) / Walter et al. (2007) microfacet conductor (Mitsuba
    ``roughconductor``).

    ``f(wo, wi) = F(wo·h) D(h) G(wo, wi, h) / (4 cos θ_o cos θ_i)``, ``h = (wo + wi)/|wo + wi|``,
    with separable Smith ``G = G1(wo) G1(wi)``; ``eval`` returns ``f cos θ_i``. ``alpha`` (and
    optional ``alpha_v`` for anisotropy) is the distribution's α (Mitsuba convention, not
    squared), > 0 (1e-4 is fine). ``distribution`` (static): ``"ggx"`` | ``"beckmann"``.
    ``fresnel`` (static): ``"none"`` (F = ``reflectance``, default without ``eta``),
    ``"conductor"`` (``reflectance · F_conductor(eta + i k)``, RGB), ``"schlick"``
    (``reflectance`` is F0, the seed's ``c_spec``). Sampling: GGX visible normals (Heitz 2018),
    weight ``F G1(wi)``; Beckmann samples ``D cos θ_m``.

    Example: GGX α = 1, F = 1, ``wo = wi = +z``: D = 1/π, G = 1, so
    ``eval = D G / 4 = 1/(4π) ≈ 0.0796``.
    """

    distribution: MicrofacetDistribution
    reflectance: jnp.ndarray
    eta: jnp.ndarray | None
    k: jnp.ndarray | None
    fresnel: str = eqx.field(static=True, default="none")

    PARAMETER_ALIASES: ClassVar[dict[str, tuple[str, ...]]] = DISTRIBUTION_ALIASES

    def __init__(
        self,
        alpha=0.1,
        *,
        alpha_v=None,
        distribution="ggx",
        reflectance=1.0,
        eta=None,
        k=None,
        fresnel=None,
        sample_visible=True,
    ):
        self.distribution = MicrofacetDistribution(
            distribution, alpha, alpha_v, sample_visible=sample_visible
        )
        self.reflectance = to_rgb(reflectance, "reflectance")
        self.fresnel, self.eta, self.k = resolve_fresnel(fresnel, eta, k)

    def __check_init__(self):
        check_rgb(self.reflectance, "reflectance")
        check_fresnel(self.fresnel, self.eta, self.k)

    @property
    def albedo(self):
        return self.reflectance

    def _F(self, cos):
        return fresnel_factor(self.fresnel, cos, self.reflectance, self.eta, self.k)

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        co, ci = wo[..., 2], wi[..., 2]
        valid = (co > 0) & (ci > 0)
        h = safe_normalize(wo + wi)
        d = self.distribution
        val = safe_div(d.eval(h) * d.G(wo, wi, h), 4.0 * co)
        return mask3(valid, val[..., None] * self._F(vdot(wo, h)))

    def _pdf_m(self, wo, m):
        """Density of ``wi = reflect(wo, m)`` given the microfacet normal ``m``."""
        return reflection_pdf(self.distribution, wo, m)

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        valid = (wo[..., 2] > 0) & (wi[..., 2] > 0)
        h = safe_normalize(wo + wi)
        return jnp.where(valid, self._pdf_m(wo, h), 0.0)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        d = self.distribution
        co = wo[..., 2]
        wo_up = jnp.where((co > 0)[..., None], wo, jnp.array([0.0, 0.0, 1.0], wo.dtype))
        m, _ = d.sample(wo_up, u2)
        wi = reflect(wo, m)
        dot_om = vdot(wo, m)
        valid = (co > 0) & (wi[..., 2] > 0) & (dot_om > 0)
        pdf = self._pdf_m(wo, m)
        valid = valid & (pdf > 0)
        F = self._F(dot_om)
        if d.type == "ggx" and d.sample_visible:
            w = d.smith_g1(wi, m)
        else:
            w = safe_div(d.G(wo, wi, m) * dot_om, co * m[..., 2])
        return glossy_sample(wi, pdf, w[..., None] * F, valid, shape, co.dtype)
