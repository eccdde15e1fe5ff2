"""Integrators: ``path`` (NEE + MIS + Russian roulette), ``direct`` (path of depth 2),
``whitted`` (shadows, reflection, refraction) and ``aov`` (albedo, normal, depth)."""

from jaxgfx.render.integrators.aov import AOV_CHANNELS as AOV_CHANNELS
from jaxgfx.render.integrators.aov import aov as aov
from jaxgfx.render.integrators.path import path_radiance as path_radiance
from jaxgfx.render.integrators.whitted import whitted_radiance as whitted_radiance

INTEGRATORS = ("path", "direct", "whitted", "aov")

__all__ = ["INTEGRATORS", "AOV_CHANNELS", "aov", "path_radiance", "whitted_radiance"]
