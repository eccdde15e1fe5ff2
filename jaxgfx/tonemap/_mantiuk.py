"""Contrast-domain tone mapping of Mantiuk, Myszkowski & Seidel (2006), "A perceptual framework
for contrast processing of high dynamic range images", ACM TAP 3(3): the contrast-mapping
variant, as ``pfstmo_mantiuk06`` runs it by default."""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .._math import safe_div, safe_pow
from ._common import (
    check_encode,
    check_hdr,
    check_scalar,
    check_weights,
    encode_display,
    recolor,
    split_luminance,
)
from ._poisson import forward_gradients

__all__ = ["tonemap_Mantiuk2006", "mantiuk_transducer", "mantiuk_transducer_inverse"]

# contrast discrimination threshold of the paper, in log10 contrast G: dG(G) = A G^B (the fit
# to Whittle's data; pfstmo weights the gradients of its solve with the same 1 / dG)
_A, _B = 0.038737, 0.537756
_G0 = (math.log10(1.01) / _A) ** (1.0 / _B)  # below: the 1 % detection threshold (dG const)
_R0 = _G0 ** (1.0 - _B) / _A  # response at _G0, in JNDs
_MIN_PIXELS = 3  # coarsest pyramid level: both sides >= 3 (pfstmo's PYRAMID_MIN_PIXELS)
_DISPLAY_DECADES = 2.3  # pfstmo's display dynamic range, log10 units
_CUT = 0.001  # quantiles mapped to the display range (pfstmo: 0.1 % / 99.9 %)


def mantiuk_transducer(G):
    """Contrast response ``R(G)`` in JNDs of a log10 contrast ``G`` (odd in ``G``).

    ``R = integral_0^|G| dg / dG(g)`` with the paper's discrimination threshold
    ``dG(g) = 0.038737 g^0.537756``, held at the 1 % detection threshold ``dG = log10 1.01``
    below ``g0 = 0.0169``: linear near 0, ``~ 55.9 G^0.462`` above (the paper's power law
    ``54.09 G^0.4185`` is a fit to the same integral). Closed form, differentiable. It stays
    within 4.3 JND (of 106) of the table pfstmo interpolates, which differs from it only by
    pfstmo's detail at the 1 % end.
    """
    g = jnp.abs(G)
    lin = g / (_A * _G0**_B)
    pw = _R0 + (safe_pow(g, 1.0 - _B) - _G0 ** (1.0 - _B)) / (_A * (1.0 - _B))
    return jnp.sign(G) * jnp.where(g <= _G0, lin, pw)


def mantiuk_transducer_inverse(R):
    """Inverse of :func:`mantiuk_transducer`: log10 contrast ``G`` of a response ``R``."""
    r = jnp.abs(R)
    lin = r * (_A * _G0**_B)
    base = jnp.maximum((r - _R0) * (_A * (1.0 - _B)) + _G0 ** (1.0 - _B), _G0 ** (1.0 - _B))
    pw = safe_pow(base, 1.0 / (1.0 - _B))
    return jnp.sign(R) * jnp.where(r <= _R0, lin, pw)


def _level_shapes(H: int, W: int):
    shapes = [(H, W)]
    while shapes[-1][0] // 2 >= _MIN_PIXELS and shapes[-1][1] // 2 >= _MIN_PIXELS:
        shapes.append((shapes[-1][0] // 2, shapes[-1][1] // 2))
    return shapes


def _down_taps(n: int):
    """Area-average ``n -> n // 2`` (pfstmo's downsampling: 2-pixel means for even ``n``,
    box integration over ``n / m``-wide cells for odd): indices and weights ``(3, m)``."""
    m = n // 2
    step = n / m
    idx = np.zeros((3, m), np.int32)
    wts = np.zeros((3, m))
    for i in range(m):
        a, b = i * step, (i + 1) * step
        for t, j in enumerate(range(int(math.floor(a)), min(int(math.ceil(b)), n))):
            idx[t, i] = j
            wts[t, i] = (min(b, j + 1) - max(a, j)) / step
    return idx, wts


def _down(x, axis, n, dtype):
    if n % 2 == 0:  # 2-pixel means (reshape: no gathers, whose adjoints are scatters)
        if axis == 0:
            return 0.5 * (x[0::2] + x[1::2])
        return 0.5 * (x[:, 0::2] + x[:, 1::2])
    idx, wts = _down_taps(n)
    out = 0.0
    for t in range(idx.shape[0]):
        w = jnp.asarray(wts[t], dtype)
        w = w[:, None] if axis == 0 else w
        out = out + w * jnp.take(x, jnp.asarray(idx[t]), axis=axis)
    return out


def _pyramid(x, shapes):
    """``x (H, W)`` and its downsampled levels."""
    levels = [x]
    for h, w in shapes[:-1]:
        y = levels[-1]
        y = _down(y, 0, h, x.dtype)
        y = _down(y, 1, w, x.dtype)
        levels.append(y)
    return levels


def _gradients(x, shapes):
    return [forward_gradients(lv) for lv in _pyramid(x, shapes)]


@functools.partial(jax.jit, static_argnames=("encode", "weights", "iterations", "tol"))
def _mantiuk(x, contrast, saturation, *, encode, weights, iterations, tol):
    L, kind = split_luminance(x, weights)
    lead = L.shape[:-2]
    H, W = L.shape[-2:]
    Lb = L.reshape((-1, H, W))
    shapes = _level_shapes(H, W)
    out = jax.vmap(lambda l: _solve_one(l, contrast, shapes, iterations, tol))(Lb)
    Ld = out.reshape(lead + (H, W))
    return encode_display(recolor(x, L, Ld, saturation, kind), encode)


def _cg(matvec, b, *, iterations, tol):
    """Conjugate gradients from 0 for a symmetric positive semi-definite ``matvec`` and a
    consistent ``b``; stops at ``|r| <= tol |b|`` or after ``iterations``. The step sizes are
    0 where a denominator is 0 (an exact solution, or a residual lost in rounding): finite in
    any precision and for any ``tol``. The null space of the operator is the constants: ``b``
    is projected onto their complement (the backward solve's cotangent is not exactly) and the
    solution has zero mean, so that rounding cannot drive it along the null space."""
    b = b - jnp.mean(b)
    bb = jnp.vdot(b, b)
    stop = (tol * tol) * bb

    def cond(state):
        k, _, _, _, rr = state
        return (k < iterations) & (rr > stop)

    def body(state):
        k, x, r, p, rr = state
        ap = matvec(p)
        alpha = safe_div(rr, jnp.vdot(p, ap))
        x = x + alpha * p
        r = r - alpha * ap
        rr_new = jnp.vdot(r, r)
        p = r + safe_div(rr_new, rr) * p
        return k + 1, x, r, p, rr_new

    x0 = jnp.zeros_like(b)
    x = jax.lax.while_loop(cond, body, (0, x0, b, b, bb))[1]
    return x - jnp.mean(x)


def _solve_one(L, contrast, shapes, iterations, tol):
    dt = L.dtype
    floor = 1e-7 * jnp.max(L) + jnp.finfo(dt).tiny * 1e6  # pfstmo clips at 1e-7 max
    Lc = jnp.maximum(L, floor)
    X = jnp.log10(Lc)
    # contrast mapping: R' = contrast * R(G) per gradient component, G' = R^-1(R')
    target = [
        tuple(mantiuk_transducer_inverse(contrast * mantiuk_transducer(g)) for g in pair)
        for pair in _gradients(X, shapes)
    ]
    # weights 1 / dG(G') (pfstmo, from the mapped gradients), times 4^k: pfstmo's upsampling of
    # the coarser levels' divergence replicates without the 1/4 of the exact adjoint
    wts = [
        tuple((4.0**k) / (_A * safe_pow(jnp.maximum(jnp.abs(g), 0.001), _B)) for g in pair)
        for k, pair in enumerate(target)
    ]

    def forward(v):
        return _gradients(v, shapes)

    adjoint = jax.linear_transpose(forward, X)

    def matvec(v):
        gs = forward(v)
        return adjoint(
            [
                tuple(w * g for w, g in zip(wp, gp, strict=True))
                for wp, gp in zip(wts, gs, strict=True)
            ]
        )[0]

    b = adjoint(
        [
            tuple(w * g for w, g in zip(wp, gp, strict=True))
            for wp, gp in zip(wts, target, strict=True)
        ]
    )[0]
    # normal equations of sum_k ||C_k (grad P_k x - G'_k)||^2 (symmetric positive
    # semi-definite, constants in the null space), solved by conjugate gradients from log L
    # (for the correction D = Y - log L); derivatives by implicit differentiation
    # (lax.custom_linear_solve: one more solve with the cotangent, nothing unrolled)
    solve = functools.partial(_cg, iterations=iterations, tol=tol)
    D = jax.lax.custom_linear_solve(matvec, b - matvec(X), solve, symmetric=True)
    Y = X + D
    flat = Y.reshape(-1)
    lo = jnp.quantile(flat, _CUT)
    hi = jnp.quantile(flat, 1.0 - _CUT)
    span = hi - lo
    ok = span > 1e-6
    Yd = jnp.where(
        ok, (Y - lo) / jnp.where(ok, span, 1.0) * _DISPLAY_DECADES - _DISPLAY_DECADES, 0.0
    )
    # exact zeros stay black (the clip floor only keeps the logarithm finite)
    return jnp.power(10.0, Yd) * safe_div(L, L + floor)


def tonemap_Mantiuk2006(
    hdr,
    *,
    contrast=0.1,
    saturation=0.8,
    iterations=200,
    tol=1e-3,
    encode="srgb",
    weights="rec709",
):
    """Contrast mapping in a perceptual contrast space (Mantiuk, Myszkowski & Seidel 2006).

    The log10 luminance is differentiated on a multi-resolution pyramid (2 x 2 area means down
    to 3 px, forward differences per level); each gradient ``G`` is mapped through the
    transducer to a visual response ``R(G)`` in JNDs (:func:`mantiuk_transducer`), the
    responses are scaled by ``contrast`` (a linear scaling in a perceptually uniform space:
    small, visible contrasts keep more of their size than large ones) and mapped back,
    ``G' = R^-1(contrast R(G))``. The image whose pyramid gradients are closest to ``G'``,
    weighted by ``1 / dG(G')`` (the discrimination threshold), solves the normal equations
    ``sum_k 4^k P_k^T grad^T C_k grad P_k x = sum_k 4^k P_k^T grad^T C_k G'_k`` (``P_k``:
    downsampling to level ``k``); conjugate gradients from ``log10 L`` (``iterations``,
    relative residual ``tol``: pfstmo's 200 and 1e-3). The result is stretched so that its
    0.1 % / 99.9 % quantiles span the display's 2.3 decades (brightest at 1), colour by
    ``(C / L)^saturation``. As ``pfstmo_mantiuk06`` with its defaults, with two differences:
    the transducer is in closed form (within 4.3 JND of pfstmo's table, docs/tonemap.md), and
    exact zeros display black (pfstmo clips them to ``1e-7 max``, which the stretch can lift).

    Args:
        contrast: in (0, 1], the scaling of the responses (pfstmo's ``--factor``, 0.1).
        saturation: > 0, colour saturation exponent (pfstmo's ``--saturation``, 0.8).
        iterations, tol: static, conjugate-gradient limits (``tol >= 10 eps`` of the dtype).
        encode, weights: see :func:`tonemap_Drago2003`.

    Differentiable in ``contrast``, ``saturation`` and the image (implicit differentiation
    through the solve; exact for a converged solve: use a small ``tol`` for finite-difference
    checks). Jittable and vmappable.

    Example:
        >>> float(tonemap_Mantiuk2006(jnp.ones((4, 4)), encode="linear")[1, 1])  # constant
        1.0
    """
    x = check_hdr(hdr)
    check_scalar(saturation, "saturation", lo=0.0)
    check_encode(encode)
    check_weights(weights)
    check_scalar(contrast, "contrast", lo=0.0, hi=1.0, hi_open=False)
    if isinstance(iterations, bool) or not isinstance(iterations, (int, np.integer)):
        raise TypeError(f"iterations: expected an integer >= 1, got {iterations!r}")
    if iterations < 1:
        raise ValueError(f"iterations: expected an integer >= 1, got {iterations}")
    if not (isinstance(tol, (int, float)) and 0.0 < float(tol) < 1.0):
        raise ValueError(f"tol: expected a relative residual in (0, 1), got {tol!r}")
    eps = float(jnp.finfo(x.dtype).eps)
    if float(tol) < 10.0 * eps:  # below rounding: CG would only lose orthogonality
        raise ValueError(
            f"tol: {tol!r} is below the {x.dtype} rounding level; expected >= {10.0 * eps:.2g}"
        )
    return _mantiuk(
        x,
        contrast,
        saturation,
        encode=encode,
        weights=weights,
        iterations=int(iterations),
        tol=float(tol),
    )
