"""Opacity mask (Mitsuba ``mask``): a nested BSDF mixed with a straight pass-through lobe."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from jaxgfx._math import safe_div
from jaxgfx.render.bsdf._base import (
    BSDF,
    BSDFSample,
    check_scalar,
    float_field,
    mask3,
    prep_dirs,
    sample_setup,
)
from jaxgfx.render.bsdf._diffuse import Diffuse

__all__ = ["Mask", "Null"]


def _frac(p):
    """``p / stop_gradient(p)``: 1 with the derivative ``1 / p`` of a discrete choice made with
    probability ``p`` (1 and no NaN where ``p == 0``)."""
    return safe_div(p, jax.lax.stop_gradient(p), fill=1.0)


class Mask(BSDF):
    """Opacity mask (Mitsuba 3 ``mask``): ``f = a f_nested`` plus a null lobe
    ``(1 - a) δ(wi + wo)`` (the ray continues unchanged), ``a = clip(opacity, 0, 1)``.

    ``bsdf``: the nested BSDF (``make_bsdf`` also takes a description dict); ``opacity``: a
    number (default 0.5, Mitsuba's), or a texture through the material's ``opacity`` key (an RGB
    texture gives its luminance, as Mitsuba's ``eval_1``). ``eval = a eval_nested``,
    ``pdf = a pdf_nested``; ``sample`` picks the pass-through with probability ``1 - a``
    (``wi = -wo``, ``pdf = 1 - a``, weight 1, delta, ``eta`` 1) and the nested BSDF otherwise
    (reusing ``u1 / a``; its ``pdf`` times ``a``, its weight unchanged), as Mitsuba does. The
    choice's derivative w.r.t. ``a`` is carried by the weights, ``a / stop_gradient(a)`` resp.
    ``(1 - a) / stop_gradient(1 - a)``, so ``d/da`` is unbiased also for the delta lobe.
    ``has_delta`` is true; ``is_transmissive`` is the nested BSDF's (the pass-through needs no
    orientation: a reflection-only nested BSDF stays two-sided as jaxgfx shades it alone).
    Shadow rays treat a masked surface as opaque and a pass-through is a bounce (it counts
    against ``max_depth``), as in Mitsuba 3.9's ``path`` integrator.
    """

    bsdf: BSDF
    opacity: jnp.ndarray = float_field(0.5, "opacity")

    has_delta: ClassVar[bool] = True

    def __init__(self, bsdf=None, opacity=0.5):
        if bsdf is None:
            raise ValueError("bsdf: missing nested BSDF")
        if not isinstance(bsdf, BSDF):
            raise TypeError(f"bsdf: expected a BSDF, got {type(bsdf).__name__}")
        if getattr(bsdf, "needs_tangents", False):  # hair: its frame is the hit's
            raise TypeError(f"bsdf: a {type(bsdf).__name__} BSDF cannot be nested (top level only)")
        self.bsdf = bsdf
        self.opacity = opacity

    def __check_init__(self):
        check_scalar(self.opacity, "opacity")

    @property
    def is_transmissive(self):
        return self.bsdf.is_transmissive

    @property
    def albedo(self):
        return self.bsdf.albedo

    def _a(self, dtype):
        return jnp.clip(self.opacity, 0.0, 1.0).astype(dtype)

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        return self._a(jnp.result_type(wo, wi))[..., None] * self.bsdf.eval(wo, wi)

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        return self._a(jnp.result_type(wo, wi)) * self.bsdf.pdf(wo, wi)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        a = jnp.broadcast_to(self._a(wo.dtype), shape)
        nested = u1 < a
        s = self.bsdf.sample(wo, jnp.clip(safe_div(u1, a), 0.0, 1.0), u2)
        ok = s.pdf > 0
        n_pdf = a * s.pdf
        n_weight = s.weight * _frac(a)[..., None]
        p_null = 1.0 - a
        null_weight = jnp.broadcast_to(_frac(p_null)[..., None], shape + (3,))
        pick = nested[..., None]
        valid = jnp.where(nested, ok & (n_pdf > 0), p_null > 0)
        return BSDFSample(
            wi=jnp.where(pick, s.wi, -wo),
            pdf=jnp.where(valid, jnp.where(nested, n_pdf, p_null), 0.0),
            weight=mask3(valid, jnp.where(pick, n_weight, null_weight).astype(wo.dtype)),
            is_delta=jnp.where(nested, s.is_delta, True),
            eta=jnp.where(nested, s.eta, 1.0).astype(wo.dtype),
        )


class Null(Mask):
    """Invisible surface (Mitsuba 3 ``null``): a :class:`Mask` of opacity 0 over a black
    diffuse BSDF, so ``eval = pdf = 0`` and ``sample`` always continues the ray straight on
    (``wi = -wo``, weight 1, ``pdf`` 1, delta), a bounce as in Mitsuba 3.9's ``path``. No
    parameters; shadow rays see the surface as opaque, as for a mask."""

    def __init__(self):
        super().__init__(Diffuse(0.0), 0.0)
