"""Integrators as objects: ``PathIntegrator`` (NEE + MIS + Russian roulette),
``DirectIntegrator`` (path of depth 2), ``WhittedIntegrator`` (shadows, reflection, refraction)
and ``AOVIntegrator`` (albedo, normal, depth), registered by name in :data:`INTEGRATORS`.

Each is an ``eqx.Module`` whose options are static fields; :func:`jaxgfx.render.render` takes
an instance (``integrator=PathIntegrator(max_depth=3)``) or a registered name.
"""

from jaxgfx.render.integrators.aov import AOV_CHANNELS as AOV_CHANNELS
from jaxgfx.render.integrators.aov import AOVIntegrator as AOVIntegrator
from jaxgfx.render.integrators.aov import aov as aov
from jaxgfx.render.integrators.base import Integrator as Integrator
from jaxgfx.render.integrators.path import DirectIntegrator as DirectIntegrator
from jaxgfx.render.integrators.path import PathIntegrator as PathIntegrator
from jaxgfx.render.integrators.path import path_radiance as path_radiance
from jaxgfx.render.integrators.whitted import WhittedIntegrator as WhittedIntegrator
from jaxgfx.render.integrators.whitted import whitted_radiance as whitted_radiance

INTEGRATORS: dict[str, type[Integrator]] = {
    "path": PathIntegrator,
    "direct": DirectIntegrator,
    "whitted": WhittedIntegrator,
    "aov": AOVIntegrator,
}
"""Integrator name -> class (the names ``render(..., integrator=NAME)`` accepts)."""


def make_integrator(name: str, **options) -> Integrator:
    """The integrator registered as ``name``, built from the ``options`` its class takes
    (``max_depth``, ``rr_depth``, ``strategy``); options the class does not take are ignored,
    as ``render(..., integrator="direct", max_depth=5)`` always has.

    >>> make_integrator("whitted", max_depth=2, strategy="mis")
    WhittedIntegrator(max_depth=2)
    """
    if name not in INTEGRATORS:
        raise ValueError(f"integrator: expected one of {tuple(INTEGRATORS)}, got {name!r}")
    cls = INTEGRATORS[name]
    fields = {f for f in cls.__dataclass_fields__}
    return cls(**{k: v for k, v in options.items() if k in fields})


__all__ = [
    "INTEGRATORS",
    "AOV_CHANNELS",
    "Integrator",
    "PathIntegrator",
    "DirectIntegrator",
    "WhittedIntegrator",
    "AOVIntegrator",
    "make_integrator",
    "aov",
    "path_radiance",
    "whitted_radiance",
]
