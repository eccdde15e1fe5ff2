"""Poisson-Gaussian sensor noise model and its measurement by the photon transfer curve.

A linear sensor pixel with mean signal ``x`` (black-subtracted, in whatever units the data are
in: DN, or normalised ``[0, 1]`` where 1 is the white level) has variance

    var(x) = gain * x + read_variance

``gain`` is the conversion factor in signal units per electron (shot noise: Poisson electrons
scaled by the conversion factor), ``read_variance`` the signal-independent floor (read noise,
dark-current noise and quantisation). This is the photon transfer curve of Janesick (2007),
*Photon Transfer*, SPIE PM170, and the EMVA 1288 standard (release 4.0, 2021).
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice, check_finite, is_concrete
from jaxgfx._math import safe_div, safe_sqrt

__all__ = ["NoiseModel", "fit_photon_transfer", "fit_noise_from_bracket", "PTC_METHODS"]

PTC_METHODS = ("pairs", "stack")


class NoiseModel(eqx.Module):
    """Per-channel Poisson-Gaussian noise model ``var(x) = gain * x + read_variance``.

    Fields (differentiable leaves):
      gain: ``(C,)`` conversion factor, signal units per electron (> 0).
      read_variance: ``(C,)`` signal-independent variance, signal units squared (>= 0).
      black_level, white_level: optional ``(C,)`` raw levels the data were normalised with
        (``x = (raw - black) / (white - black)``); informational, not used by the methods.

    The signal ``x`` passed to the methods is black-subtracted and channels-last: its last axis
    broadcasts against ``(C,)``. Negative signals (noise around black) are clamped to 0 for the
    shot-noise term.

    Example:
        >>> m = NoiseModel(jnp.array([0.01]), jnp.array([1e-4]))
        >>> float(m.variance(jnp.array([0.5]))[0])  # 0.01 * 0.5 + 1e-4
        0.0051
    """

    gain: jax.Array
    read_variance: jax.Array
    black_level: jax.Array | None = None
    white_level: jax.Array | None = None

    def __init__(self, gain, read_variance, black_level=None, white_level=None):
        self.gain = jnp.atleast_1d(as_float_array(gain, "gain"))
        self.read_variance = jnp.atleast_1d(as_float_array(read_variance, "read_variance"))
        self.black_level = (
            None if black_level is None else jnp.atleast_1d(as_float_array(black_level, "black"))
        )
        self.white_level = (
            None if white_level is None else jnp.atleast_1d(as_float_array(white_level, "white"))
        )

    def __check_init__(self):
        if self.gain.ndim != 1 or self.read_variance.shape != self.gain.shape:
            raise ValueError(
                "gain, read_variance: expected matching shapes (C,), got "
                f"{self.gain.shape} and {self.read_variance.shape}"
            )
        for name, v in (("gain", self.gain), ("read_variance", self.read_variance)):
            if is_concrete(v):
                a = np.asarray(v)
                if not np.all(np.isfinite(a)) or np.any(a < 0):
                    raise ValueError(f"{name}: expected finite values >= 0, got {a}")

    def variance(self, x):
        """Noise variance at mean signal ``x`` (``(..., C)`` or broadcastable), same units²."""
        x = as_float_array(x, "x")
        return self.gain * jnp.maximum(x, 0.0) + self.read_variance

    def std(self, x):
        """Noise standard deviation ``sqrt(variance(x))`` (finite gradient at variance 0)."""
        return safe_sqrt(self.variance(x))

    def snr(self, x):
        """Signal-to-noise ratio ``x / std(x)`` (0 where the noise is 0)."""
        x = as_float_array(x, "x")
        return safe_div(x, self.std(x))

    def to_dict(self) -> dict:
        """JSON-ready dict of plain Python lists."""
        out = {
            "gain": np.asarray(self.gain).tolist(),
            "read_variance": np.asarray(self.read_variance).tolist(),
            "read_noise": np.sqrt(np.asarray(self.read_variance)).tolist(),
        }
        if self.black_level is not None:
            out["black_level"] = np.asarray(self.black_level).tolist()
        if self.white_level is not None:
            out["white_level"] = np.asarray(self.white_level).tolist()
        return out


def _as_frames(frames, method):
    """Return ``(P, N, H, W, C)`` from a list/array of frames (see ``fit_photon_transfer``)."""
    if isinstance(frames, (list, tuple)):
        if len(frames) == 0:
            raise ValueError("frames_or_pairs: expected at least one pair/stack, got none")
        parts = [as_float_array(f, "frames_or_pairs") for f in frames]
        shapes = {p.shape for p in parts}
        if len(shapes) != 1:
            raise ValueError(f"frames_or_pairs: all entries must share one shape, got {shapes}")
        arr = jnp.stack(parts)
        if arr.ndim == 4:  # list of (N, H, W)
            arr = arr[..., None]
    else:
        arr = as_float_array(frames, "frames_or_pairs")
        if arr.ndim == 3:
            arr = arr[None, ..., None]
        elif arr.ndim == 4:
            arr = arr[None]
    if arr.ndim != 5:
        raise ValueError(
            "frames_or_pairs: expected (N, H, W), (N, H, W, C) or (P, N, H, W, C), "
            f"got shape {arr.shape}"
        )
    n = arr.shape[1]
    if method == "pairs" and n != 2:
        raise ValueError(f"frames_or_pairs: method='pairs' needs N == 2 frames per level, got {n}")
    if n < 2:
        raise ValueError(f"frames_or_pairs: need at least 2 frames per level, got {n}")
    check_finite(arr, "frames_or_pairs")
    return arr


@functools.partial(jax.jit, static_argnames=("remove_mean", "n_bins", "min_count", "iters"))
def _binned_fit(level, q, dof, valid, *, remove_mean, n_bins, min_count, iters=4, bin_by=None):
    """Bin per-sample (level, sum of squares q, dof) by level quantiles; fit var = g*level + r.

    ``bin_by`` (optional, ``(C, M)``): bin by this instead of ``level`` (an independent
    estimate of the level, so that the bin means of ``level`` are not regression-diluted).

    All inputs ``(C, M)``. With ``remove_mean``, ``q`` holds signed samples ``u`` of a
    (nearly) zero-mean quantity whose variance is wanted, and each bin's mean of ``u`` is
    removed (``ddof=1``); otherwise ``q`` holds per-sample sums of squares with ``dof`` each.
    """

    def one(level, q, dof, valid, bin_by):
        m = level.shape[0]
        key = jnp.where(valid, level if bin_by is None else bin_by, jnp.inf)
        order = jnp.argsort(key)
        n_valid = jnp.sum(valid)
        rank = jnp.arange(m)
        b = jnp.floor(rank * n_bins / jnp.maximum(n_valid, 1)).astype(jnp.int32)
        b = jnp.where(rank < n_valid, jnp.minimum(b, n_bins - 1), n_bins)
        lv, qq, dd = level[order], q[order], dof[order]
        seg = functools.partial(jax.ops.segment_sum, segment_ids=b, num_segments=n_bins + 1)
        cnt = seg(jnp.ones_like(lv))[:n_bins]
        s_level = seg(lv)[:n_bins]
        if remove_mean:
            uu = qq  # u values (signed) are passed in q when remove_mean
            s1 = seg(uu)[:n_bins]
            s2 = seg(uu * uu)[:n_bins]
            ss = jnp.maximum(s2 - safe_div(s1 * s1, cnt), 0.0)
            bdof = cnt - 1.0
        else:
            ss = seg(qq)[:n_bins]
            bdof = seg(dd)[:n_bins]
        ok = (cnt >= min_count) & (bdof >= 1)
        mu = safe_div(s_level, cnt)
        s2 = safe_div(ss, bdof)
        # IRLS: Var(s2) = 2 sigma^4 / dof with sigma^2 the model prediction.
        tiny = jnp.finfo(mu.dtype).tiny

        def solve(pred):
            # weighted line fit in centred form, weights scaled to max 1: the raw weights span
            # up to 1e18 in float32 (variance floor 1e-6 of the largest), so the textbook
            # normal equations (sw * sxx - sx^2) overflow or cancel to NaN depending on FMA
            # contraction; centring and scaling keep every sum O(1)
            w = jnp.where(ok, bdof / (2.0 * jnp.maximum(pred, tiny) ** 2), 0.0)
            w_max = jnp.max(w)
            wn = safe_div(w, w_max)
            sw = jnp.sum(wn)
            xm = safe_div(jnp.sum(wn * mu), sw)
            ym = safe_div(jnp.sum(wn * s2), sw)
            dx = mu - xm
            sxx = jnp.sum(wn * dx * dx)
            g = safe_div(jnp.sum(wn * dx * (s2 - ym)), sxx)
            r = ym - g * xm
            # inverse of the (g, r) normal matrix, in the weights' true scale
            var_g = safe_div(1.0, sxx * w_max)
            cov = jnp.array(
                [[var_g, -xm * var_g], [-xm * var_g, safe_div(1.0, sw * w_max) + xm * xm * var_g]]
            )
            return g, r, cov, w

        # floor the predicted variance so that zero-variance (clipped) bins cannot take
        # infinite weight
        floor = jnp.maximum(1e-6 * jnp.max(jnp.where(ok, s2, 0.0)), tiny)
        pred = jnp.maximum(s2, floor)
        for _ in range(iters):
            g, r, cov, w = solve(pred)
            pred = jnp.maximum(g * mu + r, jnp.maximum(0.05 * s2, floor))
        g, r, cov, w = solve(pred)
        nb = jnp.sum(ok)
        chi2 = safe_div(jnp.sum(w * (s2 - (g * mu + r)) ** 2), jnp.maximum(nb - 2, 1))
        return g, r, cov, chi2, mu, s2, jnp.where(ok, bdof, 0.0), nb

    if bin_by is None:
        return jax.vmap(lambda a, b, c, d: one(a, b, c, d, None))(level, q, dof, valid)
    return jax.vmap(one)(level, q, dof, valid, bin_by)


@functools.partial(jax.jit, static_argnames=("method", "n_bins", "min_count"))
def _ptc_core(arr, black, white, mask, saturation, *, method, n_bins, min_count):
    p, n, h, w, c = arr.shape
    valid = jnp.broadcast_to(mask[None, :, :, None], (p, h, w, c))
    if white is not None:
        arr = (arr - black) / (white - black)
        valid = valid & jnp.all(arr <= saturation, axis=1)
    else:
        arr = arr - black
    if method == "pairs":
        level = 0.5 * (arr[:, 0] + arr[:, 1])
        q = (arr[:, 0] - arr[:, 1]) / math.sqrt(2.0)
        dof = jnp.ones_like(level)
    else:
        level = jnp.mean(arr, axis=1)
        q = jnp.sum((arr - level[:, None]) ** 2, axis=1)
        dof = jnp.full_like(level, n - 1.0)

    def chan(x):  # (P, H, W, C) -> (C, P*H*W)
        return jnp.moveaxis(x, -1, 0).reshape(c, -1)

    return _binned_fit(
        chan(level),
        chan(q),
        chan(dof),
        chan(valid),
        remove_mean=(method == "pairs"),
        n_bins=n_bins,
        min_count=min_count,
    )


def fit_photon_transfer(
    frames_or_pairs,
    *,
    method: str = "pairs",
    mask=None,
    black=0.0,
    white=None,
    saturation: float = 0.98,
    n_bins: int = 32,
    min_count: int = 16,
):
    """Measure gain and read noise from the photon transfer curve (Janesick 2007, EMVA 1288).

    Each pixel of each exposure level gives a mean ``m`` and a variance estimate: with
    ``method="pairs"`` (two identical exposures ``a, b``: Janesick's difference method, which
    cancels fixed-pattern noise and scene texture) ``m = (a + b) / 2`` and the variance of
    ``(a - b) / sqrt(2)``; with ``method="stack"`` (``N >= 2`` identical exposures) the per-pixel
    sample mean and sample variance (``ddof=1``). Samples are binned by mean level into
    ``n_bins`` equal-count bins per channel; each bin's variance estimate ``s2`` (with ``dof``
    degrees of freedom) is fitted by ``s2 = gain * m + read_variance`` by iteratively reweighted
    least squares with weights ``dof / (2 sigma^4)`` (the variance of a sample variance of
    Gaussian data, ``2 sigma^4 / dof``), ``sigma^2`` the current model prediction.
    Binning by the *observed* mean is unbiased for Poisson data: given ``a + b``, the variance of
    ``a - b`` is ``a + b`` exactly.

    Args:
      frames_or_pairs: raw frames, ``(N, H, W)``, ``(N, H, W, C)`` or ``(P, N, H, W, C)``
        (``P`` exposure levels, ``N`` identical frames each; ``N == 2`` for pairs), or a list of
        ``(N, H, W[, C])`` arrays. Use ``raw_calibration.cfa_channels`` to turn Bayer mosaics
        into ``C = 4`` CFA channels first.
      method: ``"pairs"`` or ``"stack"``.
      mask: optional boolean ``(H, W)``; ``False`` pixels are excluded.
      black: black level (scalar or ``(C,)``), subtracted first.
      white: optional white level; when given, the data are normalised to
        ``(raw - black) / (white - black)`` (so the model is in ``[0, 1]`` units) and pixels with
        any frame above ``saturation`` (fraction of the range) are excluded as clipped.
      n_bins, min_count: number of level bins; bins with fewer samples are dropped.

    Returns:
      ``(NoiseModel, info)``; ``info`` holds ``gain_se``, ``read_variance_se`` (standard errors
      from the weighted fit's covariance, scaled by ``sqrt(chi2_reduced)`` when that exceeds 1),
      ``cov`` ``(C, 2, 2)``, ``chi2_reduced``, ``n_bins_used`` and the binned curve
      ``bin_mean``, ``bin_variance``, ``bin_dof`` ``(C, n_bins)`` (unused bins have dof 0).

    Example: Poisson frames with 1000 e- full well and 3 e- read noise in ``[0, 1]`` units give
    ``gain ~ 1e-3`` and ``read_variance ~ 9e-6`` (see ``tests/hdr/test_noise.py``).
    """
    check_choice(method, "method", PTC_METHODS)
    if not isinstance(n_bins, int) or n_bins < 3:
        raise ValueError(f"n_bins: expected an int >= 3, got {n_bins!r}")
    arr = _as_frames(frames_or_pairs, method)
    p, n, h, w, c = arr.shape
    black = jnp.broadcast_to(as_float_array(black, "black"), (c,)).astype(arr.dtype)
    if white is not None:
        white = jnp.broadcast_to(as_float_array(white, "white"), (c,)).astype(arr.dtype)
        if is_concrete(white) and np.any(np.asarray(white) <= np.asarray(black)):
            raise ValueError(f"white: expected > black ({black}), got {white}")
    if mask is None:
        mask = jnp.ones((h, w), bool)
    mask = jnp.asarray(mask)
    if mask.shape != (h, w):
        raise ValueError(f"mask: expected shape {(h, w)}, got {mask.shape}")
    g, r, cov, chi2, mu, s2, bdof, nb = _ptc_core(
        arr,
        black,
        white,
        mask.astype(bool),
        saturation,
        method=method,
        n_bins=n_bins,
        min_count=min_count,
    )
    if is_concrete(nb) and np.any(np.asarray(nb) < 3):
        raise ValueError(
            "frames_or_pairs: fewer than 3 populated level bins in some channel "
            f"(bins used per channel: {np.asarray(nb).tolist()}); give more pixels or levels"
        )
    model = NoiseModel(
        jnp.maximum(g, 0.0),
        jnp.maximum(r, 0.0),
        black_level=None if white is None else black,
        white_level=white,
    )
    return model, _fit_info(g, r, cov, chi2, mu, s2, bdof, nb)


def _fit_info(g, r, cov, chi2, mu, s2, bdof, nb):
    """The ``info`` dict of a binned line fit (:func:`_binned_fit`'s outputs): standard errors
    from the covariance, scaled by ``sqrt(chi2_reduced)`` when that exceeds 1."""
    scale = jnp.maximum(chi2, 1.0)
    return {
        "gain_se": jnp.sqrt(cov[:, 0, 0] * scale),
        "read_variance_se": jnp.sqrt(cov[:, 1, 1] * scale),
        "gain_raw": g,
        "read_variance_raw": r,
        "cov": cov,
        "chi2_reduced": chi2,
        "n_bins_used": nb,
        "bin_mean": mu,
        "bin_variance": s2,
        "bin_dof": bdof,
    }


@functools.partial(jax.jit, static_argnames=("n_bins", "min_count"))
def _bracket_core(y, ratios, saturation, *, n_bins, min_count):
    """``y``: ``(N, H, W, C)`` normalised frames sorted by exposure; ``ratios`` ``(N,)``
    relative exposures. Pairs (k, k+1) pooled after scaling to a common model."""
    n = y.shape[0]
    lv, uu, ok, kk = [], [], [], []
    for k in range(n - 1):
        a, b = y[k], y[k + 1]
        r = ratios[k + 1] / ratios[k]
        s_a = (a + b) / (1.0 + r)  # unbiased level; uncorrelated with b - r a (shot regime)
        q = 1.0 + r * r
        if n >= 3:  # bin by a third frame, whose noise is independent of a and b
            cidx = k + 2 if k + 2 < n else k - 1
            key = y[cidx] * (ratios[k] / ratios[cidx])
            v = (a < saturation) & (b < saturation) & (y[cidx] < saturation)
        else:
            key = s_a
            v = (a < saturation) & (b < saturation)
        lv.append(r * (1.0 + r) * s_a / q)
        kk.append(r * (1.0 + r) * key / q)
        uu.append((b - r * a) / jnp.sqrt(q))
        ok.append(v)

    def chan(parts):  # list of (H, W, C) -> (C, M)
        x = jnp.stack(parts)
        return jnp.moveaxis(x, -1, 0).reshape(x.shape[-1], -1)

    lvl, u, valid, key = chan(lv), chan(uu), chan(ok), chan(kk)
    return _binned_fit(
        lvl,
        u,
        jnp.ones_like(u),
        valid,
        remove_mean=True,
        n_bins=n_bins,
        min_count=min_count,
        bin_by=key,
    )


def fit_noise_from_bracket(
    frames,
    exposure_ratios,
    *,
    black=0.0,
    white=1.0,
    saturation: float = 0.95,
    n_bins: int = 32,
    min_count: int = 16,
    max_samples: int = 1 << 18,
):
    """Gain and read noise from a bracket of a static scene alone (no dark or flat frames).

    For frames ``a`` and ``b`` adjacent in exposure with measured ratio ``r = R_b / R_a``
    (e.g. :func:`jaxgfx.hdr.estimate_exposure_ratios`), the difference ``d = y_b − r y_a`` of
    the normalised signals ``y = (raw − black) / (white − black)`` has zero mean — scene
    texture and pixel-response non-uniformity cancel, as in Janesick's pair difference — and
    variance ``gain · s_a · r (1 + r) + read_variance · (1 + r²)`` (photon transfer,
    ``s_a`` the mean signal of ``a``). Every adjacent pair is rescaled to the common form
    ``Var(d / √(1+r²)) = gain · [s_a r (1+r) / (1+r²)] + read_variance`` and all pairs are
    pooled into the binned, iteratively reweighted fit of :func:`fit_photon_transfer`
    (standard errors from the weighted fit). Pixels are binned by their level in a *third*
    frame (``k+2``, or ``k−1`` for the last pair), whose noise is independent of ``a`` and
    ``b``, so the binning selects on neither ``d`` nor the level estimate; the level of a bin
    is the mean of ``s_a = (y_a + y_b) / (1 + r)`` (binning and averaging the same noisy
    level dilutes the slope: measured gain −10 %, read noise +7 %). With ``N = 2`` pixels are
    binned by ``s_a``, which is uncorrelated with ``d`` in the shot-noise regime. Pixels at or
    above ``saturation`` in any of the frames used are excluded.

    Args:
      frames: ``(N, H, W)`` or ``(N, H, W, C)`` raw frames (CFA planes from
        ``cfa_channels``), any order, N >= 2; black level and white level as given.
      exposure_ratios: ``(N,)`` relative exposures (measured, not nominal: an EXIF error of
        a few % leaves a residual ``δr · y_a`` that inflates the variance).
      black, white: scalars or ``(C,)`` raw levels.
      max_samples: at most this many pixel pairs per channel (all pairs together) enter the
        fit; larger frames are subsampled on a regular grid (the binning sorts the samples:
        the cost of a 5 × 2 MP bracket at full resolution, for standard errors far below
        what is needed).

    Returns:
      ``(NoiseModel, info)`` in normalised units, like :func:`fit_photon_transfer`; ``info``
      adds ``gain_e_per_dn`` (electrons per DN, ``1 / (gain · (white − black))``) and
      ``read_noise_dn`` (``sqrt(read_variance) · (white − black)``) with their standard errors
      (delta method). Quantisation adds ``1/12`` DN² to the read variance.

    Example: a DNG bracket with 2 e⁻/DN and 3 DN read noise gives back both within 10 %
    (``tests/hdr/test_raw_calibration.py``).
    """
    if not isinstance(n_bins, int) or n_bins < 3:
        raise ValueError(f"n_bins: expected an int >= 3, got {n_bins!r}")
    arr = as_float_array(frames, "frames")
    if arr.ndim == 3:
        arr = arr[..., None]
    if arr.ndim != 4 or arr.shape[0] < 2:
        raise ValueError(
            f"frames: expected (N, H, W) or (N, H, W, C) with N >= 2, got shape {arr.shape}"
        )
    check_finite(arr, "frames")
    n, c = arr.shape[0], arr.shape[-1]
    step = 1
    while (n - 1) * (arr.shape[1] // step) * (arr.shape[2] // step) > max_samples:
        step += 1
    if step > 1:
        arr = arr[:, ::step, ::step]
    rat = as_float_array(exposure_ratios, "exposure_ratios").astype(arr.dtype)
    if rat.shape != (n,):
        raise ValueError(f"exposure_ratios: expected shape ({n},), got {rat.shape}")
    if is_concrete(rat) and not np.all(np.asarray(rat) > 0):
        raise ValueError(f"exposure_ratios: expected finite values > 0, got {np.asarray(rat)}")
    b = jnp.broadcast_to(as_float_array(black, "black"), (c,)).astype(arr.dtype)
    w = jnp.broadcast_to(as_float_array(white, "white"), (c,)).astype(arr.dtype)
    if is_concrete(w) and np.any(np.asarray(w) <= np.asarray(b)):
        raise ValueError(f"white: expected > black ({np.asarray(b)}), got {np.asarray(w)}")
    order = jnp.argsort(rat)
    y = ((arr - b) / (w - b))[order]
    g, r, cov, chi2, mu, s2, bdof, nb = _bracket_core(
        y, rat[order], saturation, n_bins=n_bins, min_count=min_count
    )
    if is_concrete(nb) and np.any(np.asarray(nb) < 3):
        raise ValueError(
            "frames: fewer than 3 populated level bins in some channel "
            f"(bins used per channel: {np.asarray(nb).tolist()}); the bracket has too few "
            "unsaturated pixels in adjacent frames"
        )
    info = _fit_info(g, r, cov, chi2, mu, s2, bdof, nb)
    gain_se, read_se = info["gain_se"], info["read_variance_se"]
    span = w - b
    g_pos = jnp.maximum(g, jnp.finfo(g.dtype).tiny)
    r_pos = jnp.maximum(r, jnp.finfo(r.dtype).tiny)
    model = NoiseModel(jnp.maximum(g, 0.0), jnp.maximum(r, 0.0), black_level=b, white_level=w)
    info |= {
        "gain_e_per_dn": 1.0 / (g_pos * span),
        "gain_e_per_dn_se": gain_se / (g_pos * g_pos * span),
        "read_noise_dn": jnp.sqrt(r_pos) * span,
        "read_noise_dn_se": read_se / (2.0 * jnp.sqrt(r_pos)) * span,
    }
    return model, info
