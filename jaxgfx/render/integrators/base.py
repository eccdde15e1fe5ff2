"""The :class:`Integrator` interface: an ``eqx.Module`` whose static fields are the options that
change the compiled program (depth, Russian roulette, sampling strategy)."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx

from jaxgfx._checks import check_positive_int

__all__ = ["Integrator", "N_RANDOM", "check_depth"]

N_RANDOM = 7  # uniform numbers per bounce: light select, light (2), bsdf lobe, bsdf (2), RR


def check_depth(name: str, v) -> None:
    """``ValueError`` naming ``name`` unless ``v`` is a positive Python integer."""
    check_positive_int(v, name)


class Integrator(eqx.Module):
    """An estimator of the radiance along camera rays.

    ``integrator(scene, o, d, u) -> (..., n_channels)`` for rays ``o, d (..., 3)`` and uniform
    numbers ``u (..., *random_shape)`` (``None`` when ``random_shape`` is ``None``). Every option
    is a static field, so two integrators with equal options share one compiled program in
    :func:`jaxgfx.render.render`; invariants are checked in ``__check_init__``.
    """

    n_channels: ClassVar[int] = 3

    @property
    def random_shape(self) -> tuple[int, ...] | None:
        """Shape of the uniform numbers one camera sample consumes (``None``: none)."""
        return None

    def __call__(self, scene, o, d, u):  # pragma: no cover - interface
        raise NotImplementedError
