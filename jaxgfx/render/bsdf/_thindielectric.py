"""Thin dielectric sheet (Mitsuba ``thindielectric``): a window pane of negligible thickness."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgfx._math import safe_div
from jaxgfx.render.bsdf._base import (
    BSDFSample,
    mask3,
    sample_setup,
)
from jaxgfx.render.bsdf._dielectric import DeltaDielectric
from jaxgfx.render.bsdf.fresnel import fresnel_dielectric

__all__ = ["ThinDielectric", "thin_reflectance"]


def thin_reflectance(cos_theta, eta):
    """Total reflectance of a thin slab: ``R' = R + T² R / (1 - R²) = 2 R / (1 + R)`` with the
    Fresnel ``R(|cos θ|, η)`` of one interface and ``T = 1 - R`` (every internal bounce)."""
    r = fresnel_dielectric(jnp.abs(cos_theta), eta).r
    return 2.0 * r / (1.0 + r)


class ThinDielectric(DeltaDielectric):
    """Thin dielectric (Mitsuba 3 ``thindielectric``), both sides alike.

    ``eta`` = interior / exterior IOR. Reflection ``wi = (-wo_x, -wo_y, wo_z)`` with probability
    ``R' = 2R / (1 + R)`` (:func:`thin_reflectance`), else straight transmission ``wi = -wo``
    (the two refractions cancel; no ``1/η²`` scaling, sample ``eta`` 1). ``pdf`` is the lobe
    probability, ``weight = specular_reflectance`` resp. ``specular_transmittance``; the weight's
    derivative is that of ``R' / stop_gradient(R')`` (resp. ``1 - R'``): the discrete choice's
    contribution to ``d/dη``, as :class:`SmoothDielectric`. ``eval`` / ``pdf`` are 0 (delta).
    ``eta = 1``: everything is transmitted.
    """

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        co = wo[..., 2]
        r = thin_reflectance(co, self.eta)
        refl = u1 <= r
        wi = jnp.where(refl[..., None], wo * jnp.asarray([-1.0, -1.0, 1.0], wo.dtype), -wo)
        pdf = jnp.where(refl, r, 1.0 - r)
        w_sel = safe_div(pdf, jax.lax.stop_gradient(pdf), fill=1.0)  # p / p = 1 exactly
        ks = jnp.where(refl[..., None], self.specular_reflectance, self.specular_transmittance)
        valid = (co != 0) & (pdf > 0)
        return BSDFSample(
            wi=wi,
            pdf=jnp.where(valid, pdf, 0.0),
            weight=mask3(valid, ks * w_sel[..., None]),
            is_delta=jnp.ones(shape, bool),
            eta=jnp.ones(shape, wo.dtype),
        )
