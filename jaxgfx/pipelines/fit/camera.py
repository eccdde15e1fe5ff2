"""The fit's camera: :class:`jaxgfx.hdr.Camera` between the rendered radiance and an LDR
target, with the response chosen by name (one-hot weights, so that every camera variant of a
scene shares one compiled program)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgfx._checks import check_choice
from jaxgfx.hdr import ANALYTIC_RESPONSES, Camera, CameraResponse

__all__ = [
    "RESPONSE_MODELS",
    "fit_camera",
    "photo_camera",
    "apply_camera",
    "camera_to_linear",
    "camera_blend",
    "freeze",
]

RESPONSE_MODELS = ("gamma", *ANALYTIC_RESPONSES)
"""Camera response models for LDR targets: ``gamma`` (a fitted exponent) and the fixed
analytic curves of :meth:`jaxgfx.hdr.CameraResponse.analytic`
(:data:`jaxgfx.hdr.ANALYTIC_RESPONSES`)."""


def fit_camera(exposure, gamma, *, model: str) -> Camera:
    """The :class:`~jaxgfx.hdr.Camera` of a fit: response ``model`` anchored at ``"unit"``
    (``response(1) = 1``; ``gamma`` is ``v = x^(1/γ)``), ``exposure`` a scalar. No clip, no
    quantisation (the loss handles both)."""
    check_choice(model, "model", RESPONSE_MODELS)
    if model == "gamma":
        resp = CameraResponse.gamma(jnp.reshape(gamma, (1,)), anchor="unit")
    else:
        resp = CameraResponse.analytic(model, anchor="unit")
    return Camera(resp, exposure, clip=False)


def apply_camera(radiance, exposure, gamma, *, model: str):
    """Continuous display value ``v = response(exposure · radiance)`` (not clipped, not
    quantised). ``model``: a name in :data:`RESPONSE_MODELS`; ``gamma`` is used by ``"gamma"``
    only. Example: ``apply_camera(0.25, 1.0, 2.0, model="gamma")`` → 0.5."""
    return fit_camera(exposure, gamma, model=model).display(jnp.asarray(radiance))


def camera_to_linear(z, exposure, gamma, *, model: str):
    """Inverse of :func:`apply_camera`: linear radiance for display values ``z`` in [0, 1]."""
    return fit_camera(exposure, gamma, model=model).linearize(jnp.asarray(z))


def camera_blend(fn, weights):
    """``Σ_m weights[m] · fn(m)`` over :data:`RESPONSE_MODELS` (a one-hot ``weights`` selects
    a model without recompiling)."""
    out = 0.0
    for i, m in enumerate(RESPONSE_MODELS):
        out = out + weights[i] * fn(m)
    return out


def freeze(x, free):
    """``x`` with its gradient kept where ``free`` (1.0) and removed where 0.0."""
    return free * x + (1.0 - free) * jax.lax.stop_gradient(x)


def photo_camera(exposure, gamma, *, model: str, bits: int) -> Camera:
    """:func:`fit_camera` as a photo is taken: clipped to the sensor range and quantised to
    ``bits`` (synthetic LDR targets and the previews)."""
    cam = fit_camera(exposure, gamma, model=model)
    return Camera(cam.response, cam.exposure, bits=bits, clip=True)
