"""The RAW path: read the bracket, optionally align it (``config.align``:
:func:`jaxgfx.hdr.align_raw_stack` on the normalised mosaics, each CFA plane moved by the same
translation, before anything is measured), calibrate the sensor
(:func:`jaxgfx.hdr.calibrate_raw_stack`), merge the normalised mosaics with the measured
exposure ratios and noise model (one call, :func:`merge_mosaics`), demosaic, then white-balance
and convert camera RGB to ``config.colorspace`` (:func:`jaxgfx.hdr.raw.color_transform`: the DNG
colour tags, or LibRaw's matrix). With ``config.flat_field`` the lens vignetting is fitted from
that frame (:func:`jaxgfx.hdr.raw.fit_vignetting`) and divided out of the merged mosaic: for a
linear sensor that equals dividing every frame by it, while the saturation test of the merge
still sees the recorded levels. With ``config.chart`` (a ColorChecker's corners in the merged
image) the chart's patches are sampled from the merged camera RGB, the camera matrix and white
balance are fitted to them (:func:`fit_chart_step`: :func:`jaxgfx.hdr.raw.fit_chart_matrix`,
CIEDE2000 least squares, the DNG / LibRaw matrix reported as "before") and that fit, not the
file's matrix, makes the colour-managed output."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from .config import CalibrateConfig
from .report import CalibrateResult


class ChartResult(NamedTuple):
    """The chart step's result: the fitted :class:`jaxgfx.hdr.raw.ChartCalibration`
    (normalised: the neutral maps to Y = 1), the corners ``(4, 2)``, the patches' camera RGB
    ``(24, 3)`` at the chart's exposure, and XYZ(D50) ``(24, 3)`` in the reference's units of the
    reference, the "before" matrix (exposure matched in Y) and the fit (for ``chart.png``)."""

    calibration: Any
    corners: Any
    camera_rgb: Any
    xyz_reference: Any
    xyz_before: Any
    xyz_after: Any

    def to_dict(self) -> dict:
        """``report.json`` "chart"."""
        from jaxgfx.hdr.raw import COLORCHECKER24, CORNER_ORDER, colorchecker_reference

        f = lambda a: np.round(np.asarray(a, np.float64), 8).tolist()  # noqa: E731
        return {
            "reference": COLORCHECKER24 + " (colour-science), XYZ under D50",
            "corners_xy_px": f(self.corners),
            "corner_order": list(CORNER_ORDER),
            "patch_names": list(colorchecker_reference().patch_names),
            "camera_rgb": [[None if not np.isfinite(v) else v for v in row]
                           for row in f(self.camera_rgb)],  # fmt: skip
            **self.calibration.to_dict(),
        }


def check_chart_corners(cfg: CalibrateConfig, shape) -> None:
    """``config.chart`` inside the merged image of ``shape`` ``(H, W)`` and a convex
    quadrilateral in the documented order: one ``ValueError`` naming ``chart`` (``--chart``),
    before anything is computed."""
    from jaxgfx.hdr.raw.chart import _check_corners

    try:
        _check_corners(np.reshape(np.asarray(cfg.chart, np.float64), (4, 2)), tuple(shape))
    except ValueError as e:
        raise ValueError(f"chart (--chart): {str(e).removeprefix('corners: ')}") from None


def fit_chart_step(cfg: CalibrateConfig, camera_rgb, ct, raw) -> tuple[ChartResult, Any]:
    """Sample the chart at ``config.chart`` in the merged, demosaiced ``camera_rgb``
    ``(H, W, 3)``, fit ``config.chart_model`` with white balance (D50, the ICC connection
    space), the file's colour transform ``ct`` (:func:`jaxgfx.hdr.raw.color_transform`) giving
    the "before". Returns the :class:`ChartResult` and the :class:`jaxgfx.hdr.raw.ColorTransform`
    of the fit (its matrix: exact for ``"matrix"``, the root-polynomial's Jacobian at the
    neutral otherwise; the white's xy / CCT from the DNG matrices when the file has them)."""
    import jax.numpy as jnp

    from jaxgfx import color
    from jaxgfx.hdr import raw as hraw

    corners = np.reshape(np.asarray(cfg.chart, np.float64), (4, 2))
    patches = np.asarray(hraw.chart_patch_means(np.asarray(camera_rgb, np.float32), corners))
    to_space = np.asarray(hraw.xyz_d50_to_space_matrix(cfg.colorspace), np.float64)
    before = np.linalg.solve(to_space, np.asarray(ct.matrix, np.float64))  # camera -> XYZ(D50)
    cal = hraw.fit_chart_matrix(
        patches, model=cfg.chart_model, white_balance=True, illuminant="D50", before=before,
        before_source=f"{ct.matrix_source}; white balance: {ct.white_balance_source}",
    )  # fmt: skip
    norm = cal.normalized()
    ref = hraw.colorchecker_reference().xyz
    ok = np.all(np.isfinite(patches), axis=1)
    after = np.asarray(hraw.apply_chart_calibration(cal, np.where(ok[:, None], patches, 0.0)))
    yb = (np.where(ok[:, None], patches, 0.0) @ before.T)[:, 1]
    scale = float(yb[ok] @ ref[ok, 1] / (yb[ok] @ yb[ok]))
    xyz_before = np.where(ok[:, None], patches, 0.0) @ (before * scale).T
    nan = np.where(ok, 0.0, np.nan)[:, None]
    result = ChartResult(norm, corners, patches, ref, xyz_before + nan, after + nan)

    neutral = jnp.asarray(norm.neutral)
    xy = jnp.asarray(color.WHITEPOINTS["D50"], neutral.dtype)
    if "color_matrix1" in raw.dng_color:
        prof = hraw.DngColorProfile.from_tags(raw.dng_color, f"'{raw.path}'")
        xy = hraw.dng_neutral_to_xy(prof, neutral)
    s = cal.summary()
    src = (
        f"ColorChecker chart fit ({cfg.chart_model}; CIEDE2000 least squares, median ΔE00 "
        f"{s['before']['median']:.2f} before -> {s['after']['median']:.2f} after), "
        f"Bradford XYZ(D50) -> {cfg.colorspace}"
    )
    if cfg.chart_model != "matrix":
        src += "; this matrix is the root-polynomial's Jacobian at the neutral (report 'chart')"
    ct_chart = hraw.ColorTransform(
        jnp.asarray(to_space) @ norm.camera_to_xyz_matrix(), neutral, xy, color.xy_to_cct(xy),
        cfg.colorspace, src, "chart", "the chart's fitted white-balance gains",
    )  # fmt: skip
    return result, ct_chart

__all__: list[str] = []  # the job's stages (tests patch _fit_raw / merge_mosaics here)


class MosaicMerge(NamedTuple):
    """Output of :func:`merge_mosaics`: ``radiance`` and ``variance`` mosaics ``(H, W, 1)``;
    with ``deghost`` also ``frames``, the :class:`jaxgfx.hdr.DeghostResult` (``used``
    ``(N, H, W)``, ``reference`` ``(H, W)``: which frames each pixel came from), else None."""

    radiance: Any
    variance: Any
    frames: Any = None


def merge_mosaics(norm, times, cal, *, deghost: bool = False) -> MosaicMerge:
    """The merge stage of a RAW bracket: the normalised mosaics ``norm`` ``(N, H, W)``
    (``RawImage.normalized()``, aligned when ``align.enabled``) merged as one channel with the
    measured exposure ratios (nominal times when a ratio could not be measured) and the CFA
    channels' noise model pooled. ``deghost``: the ghost-free merge
    (:func:`jaxgfx.hdr.merge_deghosted`), which needs the noise model measured from the
    bracket; without one (``cal.noise is None``) it is refused with one error naming
    ``--deghost`` (never a silent plain merge)."""
    from jaxgfx import hdr

    norm = np.asarray(norm, np.float32)[..., None]
    ratios = np.asarray(cal.ratios.ratios, np.float64)
    ref = int(np.asarray(cal.ratios.reference))
    good = ratios.shape == times.shape and np.all(np.isfinite(ratios)) and np.all(ratios > 0)
    eff_times = times[ref] * ratios if good else times
    resp = hdr.CameraResponse.gamma(1.0, channels=1, anchor="unit")
    weighting = "noise" if cal.noise is not None else "hat"
    noise = None  # the mosaic is merged as one channel: the CFA channels' model, pooled
    if cal.noise is not None:
        noise = hdr.NoiseModel(
            np.mean(np.asarray(cal.noise.gain), keepdims=True),
            np.mean(np.asarray(cal.noise.read_variance), keepdims=True),
        )
    if deghost:  # ghost-free merge under the measured noise model
        if noise is None:
            why = cal.noise_method or "not estimated"
            raise ValueError(
                "--deghost (merge.deghost): the ghost-free RAW merge decides what moved under "
                f"the sensor noise model, and this bracket gave none ({why}); run without "
                "--deghost, or shoot a bracket whose adjacent frames overlap in unclipped "
                "pixels so that the noise model can be measured"
            )
        r = hdr.merge_deghosted(norm, eff_times, None, noise=noise)
        return MosaicMerge(r.radiance, r.variance, r)
    rad, var = hdr.merge_radiance(
        np.clip(norm, 0.0, 1.0),
        eff_times,
        resp,
        weighting=weighting,
        noise=noise,
        return_variance=True,
    )
    return MosaicMerge(rad, var)


def align_mosaics(raws, pattern: str, method: str):
    """The normalised mosaics of ``raws`` aligned to the middle frame
    (:func:`jaxgfx.hdr.align_raw_stack`, the same shift for each CFA plane) and the raw-unit
    mosaics rebuilt from them (with frame 0's black and white levels) for the sensor
    calibration. Returns ``(norm, mosaics, shifts)``; ``shifts (N, 2)`` in full-resolution px."""
    from jaxgfx import hdr

    norm = np.stack([r.normalized() for r in raws])
    aligned, shifts = hdr.align_raw_stack(norm, cfa_pattern=pattern, method=method)
    norm = np.asarray(aligned, np.float32)
    r0 = raws[0]
    black = r0.black_level_per_color[r0.raw_colors]
    mosaics = (norm * (r0.white_level - black) + black).astype(np.float32)
    return norm, mosaics, np.asarray(shifts, np.float64)


def _fit_raw(cfg: CalibrateConfig, files, steps) -> CalibrateResult:
    """Read, align (``align.enabled``), calibrate the sensor, merge, demosaic."""
    from jaxgfx import hdr, image, io

    steps.start("read raw")
    raws, times = io.read_raw_stack(files, exposure_times=cfg.exposure_times)
    pattern = raws[0].cfa_pattern
    mosaics = np.stack([r.mosaic for r in raws]).astype(np.float32)
    if cfg.chart is not None:  # the merged image has the mosaic's size
        check_chart_corners(cfg, mosaics.shape[1:])
    norm = np.stack([r.normalized() for r in raws])
    black = np.asarray(raws[0].black_level, np.float32)
    white = float(raws[0].white_level)
    shifts = None
    if cfg.align.enabled:  # before any measurement: calibration and merge assume a static frame
        steps.start("align")
        norm, mosaics, shifts = align_mosaics(raws, pattern, cfg.align.method)
    vig = None
    if cfg.flat_field is not None:
        flat = io.read_raw(cfg.flat_field)
        if flat.mosaic.shape != mosaics.shape[1:]:
            raise ValueError(
                f"flat_field '{cfg.flat_field}': mosaic {flat.mosaic.shape} differs from the "
                f"bracket's {mosaics.shape[1:]}; use a flat field of the same camera and size"
            )
        steps.start("vignetting")
        vig = hdr.raw.fit_vignetting(flat.normalized())
    steps.start("raw calibration")
    cal = hdr.calibrate_raw_stack(mosaics, times, cfa_pattern=pattern, black=black, white=white)
    steps.start("merge")
    m = merge_mosaics(norm, times, cal, deghost=cfg.merge.deghost)
    rad, var = m.radiance, m.variance
    if vig is not None:  # linear sensor: dividing the merge = dividing each frame by V
        rad, var = hdr.raw.devignette(np.asarray(rad)[..., 0], vig, np.asarray(var)[..., 0])
        rad, var = np.asarray(rad)[..., None], np.asarray(var)[..., None]
    steps.start("demosaic")
    rgb = np.asarray(image.demosaic(np.asarray(rad)[..., 0], pattern, method=cfg.demosaic))
    var_rgb = np.asarray(
        image.demosaic(np.asarray(var)[..., 0], pattern, method="bilinear"), np.float32
    )
    steps.start("colour")
    ct = hdr.raw.color_transform(
        raws[0], rgb, colorspace=cfg.colorspace, white_balance=cfg.white_balance
    )
    chart = None
    if cfg.chart is not None:
        steps.start("chart")
        chart, ct = fit_chart_step(cfg, rgb, ct, raws[0])
        rgb, var_rgb = hdr.raw.apply_chart_calibration(
            chart.calibration, rgb, var_rgb, colorspace=cfg.colorspace
        )
    else:
        rgb, var_rgb = hdr.raw.apply_color_transform(rgb, ct, var_rgb)
    return CalibrateResult(
        radiance=np.asarray(rgb, np.float32),
        variance=np.asarray(var_rgb, np.float32),
        color=ct,
        times=times,
        image_shape=mosaics.shape,
        raw_calibration=cal,
        vignetting=vig,
        chart=chart,
        alignment_shifts=shifts,
        frames=m.frames,
    )
