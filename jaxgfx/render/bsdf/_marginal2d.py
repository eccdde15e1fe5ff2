"""Mitsuba 3's continuous ``Marginal2D`` warp in JAX (``include/mitsuba/core/distr_2d.h``).

A density on the unit square that interpolates an ``(h, w)`` grid bilinearly (``x`` along the
last axis, ``w`` columns), optionally one slice per node of a grid of parameters, linearly
interpolated in the parameters. Sampling inverts the marginal distribution of ``y`` (the
integral of each row, linear between rows) then the conditional of ``x`` given ``y`` (linear
between columns); both steps solve a quadratic per patch (``sample_segment``), so the warp
is continuous. ``invert`` is the exact inverse of ``sample``; ``eval`` the bilinear value.

Tables are built on the host (NumPy, sums in float64 as Mitsuba's constructor) by
:func:`build_warp`; the warp functions are pure JAX, vectorised over any batch shape, with the
slices given by :func:`param_corners` (a list of ``(slice index, weight)``).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxgfx._math import safe_div, safe_sqrt

__all__ = ["Warp2D", "build_warp", "param_corners", "bilinear", "warp_eval", "warp_sample",
           "warp_invert"]

_EPS32 = 2.0**-24  # dr::Epsilon<float>


class Warp2D(eqx.Module):
    """Tables of one warp: ``data`` (S, h, w) (normalised per slice when built with
    ``normalize``), ``cond`` (S, h, w - 1) the cumulative integrals of each row along ``x``,
    ``marg`` (S, h - 1) the cumulative integral over rows. ``S`` = number of parameter slices.
    Without sampling tables (``cond`` and ``marg`` ``None``) only :func:`warp_eval` works."""

    data: jnp.ndarray
    cond: jnp.ndarray | None = None
    marg: jnp.ndarray | None = None

    @property
    def size(self):
        return self.data.shape[-1], self.data.shape[-2]  # (w, h) as Mitsuba's m_size


def build_warp(data, *, normalize=True, sampling=True, dtype=jnp.float32) -> Warp2D:
    """A :class:`Warp2D` from ``data`` (S, h, w) (or (h, w): one slice), h, w >= 2: with
    ``sampling`` the continuous conditional / marginal CDFs (trapezoid sums in float64, as
    Mitsuba) and, with ``normalize``, every slice scaled to integrate to 1 over the square."""
    d = np.asarray(data, np.float64)
    if d.ndim == 2:
        d = d[None]
    s, h, w = d.shape
    if h < 2 or w < 2:
        raise ValueError(f"data: resolution must be >= 2 along both axes, got {(h, w)}")
    if not sampling:
        if normalize:
            tot = 0.25 * (d[:, :-1, :-1] + d[:, :-1, 1:] + d[:, 1:, :-1] + d[:, 1:, 1:])
            d = d / (tot.sum(axis=(1, 2)) / ((h - 1) * (w - 1)))[:, None, None]
        return Warp2D(jnp.asarray(d, dtype))
    sx, sy = 0.5 / (w - 1), 0.5 / (h - 1)
    cond = np.cumsum(sx * (d[:, :, :-1] + d[:, :, 1:]), axis=2)  # (S, h, w-1)
    rows = cond[:, :, -1]
    marg = np.cumsum(sy * (rows[:, :-1] + rows[:, 1:]), axis=1)  # (S, h-1)
    if normalize:
        norm = 1.0 / marg[:, -1]
        cond, marg, d = cond * norm[:, None, None], marg * norm[:, None], d * norm[:, None, None]
    # Mitsuba stores float32 tables (its sums are double, the stored values float)
    f32 = lambda a: np.asarray(a, np.float32)  # noqa: E731
    return Warp2D(jnp.asarray(f32(d), dtype), jnp.asarray(f32(cond), dtype),
                  jnp.asarray(f32(marg), dtype))  # fmt: skip


def param_corners(params, values):
    """Slices and weights of a point ``params`` (a list of (...) arrays, one per parameter
    axis) on the grid ``values`` (a list of 1-D arrays; the slices are C-ordered over them, the
    last axis fastest): a list of ``(slice index, weight)`` with ``2^k`` entries for the ``k``
    axes of more than one node (Mitsuba's ``interpolate_weights``: the interval by binary
    search, weights clipped to [0, 1], i.e. clamped outside the grid)."""
    corners = [(0, 1.0)]
    stride = 1
    for x, v in reversed(list(zip(params, values, strict=True))):
        n = v.shape[0]
        if n == 1:
            continue
        idx = jnp.sum(v[1:-1] < x[..., None], axis=-1)  # find_interval: in [0, n - 2]
        p0, p1 = v[idx], v[idx + 1]
        w1 = jnp.clip((x - p0) / (p1 - p0), 0.0, 1.0)
        new = []
        for s, w in corners:
            new.append((s + stride * idx, w * (1.0 - w1)))
            new.append((s + stride * (idx + 1), w * w1))
        corners = new
        stride *= n
    return corners


def _rows(table, corners, idx=None):
    """``Σ weight · table[slice, idx]`` over the parameter corners: ``table`` (S, R, ...) with
    ``idx`` (...) a row index -> (..., *rest); ``table`` (S, N) without ``idx`` -> (..., N).
    (One gather of a whole row per corner: Mitsuba looks up single entries inside its binary
    searches; the rows are the same numbers, and a far smaller program.)"""
    out = 0.0
    for s, w in corners:
        v = table[s] if idx is None else table[s, idx]
        w = jnp.asarray(w)
        out = out + w.reshape(w.shape + (1,) * (v.ndim - w.ndim)) * v
    return out


def _at(row, i):
    """``row[..., i]`` for an index array ``i`` (...) (a one-hot sum: elementwise ops that
    fuse, a smaller program than a gather)."""
    hit = jnp.arange(row.shape[-1], dtype=jnp.int32) == i[..., None]
    return jnp.sum(jnp.where(hit, row, 0.0), axis=-1)


def _count_below(row, x):
    """drjit's ``binary_search`` over a nondecreasing ``row``: the number of entries < x."""
    return jnp.sum(row < x[..., None], axis=-1).astype(jnp.int32)


def _cell(pos, w, h):
    """Patch index ``(ox, oy)`` and position inside it of a point of the unit square (clipped),
    as Mitsuba's ``eval`` / ``invert``."""
    p = jnp.clip(pos, 0.0, 1.0) * jnp.asarray([w - 1, h - 1], pos.dtype)
    ox = jnp.minimum(p[..., 0].astype(jnp.int32), w - 2)
    oy = jnp.minimum(p[..., 1].astype(jnp.int32), h - 2)
    return ox, oy, p[..., 0] - ox, p[..., 1] - oy


def bilinear(table, pos, corners=((0, 1.0),)):
    """Bilinear value at ``pos`` (..., 2) of ``table`` (S, h, w) -> (...) or (S, C, h, w) ->
    (..., C), interpolated over the parameter ``corners`` (Mitsuba's ``Marginal2D::eval``)."""
    h, w = table.shape[-2:]
    ox, oy, fx, fy = _cell(pos, w, h)
    if table.ndim == 4:  # channels: rows (..., C, w)
        a = _rows(jnp.moveaxis(table, 2, 1), corners, oy)
        b = _rows(jnp.moveaxis(table, 2, 1), corners, oy + 1)

        def take(r, i):
            return _at(r, i[..., None])

        fx, fy = fx[..., None], fy[..., None]
    else:
        a, b = _rows(table, corners, oy), _rows(table, corners, oy + 1)
        take = _at
    v00, v10, v01, v11 = take(a, ox), take(a, ox + 1), take(b, ox), take(b, ox + 1)
    return _lerp(_lerp(v00, v10, fx), _lerp(v01, v11, fx), fy)


def warp_eval(warp: Warp2D, pos, corners=((0, 1.0),)):
    """Bilinear value of the (normalised) data at ``pos`` (..., 2) in the unit square
    (clipped to it), interpolated over the parameter ``corners``."""
    return bilinear(warp.data, pos, corners)


def _lerp(a, b, t):
    return a + (b - a) * t


def _sample_segment(u, inv_width, v0, v1):
    """Position in [0, 1] of a patch where the integral of ``lerp(v0, v1, t)`` reaches ``u``
    (Mitsuba's ``sample_segment``; linear when ``v0 ≈ v1``)."""
    non_const = jnp.abs(v0 - v1) > 1e-4 * (v0 + v1)
    divisor = jnp.where(non_const, v0 - v1, v0 + v1)
    u = u * (2.0 * inv_width)
    u = jnp.where(non_const, v0 - safe_sqrt(v0 * v0 + u * (v1 - v0)), u)
    return jnp.where(divisor != 0, safe_div(u, divisor), u)


def _invert_segment(u, width, v0, v1):
    return u * _lerp(v0, v1, 0.5 * u) * width


def warp_sample(warp: Warp2D, u, corners=((0, 1.0),)):
    """Mitsuba's ``Marginal2D::sample_continuous``: ``u`` (..., 2) uniform -> ``(point (..., 2),
    density)`` (normalised tables)."""
    w, h = warp.size
    u = jnp.clip(u, _EPS32, 1.0 - _EPS32)
    ux, uy = u[..., 0], u[..., 1]
    marg = jnp.broadcast_to(_rows(warp.marg, corners), uy.shape + (h - 1,))
    row = jnp.minimum(_count_below(marg, uy), h - 2)
    uy = uy - jnp.where(row > 0, _at(marg, jnp.maximum(row - 1, 0)), 0.0)
    ca, cb = _rows(warp.cond, corners, row), _rows(warp.cond, corners, row + 1)  # (..., w-1)
    r0, r1 = ca[..., -1], cb[..., -1]
    y = _sample_segment(uy, h - 1, r0, r1)
    ux = ux * _lerp(r0, r1, y)
    cc = _lerp(ca, cb, y[..., None])
    # drjit searches [0, w - 1]; index w - 1 (past the row) is only reached by round-off
    col = jnp.minimum(_count_below(cc, ux), w - 2)
    ux = ux - jnp.where(col > 0, _at(cc, jnp.maximum(col - 1, 0)), 0.0)
    da, db = _rows(warp.data, corners, row), _rows(warp.data, corners, row + 1)
    c0 = _lerp(_at(da, col), _at(db, col), y)
    c1 = _lerp(_at(da, col + 1), _at(db, col + 1), y)
    x = _sample_segment(ux, w - 1, c0, c1)
    pt = jnp.stack([(col + x) / (w - 1), (row + y) / (h - 1)], axis=-1)
    return pt, _lerp(c0, c1, x)


def warp_invert(warp: Warp2D, pt, corners=((0, 1.0),)):
    """Mitsuba's ``Marginal2D::invert_continuous``: a point (..., 2) -> ``(u (..., 2),
    density)``, the inverse of :func:`warp_sample`."""
    w, h = warp.size
    px, py, x, y = _cell(pt, w, h)
    da, db = _rows(warp.data, corners, py), _rows(warp.data, corners, py + 1)
    c0 = _lerp(_at(da, px), _at(db, px), y)
    c1 = _lerp(_at(da, px + 1), _at(db, px + 1), y)
    pdf = _lerp(c0, c1, x)
    x = _invert_segment(x, 1.0 / (w - 1), c0, c1)
    ca, cb = _rows(warp.cond, corners, py), _rows(warp.cond, corners, py + 1)
    i = jnp.maximum(px - 1, 0)
    x = x + jnp.where(px > 0, _lerp(_at(ca, i), _at(cb, i), y), 0.0)
    r0, r1 = ca[..., -1], cb[..., -1]
    x = safe_div(x, _lerp(r0, r1, y))
    y = _invert_segment(y, 1.0 / (h - 1), r0, r1)
    marg = jnp.broadcast_to(_rows(warp.marg, corners), y.shape + (h - 1,))
    y = y + jnp.where(py > 0, _at(marg, jnp.maximum(py - 1, 0)), 0.0)
    return jnp.stack([x, y], axis=-1), pdf
