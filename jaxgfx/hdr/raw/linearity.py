"""Linearity of the sensor: a line fit of the mean normalised signal against exposure time
(:func:`linearity_check`) and the choice of frames it runs on."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._math import safe_div

from ._common import _channels, _jsonable, _levels, _times

__all__ = ["Linearity", "linearity_check"]


class Linearity(eqx.Module):
    """Per-channel line fit of mean normalised signal vs exposure time (see ``linearity_check``)."""

    slope: jax.Array
    slope_se: jax.Array
    intercept: jax.Array
    intercept_se: jax.Array
    r2: jax.Array
    max_rel_deviation: jax.Array
    is_linear: jax.Array
    means: jax.Array
    n_pixels: jax.Array
    tolerance: float = eqx.field(static=True, default=0.01)

    def to_dict(self) -> dict:
        out = {k: _jsonable(getattr(self, k)) for k in _LIN_KEYS}
        out["criterion"] = (
            f"max relative deviation from the line <= {self.tolerance} and "
            f"|intercept| <= {self.tolerance} * largest mean"
        )
        return out


_LIN_KEYS = (
    "slope",
    "slope_se",
    "intercept",
    "intercept_se",
    "r2",
    "max_rel_deviation",
    "is_linear",
    "means",
    "n_pixels",
)


# ---------------------------------------------------------------------------------------------
# linearity


@jax.jit
def _linearity_core(y, t, saturation, min_signal, tol):
    # y: (N, M, C) normalised, t: (N,)
    valid = jnp.all((y > min_signal) & (y < saturation), axis=0)  # (M, C)
    n_pix = jnp.sum(valid, axis=0)
    means = safe_div(jnp.sum(jnp.where(valid[None], y, 0.0), axis=1), n_pix)  # (N, C)
    n = t.shape[0]
    tm = jnp.mean(t)
    sxx = jnp.sum((t - tm) ** 2)
    mm = jnp.mean(means, axis=0)
    slope = jnp.sum((t - tm)[:, None] * (means - mm), axis=0) / sxx
    icpt = mm - slope * tm
    fit = slope * t[:, None] + icpt
    ssr = jnp.sum((means - fit) ** 2, axis=0)
    sst = jnp.sum((means - mm) ** 2, axis=0)
    s2 = ssr / (n - 2)
    slope_se = jnp.sqrt(s2 / sxx)
    icpt_se = jnp.sqrt(s2 * (1.0 / n + tm**2 / sxx))
    r2 = 1.0 - safe_div(ssr, sst)
    dev = jnp.max(jnp.abs(safe_div(means - fit, fit)), axis=0)
    is_lin = (dev <= tol) & (jnp.abs(icpt) <= tol * jnp.max(means, axis=0)) & (n_pix > 0)
    return slope, slope_se, icpt, icpt_se, r2, dev, is_lin, means, n_pix


def linearity_check(
    stack,
    exposure_times,
    *,
    black,
    white,
    cfa_pattern: str | None = None,
    saturation: float = 0.95,
    min_signal: float = 0.02,
    tolerance: float = 0.01,
) -> Linearity:
    """Per-channel linearity of mean signal vs exposure time (EMVA 1288 sec. 6.6 style).

    Pixels are kept when their normalised signal ``y = (raw - black) / (white - black)`` lies in
    ``(min_signal, saturation)`` in *every* frame (unsaturated and above the noise), so each
    frame's mean ``m_k`` is over the same pixels and a scene (not only a flat field) can be
    used. An ordinary least-squares line ``m_k = slope * t_k + intercept`` is fitted per channel,
    with standard errors from the residual variance (``N - 2`` dof; needs ``N >= 3``), ``r2``,
    and the linearity error ``max_k |m_k - fit_k| / fit_k``.

    ``is_linear``: max relative deviation ``<= tolerance`` (default 1 %) and
    ``|intercept| <= tolerance * max_k m_k`` (a non-zero intercept means a wrong black level or
    an offset non-linearity), and at least one pixel was usable.

    Returns:
      ``Linearity`` with ``(C,)`` fields (``means``: ``(N, C)``), slope in normalised units
      per unit of ``exposure_times``.
    """
    x = _channels(stack, "stack", cfa_pattern, min_frames=3)
    n, h, w, c = x.shape
    t = _times(exposure_times, "exposure_times", n)
    b, wl = _levels(black, white, c, x.dtype)
    y = ((x - b) / (wl - b)).reshape(n, -1, c)
    out = _linearity_core(y, t.astype(x.dtype), saturation, min_signal, tolerance)
    return Linearity(*out, tolerance=float(tolerance))


def _linearity_window(x, t, black, white, *, min_signal=0.02, saturation=0.95, min_pixels=64):
    """Frames (input indices, by increasing time) for the linearity check: the longest run of
    >= 3 consecutive exposures with >= ``min_pixels`` pixels per channel inside
    ``(min_signal, saturation)`` in every frame of the run (ties: most pixels). Returns
    ``(frames, note)``; ``frames`` is empty, and ``note`` says why, when no run qualifies."""
    n = x.shape[0]
    if n < 3:
        return (), f"not run: the linearity check needs >= 3 frames, got {n}"
    order = np.argsort(np.asarray(t))
    y = (np.asarray(x)[order] - np.asarray(black)) / (np.asarray(white) - np.asarray(black))
    ok = (y > min_signal) & (y < saturation)  # (N, H, W, C)
    best, best_key = (), (0, -1)
    most = (0, ())
    for i in range(n):
        common = ok[i]
        for j in range(i + 1, n):
            common = common & ok[j]
            cnt = int(common.reshape(-1, common.shape[-1]).sum(axis=0).min())
            if j - i + 1 >= 3 and cnt > most[0]:
                most = (cnt, tuple(int(v) for v in order[i : j + 1]))
            if j - i + 1 >= 3 and cnt >= min_pixels and (j - i + 1, cnt) > best_key:
                best_key = (j - i + 1, cnt)
                best = tuple(int(v) for v in order[i : j + 1])
    if best:
        frames = sorted(best, key=lambda k: float(np.asarray(t)[k]))
        note = (
            f"frames {frames} (input order; by increasing time): the longest run of "
            f"consecutive exposures with >= {min_pixels} pixels per channel in "
            f"({min_signal}, {saturation}) of white in all of them ({best_key[1]} pixels); "
            "times are the nominal ones, so shutter errors show as non-linearity"
        )
        return tuple(frames), note
    return (), (
        f"not run: no 3 consecutive exposures share >= {min_pixels} pixels per channel in "
        f"({min_signal}, {saturation}) of white (best: {most[0]} pixels in frames "
        f"{list(most[1])}); the bracket steps are too large for this scene"
    )
