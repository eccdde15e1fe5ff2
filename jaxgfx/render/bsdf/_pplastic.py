"""Mitsuba 3's ``pplastic`` as its RGB (unpolarised) variants evaluate it."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp

from jaxgfx._checks import as_float_array
from jaxgfx._math import safe_div, safe_normalize, vdot
from jaxgfx.render.bsdf._base import (
    INV_PI,
    glossy_sample,
    mask3,
    prep_dirs,
    sample_setup,
    to_rgb,
)
from jaxgfx.render.bsdf._roughplastic import PlasticBase
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric
from jaxgfx.render.bsdf.microfacet import (
    DISTRIBUTION_ALIASES,
    MicrofacetDistribution,
    reflection_pdf,
)
from jaxgfx.render.geometry.frame import reflect
from jaxgfx.render.sampling import square_to_cosine_hemisphere

__all__ = ["PolarizedPlastic"]


class PolarizedPlastic(PlasticBase):
    """Mitsuba 3's ``pplastic`` in its unpolarised (``*_rgb``) form: a rough dielectric
    reflection lobe plus a diffuse base seen through two smooth Fresnel transmissions, with no
    internal scattering (Mitsuba's ``pplastic.cpp``, the ``else`` branches of
    ``is_polarized_v``). With ``wo`` the view direction (Mitsuba's ``si.wi``):

    ``eval = ks F(wo·h) D(h) G(wo, wi, h) / (4 cos θ_o)
    + kd (1 - F(cos θ_o)) (1 - F(cos θ_i)) cos θ_i / π``

    on the front side only (``cos θ_o, cos θ_i > 0``, else 0; ``F`` the unpolarised dielectric
    Fresnel reflectance for ``eta``, ``h = normalize(wo + wi)``). Parameters with Mitsuba's
    names and defaults: ``diffuse_reflectance`` kd (0.5), ``specular_reflectance`` ks (1),
    ``alpha`` (0.1; ``alpha_v`` for an anisotropic lobe, along the local y axis),
    ``distribution`` (static, ``"beckmann"`` as Mitsuba, or ``"ggx"``), ``eta`` = interior /
    exterior IOR (1.49 / 1.000277), ``sample_visible`` (static). Unlike ``roughplastic`` the
    diffuse term is not renormalised for light trapped under the coat, so the albedo is < 1.

    Sampling (Mitsuba 3): the specular lobe with the constant probability
    ``w_s = mean(ks) / (mean(kd) + mean(ks))`` (microfacet normal from ``distribution.sample``,
    mirrored), else the cosine-weighted hemisphere; ``pdf = w_s p_spec + (1 - w_s) cos θ_i / π``
    with ``p_spec`` the density of the reflected direction (GGX: exactly Mitsuba's; Beckmann
    with ``sample_visible``: jaxgfx samples ``D cos θ_m``, as for its other microfacet BSDFs).
    """

    distribution: MicrofacetDistribution
    diffuse_reflectance: jnp.ndarray
    specular_reflectance: jnp.ndarray
    eta: jnp.ndarray

    PARAMETER_ALIASES: ClassVar[dict[str, tuple[str, ...]]] = DISTRIBUTION_ALIASES

    def __init__(
        self,
        diffuse_reflectance=0.5,
        alpha=0.1,
        *,
        alpha_v=None,
        eta=1.49 / 1.000277,
        specular_reflectance=1.0,
        distribution="beckmann",
        sample_visible=True,
    ):
        self.distribution = MicrofacetDistribution(
            distribution, alpha, alpha_v, sample_visible=sample_visible
        )
        self.diffuse_reflectance = to_rgb(diffuse_reflectance, "diffuse_reflectance")
        self.specular_reflectance = to_rgb(specular_reflectance, "specular_reflectance")
        self.eta = as_float_array(eta, "eta")

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        co, ci = wo[..., 2], wi[..., 2]
        valid = (co > 0) & (ci > 0)
        h = safe_normalize(wo + wi)
        d = self.distribution
        f = fresnel_dielectric(vdot(wo, h), self.eta).r
        spec = safe_div(f * d.eval(h) * d.G(wo, wi, h), 4.0 * co)
        t = (1.0 - fresnel_dielectric(co, self.eta).r) * (1.0 - fresnel_dielectric(ci, self.eta).r)
        diff = self.diffuse_reflectance * (t * ci * INV_PI)[..., None]
        return mask3(valid, spec[..., None] * self.specular_reflectance + diff)

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        co, ci = wo[..., 2], wi[..., 2]
        valid = (co > 0) & (ci > 0)
        h = safe_normalize(wo + wi)
        ps = self._spec_weight()
        p = ps * reflection_pdf(self.distribution, wo, h) + (1.0 - ps) * ci * INV_PI
        return jnp.where(valid, p, 0.0)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        co = wo[..., 2]
        wo_up = jnp.where((co > 0)[..., None], wo, jnp.array([0.0, 0.0, 1.0], wo.dtype))
        m, _ = self.distribution.sample(wo_up, u2)
        spec_dir = reflect(wo, m)
        diff_dir = square_to_cosine_hemisphere(u2)
        wi = jnp.where((u1 < self._spec_weight())[..., None], spec_dir, diff_dir)
        pdf = self.pdf(wo, wi)
        valid = (co > 0) & (wi[..., 2] > 0) & (pdf > 0)
        weight = self.eval(wo, wi) / jnp.where(valid, pdf, 1.0)[..., None]
        return glossy_sample(wi, pdf, weight, valid, shape, wo.dtype)
