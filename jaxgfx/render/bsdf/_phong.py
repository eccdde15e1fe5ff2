"""Phong reflection: classic (as in the seed lecture) and energy-normalised (modified) Phong."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp

from jaxgfx._checks import check_nonnegative
from jaxgfx._math import safe_div, safe_pow, vdot
from jaxgfx.render.bsdf._base import (
    BSDF,
    INV_PI,
    check_rgb,
    float_field,
    glossy_sample,
    mask3,
    prep_dirs,
    rgb_field,
    sample_setup,
)
from jaxgfx.render.geometry.frame import frame_from_normal, reflect, to_world
from jaxgfx.render.sampling import square_to_cosine_hemisphere, square_to_phong_lobe

__all__ = ["Phong"]


class Phong(BSDF):
    """Phong (1975) reflection with diffuse ``kd`` and specular ``ks`` (RGB) and exponent ``n``.

    ``cos α = max(0, r·wi)`` with ``r = (-wo_x, -wo_y, wo_z)`` the mirror direction of ``wo``.

    * ``normalized=True`` (default; Lafortune & Willems 1994 "modified Phong"):
      ``f = kd/π + ks (n+2)/(2π) cos^n α``; reciprocal, energy conserving when
      ``kd + ks <= 1``. ``eval = f cos θ_i``.
    * ``normalized=False`` (classic, seed lecture 3): ``L_o = L_i (kd (s·n) + ks (r·v)^n)``,
      i.e. ``eval = kd cos θ_i + ks cos^n α`` — neither reciprocal nor energy conserving
      (no 1/π is applied to ``kd``, exactly as written in the lecture).

    Sampling: the specular lobe (``(n+1)/(2π) cos^n α`` around ``r``) with probability
    ``mean(ks) / (mean(kd) + mean(ks))``, otherwise cosine-weighted; ``weight = eval / pdf``.
    ``n`` >= 0 is differentiable.

    Example: normalised, ``kd = 0, ks = 1, n = 0``: ``f = 1/π``.
    """

    kd: jnp.ndarray = rgb_field(0.5, "kd")
    ks: jnp.ndarray = rgb_field(0.2, "ks")
    exponent: jnp.ndarray = float_field(30.0, "exponent")
    normalized: bool = eqx.field(static=True, default=True, converter=bool, kw_only=True)

    def __check_init__(self):
        check_rgb(self.kd, "kd")
        check_rgb(self.ks, "ks")
        check_nonnegative(self.exponent, "exponent")

    @property
    def albedo(self):
        return self.kd

    def _spec_prob(self):
        md = jnp.mean(self.kd, axis=-1)
        ms = jnp.mean(self.ks, axis=-1)
        return safe_div(ms, md + ms, fill=0.5)

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        ci = wi[..., 2]
        valid = (wo[..., 2] > 0) & (ci > 0)
        n = self.exponent
        spec = safe_pow(vdot(reflect(wo), wi), n)
        if self.normalized:
            val = (
                self.kd * (ci * INV_PI)[..., None]
                + self.ks * ((n + 2.0) / (2.0 * math.pi) * spec * ci)[..., None]
            )
        else:
            val = self.kd * ci[..., None] + self.ks * spec[..., None]
        return mask3(valid, val)

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        ci = wi[..., 2]
        valid = (wo[..., 2] > 0) & (ci > 0)
        n = self.exponent
        ps = self._spec_prob()
        p_spec = (n + 1.0) / (2.0 * math.pi) * safe_pow(vdot(reflect(wo), wi), n)
        return jnp.where(valid, ps * p_spec + (1.0 - ps) * ci * INV_PI, 0.0)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        ps = self._spec_prob()
        r = reflect(wo)
        r = jnp.where((wo[..., 2] > 0)[..., None], r, jnp.array([0.0, 0.0, 1.0], wo.dtype))
        spec_dir = to_world(frame_from_normal(r), square_to_phong_lobe(u2, self.exponent))
        diff_dir = square_to_cosine_hemisphere(u2)
        wi = jnp.where((u1 < ps)[..., None], spec_dir, diff_dir)
        pdf = self.pdf(wo, wi)
        valid = (wo[..., 2] > 0) & (wi[..., 2] > 0) & (pdf > 0)
        weight = self.eval(wo, wi) / jnp.where(valid, pdf, 1.0)[..., None]
        return glossy_sample(wi, pdf, weight, valid, shape, wo.dtype)
