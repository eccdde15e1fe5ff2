"""Integrators as objects: ``PathIntegrator`` (NEE + MIS + Russian roulette),
``DirectIntegrator`` (path of depth 2), ``WhittedIntegrator`` (shadows, reflection, refraction),
``AOVIntegrator`` (albedo, normal, depth) and ``ParticleTracer`` (light tracing, Mitsuba's
``ptracer``), registered by name in :data:`INTEGRATORS`.

Each is an ``eqx.Module`` whose options are static fields; :func:`jaxgfx.render.render` takes
an instance (``integrator=PathIntegrator(max_depth=3)``) or a registered name.
"""

import dataclasses

from jaxgfx._checks import check_choice
from jaxgfx.render.integrators._common import SAMPLING as SAMPLING
from jaxgfx.render.integrators._common import dispatch as dispatch
from jaxgfx.render.integrators._common import hit_material as hit_material
from jaxgfx.render.integrators._common import intersect as intersect
from jaxgfx.render.integrators._common import replace_grad as replace_grad
from jaxgfx.render.integrators._common import shading_frame as shading_frame
from jaxgfx.render.integrators._common import tangent_space as tangent_space
from jaxgfx.render.integrators.aov import AOV_CHANNELS as AOV_CHANNELS
from jaxgfx.render.integrators.aov import AOVIntegrator as AOVIntegrator
from jaxgfx.render.integrators.aov import aov as aov
from jaxgfx.render.integrators.base import Integrator as Integrator
from jaxgfx.render.integrators.path import DirectIntegrator as DirectIntegrator
from jaxgfx.render.integrators.path import PathIntegrator as PathIntegrator
from jaxgfx.render.integrators.path import path_radiance as path_radiance
from jaxgfx.render.integrators.path import replay_refusal as replay_refusal
from jaxgfx.render.integrators.ptracer import ParticleTracer as ParticleTracer
from jaxgfx.render.integrators.whitted import WhittedIntegrator as WhittedIntegrator
from jaxgfx.render.integrators.whitted import whitted_radiance as whitted_radiance

INTEGRATORS: dict[str, type[Integrator]] = {
    "path": PathIntegrator,
    "direct": DirectIntegrator,
    "whitted": WhittedIntegrator,
    "aov": AOVIntegrator,
    "ptracer": ParticleTracer,
}
"""Integrator name -> class (the names ``render(..., integrator=NAME)`` accepts)."""


def make_integrator(name: str, **options) -> Integrator:
    """The integrator registered as ``name``, built from ``options`` (``max_depth``,
    ``rr_depth``, ``strategy``, ``sampling``, ...). An option its class does not take is a
    ``TypeError`` naming it and what the class takes — never silently dropped
    (``DirectIntegrator``'s depth is fixed: ``max_depth=2`` is accepted, another is an error).

    >>> make_integrator("whitted", max_depth=2)
    WhittedIntegrator(max_depth=2)
    """
    check_choice(name, "integrator", tuple(INTEGRATORS))
    cls = INTEGRATORS[name]
    fields = {f.name for f in dataclasses.fields(cls)}
    fixed = {k: getattr(cls, k) for k in options if k not in fields and hasattr(cls, k)}
    fixed = {k: v.fget(cls) if isinstance(v, property) else v for k, v in fixed.items()}
    bad = sorted(
        k for k in options if k not in fields and (k not in fixed or fixed[k] != options[k])
    )
    if bad:
        detail = "; ".join(
            f"{k}: the {name!r} integrator has {k} = {fixed[k]}" if k in fixed else
            f"{k}: not an option of the {name!r} integrator"
            for k in bad
        )
        takes = sorted(fields) or ["none"]
        raise TypeError(f"{detail} (it takes: {', '.join(takes)})")
    return cls(**{k: v for k, v in options.items() if k in fields})


__all__ = [
    "INTEGRATORS",
    "SAMPLING",
    "replace_grad",
    "intersect",
    "hit_material",
    "shading_frame",
    "tangent_space",
    "dispatch",
    "AOV_CHANNELS",
    "Integrator",
    "PathIntegrator",
    "DirectIntegrator",
    "WhittedIntegrator",
    "AOVIntegrator",
    "ParticleTracer",
    "make_integrator",
    "aov",
    "path_radiance",
    "replay_refusal",
    "whitted_radiance",
]
