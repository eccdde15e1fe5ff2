"""Path tracing with next-event estimation, MIS (power heuristic) and Russian roulette.

Depth convention (Mitsuba 3): ``max_depth = 1`` renders only directly visible emitters,
``2`` adds direct illumination, ``3`` one indirect bounce, ... The bounce loop is a
``lax.scan`` with a static trip count, so the estimator is reverse-mode differentiable w.r.t.
every scene parameter (no ``while_loop`` carries radiance or throughput).
"""

from __future__ import annotations

import equinox as eqx

from jaxgfx._checks import check_choice
from jaxgfx.render.integrators import _common as C
from jaxgfx.render.integrators._bounce import (
    ADJOINTS,
    STRATEGIES,
    _check_chunk,
    _check_strategy,
    path_radiance,
)
from jaxgfx.render.integrators._replay import RADIANCE_NAME as REPLAY_RADIANCE_NAME
from jaxgfx.render.integrators._replay import path_radiance_replay, replay_refusal
from jaxgfx.render.integrators.base import N_RANDOM, Integrator, check_depth

__all__ = [
    "PathIntegrator",
    "DirectIntegrator",
    "path_radiance",
    "N_RANDOM",
    "STRATEGIES",
    "ADJOINTS",
    "REPLAY_RADIANCE_NAME",
    "replay_refusal",
]


def _check_adjoint(adjoint, sampling):
    check_choice(adjoint, "adjoint", ADJOINTS)
    if adjoint == "replay" and sampling != "detached":
        raise ValueError(
            "adjoint: 'replay' replays the detached estimator and needs sampling='detached', "
            f"got sampling={sampling!r}"
        )


def _radiance(integ, scene, o, d, u, max_depth):
    kw = dict(max_depth=max_depth, rr_depth=integ.rr_depth, strategy=integ.strategy,
              chunk=integ.chunk)  # fmt: skip
    if integ.adjoint == "replay":
        return path_radiance_replay(scene, o, d, u, **kw)
    return path_radiance(scene, o, d, u, sampling=integ.sampling, **kw)


class PathIntegrator(Integrator):
    """Path tracing with next-event estimation, MIS and Russian roulette (:func:`path_radiance`).

    ``max_depth`` follows Mitsuba 3 (1: emitters only, 2: direct light, 3: one indirect
    bounce); Russian roulette starts after ``rr_depth`` bounces; ``strategy``: ``"mis"``,
    ``"light"`` or ``"bsdf"``. ``chunk`` (default 4096): wavefront shading, the rays of a
    pass sorted by material and shaded ``chunk`` at a time, skipping chunks without a live ray
    and materials a chunk does not hold; ``None``: every ray with every material (same values
    to float rounding; docs/render.md). ``adjoint``: how reverse mode differentiates it,
    ``"ad"`` (default; every parameter, forward mode too) or ``"replay"`` (path replay
    backpropagation: material, emitter, texture and environment parameters only, memory flat
    in depth; needs ``sampling="detached"``; docs/render_gradients.md). All static.

    >>> PathIntegrator(max_depth=3).random_shape
    (3, 7)
    """

    max_depth: int = eqx.field(static=True, default=3)
    rr_depth: int = eqx.field(static=True, default=5)
    strategy: str = eqx.field(static=True, default="mis")
    sampling: str = eqx.field(static=True, default="detached")
    chunk: int | None = eqx.field(static=True, default=4096)
    adjoint: str = eqx.field(static=True, default="ad")

    def __check_init__(self):
        check_depth("max_depth", self.max_depth)
        check_depth("rr_depth", self.rr_depth)
        _check_chunk(self.chunk)
        _check_strategy(self.strategy)
        C.check_sampling(self.sampling)
        _check_adjoint(self.adjoint, self.sampling)

    @property
    def random_shape(self):
        return (self.max_depth, N_RANDOM)

    @property
    def uniform_blocks(self) -> bool:
        """Whether ``u`` may be a :class:`~jaxgfx.render.sampler.UniformBlocks` (path replay:
        each bounce draws its numbers from the key, so memory does not grow with the depth)."""
        return self.adjoint == "replay"

    def __call__(self, scene, o, d, u):
        return _radiance(self, scene, o, d, u, self.max_depth)


class DirectIntegrator(Integrator):
    """Emitted plus direct light (a path of depth 2: :class:`PathIntegrator` with
    ``max_depth = 2``); ``strategy`` and ``adjoint`` as there; ``chunk`` as there, default
    ``None`` (most camera rays are live, so sorting them does not pay: measured 5–10 % slower).

    >>> DirectIntegrator().max_depth
    2
    """

    rr_depth: int = eqx.field(static=True, default=5)
    strategy: str = eqx.field(static=True, default="mis")
    sampling: str = eqx.field(static=True, default="detached")
    chunk: int | None = eqx.field(static=True, default=None)
    adjoint: str = eqx.field(static=True, default="ad")

    def __check_init__(self):
        check_depth("rr_depth", self.rr_depth)
        _check_chunk(self.chunk)
        _check_strategy(self.strategy)
        C.check_sampling(self.sampling)
        _check_adjoint(self.adjoint, self.sampling)

    @property
    def max_depth(self) -> int:
        return 2

    @property
    def random_shape(self):
        return (self.max_depth, N_RANDOM)

    @property
    def uniform_blocks(self) -> bool:
        """Whether ``u`` may be a :class:`~jaxgfx.render.sampler.UniformBlocks` (path replay:
        each bounce draws its numbers from the key, so memory does not grow with the depth)."""
        return self.adjoint == "replay"

    def __call__(self, scene, o, d, u):
        return _radiance(self, scene, o, d, u, 2)
