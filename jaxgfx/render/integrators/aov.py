"""Arbitrary output variables at the first hit: albedo (3), shading normal (3), depth (1) by
default, or a chosen list in a chosen order (Mitsuba 3's ``aov`` integrator)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp

from jaxgfx._checks import check_choice
from jaxgfx._math import sum_last
from jaxgfx.render.integrators import _common as C
from jaxgfx.render.integrators.base import Integrator

__all__ = ["AOVIntegrator", "aov", "AOV_CHANNELS", "AOV_TYPES"]

AOV_CHANNELS = ("albedo.R", "albedo.G", "albedo.B", "nx", "ny", "nz", "depth")

AOV_TYPES = {"albedo": 3, "depth": 1, "position": 3, "geo_normal": 3, "sh_normal": 3}
"""The AOVs a chosen list may name (Mitsuba's names) -> their channel counts."""


def aov(scene, o, d, aovs=(), near_clip=0.0):
    """``(..., 7)``: albedo RGB, world shading normal (facing the camera), hit distance ``t``.
    Misses give zeros.

    With ``aovs`` (names of :data:`AOV_TYPES`), those channels in that order, as Mitsuba 3's
    ``aov`` integrator: ``albedo`` (the material's albedo), ``depth`` (the hit distance from
    the ray's start; with ``near_clip > 0``, from the camera's near plane as Mitsuba's
    perspective rays start there: ``t - near_clip / cos``, ``cos`` the angle to the viewing
    axis), ``position``, ``geo_normal`` (the shape's geometric normal, not flipped),
    ``sh_normal`` (the shading normal on the geometric normal's side); misses give zeros.
    """
    hit = C.intersect(scene, o, d)
    mat = C.hit_material(scene, hit)
    frame, ng, _ = C.shading_frame(scene, hit, d, mat)
    alb = C.dispatch(scene, mat, lambda m: jnp.broadcast_to(m.albedo, hit.p.shape), uv=hit.uv)
    v = hit.valid[..., None]
    depth = jnp.where(hit.valid, hit.t, 0.0)[..., None]
    if not aovs:
        return jnp.concatenate([jnp.where(v, alb, 0.0), jnp.where(v, frame.n, 0.0), depth], -1)
    out = []
    for name in aovs:
        if name == "albedo":
            x = alb
        elif name == "depth":
            x = hit.t
            if near_clip:
                cam = scene.camera
                fwd = cam.target - cam.origin
                fwd = (fwd / jnp.linalg.norm(fwd)).astype(d.dtype)
                cos = sum_last(d * fwd)
                x = x - near_clip / jnp.where(cos > 0, cos, 1.0)
            x = x[..., None]
        elif name == "position":
            x = hit.p
        elif name == "geo_normal":
            x = hit.ng
        else:  # sh_normal: on the geometric normal's side
            s = jnp.where(sum_last(frame.n * hit.ng) < 0, -1.0, 1.0)[..., None]
            x = frame.n * s
        out.append(jnp.where(v, x, 0.0))
    del ng
    return jnp.concatenate(out, -1)


class _Channels:
    """``n_channels``: 7 on the class and for the default list, else the chosen AOVs' sum."""

    def __get__(self, obj, cls=None) -> int:
        if obj is None or not obj.aovs:
            return len(AOV_CHANNELS)
        return sum(AOV_TYPES[a] for a in obj.aovs)


class AOVIntegrator(Integrator):
    """Arbitrary output variables (:func:`aov`): by default ``(..., 7)`` channels named by
    :data:`AOV_CHANNELS`; ``aovs`` (static) a tuple of :data:`AOV_TYPES` names for those
    channels in that order (Mitsuba's ``aov``), ``near_clip`` (static) the perspective
    camera's near plane the depth is measured from (Mitsuba's). Uses no random numbers.

    >>> AOVIntegrator().n_channels, AOVIntegrator(aovs=("depth", "position")).n_channels
    (7, 4)
    """

    aovs: tuple = eqx.field(static=True, default=())
    near_clip: float = eqx.field(static=True, default=0.0)

    def __check_init__(self):
        for name in self.aovs:
            check_choice(name, "aovs", tuple(AOV_TYPES))
        if not self.near_clip >= 0:
            raise ValueError(f"near_clip: expected a number >= 0, got {self.near_clip!r}")

    n_channels = _Channels()

    def __call__(self, scene, o, d, u=None):
        return aov(scene, o, d, self.aovs, self.near_clip)
