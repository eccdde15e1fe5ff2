"""Lambertian (ideal diffuse) reflection."""

from __future__ import annotations

import jax.numpy as jnp

from jaxgfx.render.bsdf._base import (
    BSDF,
    INV_PI,
    check_rgb,
    glossy_sample,
    mask3,
    prep_dirs,
    prep_u,
    rgb_field,
)
from jaxgfx.render.sampling import square_to_cosine_hemisphere

__all__ = ["Diffuse"]


class Diffuse(BSDF):
    """Lambert's BRDF ``f = ρ / π`` (Lambert 1760; Mitsuba ``diffuse``).

    ``reflectance`` ρ: RGB albedo in ``[0, 1]`` (scalar broadcasts), shape (3,) or (..., 3).
    ``eval(wo, wi) = ρ cos θ_i / π`` for ``cos θ_o, cos θ_i > 0``; sampled by cosine-weighted
    hemisphere sampling, so ``weight = ρ``. Seed lecture 3: ``L_o = L_i k_d (s·n)`` with
    ``k_d = ρ/π``.

    Example: ``Diffuse(1.0).eval(z, z) = [1/π]*3 ≈ 0.3183``.
    """

    reflectance: jnp.ndarray = rgb_field(0.5, "reflectance")

    def __check_init__(self):
        check_rgb(self.reflectance, "reflectance")

    @property
    def albedo(self):
        return self.reflectance

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        ci = wi[..., 2]
        valid = (wo[..., 2] > 0) & (ci > 0)
        return mask3(valid, self.reflectance * (ci * INV_PI)[..., None])

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        ci = wi[..., 2]
        valid = (wo[..., 2] > 0) & (ci > 0)
        return jnp.where(valid, ci * INV_PI, 0.0)

    def sample(self, wo, u1, u2):
        wo = prep_dirs(wo)
        u1, u2 = prep_u(u1, u2)
        wi = square_to_cosine_hemisphere(u2)
        wi = jnp.broadcast_to(wi, jnp.broadcast_shapes(wi.shape, wo.shape))
        valid = (wo[..., 2] > 0) & (wi[..., 2] > 0)
        pdf = wi[..., 2] * INV_PI
        return glossy_sample(wi, pdf, self.reflectance, valid, valid.shape, pdf.dtype)
