"""2-D convolution of images: shift-and-add, separable and FFT back ends.

All functions compute a *true* convolution (the kernel is flipped),

    out[m, n] = sum_{i, j} kernel[i, j] * f[m + ci - i, n + cj - j],   ci = kh // 2, cj = kw // 2,

with ``f`` extrapolated beyond the border by ``padding`` (see :mod:`jaxgfx.image._padding`).
For a symmetric kernel this equals correlation; ``scipy.ndimage.convolve`` gives the same result
for odd kernel sizes (``cv2.filter2D`` computes correlation: pass it the flipped kernel).
Kernels act on every channel independently. Layout: a 2-d input is one ``(H, W)`` image;
a k-d input (k >= 3) is channels-last ``(..., H, W, C)``; a batch of grey images therefore
needs a trailing channel axis of size 1.

Back ends (``method=``):

- ``"direct"``: shift-and-add over the kernel taps (one fused multiply-add per tap; XLA's CPU
  ``lax.conv`` is 10-30x slower for image-sized inputs and is not used).
- ``"separable"``: two 1-d passes; the kernel must be rank 1 (found by SVD of a concrete
  kernel), or call :func:`convolve_separable` with the two factors.
- ``"fft"``: pad by the mode, then a real FFT product (sizes rounded to 2-3-5-smooth).
- ``"auto"``: separable if the kernel is concrete and rank 1, else direct below
  :data:`FFT_CROSSOVER_2D` taps and FFT above; 1-d passes switch to FFT above
  :data:`FFT_CROSSOVER_1D` taps (crossovers measured by ``benchmarks/image_filters.py``).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import check_choice, check_finite, check_image, is_concrete

from ._padding import check_padding, pad_bhw, to_bhw

__all__ = [
    "CONVOLVE_METHODS",
    "FFT_CROSSOVER_1D",
    "FFT_CROSSOVER_2D",
    "convolve",
    "convolve_separable",
    "separable_factors",
]

CONVOLVE_METHODS = ("auto", "direct", "separable", "fft")
#: 1-d passes with more taps than this use the FFT under ``method="auto"``.
FFT_CROSSOVER_1D = 61
#: non-separable 2-d kernels with more taps than this use the FFT under ``method="auto"``.
FFT_CROSSOVER_2D = 121
_UNROLL_MAX = 64  # above this many taps, the direct sum runs in a fori_loop (bounded compile)


def _fast_len(n: int) -> int:
    """Smallest 2-3-5-smooth integer >= n (fast FFT length)."""
    m = n
    while True:
        k = m
        for p in (2, 3, 5):
            while k % p == 0:
                k //= p
        if k == 1:
            return m
        m += 1


def _check_kernel(kernel, name, ndim):
    k = jnp.asarray(kernel)
    if k.ndim != ndim:
        raise ValueError(f"{name}: expected a {ndim}-d kernel, got shape {k.shape}")
    if k.size == 0:
        raise ValueError(f"{name}: expected a non-empty kernel, got shape {k.shape}")
    if not jnp.issubdtype(k.dtype, jnp.number) or k.dtype == jnp.bool_:
        raise TypeError(f"{name}: expected a numeric kernel, got dtype {k.dtype}")
    check_finite(k, name)
    return k


def separable_factors(kernel, *, rtol: float = 1e-6):
    """Rank-1 factors ``(kv, kh)`` with ``kernel ≈ outer(kv, kh)``, or ``None``.

    ``kernel`` must be concrete (NumPy or a non-traced array). The test is
    ``s[1] <= rtol * s[0]`` on its singular values.

    Example:
        >>> kv, kh = separable_factors(np.outer([1., 2., 1.], [-1., 0., 1.]))
        >>> np.allclose(np.outer(kv, kh), np.outer([1., 2., 1.], [-1., 0., 1.]))
        True
    """
    k = np.asarray(kernel, dtype=np.float64)
    if k.ndim != 2:
        raise ValueError(f"kernel: expected a 2-d kernel, got shape {k.shape}")
    u, s, vt = np.linalg.svd(k)
    if s[0] == 0:
        return np.zeros(k.shape[0]), np.zeros(k.shape[1])
    if len(s) > 1 and s[1] > rtol * s[0]:
        return None
    r = np.sqrt(s[0])
    return u[:, 0] * r, vt[0] * r


def _conv1d_direct(xp, k, axis: int, n_out: int):
    """Valid 1-d convolution of an already padded array along ``axis`` by shift-and-add."""
    L = k.shape[0]

    def tap(i):
        start = L - 1 - i
        return jax.lax.slice_in_dim(xp, start, start + n_out, axis=axis) * k[i]

    if L <= _UNROLL_MAX:
        out = tap(0)
        for i in range(1, L):
            out = out + tap(i)
        return out

    def body(i, acc):
        sl = jax.lax.dynamic_slice_in_dim(xp, L - 1 - i, n_out, axis=axis)
        return acc + sl * k[i]

    return jax.lax.fori_loop(0, L, body, jnp.zeros_like(tap(0)))


def _conv1d_fft(xp, k, axis: int, n_out: int):
    L = k.shape[0]
    n_fft = _fast_len(xp.shape[axis])
    X = jnp.fft.rfft(xp, n=n_fft, axis=axis)
    K = jnp.fft.rfft(k, n=n_fft)
    shape = [1] * xp.ndim
    shape[axis] = K.shape[0]
    y = jnp.fft.irfft(X * K.reshape(shape), n=n_fft, axis=axis)
    return jax.lax.slice_in_dim(y, L - 1, L - 1 + n_out, axis=axis).astype(xp.dtype)


def _conv1d(x, k, axis: int, padding: str, method: str):
    """Same-size 1-d convolution of ``(B, H, W)`` ``x`` along spatial ``axis`` (1 or 2)."""
    L = k.shape[0]
    c = L // 2
    n = x.shape[axis]
    pads = [(0, 0)] * 2
    pads[axis - 1] = (L - 1 - c, c)
    xp = pad_bhw(x, pads[0], pads[1], padding)
    if method == "auto":
        method = "fft" if L > FFT_CROSSOVER_1D else "direct"
    if method == "fft":
        return _conv1d_fft(xp, k, axis, n)
    return _conv1d_direct(xp, k, axis, n)


def _conv2d_direct(xp, k, H: int, W: int):
    kh, kw = k.shape
    if kh * kw <= _UNROLL_MAX:
        out = None
        for i in range(kh):
            for j in range(kw):
                sl = xp[:, kh - 1 - i : kh - 1 - i + H, kw - 1 - j : kw - 1 - j + W]
                out = sl * k[i, j] if out is None else out + sl * k[i, j]
        return out

    def body(t, acc):
        i, j = t // kw, t % kw
        sl = jax.lax.dynamic_slice(xp, (0, kh - 1 - i, kw - 1 - j), (xp.shape[0], H, W))
        return acc + sl * k[i, j]

    zero = jnp.zeros((xp.shape[0], H, W), xp.dtype)
    return jax.lax.fori_loop(0, kh * kw, body, zero)


def _conv2d_fft(xp, k, H: int, W: int):
    kh, kw = k.shape
    s = (_fast_len(xp.shape[1]), _fast_len(xp.shape[2]))
    X = jnp.fft.rfft2(xp, s=s, axes=(1, 2))
    K = jnp.fft.rfft2(k, s=s)
    y = jnp.fft.irfft2(X * K[None], s=s, axes=(1, 2))
    return y[:, kh - 1 : kh - 1 + H, kw - 1 : kw - 1 + W].astype(xp.dtype)


def _prepare(image, padding, method, methods=CONVOLVE_METHODS):
    x = check_image(image)
    check_padding(padding)
    check_choice(method, "method", methods)
    return x


@functools.partial(jax.jit, static_argnames=("padding", "method"))
def _convolve_core(x, k, *, padding: str, method: str):
    """Same-size 2-d convolution of a checked image by a non-separable path
    (``method`` is ``"direct"`` or ``"fft"``); one compiled program per shape and mode."""
    kh, kw = k.shape
    y, undo = to_bhw(x)
    H, W = y.shape[1], y.shape[2]
    ci, cj = kh // 2, kw // 2
    yp = pad_bhw(y, (kh - 1 - ci, ci), (kw - 1 - cj, cj), padding)
    if method == "fft":
        return undo(_conv2d_fft(yp, k, H, W))
    return undo(_conv2d_direct(yp, k, H, W))


@functools.partial(jax.jit, static_argnames=("padding", "method"))
def _convolve_separable_core(x, kv, kh, *, padding: str, method: str):
    """Two 1-d passes on a checked image (``kv``, ``kh`` already in its dtype)."""
    y, undo = to_bhw(x)
    y = _conv1d(y, kv, 1, padding, method)
    y = _conv1d(y, kh, 2, padding, method)
    return undo(y)


def convolve(image, kernel, *, padding: str = "reflect", method: str = "auto"):
    """Convolve every channel of an image with a 2-d kernel (true convolution, same size).

    Args:
        image: ``(H, W)`` or channels-last ``(..., H, W, C)``, any real values.
        kernel: ``(kh, kw)``, any size (odd sizes are centred; for even sizes the anchor is
            ``(kh // 2, kw // 2)``). May be traced (differentiable) except for
            ``method="separable"``, which needs a concrete rank-1 kernel.
        padding: ``"zero" | "edge" | "reflect" | "symmetric" | "wrap"``.
        method: ``"auto" | "direct" | "separable" | "fft"`` (see the module docstring).

    Returns:
        Array of the image's shape and dtype.

    Example:
        >>> convolve(jnp.array([[0., 1., 0.]]), jnp.array([[1., 2., 3.]]), padding="zero")
        Array([[1., 2., 3.]], dtype=float32)
    """
    x = _prepare(image, padding, method)
    k = _check_kernel(kernel, "kernel", 2)
    k = k.astype(x.dtype)
    if method in ("auto", "separable"):
        factors = separable_factors(k) if is_concrete(k) else None
        if factors is not None:
            kv = jnp.asarray(factors[0]).astype(x.dtype)
            kh = jnp.asarray(factors[1]).astype(x.dtype)
            return _convolve_separable_core(x, kv, kh, padding=padding, method="auto")
        if method == "separable":
            raise ValueError(
                "method: 'separable' needs a concrete rank-1 kernel; use convolve_separable "
                "with the two 1-d factors, or method='direct'/'fft'"
            )
        method = "fft" if k.size > FFT_CROSSOVER_2D else "direct"
    return _convolve_core(x, k, padding=padding, method=method)


def convolve_separable(
    image, kernel_v, kernel_h, *, padding: str = "reflect", method: str = "auto"
):
    """Convolve with the separable kernel ``outer(kernel_v, kernel_h)`` in two 1-d passes.

    Args:
        image: ``(H, W)`` or channels-last ``(..., H, W, C)``.
        kernel_v: ``(kh,)`` taps along H (rows); may be traced.
        kernel_h: ``(kw,)`` taps along W (columns); may be traced.
        padding: see :func:`convolve`.
        method: ``"auto" | "direct" | "fft"`` for each 1-d pass.

    Returns:
        Same as ``convolve(image, outer(kernel_v, kernel_h))``.

    Example:
        >>> x = jnp.zeros((3, 3)).at[1, 1].set(1.0)
        >>> kv, kh = jnp.array([1., 2., 1.]), jnp.array([1., 0., -1.])
        >>> convolve_separable(x, kv, kh, padding="zero")[0]
        Array([ 1.,  0., -1.], dtype=float32)
    """
    x = _prepare(image, padding, method, ("auto", "direct", "fft"))
    kv = _check_kernel(kernel_v, "kernel_v", 1).astype(x.dtype)
    kh = _check_kernel(kernel_h, "kernel_h", 1).astype(x.dtype)
    return _convolve_separable_core(x, kv, kh, padding=padding, method=method)
