"""Shared BSDF interface: :class:`BSDFSample`, the :class:`BSDF` base and parameter helpers."""

from __future__ import annotations

import functools
import math
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import (
    as_float_array,
    check_finite,
    check_nonnegative,
    check_positive,
    host_float_array,
)

__all__ = [
    "BSDF",
    "BSDFSample",
    "DeltaBSDF",
    "to_rgb",
    "rgb_param",
    "scalar_param",
    "rgb_field",
    "float_field",
    "check_rgb",
    "check_scalar",
    "sample_setup",
    "glossy_sample",
]

INV_PI = 1.0 / math.pi


class BSDFSample(NamedTuple):
    """Result of ``BSDF.sample``; every field broadcasts over the batch shape ``(...)``.

    ``wi`` (..., 3) sampled local direction (unit, pointing away from the surface);
    ``pdf`` (...) its solid-angle density (for a delta lobe: the discrete lobe probability);
    ``weight`` (..., 3) throughput ``eval / pdf`` (delta lobes: the throughput directly; 0 for a
    failed sample); ``is_delta`` (...) bool; ``eta`` (...) relative IOR crossed (1 for reflection).
    """

    wi: jnp.ndarray
    pdf: jnp.ndarray
    weight: jnp.ndarray
    is_delta: jnp.ndarray
    eta: jnp.ndarray


class WrapsBSDF(eqx.Module):
    """A module around one nested ``bsdf`` (textured materials, normal / bump maps): its
    ``has_delta`` and ``is_transmissive`` are the nested BSDF's."""

    @property
    def has_delta(self):
        return self.bsdf.has_delta

    @property
    def is_transmissive(self):
        return self.bsdf.is_transmissive


class BSDF(eqx.Module):
    """Interface every jaxgfx BSDF implements (local frame, normal ``+z``, Mitsuba conventions).

    * ``eval(wo, wi) -> (..., 3)``: ``f(wo, wi) |cos θ_i|`` (0 for delta lobes),
    * ``pdf(wo, wi) -> (...)``: solid-angle density of ``sample``,
    * ``sample(wo, u1, u2) -> BSDFSample`` with ``u1`` (...) and ``u2`` (..., 2) uniform,
    * ``albedo`` (3,) or (..., 3): a diffuse-like colour for AOVs,
    * class flags ``has_delta`` and ``is_transmissive``.
    """

    has_delta: ClassVar[bool] = False
    is_transmissive: ClassVar[bool] = False
    PARAMETER_ALIASES: ClassVar[dict[str, tuple[str, ...]]] = {}
    """Description keys that are not attribute names -> the dotted attribute paths they set
    (see :mod:`jaxgfx.render.parameters`)."""

    def eval(self, wo, wi):  # pragma: no cover - interface
        raise NotImplementedError

    def pdf(self, wo, wi):  # pragma: no cover - interface
        raise NotImplementedError

    def sample(self, wo, u1, u2) -> BSDFSample:  # pragma: no cover - interface
        raise NotImplementedError

    @property
    def albedo(self):  # pragma: no cover - interface
        raise NotImplementedError


class DeltaBSDF(BSDF):
    """Base of the BSDFs made of delta lobes only (``Mirror``, the smooth and thin dielectrics,
    the pass-through polarizers): ``eval`` (..., 3) and ``pdf`` (...) are 0 for every pair of
    directions, and ``has_delta`` is true; subclasses define ``sample`` and ``albedo``.
    ``eval``'s zeros take the dtype of ``wo``, ``wi`` and the field named by ``EVAL_DTYPE_OF``;
    ``pdf``'s that of ``wo``, ``wi``."""

    has_delta: ClassVar[bool] = True
    EVAL_DTYPE_OF: ClassVar[str]

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        shape = jnp.broadcast_shapes(wo.shape, wi.shape)
        return jnp.zeros(shape, jnp.result_type(wo, wi, getattr(self, self.EVAL_DTYPE_OF)))

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        return jnp.zeros(jnp.broadcast_shapes(wo.shape, wi.shape)[:-1], jnp.result_type(wo, wi))


def to_rgb(x, name):
    """Parameter as an RGB array ``(..., 3)`` (conversion only; a scalar or a last axis of 1 is
    broadcast to 3 channels). ``TypeError`` / ``ValueError`` naming ``name`` for non-numbers or
    other shapes; values are checked by :func:`check_rgb`."""
    host = host_float_array(x, name)  # host data is broadcast by NumPy: nothing to compile
    arr, xp = (host, np) if host is not None else (as_float_array(x, name), jnp)
    if arr.ndim == 0:
        arr = xp.broadcast_to(arr, (3,))
    elif arr.shape[-1] not in (1, 3):
        raise ValueError(f"{name}: expected a scalar or an RGB array (..., 3), got {arr.shape}")
    elif arr.shape[-1] == 1:
        arr = xp.broadcast_to(arr, arr.shape[:-1] + (3,))
    return jax.device_put(np.ascontiguousarray(arr)) if host is not None else arr


def rgb_param(x, name, *, nonnegative=True):
    """Parameter as an RGB array ``(..., 3)``; a scalar is broadcast to 3 channels. Checked
    finite (and >= 0 unless ``nonnegative=False``) when concrete."""
    arr = as_float_array(x, name)
    check_finite(arr, name)
    if nonnegative:
        check_nonnegative(arr, name)
    return to_rgb(arr, name)


def scalar_param(x, name):
    """Parameter as a float array (scalar or batch-shaped), checked finite."""
    arr = as_float_array(x, name)
    check_finite(arr, name)
    return arr


def rgb_field(default, name, **kwargs):
    """An ``eqx.field`` holding an RGB parameter: converted by :func:`to_rgb` on construction;
    validate it with :func:`check_rgb` in ``__check_init__``."""
    return eqx.field(default=default, converter=functools.partial(to_rgb, name=name), **kwargs)


def float_field(default, name, **kwargs):
    """An ``eqx.field`` holding a float parameter (scalar or batch-shaped), converted by
    ``as_float_array``; validate it with :func:`check_scalar` in ``__check_init__``."""
    return eqx.field(
        default=default, converter=functools.partial(as_float_array, name=name), **kwargs
    )


def batch_dtype(*xs):
    return jnp.result_type(*xs, 1.0)


def prep_dirs(wo, wi=None):
    """Validate directions at the Python boundary (static shape only)."""
    wo = as_float_array(wo, "wo")
    if wo.shape[-1:] != (3,):
        raise ValueError(f"wo: expected shape (..., 3), got {wo.shape}")
    if wi is None:
        return wo
    wi = as_float_array(wi, "wi")
    if wi.shape[-1:] != (3,):
        raise ValueError(f"wi: expected shape (..., 3), got {wi.shape}")
    return wo, wi


def prep_u(u1, u2):
    u1 = as_float_array(u1, "u1")
    u2 = as_float_array(u2, "u2")
    if u2.shape[-1:] != (2,):
        raise ValueError(f"u2: expected shape (..., 2), got {u2.shape}")
    return u1, u2


def mask3(valid, x):
    """``where(valid[..., None], x, 0)`` broadcasting ``x`` to (..., 3)."""
    return jnp.where(valid[..., None], x, 0.0)


def check_rgb(x, name, *, nonnegative=True):
    """``__check_init__`` half of :func:`rgb_param`: a concrete RGB parameter must be finite
    (and >= 0 unless ``nonnegative=False``) with a last axis of 3; tracers pass."""
    check_finite(x, name)
    if nonnegative:
        check_nonnegative(x, name)
    if jnp.ndim(x) == 0 or jnp.shape(x)[-1] != 3:
        raise ValueError(f"{name}: expected a scalar or an RGB array (..., 3), got {jnp.shape(x)}")


def check_scalar(x, name, *, positive=False):
    """``__check_init__`` half of :func:`scalar_param`: finite (and > 0 if ``positive``)."""
    check_finite(x, name)
    if positive:
        check_positive(x, name)


def sample_setup(wo, u1, u2):
    """The common start of ``BSDF.sample``: validate ``wo (..., 3)``, ``u1 (...)``,
    ``u2 (..., 2)``, broadcast ``wo`` to the batch shape; returns ``(wo, u1, u2, shape)``."""
    wo = prep_dirs(wo)
    u1, u2 = prep_u(u1, u2)
    shape = jnp.broadcast_shapes(wo.shape[:-1], u1.shape, u2.shape[:-1])
    wo = jnp.broadcast_to(wo, shape + (3,))
    return wo, u1, u2, shape


def glossy_sample(wi, pdf, weight, valid, shape, dtype) -> BSDFSample:
    """The common end of a non-delta ``BSDF.sample``: ``pdf`` and ``weight`` zeroed where not
    ``valid``, ``is_delta = False``, ``eta = 1`` (reflection)."""
    return BSDFSample(
        wi=wi,
        pdf=jnp.where(valid, pdf, 0.0),
        weight=mask3(valid, weight),
        is_delta=jnp.zeros(shape, bool),
        eta=jnp.ones(shape, dtype),
    )
