"""Film: pixel sample positions and reconstruction filters.

Reconstruction uses *filter importance sampling* (as pbrt-v4): each camera sample's offset from
the pixel centre is drawn from the (normalised, non-negative) filter, and the sample then
contributes with weight 1 to its own pixel only. The pixel estimate is the plain mean of its
samples — unbiased for the filtered image, without splatting or atomics.

Filters follow Mitsuba 3's defaults: ``box`` (radius 0.5 px), ``gaussian`` (stddev 0.5 px,
radius 4 stddev = 2 px, lowered by its value at the radius as Mitsuba's) and ``tent`` (radius
1 px: the separable ``max(0, 1 - |x| / r) max(0, 1 - |y| / r)``, Mitsuba's ``tent``).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import check_choice, check_positive
from jaxgfx.render.sampler import uniform

__all__ = [
    "BoxFilter",
    "GaussianFilter",
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


FILTERS = {"box": BoxFilter, "gaussian": GaussianFilter, "tent": TentFilter}


def make_filter(name: str = "box", **kwargs):
    """Filter from its name (``box`` | ``gaussian`` | ``tent``) and keyword options."""
    check_choice(name, "filter", sorted(FILTERS))
    for k, v in kwargs.items():
        check_positive(v, f"filter.{k}")
    return FILTERS[name](**kwargs)


def pixel_samples(
    key, width: int, height: int, spp: int, rfilter=None, *, rows=None, dtype=jnp.float32
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
    return centre[:, :, None, :] + off
