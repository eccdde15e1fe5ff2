"""Film: pixel sample positions and reconstruction filters.

Reconstruction uses *filter importance sampling* (as pbrt-v4): each camera sample's offset from
the pixel centre is drawn from the (normalised, non-negative) filter, and the sample then
contributes with weight 1 to its own pixel only. The pixel estimate is the plain mean of its
samples — unbiased for the filtered image, without splatting or atomics.

Filters follow Mitsuba 3's defaults: ``box`` (radius 0.5 px), ``gaussian`` (stddev 0.5 px,
radius 4 stddev = 2 px, lowered by its value at the radius as Mitsuba's) and ``tent`` (radius
1 px: the separable ``max(0, 1 - |x| / r) max(0, 1 - |y| / r)``, Mitsuba's ``tent``).

Filters with negative lobes (Mitsuba's ``mitchell``, ``catmullrom``, ``lanczos``; separable
``f(x) f(y)``) are importance-sampled as in pbrt-v4: per axis the offset is drawn from ``|f|``
(a tabulated inverse CDF) and the sample carries the weight
``sign(f(x) f(y)) (∫|f| / ∫f)²`` (:func:`pixel_samples` with ``with_weights=True``), so that the
pixel mean stays an unbiased estimate of the normalised filtered image. The filters without
negative lobes carry no weight (``None``): their program is unchanged.
"""

from __future__ import annotations

import dataclasses
import functools
import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import check_choice, check_positive, check_positive_int
from jaxgfx.render.sampler import uniform

__all__ = [
    "BoxFilter",
    "CatmullRomFilter",
    "GaussianFilter",
    "LanczosFilter",
    "MitchellFilter",
    "TentFilter",
    "make_filter",
    "pixel_samples",
    "FILTERS",
]


class BoxFilter(eqx.Module):
    """Uniform filter over ``[-radius, radius]^2`` pixels (radius 0.5 = one pixel)."""

    radius: float = eqx.field(static=True, default=0.5)

    def sample(self, u):
        """Offsets (..., 2) from uniform numbers ``u (..., 2)``."""
        return (2.0 * u - 1.0) * self.radius


class GaussianFilter(eqx.Module):
    """Mitsuba 3's ``gaussian``: per axis ``max(0, exp(-x²/2σ²) - exp(-r²/2σ²))`` on
    ``[-r, r]`` (stddev ``σ`` 0.5 px, radius ``r`` 4σ by default), i.e. a Gaussian lowered by its
    value at the radius so that it reaches zero there, as Mitsuba's filter does."""

    stddev: float = eqx.field(static=True, default=0.5)
    radius: float = eqx.field(static=True, default=2.0)

    def _inverse_cdf_table(self):
        # the CDF in closed form (erf minus the linear bias term) on a fine grid, float64
        # numpy, inverted by linear interpolation: O(h^2) with h = r / 1024
        s2 = self.stddev * np.sqrt(2.0)
        bias = np.exp(-((self.radius / s2) ** 2))
        x = np.linspace(-self.radius, self.radius, 2049)
        erf_np = np.vectorize(math.erf)
        c = 0.5 * s2 * np.sqrt(np.pi) * (erf_np(x / s2) + erf_np(self.radius / s2))
        c = c - bias * (x + self.radius)
        return c / c[-1], x

    def sample(self, u):
        """Offsets (..., 2) from uniform numbers ``u (..., 2)`` (inverse CDF per axis)."""
        cdf, x = self._inverse_cdf_table()
        return jnp.interp(u, jnp.asarray(cdf, u.dtype), jnp.asarray(x, u.dtype))

    def eval(self, x):
        """The (unnormalised) 1-D filter value at offsets ``x`` (Mitsuba's ``eval``)."""
        a = -0.5 / self.stddev**2
        return jnp.maximum(jnp.exp(a * x * x) - math.exp(a * self.radius**2), 0.0)


class TentFilter(eqx.Module):
    """Separable tent ``max(0, 1 - |x| / r) max(0, 1 - |y| / r)`` of radius ``radius`` pixels
    (Mitsuba 3 ``tent``, default radius 1)."""

    radius: float = eqx.field(static=True, default=1.0)

    def sample(self, u):
        # inverse CDF of the triangle density on [-r, r], per axis
        left = jnp.sqrt(2.0 * u) - 1.0
        right = 1.0 - jnp.sqrt(jnp.maximum(2.0 - 2.0 * u, 0.0))
        return jnp.where(u < 0.5, left, right) * self.radius


# -- filters with negative lobes: sampled from |f|, signed sample weights ---------------------

_CELLS_PER_PIXEL = 1024  # the tables' grid: h = 1/1024 px (trapezoid rule, O(h^2))


def _mitchell_np(x, b, c):
    """Mitchell-Netravali cubic (B, C) at offsets ``x`` (numpy or jax arrays), radius 2
    (Mitchell & Netravali 1988, eq. 8)."""
    xp = jnp if isinstance(x, jnp.ndarray) else np
    x = xp.abs(x)
    x2, x3 = x * x, x * x * x
    near = (12.0 - 9.0 * b - 6.0 * c) * x3 + (-18.0 + 12.0 * b + 6.0 * c) * x2 + (6.0 - 2.0 * b)
    far = (
        (-b - 6.0 * c) * x3
        + (6.0 * b + 30.0 * c) * x2
        + (-12.0 * b - 48.0 * c) * x
        + (8.0 * b + 24.0 * c)
    )
    return xp.where(x < 1.0, near, xp.where(x < 2.0, far, 0.0)) / 6.0


def _lanczos_np(x, r):
    """Lanczos window ``sinc(x) sinc(x / r)`` (``sinc(t) = sin(πt) / (πt)``) on ``|x| <= r``.
    Near 0 its Taylor polynomial (both branches finite, gradients too)."""
    xp = jnp if isinstance(x, jnp.ndarray) else np
    x = xp.abs(x)
    small = x < 1e-3
    xs = xp.where(small, 1.0, x)
    a, b = np.pi * xs, np.pi * xs / r
    full = xp.sin(a) * xp.sin(b) / (a * b)
    t = (np.pi * x) ** 2
    taylor = 1.0 - t * (1.0 + 1.0 / r**2) / 6.0
    return xp.where(x > r, 0.0, xp.where(small, taylor, full))


@functools.lru_cache(maxsize=32)
def _abs_table(filt):
    """``(x grid, CDF of |f| on it, ∫|f| / ∫f)`` in float64 numpy (trapezoid rule)."""
    r = float(filt.radius)
    x = np.linspace(-r, r, int(round(2 * r * _CELLS_PER_PIXEL)) + 1)
    f = filt._f(x)
    h = x[1] - x[0]
    cell_abs = 0.5 * h * (np.abs(f[1:]) + np.abs(f[:-1]))
    cdf = np.concatenate([[0.0], np.cumsum(cell_abs)])
    total = float(np.sum(0.5 * h * (f[1:] + f[:-1])))
    return x, cdf / cdf[-1], float(cdf[-1]) / total


class _SignedFilter(eqx.Module):
    """A separable filter ``f(x) f(y)`` with negative lobes (see the module docstring)."""

    def _f(self, x):  # the 1-D filter, numpy (float64 tables) or jax
        raise NotImplementedError

    def eval(self, x):
        """The (unnormalised) 1-D filter value at offsets ``x`` (Mitsuba's ``eval``)."""
        return self._f(jnp.asarray(x))

    @property
    def weight_scale(self) -> float:
        """``(∫|f| / ∫f)²``: the magnitude of every sample's weight."""
        return _abs_table(self)[2] ** 2

    def sample(self, u):
        """Offsets (..., 2) from uniform numbers ``u (..., 2)``: per axis drawn from ``|f|``
        (the inverse of its tabulated CDF, linear between grid points)."""
        x, cdf, _ = _abs_table(self)
        return jnp.interp(u, jnp.asarray(cdf, u.dtype), jnp.asarray(x, u.dtype))

    def sample_weight(self, off):
        """``(...)`` weight ``sign(f(x) f(y)) (∫|f| / ∫f)²`` of samples at offsets
        ``off (..., 2)``."""
        s = jnp.sign(self._f(off[..., 0])) * jnp.sign(self._f(off[..., 1]))
        return (s * self.weight_scale).astype(off.dtype)


class MitchellFilter(_SignedFilter):
    """Mitsuba 3's ``mitchell``: the separable Mitchell-Netravali cubic with parameters ``B``
    and ``C`` (default 1/3 each), radius 2 px; negative lobes for ``1 < |x| < 2``."""

    B: float = eqx.field(static=True, default=1.0 / 3.0)
    C: float = eqx.field(static=True, default=1.0 / 3.0)

    def __check_init__(self):
        for name in ("B", "C"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ValueError(f"filter.{name}: expected a finite number, got {v!r}")
        if not _abs_table(self)[2] > 0:
            raise ValueError(f"filter.B, filter.C: ∫f <= 0 for B={self.B}, C={self.C}")

    @property
    def radius(self) -> float:
        return 2.0

    def _f(self, x):
        return _mitchell_np(x, float(self.B), float(self.C))


class CatmullRomFilter(_SignedFilter):
    """Mitsuba 3's ``catmullrom``: the Mitchell-Netravali cubic with ``B = 0``, ``C = 1/2``
    (radius 2 px)."""

    @property
    def radius(self) -> float:
        return 2.0

    def _f(self, x):
        return _mitchell_np(x, 0.0, 0.5)


class LanczosFilter(_SignedFilter):
    """Mitsuba 3's ``lanczos``: ``sinc(x) sinc(x / lobes)`` on ``|x| <= lobes`` per axis
    (``lobes`` 3 by default: radius 3 px)."""

    lobes: int = eqx.field(static=True, default=3)

    def __check_init__(self):
        check_positive_int(self.lobes, "filter.lobes")

    @property
    def radius(self) -> float:
        return float(self.lobes)

    def _f(self, x):
        return _lanczos_np(x, float(self.lobes))


FILTERS = {
    "box": BoxFilter,
    "gaussian": GaussianFilter,
    "tent": TentFilter,
    "mitchell": MitchellFilter,
    "catmullrom": CatmullRomFilter,
    "lanczos": LanczosFilter,
}


def make_filter(name: str = "box", **kwargs):
    """Filter from its name (``box`` | ``gaussian`` | ``tent`` | ``mitchell`` |
    ``catmullrom`` | ``lanczos``) and keyword options (``radius``, ``stddev``: > 0;
    ``mitchell``'s ``B``, ``C``: numbers; ``lanczos``'s ``lobes``: a positive integer)."""
    check_choice(name, "filter", sorted(FILTERS))
    for k, v in kwargs.items():
        if k in ("radius", "stddev"):
            check_positive(v, f"filter.{k}")
    known = {f.name for f in dataclasses.fields(FILTERS[name])}
    bad = sorted(set(kwargs) - known)
    if bad:
        raise ValueError(
            f"filter.{bad[0]}: not an option of the {name!r} filter (options: {sorted(known)})"
        )
    return FILTERS[name](**kwargs)


def pixel_samples(
    key,
    width: int,
    height: int,
    spp: int,
    rfilter=None,
    *,
    rows=None,
    dtype=jnp.float32,
    with_weights: bool = False,
):
    """Continuous sample positions ``(height, width, spp, 2)`` (x, y) in pixels, of float
    ``dtype`` (the renderer draws them in the scene's dtype).

    Stratified per pixel when ``spp`` is a perfect square (jittered grid), otherwise
    independent uniform samples; offsets then warped by the reconstruction filter.
    ``rows``: ``None`` (the whole image) or global row indices ``(R,)`` (may be traced): only
    those rows' samples are drawn (:func:`~jaxgfx.render.sampler.uniform` with ``rows``), and
    they equal the whole image's. :func:`jaxgfx.render.estimator.render_partial` draws its
    samples here, in the scene's float ``dtype``. The one draw that grows with a user option:
    more than 2**32 numbers raise ``ValueError`` naming ``spp`` (the ``render`` argument and
    the CLI's ``--spp``) and the largest that fits.

    ``with_weights=True``: ``(positions, weights)``, ``weights (height, width, spp)`` the
    signed sample weights of a filter with negative lobes (``sample_weight``), ``None`` for
    the others (every sample weighs 1).
    """
    size = height * width * spp * 2
    if size > 2**32:
        raise ValueError(
            f"spp: {spp} samples per pixel at {width}x{height} pixels need {size} random "
            f"numbers, more than the 2**32 of one key; use spp <= {2**32 // (height * width * 2)}"
            " (and average renders made with split keys for more)"
        )
    rfilter = rfilter or BoxFilter()
    n = int(round(spp**0.5))
    u = uniform(key, (height, width, spp, 2), dtype, rows=rows)
    if n * n == spp and spp > 1:
        iy, ix = jnp.divmod(jnp.arange(spp), n)
        u = (jnp.stack([ix, iy], -1) + u) / n
    off = rfilter.sample(u)
    jj, ii = jnp.meshgrid(jnp.arange(width), jnp.arange(height) if rows is None else rows)
    centre = jnp.stack([jj, ii], -1).astype(u.dtype) + 0.5
    px = centre[:, :, None, :] + off
    if not with_weights:
        return px
    weigh = getattr(rfilter, "sample_weight", None)
    return px, (None if weigh is None else weigh(off))
