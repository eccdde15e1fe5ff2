"""Ghost-free merging of brackets of scenes that move.

A plain merge (:func:`jaxgfx.hdr.merge_radiance`) averages every frame's radiance estimate per
pixel; where something moved between the exposures the average holds a semi-transparent copy
of the object at each of its positions (a "ghost"). :func:`merge_deghosted` keeps, per pixel,
only the frames that agree with a reference exposure *within their noise*, in the spirit of
Granados, Kim, Tompkin & Theobalt (2013), "Automatic noise modeling for ghost-free HDR
reconstruction" (ACM TOG 32(6)): the same noise model that gives the merge its optimal weights
(Granados et al. 2010) decides which differences are noise and which are motion.

Algorithm (all steps traced; one compiled program):

1. Per frame ``j``: linear exposure ``x_j`` (``response.to_linear`` of the levels, or the RAW
   values themselves), radiance estimate ``E_j = x_j / t_j``, its variance ``v_j = Var(x_j) /
   t_j^2`` from the noise model (``gain x + read_variance``, plus quantisation
   ``(dx/dz)^2 / (12 code_max^2)`` for LDR levels) and a validity flag (not clipped, not black).
2. Reference: one frame ``r`` for the whole image (``reference=``; default the frame with the
   most valid pixels), replaced *per region* where it is clipped or black: there the reference
   is the frame nearest to ``r`` in exposure whose validity, averaged over a Gaussian window of
   ``region_sigma`` px, is >= 1/2 (the best-exposed frame of that region).
3. Consistency: ``d_j = sum_c (E_j - E_ref)^2 / (v_j + v_ref)``, a chi-square variable with one
   degree of freedom per channel when both frames see the same radiance. Where the reference
   is clipped (black), a frame that predicts a level clearly below the clipping level (above
   black) for it is inconsistent too (one-sided, censored test). ``d_j`` is averaged over a
   Gaussian window of ``sigma`` px (numerator and count blurred separately), so the decision
   is taken per region, not per pixel: the mask is smooth, isolated noise outliers do not
   punch holes, and a moving object's rim is dropped with it. Frame ``j`` is used where the
   averaged statistic is <= ``threshold`` (about 1 when consistent; a moving object gives
   tens to thousands).
4. Merge: the consistent frames (the reference always) with the noise-optimal weights
   ``t_j^2 / Var(x_j)`` of ``merge_radiance(weighting="noise")``; pixels where no used frame
   is valid take the reference's estimate.

The choice of frames is discrete (its gradient is zero almost everywhere and is stopped); the
radiance is differentiable in the levels (float input), the response parameters, the noise
model and the exposure times, given that choice.

Limits: a moving object that is clipped or black in *every* frame that sees it cannot be
tested; when the reference changes across a region border (step 2) an object crossing that
border can appear in both references' positions; the method corrects local motion, not camera
shake (align first: :func:`jaxgfx.hdr.align_stack`, :func:`jaxgfx.hdr.align_raw_stack`).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import as_float_array, check_finite, check_positive, is_concrete
from ..image.filters import gaussian_blur
from ._model import CameraResponse
from ._stack import prepare_stack
from .merge import _frame_terms, _noise_arrays

__all__ = ["DeghostResult", "merge_deghosted"]


class DeghostResult(NamedTuple):
    """Output of :func:`merge_deghosted`.

    ``radiance`` ``(H, W, C)`` (``(H, W)`` for 3-d input); ``variance`` its variance under the
    noise model, same shape; ``used`` ``(N, H, W)`` float 0/1, frame ``j`` (input order)
    entered the merge at that pixel (consistent with the reference *and* valid there);
    ``reference`` ``(H, W)`` int32, the reference frame of each pixel (the confidence map:
    which exposure each pixel's content comes from); ``statistic`` ``(N, H, W)`` the
    window-averaged consistency statistic of each frame (0 for the reference).
    """

    radiance: jax.Array
    variance: jax.Array
    used: jax.Array
    reference: jax.Array
    statistic: jax.Array


def _blur_frames(a, sigma):
    """Gaussian blur of ``(N, H, W)`` over the image axes (frames as channels)."""
    if sigma == 0:
        return a
    out = gaussian_blur(jnp.moveaxis(a, 0, -1), sigma, padding="reflect")
    return jnp.moveaxis(out, -1, 0)


def merge_deghosted(
    images,
    exposure_times,
    response: CameraResponse | None = None,
    *,
    noise=None,
    reference: int | None = None,
    threshold: float = 4.0,
    sigma: float = 2.0,
    region_sigma: float = 4.0,
    saturation: float = 0.98,
) -> DeghostResult:
    """Merge a bracket of a scene with moving objects without ghosts (see the module docs).

    Args:
      images: ``(N, H, W, C)`` / ``(N, H, W)`` (or a sequence of frames). With a
        ``response``: LDR levels, uint8, uint16 or floats in ``[0, 1]`` (as for
        :func:`merge_radiance`). Without (``response=None``): *linear RAW* frames, floats
        normalised so that 0 is black and 1 the white level (``RawFrame.normalized()``;
        a CFA mosaic works as one channel), slightly negative values allowed.
      exposure_times: ``(N,)`` seconds > 0 (any order; effective times or ratios for RAW).
      response: the camera's :class:`CameraResponse` (LDR), or ``None`` (linear RAW).
      noise: a :class:`NoiseModel` in normalised linear units (``.gain``,
        ``.read_variance``; per channel or one for all). Required for RAW; for LDR, ``None``
        means quantisation noise only.
      reference: index of the reference frame (input order); default the frame with the most
        valid pixels.
      threshold: > 0, largest window-averaged chi-square per channel (mean 1 under the noise
        model) of a frame that is merged. 4 leaves margin for model error (8-bit JPEG-free
        stacks: static pixels measured at 0.6-1.5, see docs/hdr.md).
      sigma: >= 0, Gaussian window (px) of the consistency decision (0: per pixel).
      region_sigma: >= 0, window (px) of the per-region reference choice.
      saturation: RAW only: normalised level at and above which a RAW value is clipped.

    Returns:
      :class:`DeghostResult` (radiance, variance, used, reference, statistic).

    Example:
        >>> resp = CameraResponse.gamma(1.0, anchor="unit")
        >>> frames = jnp.stack([jnp.full((8, 8), 0.2), jnp.full((8, 8), 0.4)])
        >>> r = merge_deghosted(frames, jnp.array([1.0, 2.0]), resp)
        >>> round(float(r.radiance[0, 0]), 4), r.used.shape
        (0.2, (2, 8, 8))
    """
    raw = response is None
    if not raw and not isinstance(response, CameraResponse):
        raise TypeError(
            f"response: expected a CameraResponse (LDR) or None (linear RAW), "
            f"got {type(response).__name__}"
        )
    if raw and noise is None:
        raise ValueError("noise: linear RAW frames (response=None) need a noise model")
    for name, v in (("threshold", threshold), ("sigma", sigma), ("region_sigma", region_sigma)):
        if isinstance(v, bool) or not isinstance(v, (int, float, np.floating)):
            raise TypeError(f"{name}: expected a number, got {v!r}")
    check_positive(threshold, "threshold")
    for name, v in (("sigma", sigma), ("region_sigma", region_sigma)):
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"{name}: expected a window in pixels >= 0, got {v!r}")
    if raw:
        if not 0.0 < float(saturation) <= 1.0:
            raise ValueError(f"saturation: expected a level in (0, 1], got {saturation!r}")
        x = as_float_array(images, "images")
        if x.ndim not in (3, 4) or x.size == 0:
            raise ValueError(
                f"images: expected linear frames (N, H, W) or (N, H, W, C), got {x.shape}"
            )
        check_finite(x, "images")
        squeeze = x.ndim == 3
        z = x[..., None] if squeeze else x
        code_max = 1.0
        t = as_float_array(exposure_times, "exposure_times")
        if t.shape != (z.shape[0],):
            raise ValueError(
                f"exposure_times: expected shape ({z.shape[0]},) matching the frames, got {t.shape}"
            )
        if is_concrete(t) and not np.all(np.asarray(t) > 0):
            raise ValueError(f"exposure_times: expected finite values > 0, got {np.asarray(t)}")
    else:
        z, t, code_max, squeeze = prepare_stack(images, exposure_times, min_frames=1, raw=True)
        if response.channels not in (1, z.shape[-1]):
            raise ValueError(
                f"response: has {response.channels} channels but the images have {z.shape[-1]}"
            )
    n = z.shape[0]
    if reference is not None:
        if isinstance(reference, bool) or not isinstance(reference, (int, np.integer)):
            raise TypeError(f"reference: expected a frame index, got {reference!r}")
        if not 0 <= reference < n:
            raise ValueError(f"reference: expected an index in [0, {n}), got {reference}")
    c = z.shape[-1]
    fdt = z.dtype if jnp.issubdtype(z.dtype, jnp.floating) else jnp.float32
    rdt = response.params.dtype if not raw else fdt
    dt = jnp.result_type(fdt, rdt, t.dtype)
    if jnp.issubdtype(z.dtype, jnp.floating):
        z = z.astype(dt)
    t = t.astype(dt)
    noise_arr = None if noise is None else _noise_arrays(noise, c, dt)
    out = _deghost(
        z,
        t,
        response,
        noise_arr,
        jnp.asarray(-1 if reference is None else reference, jnp.int32),
        jnp.asarray(threshold, dt),
        jnp.asarray(saturation, dt),
        code_max=code_max,
        sigma=float(sigma),
        region_sigma=float(region_sigma),
    )
    if squeeze:
        out = out._replace(radiance=out.radiance[..., 0], variance=out.variance[..., 0])
    return out


_SNR_BRIGHT = 3.0  # a value with SNR >= 3 is "bright" (two-sided test); below: "dark"
_CAP = 4.0  # per-pixel statistic capped at _CAP * threshold before the window average


@functools.partial(jax.jit, static_argnames=("code_max", "sigma", "region_sigma"))
def _deghost(
    z, t, response, noise, reference, threshold, saturation, *, code_max, sigma, region_sigma
):
    n, h, w_, c = z.shape
    dt = t.dtype
    tb = t[:, None, None, None]
    if response is None:  # linear RAW
        gain, read = noise
        x = z
        var_x = gain * jnp.maximum(x, 0.0) + read
        clipped = x >= saturation
        valid_c = ~clipped
        w = jnp.where(valid_c, tb * tb / jnp.maximum(var_x, 1e-30), 0.0)
        x_hi = jnp.broadcast_to(saturation, (c,))
        var_hi = gain * saturation + read
    else:
        x, w, var_x, _ = _frame_terms(
            z,
            t,
            response,
            noise,
            weighting="noise",
            code_max=code_max,
            need_var=True,
            time_power=0.0,
        )
        valid_c = w > 0
        step = 1.0 / code_max if code_max > 1.0 else 1.0 / 255.0
        zn = z.astype(dt) / code_max if code_max > 1.0 else z
        clipped = zn >= 1.0 - 0.5 * step
        # the clipping level: the largest unclipped level's exposure and its variance
        top = jnp.full((1, c), 1.0 - step, dt)
        x_hi = response.to_linear_normalized(top)[0]
        var_hi = _frame_terms(
            top[None, None],
            t[:1],
            response,
            noise,
            weighting="noise",
            code_max=code_max,
            need_var=True,
            time_power=0.0,
        )[2][0, 0, 0]
    e = x / tb
    v = var_x / (tb * tb)
    valid = jnp.all(valid_c, axis=-1)  # (N, H, W): usable where every channel is
    # --- reference: global r, replaced per region where r is not valid
    count = jnp.sum(valid, axis=(1, 2))
    r = jnp.where(reference >= 0, reference, jnp.argmax(count)).astype(jnp.int32)
    rank = jnp.argsort(jnp.argsort(t))  # exposure rank of each frame
    vfrac = _blur_frames(valid.astype(dt), region_sigma)
    pref = (n + 1.0) - jnp.abs(rank - rank[r]).astype(dt) - 0.25 * (rank > rank[r])
    # nearest exposure first; ties go to the shorter frame; no frame usable: the most valid
    score = jnp.where(vfrac >= 0.5, pref[:, None, None], 0.0) + 1e-3 * vfrac
    ref = jnp.argmax(score, axis=0).astype(jnp.int32)  # (H, W)
    onehot = jnp.arange(n)[:, None, None] == ref[None]

    def pick(a):
        return jnp.sum(jnp.where(onehot[..., None], a, jnp.zeros((), a.dtype)), axis=0)

    # --- consistency statistic per frame and pixel (no gradient: a discrete choice)
    es, vs = jax.lax.stop_gradient(e), jax.lax.stop_gradient(v)
    e_r, v_r, clip_r = pick(es)[None], pick(vs)[None], pick(clipped)[None]
    snr = jnp.abs(x) / jnp.sqrt(jnp.maximum(var_x, 1e-30))
    bright = (snr >= _SNR_BRIGHT) & ~clipped
    dark = ~bright & ~clipped
    bright_r, dark_r = pick(bright)[None], pick(dark)[None]
    den = jnp.maximum(vs + v_r, 1e-30)
    diff = es - e_r
    # both bright: two-sided; one dark: only a prediction above the dark value counts
    # (its true value is small; its own value is biased up by the clip at black); the
    # reference clipped: frame j must not predict a level clearly below the clipping level
    e_hi_r = x_hi / pick(jnp.broadcast_to(tb, x.shape))[None]
    v_hi_r = var_hi / pick(jnp.broadcast_to(tb * tb, x.shape))[None]
    d = jnp.where(bright & bright_r, diff * diff / den, 0.0)
    d = d + jnp.where(bright & dark_r, jnp.maximum(diff, 0.0) ** 2 / den, 0.0)
    d = d + jnp.where(dark & bright_r, jnp.maximum(-diff, 0.0) ** 2 / den, 0.0)
    d = d + jnp.where(~clipped & clip_r, jnp.maximum(e_hi_r - es, 0.0) ** 2 / (vs + v_hi_r), 0.0)
    tested = (bright & (bright_r | dark_r)) | (dark & bright_r) | (~clipped & clip_r)
    cnt = jnp.sum(tested, axis=-1).astype(dt)
    # capped at _CAP x threshold per channel before the window average: a fully inconsistent
    # region averages to the cap, and the decision spreads only where >= 1 / _CAP of the
    # window is inconsistent (about sigma / 2 px past a moving object's rim), not as far as
    # the Gaussian tail of a huge difference reaches
    d = jnp.minimum(jnp.sum(d, axis=-1), _CAP * threshold * cnt)  # (N, H, W)
    num = _blur_frames(d, sigma)
    cnt_b = _blur_frames(cnt, sigma)
    stat = jnp.where(cnt_b > 1e-3, num / jnp.maximum(cnt_b, 1e-3), 0.0)
    stat = jnp.where(onehot, 0.0, stat)
    consistent = (stat <= threshold) | onehot
    # --- merge the consistent frames with the noise-optimal weights
    e_ref, v_ref = pick(e), pick(v)
    wm = jnp.where(consistent[..., None], w, 0.0)
    wsum = jnp.sum(wm, axis=0)
    ok = wsum > 0
    den_w = jnp.where(ok, wsum, 1.0)
    rad = jnp.where(ok, jnp.sum(wm * e, axis=0) / den_w, e_ref)
    var = jnp.where(
        ok, jnp.sum(wm * wm * v, axis=0) / (den_w * den_w), jnp.maximum(v_ref, e_ref**2)
    )
    used = (consistent & valid).astype(dt)
    return DeghostResult(rad, var, used, ref, stat)
