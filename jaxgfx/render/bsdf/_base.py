"""Shared BSDF interface: :class:`BSDFSample`, the :class:`BSDF` base and parameter helpers."""

from __future__ import annotations

import math
from typing import ClassVar, NamedTuple

import equinox as eqx
import jax.numpy as jnp

from jaxgfx._checks import as_float_array, check_finite, check_nonnegative

__all__ = ["BSDF", "BSDFSample"]

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

    def eval(self, wo, wi):  # pragma: no cover - interface
        raise NotImplementedError

    def pdf(self, wo, wi):  # pragma: no cover - interface
        raise NotImplementedError

    def sample(self, wo, u1, u2) -> BSDFSample:  # pragma: no cover - interface
        raise NotImplementedError

    @property
    def albedo(self):  # pragma: no cover - interface
        raise NotImplementedError


def rgb_param(x, name, *, nonnegative=True):
    """Parameter as an RGB array ``(..., 3)``; a scalar is broadcast to 3 channels."""
    arr = as_float_array(x, name)
    check_finite(arr, name)
    if nonnegative:
        check_nonnegative(arr, name)
    if arr.ndim == 0:
        arr = jnp.broadcast_to(arr, (3,))
    elif arr.shape[-1] not in (1, 3):
        raise ValueError(f"{name}: expected a scalar or an RGB array (..., 3), got {arr.shape}")
    elif arr.shape[-1] == 1:
        arr = jnp.broadcast_to(arr, arr.shape[:-1] + (3,))
    return arr


def scalar_param(x, name):
    """Parameter as a float array (scalar or batch-shaped), checked finite."""
    arr = as_float_array(x, name)
    check_finite(arr, name)
    return arr


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
