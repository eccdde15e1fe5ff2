"""Safe elementwise math: finite values *and* finite gradients everywhere.

Every function guards both branches of its ``jnp.where`` so that reverse-mode AD never
multiplies a zero cotangent by an infinite/NaN partial derivative (the "double where" trick).
"""

from __future__ import annotations

import math

import jax
import jax.custom_batching
import jax.numpy as jnp

__all__ = [
    "safe_div",
    "safe_sqrt",
    "safe_log",
    "safe_pow",
    "safe_norm",
    "safe_normalize",
    "safe_arccos",
    "safe_atan2",
    "eps_for",
    "sum_last",
    "max_last",
    "vdot",
    "cross",
    "fusion_barrier",
    "sincos",
    "take_rows",
    "spd_solve_small",
]


def eps_for(x) -> float:
    """Machine epsilon of ``x``'s floating dtype (float32 if ``x`` is not floating)."""
    dt = jnp.result_type(x)
    if not jnp.issubdtype(dt, jnp.floating):
        dt = jnp.float32
    return float(jnp.finfo(dt).eps)


def sum_last(x, *, keepdims=False):
    """Sum over the last axis; unrolled into elementwise adds when it is short (<= 4).

    XLA on CPU turns ``jnp.sum(v, -1)`` over a minor axis of length 3 into a separate reduction
    kernel that breaks loop fusion; the unrolled form fuses with its neighbours and is ~10x
    faster for ``(N, 3)`` vectors (measured: 47 ms -> 4.8 ms for 10 normalisations of 262k
    vectors). Results equal ``jnp.sum`` up to summation order (``x0 + x1 + x2``, left to
    right). The components come from one ``split`` and the sum is squeezed once (4 primitives
    for a length-3 axis instead of 8 with ``x[..., i]``: fewer equations to trace and lower).
    """
    n = x.shape[-1]
    if n > 4:
        return jnp.sum(x, axis=-1, keepdims=keepdims)
    return _unrolled_last(jnp.add, x, keepdims)


def _unrolled_last(op, x, keepdims):
    if x.shape[-1] == 1:
        r = x
    else:
        parts = jax.lax.split(x, (1,) * x.shape[-1], axis=x.ndim - 1)
        r = parts[0]
        for p in parts[1:]:
            r = op(r, p)
    return r if keepdims else jax.lax.squeeze(r, (x.ndim - 1,))


def max_last(x, *, keepdims=False):
    """Maximum over the last axis, unrolled when it is short (see :func:`sum_last`)."""
    n = x.shape[-1]
    if n > 4:
        return jnp.max(x, axis=-1, keepdims=keepdims)
    return _unrolled_last(jnp.maximum, x, keepdims)


def vdot(a, b, *, keepdims=False):
    """Dot product over the last axis of broadcastable ``a, b (..., n)`` (fusion-friendly)."""
    return sum_last(a * b, keepdims=keepdims)


def cross(a, b):
    """Cross product of broadcastable ``a, b (..., 3)``: the products and differences of
    ``jnp.cross`` (``a1 b2 - a2 b1``, ...) on components from one ``split`` per vector, joined by
    one ``concatenate`` (12 primitives instead of ~30: ``jnp.cross`` takes six components with
    slice + squeeze, stacks three and moves axes)."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    if a.shape[-1] != 3 or b.shape[-1] != 3:
        raise ValueError(f"cross: expected vectors of length 3, got {a.shape} and {b.shape}")
    a0, a1, a2 = jax.lax.split(a, (1, 1, 1), axis=a.ndim - 1)
    b0, b1, b2 = jax.lax.split(b, (1, 1, 1), axis=b.ndim - 1)
    return jnp.concatenate([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def fusion_barrier(tree):
    """Identity on a pytree of arrays that XLA materialises instead of fusing through.

    XLA's CPU fusion duplicates cheap producers into every consumer; in deep select chains (the
    hit records of a scene, a BSDF dispatch) it recomputes whole intersection tests many times
    (measured 5x slower scene intersection, 4x longer compiles). ``lax.optimization_barrier``
    is expanded away before fusion on CPU, so this wraps the values in a ``lax.cond`` on a
    runtime predicate (always true) whose two branches are both the identity. Differentiable,
    jittable and vmappable.

    Under ``jax.vmap`` the barrier stays a barrier: the predicate is read from ONE element of
    the batch (:func:`_one_of_batch`), so it is unbatched and the ``cond`` keeps its branches
    (a batched predicate would turn it into a ``select``, no barrier: ``render`` vmapped over
    keys was measured 7-31x slower per key than one key at a time, docs/performance.md).
    """
    leaves = [x for x in jax.tree_util.tree_leaves(tree) if x.size > 0]
    if not leaves:
        return tree
    first = leaves[0].reshape(-1)[0].astype(jnp.float32)
    # int32 bits carry no tangent, so no derivative ever passes through the custom_vmap
    bits = _one_of_batch(jax.lax.bitcast_convert_type(jax.lax.stop_gradient(first), jnp.int32))
    pred = bits != 0x7FBADBAD  # a NaN payload
    return jax.lax.cond(
        pred,
        lambda t, p: t,
        lambda t, p: jax.tree_util.tree_map(lambda x: _same(x, p), t),
        tree,
        pred,
    )


@jax.custom_batching.custom_vmap
def _one_of_batch(x):
    """Identity on an array; under ``vmap``, its first element along the batch axis, unbatched.

    Only for values whose every element gives the same result downstream (the always-true
    predicate of :func:`fusion_barrier`): it keeps such a predicate out of the batch.
    """
    return x


@_one_of_batch.def_vmap
def _one_of_batch_vmap(axis_size, in_batched, x):
    del axis_size
    # recurse: under nested vmaps each level drops its own batch axis
    return _one_of_batch(x[0] if in_batched else x), False


def _same(x, pred):
    # The false branch returns the same values by operations XLA cannot prove to be the
    # identity: were both branches the identity on a leaf, XLA forwards that operand past the
    # conditional and the barrier vanishes for it (it did for booleans: `x ^ pred` is `x` here,
    # where pred is False, but only at run time).
    return jnp.logical_xor(x, pred) if x.dtype == bool else x + jnp.zeros((), x.dtype)


# Cody-Waite split of pi/2 (fdlibm's pio2_1 / pio2_1t for float64, float32 hi/lo for float32)
# pi/2 split so that k * part is exact for every part but the last (Cody & Waite 1980): the
# float32 parts have 8 and 11 significant bits (|k| < 2^13), fdlibm's float64 first part 33 bits
# (|k| < 2^20). The reduction must not rely on FMA contraction: with a full-precision float32
# first part, x - k * hi is exact only when the compiler fuses it (XLA CPU at -O2 does, -O0 and
# FMA-less CPUs do not: 5e-4 error at |x| = 1e4).
_PIO2 = {
    "float32": (1.5703125, 4.837512969970703125e-4, 7.549790126404332e-08),
    "float64": (1.57079632673412561417e00, 6.07710050650619224932e-11),
}
# minimax polynomials on [-pi/4, pi/4]: Cephes sinf/cosf (float32), fdlibm kernel_sin/cos (f64)
_SIN = {
    "float32": (-1.6666654611e-1, 8.3321608736e-3, -1.9515295891e-4),
    "float64": (
        -1.66666666666666324348e-01,
        8.33333333332248946124e-03,
        -1.98412698298579493134e-04,
        2.75573137070700676789e-06,
        -2.50507602534068634195e-08,
        1.58969099521155010221e-10,
    ),
}
_COS = {
    "float32": (4.166664568298827e-2, -1.388731625493765e-3, 2.443315711809948e-5),
    "float64": (
        4.16666666666666019037e-02,
        -1.38888888888741095749e-03,
        2.48015872894767294178e-05,
        -2.75573143513906633035e-07,
        2.08757232129817482790e-09,
        -1.13596475577881948265e-11,
    ),
}


def _horner(z, coeffs):
    r = jnp.full_like(z, coeffs[-1])
    for c in coeffs[-2::-1]:
        r = r * z + c
    return r


@jax.custom_jvp
def sincos(x):
    """``(sin x, cos x)`` from one range reduction and two polynomials.

    XLA on CPU evaluates ``jnp.sin`` / ``jnp.cos`` with a scalar call per element (~11 ns each,
    10x a vectorised ``exp``); this form uses only multiply-adds and selects, so it vectorises
    and fuses (~1 ns). Range reduction ``x = k pi/2 + r`` (Cody & Waite 1980) with
    ``|r| <= pi/4``, then the Cephes (float32) or fdlibm (float64) minimax polynomials.
    Accuracy: within 2 ulp of ``numpy.sin``/``cos`` for ``|x| <= 1e4`` (float32) and
    ``|x| <= 1e6`` (float64); larger arguments lose accuracy (not used by the renderer).
    Derivatives are exact (``d sin = cos dx``).

    Example: ``sincos(jnp.pi / 6)`` → ``(0.5, 0.8660254)``.
    """
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.float32)
    key = "float64" if x.dtype == jnp.float64 else "float32"
    k = jnp.round(x * (2.0 / math.pi))
    r = x
    for part in _PIO2[key]:
        r = r - k * part
    z = r * r
    s = r + r * z * _horner(z, _SIN[key])
    c = 1.0 - 0.5 * z + z * z * _horner(z, _COS[key])
    q = k.astype(jnp.int32) & 3  # the quadrant, 0..3: one 4-way select per output
    return jax.lax.select_n(q, s, c, -s, -c), jax.lax.select_n(q, c, -s, -c, s)


@sincos.defjvp
def _sincos_jvp(primals, tangents):
    (x,), (dx,) = primals, tangents
    s, c = sincos(x)
    return (s, c), (c * dx, -s * dx)


def take_rows(arr, idx):
    """``arr[idx]`` for a small table ``arr (N, ...)``: a chain of selects when ``N <= 8``
    (XLA CPU gathers do not fuse; for one to a few spheres or rectangles the selects are
    several times faster), an ordinary gather otherwise."""
    n = arr.shape[0]
    if n > 8:
        return arr[idx]
    batch = idx.shape
    idx = idx.reshape(batch + (1,) * (arr.ndim - 1))
    out = jnp.broadcast_to(arr[0], batch + arr.shape[1:])
    for i in range(1, n):
        out = jnp.where(idx == i, arr[i], out)
    return out


def safe_div(a, b, *, fill=0.0):
    """``a / b`` where ``b != 0``, else ``fill``; gradient is 0 (not NaN) where ``b == 0``."""
    nz = b != 0
    b_safe = jnp.where(nz, b, 1.0)
    return jnp.where(nz, a / b_safe, fill)


def safe_sqrt(x):
    """``sqrt(max(x, 0))`` with gradient 0 at and below 0 (instead of inf/NaN)."""
    pos = x > 0
    x_safe = jnp.where(pos, x, 1.0)
    return jnp.where(pos, jnp.sqrt(x_safe), 0.0)


def safe_log(x, *, floor=None):
    """``log(max(x, floor))``; ``floor`` defaults to the dtype's smallest normal number."""
    if floor is None:
        dt = jnp.result_type(x)
        if not jnp.issubdtype(dt, jnp.floating):
            dt = jnp.float32
        floor = float(jnp.finfo(dt).tiny)
    ok = x > floor
    x_safe = jnp.where(ok, x, 1.0)
    return jnp.where(ok, jnp.log(x_safe), jnp.log(jnp.asarray(floor, jnp.result_type(x, 1.0))))


def safe_pow(x, p):
    """``max(x, 0) ** p`` with finite gradient w.r.t. both ``x`` and ``p`` at ``x == 0``."""
    pos = x > 0
    x_safe = jnp.where(pos, x, 1.0)
    return jnp.where(pos, x_safe**p, 0.0)


def safe_norm(v, *, axis=-1, keepdims=False):
    """Euclidean norm with zero (not NaN) gradient at the zero vector."""
    if axis == -1 or axis == v.ndim - 1:
        return safe_sqrt(sum_last(v * v, keepdims=keepdims))
    return safe_sqrt(jnp.sum(v * v, axis=axis, keepdims=keepdims))


def safe_normalize(v, *, axis=-1):
    """``v / |v|``; the zero vector maps to zero with a finite gradient."""
    n = safe_norm(v, axis=axis, keepdims=True)
    return safe_div(v, n)


def safe_arccos(x):
    """``arccos(clip(x, -1, 1))`` with finite gradient at the clip boundaries."""
    eps = eps_for(x)
    inside = jnp.abs(x) < 1.0 - eps
    x_safe = jnp.where(inside, x, 0.0)
    return jnp.where(inside, jnp.arccos(x_safe), jnp.where(x > 0, 0.0, jnp.pi))


def safe_atan2(y, x):
    """``atan2(y, x)`` that returns 0 with zero gradient at the origin."""
    origin = (x == 0) & (y == 0)
    x_safe = jnp.where(origin, 1.0, x)
    y_safe = jnp.where(origin, 0.0, y)
    return jnp.where(origin, 0.0, jnp.arctan2(y_safe, x_safe))


def spd_solve_small(a, b):
    """Solve ``a x = b`` for a small symmetric positive definite ``a`` ``(K, K)`` (``K`` static,
    up to ~12) and ``b`` ``(K,)`` by an unrolled Cholesky factorisation: elementwise XLA ops,
    no LAPACK custom call. Two LAPACK calls that are independent in one XLA CPU program may run
    side by side on the 2-thread pool, and that was seen to deadlock (every thread in a futex
    wait: the instanced queries' batched ``inv``, issue 24; the Debevec self-check's candidate
    fits, issue 26), so programs that need a small solve beside a large one use this.
    Pivots are floored at the smallest normal number (a singular ``a`` gives large, finite
    values, not NaN)."""
    k = a.shape[-1]
    if a.shape != (k, k) or b.shape != (k,):
        raise ValueError(f"a, b: expected shapes (K, K) and (K,), got {a.shape} and {b.shape}")
    tiny = jnp.finfo(a.dtype).tiny
    low = [[None] * k for _ in range(k)]
    for j in range(k):
        s = a[j, j] - sum((low[j][p] * low[j][p] for p in range(j)), jnp.zeros((), a.dtype))
        d = jnp.sqrt(jnp.maximum(s, tiny))
        low[j][j] = d
        for i in range(j + 1, k):
            acc = sum((low[i][p] * low[j][p] for p in range(j)), jnp.zeros((), a.dtype))
            low[i][j] = (a[i, j] - acc) / d
    y = []
    for i in range(k):
        acc = sum((low[i][p] * y[p] for p in range(i)), jnp.zeros((), a.dtype))
        y.append((b[i] - acc) / low[i][i])
    x = [None] * k
    for i in reversed(range(k)):
        acc = sum((low[p][i] * x[p] for p in range(i + 1, k)), jnp.zeros((), a.dtype))
        x[i] = (y[i] - acc) / low[i][i]
    return jnp.stack(x)
