"""Local shading frames (normal = +z) and spherical-coordinate helpers.

Conventions follow Mitsuba 3: in the local frame the shading normal is ``+z``; directions are
unit vectors pointing *away* from the surface; ``cos_theta(w) = w[..., 2]``.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._math import safe_div, safe_sqrt, sum_last

__all__ = [
    "Frame",
    "frame_from_normal",
    "to_local",
    "to_world",
    "cos_theta",
    "cos2_theta",
    "sin_theta",
    "sin2_theta",
    "tan_theta",
    "tan2_theta",
    "sincos_phi",
    "reflect",
    "dot",
]


def dot(a, b):
    """Dot product over the last axis: ``(..., 3), (..., 3) -> (...)``."""
    return sum_last(a * b)


class Frame(eqx.Module):
    """Orthonormal frame ``(s, t, n)``; each field has shape ``(..., 3)``."""

    s: jnp.ndarray
    t: jnp.ndarray
    n: jnp.ndarray


def frame_from_normal(n) -> Frame:
    """Right-handed orthonormal basis ``(s, t, n)`` around a unit normal ``n`` (..., 3).

    Branchless construction of Duff, Burgess, Christensen, Hery, Kensler, Liani, Villemin,
    "Building an Orthonormal Basis, Revisited", JCGT 6(1), 2017. Continuous everywhere except
    across ``n_z = 0`` (where the sign flips); finite gradients everywhere (``|sign + n_z| >= 1``).

    Example: ``frame_from_normal(jnp.array([0., 0., 1.])).s`` is ``[1, 0, 0]``.
    """
    n = jnp.asarray(n)
    if not jnp.issubdtype(n.dtype, jnp.floating):
        n = n.astype(jnp.float32)
    if n.shape[-1:] != (3,):
        raise ValueError(f"n: expected shape (..., 3), got {n.shape}")
    s, t = _basis(n, jnp)
    return Frame(s=s, t=t, n=n)


def _basis(n, xp):
    """The ``(s, t)`` of :func:`frame_from_normal` with array module ``xp`` (jnp, or np for
    a scene description's constants: nothing to compile)."""
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    sign = xp.where(z >= 0, 1.0, -1.0).astype(n.dtype)
    a = -1.0 / (sign + z)
    b = x * y * a
    s = xp.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=-1)
    t = xp.stack([b, sign + y * y * a, -y], axis=-1)
    return s, t


def host_basis(n):
    """:func:`frame_from_normal`'s ``(s, t)`` of a NumPy normal ``n`` (..., 3), in NumPy."""
    n = np.asarray(n)
    return _basis(n, np)


def to_local(frame: Frame, v):
    """World vector ``v`` (..., 3) expressed in ``frame`` (normal becomes ``+z``)."""
    return jnp.stack([dot(v, frame.s), dot(v, frame.t), dot(v, frame.n)], axis=-1)


def to_world(frame: Frame, v):
    """Local vector ``v`` (..., 3) expressed in world coordinates."""
    return v[..., 0:1] * frame.s + v[..., 1:2] * frame.t + v[..., 2:3] * frame.n


def rotation_to_local(to_world, d):
    """World direction(s) ``d (..., 3)`` -> the frame of an environment emitter's rotation
    ``to_world (3, 3)`` (``to_world^T d``); ``d`` itself when ``to_world`` is None. The rotation
    is a fixed placement: no derivative flows into it."""
    if to_world is None:
        return d
    return d @ jax.lax.stop_gradient(to_world).astype(d.dtype)


def rotation_to_world(to_world, d):
    """The inverse of :func:`rotation_to_local` (``to_world d``)."""
    if to_world is None:
        return d
    return d @ jax.lax.stop_gradient(to_world).astype(d.dtype).T


def cos_theta(w):
    """``cos θ`` of a local direction: ``w[..., 2]``."""
    return w[..., 2]


def cos2_theta(w):
    """``cos² θ``."""
    return w[..., 2] * w[..., 2]


def sin2_theta(w):
    """``sin² θ = x² + y²`` (exact for unit vectors, no cancellation near the pole)."""
    return w[..., 0] * w[..., 0] + w[..., 1] * w[..., 1]


def sin_theta(w):
    """``sin θ`` (>= 0), with a finite gradient at the pole."""
    return safe_sqrt(sin2_theta(w))


def tan2_theta(w):
    """``tan² θ``; 0 where ``cos θ = 0`` (caller handles grazing directions)."""
    return safe_div(sin2_theta(w), cos2_theta(w))


def tan_theta(w):
    """``tan θ`` (signed like ``cos θ``); 0 where ``cos θ = 0``."""
    return safe_div(sin_theta(w), cos_theta(w))


def sincos_phi(w):
    """``(sin φ, cos φ)`` of a local direction; ``(0, 1)`` at the pole."""
    st = sin_theta(w)
    pole = st == 0
    st_safe = jnp.where(pole, 1.0, st)
    sp = jnp.where(pole, 0.0, jnp.clip(w[..., 1] / st_safe, -1.0, 1.0))
    cp = jnp.where(pole, 1.0, jnp.clip(w[..., 0] / st_safe, -1.0, 1.0))
    return sp, cp


def reflect(w, m=None):
    """Mirror ``w`` about ``m`` (default: the normal ``+z``): ``2 (w·m) m - w``."""
    if m is None:
        return jnp.stack([-w[..., 0], -w[..., 1], w[..., 2]], axis=-1)
    return 2.0 * dot(w, m)[..., None] * m - w
