"""Warps from the unit square ``[0, 1)²`` to common domains, with their pdfs and inverses.

Every ``square_to_X(u)`` takes uniform numbers ``u`` of shape ``(..., 2)`` (samplers never take
keys), ``square_to_X_pdf(v)`` is the density w.r.t. the natural measure of the target domain
(solid angle for directions, area for disks/triangles) and ``X_to_square(v)`` inverts the warp.
Conventions follow Mitsuba 3 (``mitsuba/core/warp.h``) and pbrt-v4 (chapter A.5).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp

from jaxgfx._checks import as_float_array
from jaxgfx._math import safe_div, safe_pow, safe_sqrt, sincos, sum_last

__all__ = [
    "square_to_uniform_disk_concentric",
    "square_to_uniform_disk_concentric_pdf",
    "uniform_disk_to_square_concentric",
    "square_to_uniform_sphere",
    "square_to_uniform_sphere_pdf",
    "uniform_sphere_to_square",
    "square_to_uniform_hemisphere",
    "square_to_uniform_hemisphere_pdf",
    "uniform_hemisphere_to_square",
    "square_to_cosine_hemisphere",
    "square_to_cosine_hemisphere_pdf",
    "cosine_hemisphere_to_square",
    "square_to_uniform_cone",
    "square_to_uniform_cone_pdf",
    "uniform_cone_to_square",
    "square_to_phong_lobe",
    "square_to_phong_lobe_pdf",
    "phong_lobe_to_square",
    "square_to_uniform_triangle",
    "square_to_uniform_triangle_pdf",
    "uniform_triangle_to_square",
    "Distribution2D",
]

_TWO_PI = 2.0 * math.pi
_INV_PI = 1.0 / math.pi
_QUARTER_PI = 0.25 * math.pi


def _u(u, name="u"):
    u = as_float_array(u, name)
    if u.shape[-1:] != (2,):
        raise ValueError(f"{name}: expected shape (..., 2), got {u.shape}")
    return u


def _phi01(x, y):
    """Azimuth mapped to [0, 1)."""
    phi = jnp.arctan2(y, x)
    phi = jnp.where(phi < 0, phi + _TWO_PI, phi)
    return phi / _TWO_PI


# ------------------------------------------------------------------ disk


def square_to_uniform_disk_concentric(u):
    """Shirley & Chiu (1997) concentric map ``[0,1)² -> unit disk`` (..., 2); pdf ``1/π``."""
    u = _u(u)
    x = 2.0 * u[..., 0] - 1.0
    y = 2.0 * u[..., 1] - 1.0
    first = jnp.abs(x) > jnp.abs(y)
    r = jnp.where(first, x, y)
    phi = jnp.where(
        first, _QUARTER_PI * safe_div(y, x), 0.5 * math.pi - _QUARTER_PI * safe_div(x, y)
    )
    sp, cp = sincos(phi)
    return jnp.stack([r * cp, r * sp], axis=-1)


def square_to_uniform_disk_concentric_pdf(p):
    """Area density of the concentric disk warp: ``1/π`` inside the unit disk, else 0."""
    p = jnp.asarray(p)
    inside = sum_last(p * p) <= 1.0
    return jnp.where(inside, _INV_PI, 0.0).astype(p.dtype)


def uniform_disk_to_square_concentric(p):
    """Inverse of :func:`square_to_uniform_disk_concentric`."""
    p = _u(p, "p")
    px, py = p[..., 0], p[..., 1]
    r = jnp.sqrt(px * px + py * py)
    first = jnp.abs(px) >= jnp.abs(py)
    a1 = jnp.where(px >= 0, r, -r)
    b1 = a1 * jnp.arctan(safe_div(py, px)) / _QUARTER_PI
    b2 = jnp.where(py >= 0, r, -r)
    a2 = b2 * jnp.arctan(safe_div(px, py)) / _QUARTER_PI
    a = jnp.where(first, a1, a2)
    b = jnp.where(first, b1, b2)
    return jnp.stack([0.5 * (a + 1.0), 0.5 * (b + 1.0)], axis=-1)


# ------------------------------------------------------------------ sphere / hemisphere


def _z_phi_to_dir(z, u1):
    r = safe_sqrt(1.0 - z * z)
    phi = _TWO_PI * u1
    sp, cp = sincos(phi)
    return jnp.stack([r * cp, r * sp, z], axis=-1)


def square_to_uniform_sphere(u):
    """Uniform direction on the unit sphere (..., 3); pdf ``1/(4π)`` sr⁻¹."""
    u = _u(u)
    return _z_phi_to_dir(1.0 - 2.0 * u[..., 0], u[..., 1])


def square_to_uniform_sphere_pdf(v):
    """Solid-angle density ``1/(4π)``."""
    v = jnp.asarray(v)
    return jnp.full(v.shape[:-1], 0.25 * _INV_PI, dtype=v.dtype)


def uniform_sphere_to_square(v):
    """Inverse of :func:`square_to_uniform_sphere`."""
    v = jnp.asarray(v)
    return jnp.stack([0.5 * (1.0 - v[..., 2]), _phi01(v[..., 0], v[..., 1])], axis=-1)


def square_to_uniform_hemisphere(u):
    """Uniform direction on the ``+z`` hemisphere (..., 3); pdf ``1/(2π)`` sr⁻¹."""
    u = _u(u)
    return _z_phi_to_dir(u[..., 0], u[..., 1])


def square_to_uniform_hemisphere_pdf(v):
    """``1/(2π)`` for ``v_z >= 0``, else 0."""
    v = jnp.asarray(v)
    return jnp.where(v[..., 2] >= 0, 0.5 * _INV_PI, 0.0).astype(v.dtype)


def uniform_hemisphere_to_square(v):
    """Inverse of :func:`square_to_uniform_hemisphere`."""
    v = jnp.asarray(v)
    return jnp.stack([v[..., 2], _phi01(v[..., 0], v[..., 1])], axis=-1)


def square_to_cosine_hemisphere(u):
    """Cosine-weighted hemisphere (Malley's method on the concentric disk); pdf ``cos θ / π``."""
    p = square_to_uniform_disk_concentric(u)
    z = safe_sqrt(1.0 - sum_last(p * p))
    return jnp.concatenate([p, z[..., None]], axis=-1)


def square_to_cosine_hemisphere_pdf(v):
    """``max(cos θ, 0) / π``."""
    v = jnp.asarray(v)
    return jnp.maximum(v[..., 2], 0.0) * _INV_PI


def cosine_hemisphere_to_square(v):
    """Inverse of :func:`square_to_cosine_hemisphere`."""
    v = jnp.asarray(v)
    return uniform_disk_to_square_concentric(v[..., :2])


# ------------------------------------------------------------------ cone / Phong lobe


def square_to_uniform_cone(u, cos_cutoff):
    """Uniform direction in the cone ``cos θ >= cos_cutoff`` around ``+z``.

    pdf ``1 / (2π (1 - cos_cutoff))``. ``cos_cutoff`` in ``[-1, 1)``.
    """
    u = _u(u)
    z = (1.0 - u[..., 0]) + u[..., 0] * cos_cutoff
    return _z_phi_to_dir(z, u[..., 1])


def square_to_uniform_cone_pdf(v, cos_cutoff):
    """Solid-angle density of :func:`square_to_uniform_cone`."""
    v = jnp.asarray(v)
    val = 1.0 / (_TWO_PI * (1.0 - cos_cutoff))
    return jnp.where(v[..., 2] >= cos_cutoff, val, 0.0).astype(v.dtype)


def uniform_cone_to_square(v, cos_cutoff):
    """Inverse of :func:`square_to_uniform_cone`."""
    v = jnp.asarray(v)
    u0 = (1.0 - v[..., 2]) / (1.0 - cos_cutoff)
    return jnp.stack([u0, _phi01(v[..., 0], v[..., 1])], axis=-1)


def square_to_phong_lobe(u, exponent):
    """Direction with density ``(n+1)/(2π) cos^n θ`` around ``+z`` (Phong lobe, exponent n>=0).

    ``cos θ = u₀^(1/(n+1))``, ``φ = 2π u₁`` (Lafortune & Willems 1994).
    """
    u = _u(u)
    z = safe_pow(u[..., 0], 1.0 / (exponent + 1.0))
    return _z_phi_to_dir(z, u[..., 1])


def square_to_phong_lobe_pdf(v, exponent):
    """``(n+1)/(2π) max(cos θ, 0)^n``."""
    v = jnp.asarray(v)
    return (exponent + 1.0) / _TWO_PI * safe_pow(v[..., 2], exponent)


def phong_lobe_to_square(v, exponent):
    """Inverse of :func:`square_to_phong_lobe`."""
    v = jnp.asarray(v)
    return jnp.stack([safe_pow(v[..., 2], exponent + 1.0), _phi01(v[..., 0], v[..., 1])], axis=-1)


# ------------------------------------------------------------------ triangle


def square_to_uniform_triangle(u):
    """Uniform barycentrics ``(b1, b2)`` on the triangle ``b1, b2 >= 0, b1 + b2 <= 1``.

    Square-root form (Shirley & Wang; pbrt-v3 ``UniformSampleTriangle``):
    ``t = sqrt(u₀), b1 = 1 - t, b2 = u₁ t``. Density ``2`` w.r.t. area in barycentric space.
    """
    u = _u(u)
    t = safe_sqrt(u[..., 0])
    return jnp.stack([1.0 - t, u[..., 1] * t], axis=-1)


def square_to_uniform_triangle_pdf(b):
    """``2`` inside the reference triangle, else 0."""
    b = jnp.asarray(b)
    inside = (b[..., 0] >= 0) & (b[..., 1] >= 0) & (b[..., 0] + b[..., 1] <= 1.0)
    return jnp.where(inside, 2.0, 0.0).astype(b.dtype)


def uniform_triangle_to_square(b):
    """Inverse of :func:`square_to_uniform_triangle`."""
    b = jnp.asarray(b)
    t = 1.0 - b[..., 0]
    return jnp.stack([t * t, safe_div(b[..., 1], t)], axis=-1)


# ------------------------------------------------------------------ 2-D discrete


class Distribution2D(eqx.Module):
    """Piecewise-constant 2-D density on ``[0,1]²`` proportional to a non-negative image.

    Built from weights ``(H, W)`` (e.g. an environment map's luminance × sin θ): samples a row
    from the marginal, then a column from that row's conditional, then a uniform position in the
    texel (pbrt-v3 ``Distribution2D``). ``uv = (u, v)``: ``u`` runs along the width (columns),
    ``v`` along the height (rows, 0 = first row). The pdf is w.r.t. area on ``[0,1]²``:
    ``pdf(uv) = weight[row, col] * H * W / sum(weight)``.

    Fully jittable (``jnp.cumsum`` / ``jnp.searchsorted``). An all-zero image becomes uniform.

    Example: weights ``[[1, 3]]`` give ``pdf((0.75, 0.5)) = 1.5``.
    """

    marginal_cdf: jnp.ndarray  # (H + 1,)
    conditional_cdf: jnp.ndarray  # (H, W + 1)
    weights: jnp.ndarray  # (H, W), normalised to mean 1 (= pdf values)

    def __init__(self, weights):
        w = as_float_array(weights, "weights")
        if w.ndim != 2 or w.size == 0:
            raise ValueError(f"weights: expected a non-empty (H, W) array, got shape {w.shape}")
        from jaxgfx._checks import check_finite, is_concrete

        check_finite(w, "weights")
        if is_concrete(w) and bool(jnp.any(w < 0)):
            raise ValueError("weights: expected non-negative values")
        w = jnp.maximum(w, 0.0)
        total = jnp.sum(w)
        w = jnp.where(total > 0, w, jnp.ones_like(w))
        h, wd = w.shape
        row_sum = jnp.sum(w, axis=1)
        zeros_row = row_sum == 0
        w_rows = jnp.where(zeros_row[:, None], 1.0, w)
        csum = jnp.cumsum(w_rows, axis=1)
        cond = csum / csum[:, -1:]
        self.conditional_cdf = jnp.concatenate([jnp.zeros((h, 1), w.dtype), cond], axis=1)
        msum = jnp.cumsum(row_sum)
        self.marginal_cdf = jnp.concatenate([jnp.zeros((1,), w.dtype), msum / msum[-1]])
        self.weights = w * (h * wd) / jnp.sum(w)

    @property
    def shape(self):
        return self.weights.shape

    def sample(self, u):
        """Map ``u`` (..., 2) to ``(uv (..., 2), pdf (...))``."""
        u = _u(u)
        h, w = self.weights.shape
        u0 = jnp.clip(u[..., 1], 0.0, 1.0)
        row = jnp.clip(jnp.searchsorted(self.marginal_cdf, u0, side="right") - 1, 0, h - 1)
        c0, c1 = self.marginal_cdf[row], self.marginal_cdf[row + 1]
        dv = safe_div(u0 - c0, c1 - c0, fill=0.5)
        cdf_row = self.conditional_cdf[row]  # (..., W + 1)
        u1 = jnp.clip(u[..., 0], 0.0, 1.0)
        col = jnp.sum(cdf_row[..., 1:-1] <= u1[..., None], axis=-1)
        col = jnp.clip(col, 0, w - 1)
        d0 = jnp.take_along_axis(cdf_row, col[..., None], axis=-1)[..., 0]
        d1 = jnp.take_along_axis(cdf_row, col[..., None] + 1, axis=-1)[..., 0]
        du = safe_div(u1 - d0, d1 - d0, fill=0.5)
        uv = jnp.stack([(col + du) / w, (row + dv) / h], axis=-1)
        return uv, self.weights[row, col]

    def pdf(self, uv):
        """Area density on ``[0,1]²`` at ``uv`` (..., 2); 0 outside the square."""
        uv = jnp.asarray(uv)
        h, w = self.weights.shape
        inside = jnp.all((uv >= 0) & (uv <= 1), axis=-1)
        col = jnp.clip(jnp.floor(uv[..., 0] * w).astype(jnp.int32), 0, w - 1)
        row = jnp.clip(jnp.floor(uv[..., 1] * h).astype(jnp.int32), 0, h - 1)
        return jnp.where(inside, self.weights[row, col], 0.0)

    def invert(self, uv):
        """Inverse of :meth:`sample`: ``uv`` (..., 2) -> uniform numbers ``u`` (..., 2)."""
        uv = jnp.asarray(uv)
        h, w = self.weights.shape
        col = jnp.clip(jnp.floor(uv[..., 0] * w).astype(jnp.int32), 0, w - 1)
        row = jnp.clip(jnp.floor(uv[..., 1] * h).astype(jnp.int32), 0, h - 1)
        dv = uv[..., 1] * h - row
        du = uv[..., 0] * w - col
        c0, c1 = self.marginal_cdf[row], self.marginal_cdf[row + 1]
        d0 = self.conditional_cdf[row, col]
        d1 = self.conditional_cdf[row, col + 1]
        return jnp.stack([d0 + du * (d1 - d0), c0 + dv * (c1 - c0)], axis=-1)
