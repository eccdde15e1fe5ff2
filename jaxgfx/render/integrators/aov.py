"""Arbitrary output variables at the first hit: albedo (3), shading normal (3), depth (1)."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp

from jaxgfx.render.integrators import _common as C
from jaxgfx.render.integrators.base import Integrator

__all__ = ["AOVIntegrator", "aov", "AOV_CHANNELS"]

AOV_CHANNELS = ("albedo.R", "albedo.G", "albedo.B", "nx", "ny", "nz", "depth")


def aov(scene, o, d):
    """``(..., 7)``: albedo RGB, world shading normal (facing the camera), hit distance ``t``.

    Misses give zeros.
    """
    hit = C.intersect(scene, o, d)
    mat = C.hit_material(scene, hit)
    frame, _, _ = C.shading_frame(scene, hit, d, mat)
    alb = C.dispatch(scene, mat, lambda m: jnp.broadcast_to(m.albedo, hit.p.shape), uv=hit.uv)
    v = hit.valid[..., None]
    depth = jnp.where(hit.valid, hit.t, 0.0)[..., None]
    return jnp.concatenate([jnp.where(v, alb, 0.0), jnp.where(v, frame.n, 0.0), depth], -1)


class AOVIntegrator(Integrator):
    """Arbitrary output variables (:func:`aov`): ``(..., 7)`` channels named by
    :data:`AOV_CHANNELS`; uses no random numbers.

    >>> AOVIntegrator.n_channels
    7
    """

    n_channels: ClassVar[int] = len(AOV_CHANNELS)

    def __call__(self, scene, o, d, u=None):
        return aov(scene, o, d)
