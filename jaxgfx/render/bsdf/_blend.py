"""Blend of two BSDFs (Mitsuba ``blendbsdf``): ``(1 - w) f_0 + w f_1``."""

from __future__ import annotations

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

__all__ = ["BlendBSDF"]

_FLIP = (1.0, 1.0, -1.0)


def _as_bsdf(x, name):
    # description dicts are built by make_bsdf (bsdf/__init__.py), which owns the registry
    if getattr(x, "needs_tangents", False):  # hair: its frame is the hit's, not nestable
        raise TypeError(f"{name}: a {type(x).__name__} BSDF cannot be nested (top level only)")
    if isinstance(x, BSDF):
        return x
    raise TypeError(f"{name}: expected a BSDF, got {type(x).__name__}")


class BlendBSDF(BSDF):
    """Weighted blend of two BSDFs (Mitsuba 3 ``blendbsdf``): ``f = (1 - w) f_0 + w f_1`` with
    ``w = clip(weight, 0, 1)`` (a number, or a texture through the material's ``weight`` key).

    ``bsdf0`` / ``bsdf1``: BSDFs (``make_bsdf`` also takes description dicts for them). ``pdf`` is
    the mixture ``(1 - w) p_0 + w p_1``; ``sample`` picks component 1 with probability ``w``
    (reusing ``u1``) and, for a non-delta sample, returns the mixture pdf and
    ``weight = f / pdf`` (so MIS sees the true density; Mitsuba returns the chosen component's
    own pdf and weight: same expectation). A delta sample keeps its component's weight, with
    the derivative of ``w / stop_gradient(w)`` for the choice. Flags: delta / transmissive if
    either component is. In a transmissive blend, a reflection-only component is two-sided
    (evaluated mirrored when ``wo`` is below the surface), as jaxgfx shades it alone.
    """

    bsdf0: BSDF
    bsdf1: BSDF
    weight: jnp.ndarray = float_field(0.5, "weight")

    def __init__(self, bsdf0, bsdf1, weight=0.5):
        self.bsdf0 = _as_bsdf(bsdf0, "bsdf0")
        self.bsdf1 = _as_bsdf(bsdf1, "bsdf1")
        self.weight = weight

    def __check_init__(self):
        check_scalar(self.weight, "weight")

    @property
    def has_delta(self):
        return self.bsdf0.has_delta or self.bsdf1.has_delta

    @property
    def is_transmissive(self):
        return self.bsdf0.is_transmissive or self.bsdf1.is_transmissive

    @property
    def albedo(self):
        w = jnp.clip(self.weight, 0.0, 1.0)[..., None]
        return (1 - w) * self.bsdf0.albedo + w * self.bsdf1.albedo

    def _w(self, dtype):
        return jnp.clip(self.weight, 0.0, 1.0).astype(dtype)

    def _flip(self, b, wo):
        """Per-ray sign (..., 1) mirroring ``z`` for a reflection-only component below."""
        if b.is_transmissive or not self.is_transmissive:
            return None
        return jnp.where(wo[..., 2:3] < 0, jnp.asarray(_FLIP, wo.dtype), 1.0)

    def _eval_pdf(self, b, wo, wi):
        s = self._flip(b, wo)
        if s is not None:
            wo, wi = wo * s, wi * s
        return b.eval(wo, wi), b.pdf(wo, wi)

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        w = self._w(jnp.result_type(wo, wi))[..., None]
        f0, _ = self._eval_pdf(self.bsdf0, wo, wi)
        f1, _ = self._eval_pdf(self.bsdf1, wo, wi)
        return (1 - w) * f0 + w * f1

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        w = self._w(jnp.result_type(wo, wi))
        _, p0 = self._eval_pdf(self.bsdf0, wo, wi)
        _, p1 = self._eval_pdf(self.bsdf1, wo, wi)
        return (1 - w) * p0 + w * p1

    def _sample_one(self, b, wo, u1, u2):
        s = self._flip(b, wo)
        smp = b.sample(wo if s is None else wo * s, u1, u2)
        return smp if s is None else smp._replace(wi=smp.wi * s)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        w = jnp.broadcast_to(self._w(wo.dtype), shape)
        pick1 = u1 <= w
        s0 = self._sample_one(self.bsdf0, wo, safe_div(u1 - w, 1 - w), u2)
        s1 = self._sample_one(self.bsdf1, wo, safe_div(u1, w), u2)
        sel = jax.tree_util.tree_map(
            lambda a, b: jnp.where(pick1.reshape(shape + (1,) * (a.ndim - len(shape))), b, a),
            s0,
            s1,
        )
        wk = jnp.where(pick1, w, 1 - w)  # probability of the chosen component
        # delta lobe: f = w_k f_k, chosen with probability w_k -> the component's weight
        w_sel = safe_div(wk, jax.lax.stop_gradient(wk), fill=1.0)
        delta_weight = sel.weight * w_sel[..., None]
        # non-delta: the mixture's density and f / pdf at the sampled direction
        pdf_mix = self.pdf(wo, sel.wi)
        f_mix = self.eval(wo, sel.wi)
        cont_weight = safe_div(f_mix, pdf_mix[..., None])
        pdf = jnp.where(sel.is_delta, wk * sel.pdf, pdf_mix)
        weight = jnp.where(sel.is_delta[..., None], delta_weight, cont_weight)
        valid = (sel.pdf > 0) & (pdf > 0)
        return BSDFSample(
            wi=sel.wi,
            pdf=jnp.where(valid, pdf, 0.0),
            weight=mask3(valid, weight),
            is_delta=sel.is_delta,
            eta=sel.eta,
        )
