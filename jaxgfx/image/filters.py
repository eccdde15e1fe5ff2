"""Linear and non-linear image filters: box, Gaussian, median, bilateral, sharpening, LoG.

Layout as in :mod:`jaxgfx.image.convolve`: ``(H, W)`` or channels-last ``(..., H, W, C)``;
every filter acts on each channel independently and keeps shape and dtype. Kernel *sizes*
(radii) are static Python ints; widths (sigma), amounts and thresholds may be traced arrays
and are differentiable. Reference for the linear filters and the median: the seed's lecture 1
and Szeliski, *Computer Vision: Algorithms and Applications* (2010), sec. 3.2-3.3.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import (
    check_choice,
    check_image,
    check_nonnegative,
    check_odd_int,
    check_positive,
    is_concrete,
)
from jaxgfx._math import safe_div

from ._padding import check_padding, pad_bhw, to_bhw
from .convolve import _conv1d, _convolve_core, _convolve_separable_core

__all__ = [
    "BILATERAL_METHODS",
    "gaussian_kernel1d",
    "gaussian_blur",
    "box_blur",
    "median_filter",
    "bilateral_filter",
    "bilateral_Tomasi1998",
    "bilateral_Chen2007",
    "unsharp_mask",
    "laplacian_of_gaussian",
    "sharpen",
]


def _static_radius(sigma, truncate, radius, name="sigma"):
    """Radius from ``ceil(truncate * sigma)`` (concrete sigma) or the explicit ``radius``."""
    if radius is not None:
        if isinstance(radius, bool) or not isinstance(radius, (int, np.integer)) or radius < 0:
            raise ValueError(f"radius: expected a non-negative int, got {radius!r}")
        return int(radius)
    check_positive(truncate, "truncate")
    if not is_concrete(sigma):
        raise ValueError(
            f"radius: {name} is traced, so the kernel radius cannot be derived from it; pass "
            f"a static radius=int (e.g. ceil(truncate * max expected {name}))"
        )
    s = float(np.max(np.asarray(sigma)))
    return int(math.ceil(truncate * s - 1e-9)) if s > 0 else 0


def gaussian_kernel1d(sigma, radius: int, *, dtype=None):
    """Normalised sampled Gaussian ``exp(-i^2 / (2 sigma^2)) / sum``, ``i = -radius..radius``.

    Computed as a softmax of ``-i^2 / (2 sigma^2)``: stable for tiny sigma, and sigma <= 0
    (or sigma -> 0) gives the unit impulse with finite gradients.

    Args:
        sigma: scalar standard deviation in pixels, may be traced.
        radius: static non-negative int.

    Example:
        >>> gaussian_kernel1d(1.0, 1)
        Array([0.27406862, 0.45186275, 0.27406862], dtype=float32)
    """
    sigma = jnp.asarray(sigma, dtype=dtype if dtype is not None else jnp.result_type(sigma, 1.0))
    i = jnp.arange(-radius, radius + 1, dtype=sigma.dtype)
    tiny = jnp.finfo(sigma.dtype).tiny ** 0.25
    ok = sigma > tiny
    s = jnp.where(ok, sigma, 1.0)
    w = jax.nn.softmax(-(i * i) / (2.0 * s * s))
    delta = (i == 0).astype(sigma.dtype)
    return jnp.where(ok, w, delta)


def gaussian_blur(
    image,
    sigma,
    *,
    truncate: float = 3.0,
    radius: int | None = None,
    padding: str = "reflect",
    method: str = "auto",
):
    """Separable Gaussian blur with a normalised, truncated kernel.

    The kernel has radius ``ceil(truncate * sigma)`` (the seed's "3 sigma" rule by default).
    To differentiate w.r.t. a *traced* sigma (inside ``jit``/``grad``), pass a static
    ``radius=`` that covers the sigmas you expect. ``sigma = 0`` is the identity (finite
    gradients); a huge sigma with ``padding="wrap"`` tends to the image mean.

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        sigma: standard deviation in pixels, >= 0 (scalar; may be traced with ``radius``).
        truncate: kernel half-width in sigmas when ``radius`` is None.
        radius: static kernel radius overriding ``truncate``.
        padding: ``"zero" | "edge" | "reflect" | "symmetric" | "wrap"``.
        method: ``"auto" | "direct" | "fft"`` for the two 1-d passes.

    Returns:
        Blurred image, same shape and dtype.

    Reference: matches ``cv2.GaussianBlur(img, (2r+1, 2r+1), sigma,
    borderType=cv2.BORDER_REFLECT_101)`` and ``scipy.ndimage.gaussian_filter(mode="mirror")``
    with the same radius.

    Example:
        >>> gaussian_blur(jnp.full((4, 4), 2.0), 1.5)[0, 0]
        Array(2., dtype=float32)
    """
    x = check_image(image)
    r = _gaussian_radius(sigma, truncate, radius, padding, method)
    return _gaussian_blur_core(x, _as_dtype(sigma, x), radius=r, padding=padding, method=method)


def _as_dtype(value, x):
    """``value`` as an array of ``x``'s dtype (done before the jitted core, so that Python
    floats, NumPy scalars and arrays of other dtypes share one compiled program)."""
    return jnp.asarray(value, dtype=x.dtype)


def _gaussian_radius(sigma, truncate, radius, padding, method) -> int:
    """Validate :func:`gaussian_blur`'s options and return the static kernel radius."""
    check_padding(padding)
    check_choice(method, "method", ("auto", "direct", "fft"))
    check_nonnegative(sigma, "sigma")
    if jnp.ndim(sigma) != 0:
        raise ValueError(f"sigma: expected a scalar, got shape {jnp.shape(sigma)}")
    return _static_radius(sigma, truncate, radius)


def _gaussian_blur_impl(x, sigma, radius: int, padding: str, method: str):
    k = gaussian_kernel1d(sigma, radius, dtype=x.dtype)
    if radius == 0:
        return x * k[0]
    return _convolve_separable_core(x, k, k, padding=padding, method=method)


_gaussian_blur_core = jax.jit(_gaussian_blur_impl, static_argnames=("radius", "padding", "method"))


_BOX_CUMSUM_MIN = 15  # box sizes >= this use running sums instead of shift-and-add


def _box1d(y, size: int, axis: int, padding: str):
    r = size // 2
    n = y.shape[axis]
    if size < _BOX_CUMSUM_MIN:
        k = jnp.full((size,), 1.0 / size, y.dtype)
        return _conv1d(y, k, axis, padding, "direct")
    pads = [(0, 0), (0, 0)]
    pads[axis - 1] = (r, r)
    yp = pad_bhw(y, pads[0], pads[1], padding)
    acc = jnp.float64 if y.dtype == jnp.float64 else jnp.float32
    cs = jnp.cumsum(yp.astype(acc), axis=axis)
    zshape = list(cs.shape)
    zshape[axis] = 1
    cs = jnp.concatenate([jnp.zeros(zshape, cs.dtype), cs], axis=axis)
    hi = jax.lax.slice_in_dim(cs, size, size + n, axis=axis)
    lo = jax.lax.slice_in_dim(cs, 0, n, axis=axis)
    return ((hi - lo) / size).astype(y.dtype)


def box_blur(image, size, *, padding: str = "reflect"):
    """Mean over a ``size`` box (odd int, or ``(size_h, size_w)``), per channel.

    Separable; small boxes by shift-and-add, boxes of :data:`_BOX_CUMSUM_MIN` or more taps by
    running (cumulative) sums, O(1) per pixel. Matches ``cv2.blur(img, (size_w, size_h),
    borderType=cv2.BORDER_REFLECT_101)``.

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        size: odd int >= 1 (radius ``r`` is ``size = 2 r + 1``), or a pair of them.
        padding: border mode.

    Example:
        >>> box_blur(jnp.array([[0., 3., 0.]]), (1, 3), padding="zero")
        Array([[1., 1., 1.]], dtype=float32)
    """
    x = check_image(image)
    check_padding(padding)
    sh, sw = (size, size) if np.ndim(size) == 0 else tuple(size)
    sh = check_odd_int(sh, "size")
    sw = check_odd_int(sw, "size")
    return _box_blur_core(x, sh=sh, sw=sw, padding=padding)


@functools.partial(jax.jit, static_argnames=("sh", "sw", "padding"))
def _box_blur_core(x, *, sh: int, sw: int, padding: str):
    y, undo = to_bhw(x)
    if sh > 1:
        y = _box1d(y, sh, 1, padding)
    if sw > 1:
        y = _box1d(y, sw, 2, padding)
    return undo(y)


# ----------------------------------------------------------------------------- median


@functools.lru_cache(maxsize=32)
def _median_network(n: int):
    """Comparators (i, j) of Batcher's odd-even merge sort on ``n`` wires, pruned to those
    that the middle output depends on. Wires >= n are +inf padding (resolved statically)."""
    p2 = 1
    while p2 < n:
        p2 *= 2
    comps = []
    p = 1
    while p < p2:
        k = p
        while k >= 1:
            for j in range(k % p, p2 - k, 2 * k):
                for i in range(min(k, p2 - j - k)):
                    if (i + j) // (2 * p) == (i + j + k) // (2 * p):
                        comps.append((i + j, i + j + k))
            k //= 2
        p *= 2
    needed = {n // 2}
    kept = []
    for a, b in reversed(comps):
        if a in needed or b in needed:
            kept.append((a, b))
            needed |= {a, b}
    return p2, tuple(reversed(kept))


def _median_select(values):
    """Exact median of an odd-length list of equally shaped arrays via a min/max network."""
    n = len(values)
    p2, comps = _median_network(n)
    wires = list(values) + [None] * (p2 - n)  # None = +inf
    for a, b in comps:
        va, vb = wires[a], wires[b]
        if vb is None:
            continue
        if va is None:
            wires[a], wires[b] = vb, None
            continue
        wires[a], wires[b] = jnp.minimum(va, vb), jnp.maximum(va, vb)
    return wires[n // 2]


_MEDIAN_NETWORK_MAX = 49  # up to 7x7 windows use the selection network, larger ones sort


def median_filter(image, size, *, padding: str = "reflect"):
    """Exact median over a ``size x size`` window (odd ``size``), per channel.

    Windows up to 7x7 use a pruned Batcher odd-even merge network (elementwise min/max, which
    XLA fuses into one pass); larger windows sort the stacked shifts. Output values are always
    input values. Matches ``scipy.ndimage.median_filter(size=size, mode="mirror")`` exactly
    (``cv2.medianBlur`` with ``padding="edge"``).

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        size: odd int >= 1.
        padding: border mode.

    Example:
        >>> median_filter(jnp.array([[1., 9., 2., 3.]]), 3)
        Array([[9., 2., 3., 2.]], dtype=float32)

    (the border is mirrored: the first window is ``9 1 9`` -> 9, the last ``2 3 2`` -> 2.)
    """
    x = check_image(image)
    check_padding(padding)
    size = check_odd_int(size, "size")
    if size == 1:
        return x
    return _median_core(x, size=size, padding=padding)


@functools.partial(jax.jit, static_argnames=("size", "padding"))
def _median_core(x, *, size: int, padding: str):
    r = size // 2
    y, undo = to_bhw(x)
    H, W = y.shape[1], y.shape[2]
    yp = pad_bhw(y, (r, r), (r, r), padding)
    shifts = [yp[:, i : i + H, j : j + W] for i in range(size) for j in range(size)]
    if size * size <= _MEDIAN_NETWORK_MAX:
        return undo(_median_select(shifts))
    stacked = jnp.stack(shifts, axis=0)
    return undo(jnp.sort(stacked, axis=0)[size * size // 2])


# -------------------------------------------------------------------------- bilateral


def _bilateral_brute(y, sigma_spatial, sigma_range, radius: int, padding: str):
    """Tomasi & Manduchi (1998) on ``(B, H, W)`` ``y``: circular window of ``radius``."""
    H, W = y.shape[1], y.shape[2]
    yp = pad_bhw(y, (radius, radius), (radius, radius), padding)
    offs = [
        (i, j)
        for i in range(-radius, radius + 1)
        for j in range(-radius, radius + 1)
        if i * i + j * j <= radius * radius
    ]
    cs = -0.5 / (sigma_spatial * sigma_spatial)
    cr = -0.5 / (sigma_range * sigma_range)

    def contrib(i, j, q):
        w = jnp.exp(cs * (i * i + j * j) + cr * (q - y) ** 2)
        return w * q, w

    if len(offs) <= _UNROLL_TAPS:
        num = jnp.zeros_like(y)
        den = jnp.zeros_like(y)
        for i, j in offs:
            q = yp[:, radius + i : radius + i + H, radius + j : radius + j + W]
            a, b = contrib(float(i), float(j), q)
            num, den = num + a, den + b
    else:
        oi = jnp.asarray([o[0] for o in offs], jnp.int32)
        oj = jnp.asarray([o[1] for o in offs], jnp.int32)

        def body(t, carry):
            num, den = carry
            i, j = oi[t], oj[t]
            q = jax.lax.dynamic_slice(yp, (0, radius + i, radius + j), y.shape)
            a, b = contrib(i.astype(y.dtype), j.astype(y.dtype), q)
            return num + a, den + b

        num, den = jax.lax.fori_loop(0, len(offs), body, (jnp.zeros_like(y), jnp.zeros_like(y)))
    return num / den  # den >= 1 (centre tap)


_UNROLL_TAPS = 81


def _trilinear_corners(u, v, w):
    u0, v0, w0 = jnp.floor(u), jnp.floor(v), jnp.floor(w)
    fu, fv, fw = u - u0, v - v0, w - w0
    out = []
    for du in (0, 1):
        for dv in (0, 1):
            for dw in (0, 1):
                wt = (fu if du else 1 - fu) * (fv if dv else 1 - fv) * (fw if dw else 1 - fw)
                out.append(
                    (
                        u0.astype(jnp.int32) + du,
                        v0.astype(jnp.int32) + dv,
                        w0.astype(jnp.int32) + dw,
                        wt,
                    )
                )
    return out


def _bilateral_grid(y, sigma_spatial: float, sigma_range, range_bins: int):
    """Chen, Paris & Durand (2007) bilateral grid on ``(B, H, W)`` ``y`` (one grid per B)."""
    B, H, W = y.shape
    P = 2  # grid padding (blur radius in cells)
    x = y
    vmin = jnp.min(x, axis=(1, 2), keepdims=True)
    Gh = int(math.floor((H - 1) / sigma_spatial)) + 2 * P + 2
    Gw = int(math.floor((W - 1) / sigma_spatial)) + 2 * P + 2
    Gz = range_bins + 2 * P + 2
    yy = jnp.arange(H, dtype=x.dtype)[:, None] / sigma_spatial + P
    xx = jnp.arange(W, dtype=x.dtype)[None, :] / sigma_spatial + P
    u = jnp.broadcast_to(yy, (B, H, W))
    v = jnp.broadcast_to(xx, (B, H, W))
    w = jnp.clip((x - vmin) / sigma_range + P, P, Gz - P - 1.0001)
    b = jnp.broadcast_to(jnp.arange(B)[:, None, None], (B, H, W))
    corners = _trilinear_corners(u, v, w)
    size = B * Gh * Gw * Gz
    grid_v = jnp.zeros((size,), x.dtype)
    grid_w = jnp.zeros((size,), x.dtype)
    for iu, iv, iw, wt in corners:
        flat = ((b * Gh + iu) * Gw + iv) * Gz + iw
        grid_v = grid_v.at[flat].add(wt * x)
        grid_w = grid_w.at[flat].add(wt)
    grid = jnp.stack([grid_v, grid_w], -1).reshape(B, Gh, Gw, Gz, 2)
    k = jnp.exp(-0.5 * jnp.arange(-P, P + 1, dtype=x.dtype) ** 2)
    k = k / jnp.sum(k)
    for ax in (1, 2, 3):
        gp = jnp.pad(grid, [(0, 0)] * ax + [(P, P)] + [(0, 0)] * (4 - ax))
        n = grid.shape[ax]
        grid = sum(k[t] * jax.lax.slice_in_dim(gp, t, t + n, axis=ax) for t in range(2 * P + 1))
    flat_grid = grid.reshape(-1, 2)
    num = jnp.zeros_like(x)
    den = jnp.zeros_like(x)
    for iu, iv, iw, wt in corners:
        flat = ((b * Gh + iu) * Gw + iv) * Gz + iw
        g = flat_grid[flat]
        num = num + wt * g[..., 0]
        den = den + wt * g[..., 1]
    return safe_div(num, den)


def bilateral_Tomasi1998(image, sigma_spatial, sigma_range, *, radius=None, padding="reflect"):
    """Brute-force bilateral filter (Tomasi & Manduchi, ICCV 1998), per channel.

    ``out(p) = sum_q w(p, q) I(q) / sum_q w(p, q)`` over the disc ``|q - p| <= radius``, with
    ``w = exp(-|q - p|^2 / (2 sigma_spatial^2) - (I(q) - I(p))^2 / (2 sigma_range^2))``.
    Default radius ``round(1.5 * sigma_spatial)`` (OpenCV's choice). Differentiable in the
    image and both sigmas. See :func:`bilateral_filter`.
    """
    return bilateral_filter(
        image, sigma_spatial, sigma_range, method="brute", radius=radius, padding=padding
    )


def bilateral_Chen2007(image, sigma_spatial, sigma_range, *, range_bins=None):
    """Bilateral grid approximation (Paris & Durand 2006; Chen, Paris & Durand 2007).

    See :func:`bilateral_filter` with ``method="grid"``.
    """
    return bilateral_filter(image, sigma_spatial, sigma_range, method="grid", range_bins=range_bins)


BILATERAL_METHODS = {"Tomasi1998": bilateral_Tomasi1998, "Chen2007": bilateral_Chen2007}


def bilateral_filter(
    image,
    sigma_spatial,
    sigma_range,
    *,
    method: str = "auto",
    radius: int | None = None,
    padding: str = "reflect",
    range_bins: int | None = None,
):
    """Edge-preserving bilateral filter, every channel filtered on its own values.

    Methods:

    - ``"brute"`` (Tomasi & Manduchi 1998): exact sum over the disc of ``radius`` (default
      ``round(1.5 * sigma_spatial)``, as OpenCV), weights ``exp(-d^2/(2 ss^2)) *
      exp(-(I_q - I_p)^2/(2 sr^2))``. On single-channel input it matches
      ``cv2.bilateralFilter(img, 0, sr, ss)`` (BORDER_REFLECT_101) to ~1e-4 (OpenCV
      tabulates the range Gaussian). OpenCV filters colour images jointly with an L1 colour
      distance; here channels are independent.
    - ``"grid"`` (Paris & Durand 2006; Chen, Paris & Durand 2007): splat into a 3-d grid with
      cells ``sigma_spatial`` pixels by ``sigma_range`` value units (trilinear), blur it by a
      5-tap Gaussian (sigma = 1 cell), slice trilinearly. Works on any value range (e.g. log
      luminance): the range axis spans ``[min, max]`` of each channel. Cost independent of
      sigma_spatial; borders behave like zero padding with renormalisation.
    - ``"auto"``: brute when ``radius <= 4`` else grid.

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``, any finite values.
        sigma_spatial: > 0, pixels. Concrete for ``"grid"``; may be traced for ``"brute"``
            when ``radius`` is given.
        sigma_range: > 0, in image value units; may be traced (for ``"grid"`` then pass
            ``range_bins``).
        radius: brute-force window radius (static).
        padding: border mode for ``"brute"``.
        range_bins: number of range cells for ``"grid"``; default
            ``ceil((max - min) / sigma_range)`` from a concrete image.

    Returns:
        Filtered image, same shape and dtype.

    Example:
        >>> out = bilateral_filter(jnp.array([[0., 0., 1., 1.]]), 1.0, 0.1, method="brute")
        >>> jnp.round(out, 6)  # the step survives (a Gaussian blur would smear it)
        Array([[0., 0., 1., 1.]], dtype=float32)
    """
    x = check_image(image)
    check_choice(method, "method", ("auto", "brute", "grid"))
    check_padding(padding)
    check_positive(sigma_spatial, "sigma_spatial")
    check_positive(sigma_range, "sigma_range")
    for name, s in (("sigma_spatial", sigma_spatial), ("sigma_range", sigma_range)):
        if jnp.ndim(s) != 0:
            raise ValueError(f"{name}: expected a scalar, got shape {jnp.shape(s)}")
    if radius is None and method != "grid":
        if not is_concrete(sigma_spatial):
            raise ValueError("radius: sigma_spatial is traced; pass a static radius=int")
        radius = max(1, int(round(1.5 * float(sigma_spatial))))
    if method == "auto":
        method = "brute" if radius <= 4 else "grid"
    if method == "brute":
        radius = _static_radius(sigma_spatial, 1.5, radius, "sigma_spatial")
        return _bilateral_brute_core(
            x,
            _as_dtype(sigma_spatial, x),
            _as_dtype(sigma_range, x),
            radius=radius,
            padding=padding,
        )
    if not is_concrete(sigma_spatial):
        raise ValueError("sigma_spatial: method='grid' needs a concrete sigma_spatial")
    if range_bins is None:
        if not (is_concrete(x) and is_concrete(sigma_range)):
            raise ValueError(
                "range_bins: image or sigma_range is traced; pass a static range_bins=int"
            )
        a = np.asarray(x)
        hw = (0, 1) if a.ndim == 2 else (a.ndim - 3, a.ndim - 2)  # per channel (and image)
        span = float(np.max(a.max(axis=hw) - a.min(axis=hw)))
        range_bins = max(1, int(math.ceil(span / float(sigma_range))))
    elif isinstance(range_bins, bool) or not isinstance(range_bins, (int, np.integer)):
        raise TypeError(f"range_bins: expected an int, got {type(range_bins).__name__}")
    elif range_bins < 1:
        raise ValueError(f"range_bins: expected an int >= 1, got {range_bins}")
    return _bilateral_grid_core(
        x,
        _as_dtype(sigma_range, x),
        sigma_spatial=float(sigma_spatial),
        range_bins=int(range_bins),
    )


@functools.partial(jax.jit, static_argnames=("radius", "padding"))
def _bilateral_brute_core(x, sigma_spatial, sigma_range, *, radius: int, padding: str):
    y, undo = to_bhw(x)
    return undo(_bilateral_brute(y, sigma_spatial, sigma_range, radius, padding))


@functools.partial(jax.jit, static_argnames=("sigma_spatial", "range_bins"))
def _bilateral_grid_core(x, sigma_range, *, sigma_spatial: float, range_bins: int):
    y, undo = to_bhw(x)
    return undo(_bilateral_grid(y, sigma_spatial, sigma_range, range_bins))


# ----------------------------------------------------------------------- sharpening


def unsharp_mask(
    image,
    sigma,
    amount,
    *,
    threshold=0.0,
    truncate: float = 3.0,
    radius: int | None = None,
    padding: str = "reflect",
):
    """Unsharp masking: ``image + amount * shrink(image - gaussian_blur(image, sigma))``.

    ``shrink(d) = d - clip(d, -threshold, threshold)`` (soft thresholding / coring):
    details smaller than ``threshold`` are not amplified, and the output is continuous and
    differentiable in ``threshold``. With ``threshold = 0`` this equals
    ``skimage.filters.unsharp_mask(preserve_range=True)`` for the same Gaussian. No clipping.

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        sigma: blur width in pixels, >= 0 (traced with ``radius``).
        amount: detail gain (any real; 0 = identity).
        threshold: >= 0, image value units.

    Example:
        >>> x = jnp.array([[0., 0., 1., 1.]])
        >>> round(float(unsharp_mask(x, 1.0, 1.0)[0, 1]), 3)  # undershoot before the step
        -0.305
    """
    x = check_image(image)
    check_nonnegative(threshold, "threshold")
    r = _gaussian_radius(sigma, truncate, radius, padding, "auto")
    return _unsharp_core(
        x,
        _as_dtype(sigma, x),
        _as_dtype(amount, x),
        _as_dtype(threshold, x),
        radius=r,
        padding=padding,
    )


@functools.partial(jax.jit, static_argnames=("radius", "padding"))
def _unsharp_core(x, sigma, amount, threshold, *, radius: int, padding: str):
    d = x - _gaussian_blur_impl(x, sigma, radius, padding, "auto")
    d = d - jnp.clip(d, -threshold, threshold)
    return x + amount * d


def laplacian_of_gaussian(
    image, sigma, *, truncate: float = 4.0, radius: int | None = None, padding: str = "reflect"
):
    """Laplacian of Gaussian ``(d^2/dy^2 + d^2/dx^2)(G_sigma * f)``, per channel.

    Separable: ``G'' (y) G(x) + G(y) G''(x)`` with ``G`` the normalised sampled Gaussian and
    ``G''(i) = G(i) (i^2 / sigma^4 - 1 / sigma^2)``, exactly as
    ``scipy.ndimage.gaussian_laplace`` (default ``truncate = 4``, its default too). Negative
    at bright blobs (Marr & Hildreth, 1980). For a quadratic ``f = a (y^2 + x^2)`` it gives
    ``4 a`` as the truncation goes to infinity.

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        sigma: > 0 pixels (traced with a static ``radius``).

    Example:
        >>> yy, xx = jnp.mgrid[-10:11, -10:11].astype(jnp.float32)
        >>> round(float(laplacian_of_gaussian(yy**2 + xx**2, 1.0)[10, 10]), 2)
        4.0
    """
    x = check_image(image)
    check_padding(padding)
    check_positive(sigma, "sigma")
    s_min = float(jnp.finfo(x.dtype).max) ** (-1.0 / 3.0) * 4.0
    if is_concrete(sigma) and float(np.min(np.asarray(sigma))) < s_min:
        raise ValueError(
            f"sigma: expected >= {s_min:.3g} pixels for {jnp.dtype(x.dtype).name} images (the "
            f"kernel's centre -2/sigma^2 and its sigma-derivative overflow below), got {sigma!r}"
        )
    r = max(1, _static_radius(sigma, truncate, radius))
    return _log_core(x, _as_dtype(sigma, x), radius=r, padding=padding)


@functools.partial(jax.jit, static_argnames=("radius", "padding"))
def _log_core(x, s, *, radius: int, padding: str):
    r = radius
    g = gaussian_kernel1d(s, r, dtype=x.dtype)
    i = jnp.arange(-r, r + 1, dtype=x.dtype)
    # G''(i) = G(i) i^2 / s^4 - G(i) / s^2. The first term in log space: G(i) underflows to 0
    # for s << 1 while i^2 / s^4 overflows, and 0 * inf would make the sigma-gradient NaN.
    i2 = i * i
    log_g = jax.nn.log_softmax(-i2 / (2.0 * s * s))
    safe_i2 = jnp.where(i == 0, 1.0, i2)
    tail = jnp.where(i == 0, 0.0, jnp.exp(log_g + jnp.log(safe_i2) - 4.0 * jnp.log(s)))
    g2 = tail - g / (s * s)
    return _convolve_separable_core(
        x, g2, g, padding=padding, method="auto"
    ) + _convolve_separable_core(x, g, g2, padding=padding, method="auto")


def sharpen(image, amount=1.0, *, padding: str = "reflect"):
    """The lecture's 3x3 "hat" sharpening filter: ``(1 + amount) delta - amount * box3``.

    Kernel: centre ``1 + 8 amount / 9``, the eight neighbours ``-amount / 9`` (sums to 1,
    so flat regions are unchanged); ``amount = 1`` is ``(1/9) [[-1,-1,-1],[-1,17,-1],
    [-1,-1,-1]]``. A cheap unsharp mask with a box blur; ``amount`` is differentiable.

    Example:
        >>> sharpen(jnp.array([[0., 0., 0.], [0., 9., 0.], [0., 0., 0.]]), padding="zero")[1, 1]
        Array(17., dtype=float32)
    """
    x = check_image(image)
    check_padding(padding)
    return _sharpen_core(x, _as_dtype(amount, x), padding=padding)


@functools.partial(jax.jit, static_argnames=("padding",))
def _sharpen_core(x, a, *, padding: str):
    k = jnp.full((3, 3), -1.0 / 9.0, x.dtype) * a
    k = k.at[1, 1].add(1.0 + a)
    return _convolve_core(x, k, padding=padding, method="direct")
