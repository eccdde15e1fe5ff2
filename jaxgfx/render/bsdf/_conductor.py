"""Smooth conductor: an ideal mirror with optional complex-IOR Fresnel reflectance."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from jaxgfx._checks import check_choice
from jaxgfx.render.bsdf._base import (
    BSDFSample,
    DeltaBSDF,
    check_rgb,
    mask3,
    sample_setup,
    to_rgb,
)
from jaxgfx.render.bsdf.fresnel import fresnel_conductor, fresnel_schlick
from jaxgfx.render.geometry.frame import reflect

__all__ = ["Mirror", "fresnel_factor", "resolve_fresnel", "check_fresnel", "FRESNEL_MODES"]

FRESNEL_MODES = ("none", "conductor", "schlick")


def fresnel_factor(mode, cos_theta, reflectance, eta, k):
    """RGB Fresnel factor shared by :class:`Mirror` and ``RoughConductor``.

    ``"none"``: ``reflectance``; ``"conductor"``: ``reflectance · F_conductor(cos, eta, k)``;
    ``"schlick"``: ``F_schlick(F0 = reflectance, cos)``.
    """
    c = cos_theta[..., None]
    if mode == "none":
        return jnp.broadcast_to(reflectance, jnp.broadcast_shapes(c.shape, reflectance.shape))
    if mode == "conductor":
        return reflectance * fresnel_conductor(c, eta, k)
    return fresnel_schlick(reflectance, c)


def resolve_fresnel(fresnel, eta, k):
    """Constructor arguments ``(fresnel, eta, k)`` of a conductor -> field values: ``fresnel``
    defaults to ``"conductor"`` when ``eta`` is given, else ``"none"``; ``k`` defaults to 0
    for ``"conductor"``; ``eta``, ``k`` converted to RGB (validated by :func:`check_fresnel`)."""
    if fresnel is None:
        fresnel = "none" if eta is None else "conductor"
    if fresnel == "conductor" and eta is not None and k is None:
        k = 0.0
    eta = None if eta is None else to_rgb(eta, "eta")
    k = None if k is None else to_rgb(k, "k")
    return fresnel, eta, k


def check_fresnel(fresnel, eta, k):
    """``__check_init__`` of the conductor Fresnel fields (shared with ``RoughConductor``)."""
    check_choice(fresnel, "fresnel", FRESNEL_MODES)
    if fresnel == "conductor" and (eta is None or k is None):
        raise ValueError("eta: required when fresnel='conductor'")
    if eta is not None:
        check_rgb(eta, "eta")
    if k is not None:
        check_rgb(k, "k")


class Mirror(DeltaBSDF):
    """Ideal specular reflection (Mitsuba ``conductor``): ``wi = (-wo_x, -wo_y, wo_z)``.

    ``f = reflectance · F(cos θ_o) δ(ω_i - ω_r) / |cos θ_i|`` (seed lecture 3,
    ``f_mirror = δ(θ_i - θ_o) δ(φ_i - φ_o) / cos θ_i``). ``fresnel`` (static) is ``"none"``
    (F = 1, the default when ``eta`` is not given), ``"conductor"`` (exact complex IOR
    ``eta + i k`` per RGB channel) or ``"schlick"`` (``reflectance`` is F0).
    ``eval`` and ``pdf`` are 0 (delta lobe); ``sample`` returns ``pdf = 1``, ``is_delta = True``
    and ``weight = reflectance · F``.

    Example: ``Mirror(eta=1.5, k=0.).sample(z, u1, u2).weight = 0.04`` at normal incidence.
    """

    reflectance: jnp.ndarray
    eta: jnp.ndarray | None
    k: jnp.ndarray | None
    fresnel: str = eqx.field(static=True, default="none")

    EVAL_DTYPE_OF = "reflectance"

    def __init__(self, reflectance=1.0, *, eta=None, k=None, fresnel=None):
        self.reflectance = to_rgb(reflectance, "reflectance")
        self.fresnel, self.eta, self.k = resolve_fresnel(fresnel, eta, k)

    def __check_init__(self):
        check_rgb(self.reflectance, "reflectance")
        check_fresnel(self.fresnel, self.eta, self.k)

    @property
    def albedo(self):
        return self.reflectance

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        co = wo[..., 2]
        valid = co > 0
        f = fresnel_factor(self.fresnel, co, self.reflectance, self.eta, self.k)
        return BSDFSample(
            wi=reflect(wo),
            pdf=jnp.where(valid, 1.0, 0.0).astype(co.dtype),
            weight=mask3(valid, f),
            is_delta=jnp.ones(shape, bool),
            eta=jnp.ones(shape, co.dtype),
        )
