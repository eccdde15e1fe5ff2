"""Mitsuba 3's ``polarizer``, ``circular`` and ``retarder`` as its RGB (unpolarised) variants
evaluate them: straight pass-through surfaces that scale the light."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp

from jaxgfx.render.bsdf._base import (
    BSDFSample,
    DeltaBSDF,
    check_rgb,
    check_scalar,
    float_field,
    rgb_field,
    sample_setup,
)

__all__ = ["PassThrough", "Polarizer", "CircularPolarizer", "Retarder"]


class PassThrough(DeltaBSDF):
    """A null-like surface that scales the light crossing it: ``eval = pdf = 0`` and ``sample``
    always continues the ray straight on (``wi = -wo``, ``pdf`` 1, delta, ``eta`` 1) with the
    weight ``FACTOR · transmittance``; a bounce, and opaque to shadow rays, as the ``null``
    BSDF (:class:`~jaxgfx.render.bsdf.Null`) and Mitsuba 3.9's ``path`` treat ``Null``-flagged
    lobes. ``transmittance``: RGB, >= 0 (default 1)."""

    transmittance: jnp.ndarray = rgb_field(1.0, "transmittance")

    EVAL_DTYPE_OF: ClassVar[str] = "transmittance"
    FACTOR: ClassVar[float] = 1.0

    def __check_init__(self):
        check_rgb(self.transmittance, "transmittance")

    @property
    def albedo(self):
        return jnp.zeros_like(self.transmittance)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        w = (self.FACTOR * self.transmittance).astype(wo.dtype)
        return BSDFSample(
            wi=-wo,
            pdf=jnp.ones(shape, wo.dtype),
            weight=jnp.broadcast_to(w, shape + (3,)),
            is_delta=jnp.ones(shape, bool),
            eta=jnp.ones(shape, wo.dtype),
        )


class Polarizer(PassThrough):
    """Mitsuba 3's linear ``polarizer`` in its RGB variants: a straight pass-through of weight
    ``0.5 · transmittance`` (unpolarised light loses half its power; Mitsuba's ``polarizer.cpp``,
    the non-polarised branches of ``sample`` and ``eval_null_transmission``). ``theta`` (the
    polariser's angle in degrees, default 0) and ``polarizing`` (static, default true) are
    accepted and kept for the round trip; they have no effect on unpolarised light, in Mitsuba's
    RGB variants as here (so the derivative w.r.t. ``theta`` is 0)."""

    theta: jnp.ndarray = float_field(0.0, "theta")
    polarizing: bool = eqx.field(static=True, default=True)

    FACTOR: ClassVar[float] = 0.5

    def __check_init__(self):  # equinox also runs PassThrough's
        check_scalar(self.theta, "theta")
        if not isinstance(self.polarizing, bool):
            raise ValueError(f"polarizing: expected a bool, got {self.polarizing!r}")


class CircularPolarizer(PassThrough):
    """Mitsuba 3's ``circular`` polarizer in its RGB variants: a straight pass-through of weight
    ``0.5 · transmittance`` (Mitsuba's ``circular.cpp``, the non-polarised branches).
    ``left_handed`` (static, default false) is accepted and kept for the round trip; it has no
    effect on unpolarised light."""

    left_handed: bool = eqx.field(static=True, default=False)

    FACTOR: ClassVar[float] = 0.5

    def __check_init__(self):  # equinox also runs PassThrough's
        if not isinstance(self.left_handed, bool):
            raise ValueError(f"left_handed: expected a bool, got {self.left_handed!r}")


class Retarder(PassThrough):
    """Mitsuba 3's linear ``retarder`` in its RGB variants: a straight pass-through of weight
    ``transmittance`` (Mitsuba's ``retarder.cpp``, the non-polarised branches). ``theta`` (the
    fast axis' angle, degrees, default 0) and ``delta`` (the retardance, degrees, default 90)
    are accepted and kept for the round trip; they only rotate polarisation states, so they
    have no effect on unpolarised light (derivatives 0)."""

    theta: jnp.ndarray = float_field(0.0, "theta")
    delta: jnp.ndarray = float_field(90.0, "delta")

    def __check_init__(self):  # equinox also runs PassThrough's
        check_scalar(self.theta, "theta")
        check_scalar(self.delta, "delta")
