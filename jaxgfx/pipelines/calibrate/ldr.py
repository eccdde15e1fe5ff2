"""The LDR path: load the stack (files, or the embedded synthetic one), align, fit the
response, merge (one call, :func:`merge`: the seam for a ghost-free merge), self-check, and
compare with the ground truth of a synthetic stack."""

from __future__ import annotations

import numpy as np

from .config import CalibrateConfig, MergeConfig
from .inputs import to_float01
from .report import CalibrateResult

__all__: list[str] = []  # the job's stages (tests patch _load_ldr / _fit_ldr here)


def _load_ldr(cfg: CalibrateConfig, files, sidecar, steps, result_kw: dict):
    """The LDR stack (files, or the embedded synthetic one) as ``(images, times, truth)``."""
    import jax

    from jaxgfx import hdr, io

    steps.start("load")
    if files:
        images, times = io.read_ldr_stack(files, exposure_times=cfg.exposure_times, sidecar=sidecar)
        truth = None
    else:
        s = cfg.synthetic
        k1, k2 = jax.random.split(jax.random.key(s.seed))
        radiance = hdr.synthetic_radiance(k1, s.height, s.width, dynamic_range=s.dynamic_range)
        true_resp = hdr.synthetic_response(s.response)
        times = np.asarray(s.exposure_times, np.float64)
        images = hdr.make_bracketed_stack(
            k2, radiance, times, true_resp, bits=s.bits, gain=s.gain, read_sigma=s.read_sigma
        ).images
        truth = (true_resp, np.asarray(radiance))
        result_kw["synthetic"] = {"response": s.response, "bits": s.bits}
    images = np.asarray(images)
    times = np.asarray(times, np.float64)
    result_kw["times"] = times
    result_kw["image_shape"] = images.shape
    if cfg.align.enabled:
        steps.start("align")
        aligned, shifts = hdr.align_stack(to_float01(images), method=cfg.align.method)
        result_kw["alignment_shifts"] = shifts
        images = np.asarray(aligned)
    return images, times, truth


def merge(
    images,
    times,
    resp,
    cfg: MergeConfig,
    *,
    return_variance: bool = True,
    frames: dict | None = None,
):
    """The merge stage: radiance (and its variance) of the bracket through ``resp``; with
    ``merge.deghost`` the ghost-free merge (:func:`jaxgfx.hdr.merge_deghosted`: frames that
    disagree with a per-region reference exposure under the noise model are left out), whose
    :class:`jaxgfx.hdr.DeghostResult` (which frames each pixel came from) is stored as
    ``frames["result"]`` when a dict ``frames`` is given."""
    from jaxgfx import hdr

    if cfg.deghost:
        r = hdr.merge_deghosted(images, times, resp)
        if frames is not None:
            frames["result"] = r
        return (r.radiance, r.variance) if return_variance else r.radiance
    return hdr.merge_radiance(
        images, times, resp, weighting=cfg.weighting, return_variance=return_variance
    )


def _fit_ldr(cfg: CalibrateConfig, images, times, truth, steps, result_kw) -> CalibrateResult:
    """Response fit, merge, leave-one-out self-check (and errors vs a synthetic truth)."""
    import jax

    from jaxgfx import hdr

    steps.start("fit response")
    resp = hdr.recover_response(
        images, times, method=cfg.response.method, **dict(cfg.response.options)
    )
    jax.block_until_ready(jax.tree_util.tree_leaves(resp))
    steps.start("merge")
    frames: dict = {}
    radiance, variance = merge(images, times, resp, cfg.merge, frames=frames)
    result_kw["frames"] = frames.get("result")
    steps.start("evaluate")
    loo = hdr.leave_one_out(images, times, resp, weighting=cfg.merge.weighting)
    result_kw["loo"] = loo
    curves = {cfg.response.method: resp}
    errors = None
    if truth is not None:
        true_resp, true_radiance = truth
        errors = {}
        for m in dict.fromkeys((cfg.response.method, *cfg.response.compare)):
            r = curves.get(m) or hdr.recover_response(images, times, method=m)
            curves[m] = r
            e = merge(images, times, r, cfg.merge, return_variance=False)
            errors[m] = {
                "curve_rmse_ln": float(hdr.response_curve_error(r, true_resp)),
                "radiance_median_abs_ln": float(hdr.radiance_error(e, true_radiance)),
            }
    return CalibrateResult(
        radiance=np.asarray(radiance, np.float32),
        variance=np.asarray(variance, np.float32),
        response=resp,
        curves=curves,
        truth=truth,
        errors=errors,
        **result_kw,
    )
