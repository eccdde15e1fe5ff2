"""Image gradients (Roberts, Prewitt, Sobel) and Canny edge detection (hard and soft).

Axes convention: ``x`` runs along W (columns, rightwards), ``y`` along H (rows, downwards);
``gx > 0`` where intensity grows to the right, ``gy > 0`` where it grows downwards (the sign
of ``cv2.Sobel`` and ``scipy.ndimage.sobel``). The gradient operators act per channel; Canny
works on one channel: multi-channel input ``(..., H, W, C)`` is reduced to the channel mean
first and the edge map has shape ``(..., H, W)``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import check_choice, check_image, check_nonnegative, check_positive
from jaxgfx._math import safe_atan2, safe_div, safe_sqrt

from ._padding import check_padding, pad_bhw, to_bhw
from .convolve import _conv1d
from .filters import _as_dtype, _static_radius, gaussian_kernel1d

__all__ = [
    "EDGE_OPERATORS",
    "roberts",
    "prewitt",
    "sobel",
    "image_gradients",
    "gradient_magnitude_direction",
    "canny",
    "soft_canny",
]


def _smoothed_diff_bhw(y, smooth, padding):
    H, W = y.shape[1], y.shape[2]
    p = pad_bhw(y, (1, 1), (1, 1), padding)
    s0, s1, s2 = smooth

    def sl(i, j):
        return p[:, i : i + H, j : j + W]

    dx = [sl(i, 2) - sl(i, 0) for i in range(3)]  # f(x+1) - f(x-1) on rows y-1, y, y+1
    dy = [sl(2, j) - sl(0, j) for j in range(3)]
    gx = s0 * dx[0] + s1 * dx[1] + s2 * dx[2]
    gy = s0 * dy[0] + s1 * dy[1] + s2 * dy[2]
    return gx, gy


def _smoothed_diff_xy(x, smooth, padding):
    """``(gx, gy)`` of a checked image in its own layout (traceable, no checks)."""
    y, undo = to_bhw(x)
    gx, gy = _smoothed_diff_bhw(y, smooth, padding)
    return undo(gx), undo(gy)


_smoothed_diff_core = jax.jit(_smoothed_diff_xy, static_argnames=("smooth", "padding"))


def _smoothed_diff(image, smooth, padding):
    x = check_image(image)
    check_padding(padding)
    return _smoothed_diff_core(x, smooth, padding)


def sobel(image, *, padding: str = "reflect"):
    """Sobel derivatives ``(gx, gy)``: ``[-1, 0, 1]`` differences smoothed by ``[1, 2, 1]``.

    Equals ``cv2.Sobel(img, -1, 1, 0)`` / ``(0, 1)`` (ksize 3, BORDER_REFLECT_101); for a
    ramp ``f = x`` it gives ``gx = 8``. Shapes as the image. (Sobel & Feldman, 1968.)

    Example:
        >>> gx, gy = sobel(jnp.tile(jnp.arange(4.0), (4, 1)))
        >>> gx[1, 1], gy[1, 1]
        (Array(8., dtype=float32), Array(0., dtype=float32))
    """
    return _smoothed_diff(image, (1.0, 2.0, 1.0), padding)


def prewitt(image, *, padding: str = "reflect"):
    """Prewitt derivatives ``(gx, gy)``: ``[-1, 0, 1]`` differences summed over 3 rows/cols.

    Unnormalised (a ramp ``f = x`` gives ``gx = 6``). (Prewitt, 1970.)

    Example:
        >>> prewitt(jnp.tile(jnp.arange(4.0), (4, 1)))[0][1, 1]
        Array(6., dtype=float32)
    """
    return _smoothed_diff(image, (1.0, 1.0, 1.0), padding)


def roberts(image, *, padding: str = "reflect"):
    """Roberts cross diagonal differences ``(g1, g2)`` (Roberts, 1963).

    ``g1[y, x] = f[y+1, x+1] - f[y, x]`` and ``g2[y, x] = f[y+1, x] - f[y, x+1]`` (the
    lecture's kernels ``[[-1, 0], [0, 1]]`` and ``[[0, -1], [1, 0]]`` anchored at their
    top-left tap); the last row/column use ``padding``. Gradient at the half-pixel centre:
    ``gx = (g1 - g2) / 2``, ``gy = (g1 + g2) / 2`` (what :func:`image_gradients` returns).

    Example:
        >>> roberts(jnp.array([[0., 1.], [2., 3.]]))[0][0, 0]
        Array(3., dtype=float32)
    """
    x = check_image(image)
    check_padding(padding)
    return _roberts_core(x, padding=padding)


def _roberts_bhw(x, padding):
    y, undo = to_bhw(x)
    H, W = y.shape[1], y.shape[2]
    p = pad_bhw(y, (0, 1), (0, 1), padding)
    g1 = p[:, 1 : H + 1, 1 : W + 1] - p[:, :H, :W]
    g2 = p[:, 1 : H + 1, :W] - p[:, :H, 1 : W + 1]
    return undo(g1), undo(g2)


_roberts_core = jax.jit(_roberts_bhw, static_argnames=("padding",))


def _gradients(x, operator, padding):
    """``(gx, gy)`` of a checked image by ``operator`` (traceable, no checks)."""
    if operator == "roberts":
        g1, g2 = _roberts_bhw(x, padding)
        return 0.5 * (g1 - g2), 0.5 * (g1 + g2)
    smooth = (1.0, 2.0, 1.0) if operator == "sobel" else (1.0, 1.0, 1.0)
    return _smoothed_diff_xy(x, smooth, padding)


_gradients_core = jax.jit(_gradients, static_argnames=("operator", "padding"))


def _roberts_xy(image, *, padding="reflect"):
    x = check_image(image)
    check_padding(padding)
    return _gradients_core(x, "roberts", padding)


EDGE_OPERATORS = {"roberts": _roberts_xy, "prewitt": prewitt, "sobel": sobel}


def image_gradients(image, *, operator: str = "sobel", padding: str = "reflect"):
    """Image derivatives ``(gx, gy)`` by ``operator`` in :data:`EDGE_OPERATORS`.

    ``"sobel"`` / ``"prewitt"`` are unnormalised (gain 8 / 6 on a unit ramp); ``"roberts"``
    returns the half-pixel gradient (gain 1). Shapes as the image.

    Example:
        >>> image_gradients(jnp.tile(jnp.arange(4.0), (4, 1)), operator="roberts")[0][1, 1]
        Array(1., dtype=float32)
    """
    check_choice(operator, "operator", tuple(EDGE_OPERATORS))
    return EDGE_OPERATORS[operator](image, padding=padding)


def gradient_magnitude_direction(image, *, operator: str = "sobel", padding: str = "reflect"):
    """``(|g|, atan2(gy, gx))``: magnitude and direction in radians, ``(-pi, pi]``.

    Both are finite with finite gradients where ``g = 0`` (direction 0 there).

    Example:
        >>> m, t = gradient_magnitude_direction(jnp.tile(jnp.arange(4.0), (4, 1)))
        >>> m[1, 1], t[1, 1]
        (Array(8., dtype=float32), Array(0., dtype=float32))
    """
    check_choice(operator, "operator", tuple(EDGE_OPERATORS))
    x = check_image(image)
    check_padding(padding)
    return _magnitude_direction_core(x, operator=operator, padding=padding)


@functools.partial(jax.jit, static_argnames=("operator", "padding"))
def _magnitude_direction_core(x, *, operator, padding):
    gx, gy = _gradients(x, operator, padding)
    return safe_sqrt(gx * gx + gy * gy), safe_atan2(gy, gx)


# --------------------------------------------------------------------------- Canny


def _neighbours(mag, gx, gy):
    """Magnitude interpolated one pixel forward/backward along the gradient, ``(B, H, W)``."""
    H, W = mag.shape[1], mag.shape[2]
    p = jnp.pad(mag, ((0, 0), (1, 1), (1, 1)))

    def at(dy, dx):
        return p[:, 1 + dy : 1 + dy + H, 1 + dx : 1 + dx + W]

    ax, ay = jnp.abs(gx), jnp.abs(gy)
    sx = gx >= 0
    sy = gy >= 0
    horiz = ax >= ay
    w = jnp.where(horiz, safe_div(ay, ax), safe_div(ax, ay))

    def pick(fy, fx):
        # fy, fx in {+1, -1}: the signed step direction along each axis for "forward".
        out = {}
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                out[(dy, dx)] = at(dy, dx)
        sgn_y = jnp.where(sy, fy, -fy)
        sgn_x = jnp.where(sx, fx, -fx)

        def sel(dy_pos, dx_pos):
            # neighbour at (sgn_y * dy_pos, sgn_x * dx_pos), dy_pos/dx_pos in {0, 1}
            a = out[(dy_pos, dx_pos)]
            b = out[(-dy_pos, dx_pos)]
            c = out[(dy_pos, -dx_pos)]
            d = out[(-dy_pos, -dx_pos)]
            return jnp.where(sgn_y > 0, jnp.where(sgn_x > 0, a, c), jnp.where(sgn_x > 0, b, d))

        straight = jnp.where(horiz, sel(0, 1), sel(1, 0))
        diag = sel(1, 1)
        return (1 - w) * straight + w * diag

    return pick(1, 1), pick(-1, -1)


def _canny_magnitude(x, sigma, padding, r):
    if x.ndim > 2:
        x = jnp.mean(x, axis=-1, keepdims=True)
    y, undo = to_bhw(x)
    if r > 0:
        k = gaussian_kernel1d(sigma, r, dtype=y.dtype)
        y = _conv1d(_conv1d(y, k, 1, padding, "auto"), k, 2, padding, "auto")
    gx, gy = _smoothed_diff_bhw(y, (1.0, 2.0, 1.0), padding)
    mag = safe_sqrt(gx * gx + gy * gy)
    return mag, gx, gy, undo


def _dilate8(e):
    H, W = e.shape[1], e.shape[2]
    p = jnp.pad(e, ((0, 0), (1, 1), (1, 1)))
    out = e
    for dy in range(3):
        for dx in range(3):
            if dy != 1 or dx != 1:
                out = out | p[:, dy : dy + H, dx : dx + W]
    return out


def _hysteresis(strong, weak, steps_per_check: int = 8):
    def cond(state):
        return state[1]

    def body(state):
        e, _ = state
        new = e
        for _ in range(steps_per_check):
            new = weak & _dilate8(new)
        return new, jnp.any(new != e)

    e, _ = jax.lax.while_loop(cond, body, (strong, jnp.array(True)))
    return e


def _border_mask(shape):
    H, W = shape[1], shape[2]
    m = np.zeros((H, W), bool)
    m[1:-1, 1:-1] = True
    return jnp.asarray(m)[None]


def canny(
    image,
    sigma=1.0,
    low=0.1,
    high=0.2,
    *,
    use_quantiles: bool = False,
    padding: str = "reflect",
    truncate: float = 4.0,
    radius: int | None = None,
):
    """Canny edge detector (Canny, PAMI 1986) -> boolean edge map.

    Steps: channel mean; Gaussian blur (``sigma``, radius ``ceil(truncate * sigma)``);
    Sobel ``(gx, gy)``; magnitude ``hypot(gx, gy)``; non-maximum suppression against the
    magnitude *interpolated* at one pixel forward and backward along the gradient (as
    scikit-image); double threshold; hysteresis: weak pixels 8-connected to strong ones, by
    iterated dilation in a ``lax.while_loop`` until nothing changes. The one-pixel image
    border is never an edge (as scikit-image).

    Thresholds are absolute on the (unnormalised, ``cv2.Sobel``-scale) Sobel magnitude of the
    blurred image: a unit step blurred by ``sigma`` peaks near ``8 / (sqrt(2 pi) sigma)``.
    Defaults ``low = 0.1``, ``high = 0.2`` as ``skimage.feature.canny`` for float images.
    With ``use_quantiles=True`` they are quantiles in ``[0, 1]`` of the magnitude image.
    A pixel with zero gradient magnitude is never an edge, so a flat image has no edges
    whatever the thresholds (as scikit-image).

    Args:
        image: ``(H, W)`` or ``(..., H, W, C)``.
        sigma: blur width in pixels, >= 0.
        low, high: thresholds, ``0 <= low <= high`` (``None``: the defaults 0.1, 0.2).

    Returns:
        Boolean ``(..., H, W)``.

    Agreement: >= 95% F1 (1-pixel tolerance) with ``skimage.feature.canny(mode="mirror")``
    on shapes + noise (tests/image/test_edges.py).

    Example:
        >>> img = jnp.zeros((9, 9)).at[:, 4].set(0.5).at[:, 5:].set(1.0)
        >>> canny(img, 1.0)[4].astype(int)
        Array([0, 0, 0, 0, 1, 0, 0, 0, 0], dtype=int32)
    """
    x = check_image(image)
    check_padding(padding)
    check_nonnegative(sigma, "sigma")
    low = 0.1 if low is None else low
    high = 0.2 if high is None else high
    check_nonnegative(low, "low")
    check_nonnegative(high, "high")
    if isinstance(low, (int, float)) and isinstance(high, (int, float)) and low > high:
        raise ValueError(f"low: expected low <= high, got low={low}, high={high}")
    if use_quantiles:
        for name, q in (("low", low), ("high", high)):
            if isinstance(q, (int, float)) and q > 1:
                raise ValueError(f"{name}: quantile must be in [0, 1], got {q}")
    r = _static_radius(sigma, truncate, radius)
    return _canny_core(
        x,
        _as_dtype(sigma, x),
        _as_dtype(low, x),
        _as_dtype(high, x),
        radius=r,
        use_quantiles=bool(use_quantiles),
        padding=padding,
    )


@functools.partial(jax.jit, static_argnames=("radius", "use_quantiles", "padding"))
def _canny_core(x, sigma, low, high, *, radius, use_quantiles, padding):
    mag, gx, gy, undo = _canny_magnitude(x, sigma, padding, radius)
    if use_quantiles:
        flat = mag.reshape(mag.shape[0], -1)
        lo = jnp.quantile(flat, low, axis=1)[:, None, None]
        hi = jnp.quantile(flat, high, axis=1)[:, None, None]
    else:
        lo = jnp.asarray(low, mag.dtype)
        hi = jnp.asarray(high, mag.dtype)
    fwd, bwd = _neighbours(mag, gx, gy)
    # a pixel without gradient is never an edge (a flat image has none, as scikit-image),
    # whatever the thresholds (quantile thresholds of a flat image are 0)
    nms = (mag >= fwd) & (mag >= bwd) & (mag > 0) & _border_mask(mag.shape)
    weak = nms & (mag >= lo)
    strong = weak & (mag >= hi)
    e = _hysteresis(strong, weak)
    return undo(e)[..., 0] if x.ndim > 2 else undo(e)


def soft_canny(
    image,
    sigma,
    low,
    high,
    *,
    temperature=0.05,
    iterations: int = 2,
    padding: str = "reflect",
    truncate: float = 4.0,
    radius: int | None = None,
):
    """Differentiable relaxation of :func:`canny` -> edge probability in ``[0, 1]``.

    Same smoothing, Sobel and interpolated neighbours; each hard comparison becomes a
    sigmoid with ``temperature`` (magnitude units): ``nms = s((m - max(fwd, bwd)) / T)``,
    ``weak = nms * s((m - low) / T)``, ``strong = nms * s((m - high) / T)``; hysteresis is
    ``iterations`` steps of ``e <- max(e, weak * maxpool3x3(e))`` starting from ``strong``.
    As ``T -> 0`` and ``iterations -> inf`` it tends to :func:`canny` (without the border
    rule). Differentiable in the image, ``sigma`` (with ``radius``), ``low``, ``high``, ``T``.

    Returns:
        ``(..., H, W)`` float array of the image's dtype.

    Example:
        >>> img = jnp.zeros((9, 9)).at[:, 4].set(0.5).at[:, 5:].set(1.0)
        >>> float(soft_canny(img, 1.0, 0.1, 0.2, temperature=0.01)[4, 4]) > 0.99
        True
    """
    x = check_image(image)
    check_padding(padding)
    check_nonnegative(sigma, "sigma")
    check_nonnegative(low, "low")
    check_nonnegative(high, "high")
    check_positive(temperature, "temperature")
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 0:
        raise ValueError(f"iterations: expected a non-negative int, got {iterations!r}")
    r = _static_radius(sigma, truncate, radius)
    return _soft_canny_core(
        x,
        _as_dtype(sigma, x),
        _as_dtype(low, x),
        _as_dtype(high, x),
        _as_dtype(temperature, x),
        radius=r,
        iterations=iterations,
        padding=padding,
    )


@functools.partial(jax.jit, static_argnames=("radius", "iterations", "padding"))
def _soft_canny_core(x, sigma, low, high, temperature, *, radius, iterations, padding):
    mag, gx, gy, undo = _canny_magnitude(x, sigma, padding, radius)
    t = jnp.asarray(temperature, mag.dtype)
    fwd, bwd = _neighbours(mag, gx, gy)
    nms = jax.nn.sigmoid((mag - jnp.maximum(fwd, bwd)) / t)
    weak = nms * jax.nn.sigmoid((mag - jnp.asarray(low, mag.dtype)) / t)
    e = nms * jax.nn.sigmoid((mag - jnp.asarray(high, mag.dtype)) / t)
    H, W = e.shape[1], e.shape[2]
    for _ in range(iterations):
        p = jnp.pad(e, ((0, 0), (1, 1), (1, 1)))
        pooled = e
        for dy in range(3):
            for dx in range(3):
                pooled = jnp.maximum(pooled, p[:, dy : dy + H, dx : dx + W])
        e = jnp.maximum(e, weak * pooled)
    return undo(e)[..., 0] if x.ndim > 2 else undo(e)
