"""Colour-chart calibration (issue 26, `jaxgfx.hdr.raw.chart`): the ColorChecker reference,
patch sampling from a perspective-warped chart (OpenCV's warp as the independent renderer), the
root-polynomial's exposure invariance, jit, AD vs finite differences of the ΔE residuals, bad
input, and (slow: one Levenberg-Marquardt compile each) the fit on a synthetic camera with a
published colour matrix."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx import color, hdr
from jaxgfx.hdr.raw import (
    ChartCalibration,
    DngColorProfile,
    apply_chart_calibration,
    chart_delta_e,
    chart_patch_means,
    chart_terms,
    colorchecker_reference,
    dng_camera_to_xyz_d50,
    dng_xyz_to_camera,
    fit_chart_matrix,
)
from jaxgfx.hdr.raw.chart import _Residuals
from jaxgfx.testing import check_grads_fd

CORNERS = np.array([[30.3, 20.7], [170.2, 35.1], [160.8, 125.4], [22.5, 110.9]])


def _warped_chart(colors, h=150, w=200, cell=40, gap=0.15, background=0.3, seed=0):
    """An axis-aligned 4x6 chart (cells of ``cell`` px, ``gap`` of body grey 0.05 between
    patches) warped onto ``CORNERS`` by OpenCV, plus noise and a few hot pixels."""
    import cv2

    flat = np.full((4 * cell, 6 * cell, 3), 0.05, np.float32)
    b = int(round(gap / 2 * cell))
    for k, c in enumerate(colors):
        r, s = divmod(k, 6)
        flat[r * cell + b : (r + 1) * cell - b, s * cell + b : (s + 1) * cell - b] = c
    src = np.array(
        [
            [-0.5, -0.5],
            [6 * cell - 0.5, -0.5],
            [6 * cell - 0.5, 4 * cell - 0.5],
            [-0.5, 4 * cell - 0.5],
        ],
        np.float32,
    )
    m = cv2.getPerspectiveTransform(src, CORNERS.astype(np.float32))
    img = cv2.warpPerspective(
        flat,
        m,
        (w, h),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=(background,) * 3,
    )
    rng = np.random.default_rng(seed)
    img = img + rng.normal(0, 0.01, img.shape).astype(np.float32)
    hot = rng.integers(0, [h, w], (60, 2))
    img[hot[:, 0], hot[:, 1]] = 5.0  # specks: the interquartile mean ignores them
    return img


def test_reference_is_colour_sciences_colorchecker():
    ref = colorchecker_reference()
    cc = colour.CCS_COLOURCHECKERS["ColorChecker24 - After November 2014"]
    assert ref.patch_names == tuple(cc.data) and len(ref.patch_names) == 24
    np.testing.assert_allclose(
        ref.xyz, colour.xyY_to_XYZ(np.array(list(cc.data.values()))), rtol=1e-12
    )
    np.testing.assert_allclose(ref.illuminant_xy, color.WHITEPOINTS["D50"], atol=1e-4)
    ref.xyz[0] = 0  # a copy: the cached values stay
    assert colorchecker_reference().xyz[0, 1] > 0


def test_patch_means_of_a_perspective_warped_chart():
    colors = np.random.default_rng(1).uniform(0.1, 0.9, (24, 3)).astype(np.float32)
    img = _warped_chart(colors)
    got = np.asarray(chart_patch_means(img, CORNERS))
    assert got.shape == (24, 3)
    # 144 bilinear samples of 0.01 noise per patch: the mean is within ~0.003
    np.testing.assert_allclose(got, colors, atol=0.006)
    # one channel in, one channel out; a saturated patch is NaN
    np.testing.assert_allclose(
        np.asarray(chart_patch_means(img[..., 1], CORNERS)), got[:, 1], atol=1e-6
    )
    sat = np.asarray(chart_patch_means(np.minimum(img, 0.85), CORNERS, saturation=0.85))
    assert np.all(np.isnan(sat[colors.max(1) > 0.87])) and np.all(
        np.isfinite(sat[colors.max(1) < 0.8])
    )


def test_colorchecker_scene_patches_recovered():
    """hdr.colorchecker_scene (the CLI test's chart) holds the reference in linear Rec.709."""
    scene = hdr.colorchecker_scene(150, 200, CORNERS)
    got = np.asarray(chart_patch_means(scene.astype(np.float32), CORNERS))
    ref = colorchecker_reference()
    cat = np.asarray(color.chromatic_adaptation_matrix(jnp.asarray(ref.illuminant_xy), "D65"))
    want = ref.xyz @ (np.linalg.inv(color.rgb_to_xyz_matrix("rec709")) @ cat).T
    np.testing.assert_allclose(got, want, atol=1e-5)


def test_root_polynomial_is_exposure_invariant(rng):
    """Finlayson et al. 2015: terms of degree 1, so t(k rgb) = k t(rgb) and the fitted map
    scales with the exposure (a plain polynomial would not)."""
    rgb = rng.uniform(0.01, 2.0, (50, 3))
    for k in (0.01, 3.0, 250.0):
        np.testing.assert_allclose(
            np.asarray(chart_terms(k * rgb, "root-polynomial")),
            k * np.asarray(chart_terms(rgb, "root-polynomial")),
            rtol=1e-6,
        )
    cal = ChartCalibration(
        jnp.asarray(rng.normal(size=(3, 6)), jnp.float32),
        jnp.asarray([1.7, 1.0, 1.4]),
        jnp.ones(3),
        jnp.zeros(24),
        jnp.zeros(24),
        "root-polynomial",
    )
    out = np.asarray(apply_chart_calibration(cal, rgb, colorspace="rec709"))
    np.testing.assert_allclose(
        np.asarray(apply_chart_calibration(cal, 40.0 * rgb, colorspace="rec709")),
        40.0 * out,
        rtol=2e-5,
        atol=1e-6,
    )
    # the neutral axis: sqrt(rg) = g for r = g, so greys see the linear part only
    grey = np.asarray(chart_terms(jnp.array([0.5, 0.5, 0.5]), "root-polynomial"))
    np.testing.assert_allclose(grey, 0.5, rtol=1e-6)


def test_jit_matches_eager(rng):
    img = _warped_chart(rng.uniform(0.1, 0.9, (24, 3)))
    f = jax.jit(chart_patch_means, static_argnames=("rows", "cols", "samples", "margin"))
    np.testing.assert_allclose(
        np.asarray(f(img, jnp.asarray(CORNERS, jnp.float32))),
        np.asarray(chart_patch_means(img, CORNERS)),
        atol=1e-6,
    )
    cal = ChartCalibration(
        jnp.asarray(rng.normal(size=(3, 3)), jnp.float32),
        jnp.ones(3),
        jnp.ones(3),
        jnp.zeros(24),
        jnp.zeros(24),
    )
    x, v = jnp.asarray(rng.uniform(0, 1, (4, 5, 3)), jnp.float32), jnp.full((4, 5, 3), 0.01)
    jf = jax.jit(apply_chart_calibration, static_argnames="colorspace")
    eager = apply_chart_calibration(cal, x, v, colorspace="acescg")
    for a, b in zip(jf(cal, x, v, colorspace="acescg"), eager, strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5, atol=1e-7)
    # the matrix model's variance is M² var (exact)
    m = np.asarray(cal.matrix, np.float64)
    np.testing.assert_allclose(
        np.asarray(jf(cal, x, v)[1]), np.full((4, 5, 3), 0.01) @ (m * m).T, rtol=1e-5
    )
    ref_lab = color.xyz_to_lab(jnp.asarray(colorchecker_reference().xyz, jnp.float32), white="D50")
    de = jax.jit(chart_delta_e, static_argnames=("model", "illuminant"))
    rgb = jnp.asarray(rng.uniform(0.05, 0.9, (24, 3)), jnp.float32)
    np.testing.assert_allclose(
        np.asarray(de(rgb, ref_lab, cal.matrix)),
        np.asarray(chart_delta_e(rgb, ref_lab, cal.matrix)),
        rtol=1e-5,
    )


# 4.2 s of the default run (2026-12-04, load 4.5);
# tests/color keeps delta_e_2000_residuals' fast checks
@pytest.mark.slow
def test_delta_e_residual_gradients_vs_finite_differences(x64, rng):
    """AD of the fit's least-squares objective ½ Σ ||r||² (r = delta_e_2000_residuals of the
    predicted Lab, ||r|| = ΔE00 per patch) w.r.t. the root-polynomial matrix (its linear part,
    the roots and the white-preserving column) and the white-balance gains, against central
    differences in float64 (2-3 s on the loaded 2-core machine: two compiles)."""
    ref = colorchecker_reference()
    lab = color.xyz_to_lab(jnp.asarray(ref.xyz), white="D50")
    c = np.array([[0.9, 0.3, -0.1], [-0.2, 1.1, 0.1], [0.05, -0.3, 1.2]])  # XYZ -> camera
    rgb = jnp.asarray(ref.xyz @ c.T)
    m0 = np.c_[
        np.linalg.inv(c) * (1 + 0.05 * rng.standard_normal((3, 3))),
        0.02 * rng.standard_normal((3, 3)),
    ]  # away from ΔE = 0
    res = _Residuals("root-polynomial", True)
    white = color.whitepoint_xyz("D50", like=rgb)
    args = (rgb, lab, jnp.ones(24, bool), white)

    def unflat(flat):
        return {"a": flat[:15].reshape(3, 5), "s": flat[15], "log_g": flat[16:]}

    def obj(flat):
        return 0.5 * jnp.sum(res(unflat(flat), args) ** 2)

    flat = jnp.concatenate([jnp.asarray(m0[:, :5]).ravel(), jnp.array([1.0, 0.1, -0.2])])
    ok, g_ad, g_fd = check_grads_fd(obj, flat, eps=1e-6, rtol=1e-5, atol=1e-6, jit=True)
    assert ok, (g_ad, g_fd)
    assert np.abs(g_ad).min() > 0  # every parameter (gains included) moves the ΔE
    # the white-preserving constraint: the balanced neutral maps to s · white
    mm, _ = res.unpack(unflat(flat), white)
    np.testing.assert_allclose(np.asarray(mm @ jnp.ones(6)), np.asarray(white), rtol=1e-12)


def test_bad_input_is_one_clear_error():
    img = np.ones((100, 150, 3), np.float32)
    ok = np.array([[10.0, 10], [140, 10], [140, 90], [10, 90]])
    with pytest.raises(
        ValueError,
        match=r"corners: the bottom-right point \(x=160, y=90\) lies "
        r"outside the 150x100 image",
    ):
        chart_patch_means(img, ok + [[0, 0], [0, 0], [20, 0], [0, 0]])
    with pytest.raises(ValueError, match=r"corners: expected shape \(4, 2\)"):
        chart_patch_means(img, ok[:3])
    with pytest.raises(
        ValueError,
        match="corners: not a convex quadrilateral in the order "
        "top-left, top-right, bottom-right, bottom-left",
    ):
        chart_patch_means(img, ok[[0, 1, 3, 2]])
    with pytest.raises(ValueError, match=r"image: expected \(H, W\) or \(H, W, C\)"):
        chart_patch_means(np.ones(5), ok)
    with pytest.raises(ValueError, match="margin: expected a fraction"):
        chart_patch_means(img, ok, margin=0.5)
    with pytest.raises(ValueError, match="camera_rgb: 0 usable patches of 24"):
        fit_chart_matrix(np.zeros((24, 3)))
    with pytest.raises(ValueError, match="camera_rgb: 4 usable patches of 24"):
        fit_chart_matrix(np.r_[np.ones((4, 3)), np.full((20, 3), np.nan)])
    with pytest.raises(ValueError, match=r"camera_rgb: expected shape \(P, 3\)"):
        fit_chart_matrix(np.ones((24, 4)))
    with pytest.raises(ValueError, match="camera_rgb: expected 24 patches"):
        fit_chart_matrix(np.ones((18, 3)))
    with pytest.raises(ValueError, match=r"reference: expected shape \(24, 3\)"):
        fit_chart_matrix(np.ones((24, 3)), np.ones((20, 3)))
    with pytest.raises(ValueError, match="model: .*expected one of"):
        fit_chart_matrix(np.ones((24, 3)), model="polynomial")
    with pytest.raises(ValueError, match=r"matrix: expected shape \(3, 6\)"):
        chart_delta_e(np.ones((24, 3)), np.ones((24, 3)), np.eye(3), model="root-polynomial")


def test_chart_calibration_dict_round_trip():
    cal = ChartCalibration(
        jnp.arange(18.0).reshape(3, 6),
        jnp.array([2.0, 1.0, 1.5]),
        jnp.array([0.5, 1.0, 0.66]),
        jnp.array([3.0, np.nan]),
        jnp.array([0.5, np.nan]),
        "root-polynomial",
        "D65",
        False,
        "x",
    )
    d = cal.to_dict()
    assert d["delta_e_after"] == [0.5, None] and d["after"]["median"] == 0.5
    back = ChartCalibration.from_dict(d)
    np.testing.assert_array_equal(np.asarray(back.matrix), np.asarray(cal.matrix))
    assert (back.model, back.illuminant, back.white_balance) == ("root-polynomial", "D65", False)
    with pytest.raises(ValueError, match="chart: not a chart calibration record"):
        ChartCalibration.from_dict({"matrix": [1]})


# ------------------------------------------------------------------------------ the fit


def _synthetic_camera(seed=0, rel_noise=0.005):
    """ColorChecker patches under D65 seen by a Canon EOS 5D Mark II (its published DNG
    ColorMatrix1/2 interpolated at D65) at an arbitrary exposure, with 0.5 % noise. Returns
    (camera RGB, the true camera -> XYZ(D50) matrix, the true camera neutral (max 1))."""
    tags = {k: np.ravel(v).astype(float) for k, v in hdr.CANON_EOS_5D_MARK_II.items()}
    prof = DngColorProfile.from_tags(tags)
    d65 = jnp.asarray(color.WHITEPOINTS["D65"])
    xyz_to_cam = np.asarray(dng_xyz_to_camera(prof, d65), np.float64)
    cat = np.asarray(color.chromatic_adaptation_matrix("D50", "D65"), np.float64)
    true = np.linalg.inv(0.37 * xyz_to_cam @ cat)  # camera -> XYZ(D50)
    rgb = colorchecker_reference().xyz @ np.linalg.inv(true).T
    rng = np.random.default_rng(seed)
    rgb = rgb * (1 + rel_noise * rng.standard_normal(rgb.shape)) + 1e-4 * rng.standard_normal(
        rgb.shape
    )
    n = xyz_to_cam @ np.asarray(color.whitepoint_xyz("D65"), np.float64)
    return rgb, true, n / n.max(), prof


@pytest.mark.slow  # ~14 s on the loaded 2-core machine: two LM compiles (~6 s each)
def test_fit_recovers_the_camera_matrix_and_white_balance():
    rgb, true, neutral, prof = _synthetic_camera()
    cal = fit_chart_matrix(rgb)
    s = cal.summary()
    assert s["patches_used"] == 24 and s["after"]["median"] < 1.0  # issue 26 target
    # the matrix (white balance folded in) within 1 % of its largest entry
    m = np.asarray(cal.camera_to_xyz_matrix(), np.float64)
    assert np.abs(m - true).max() < 0.01 * np.abs(true).max()
    np.testing.assert_allclose(np.asarray(cal.neutral), neutral, atol=0.005)
    np.testing.assert_allclose(np.asarray(cal.gains), neutral[1] / neutral, rtol=0.01)
    assert s["after"]["median"] <= s["before"]["median"] + 1e-6  # ΔE fit <= its XYZ start
    # normalised: the neutral (max 1) maps to Y = 1, as the DNG matrix does
    norm = cal.normalized()
    assert float(apply_chart_calibration(norm, norm.neutral)[1]) == pytest.approx(1.0, rel=1e-5)
    # "before" from the DNG matrix of the same camera: reported, exposure matched
    dng, _, _ = dng_camera_to_xyz_d50(prof, jnp.asarray(neutral))
    cal2 = fit_chart_matrix(rgb, white_balance=False, before=np.asarray(dng), before_source="DNG")
    assert cal2.before.startswith("DNG") and cal2.summary()["before"]["median"] < 3.0
    # without white balance: the same optimum (the split is a reparametrisation for a matrix)
    np.testing.assert_allclose(
        np.asarray(cal2.camera_to_xyz_matrix()), m, atol=2e-3 * np.abs(m).max()
    )


@pytest.mark.slow  # ~8 s on the loaded 2-core machine (one LM compile)
def test_root_polynomial_fit_and_exposure():
    rgb, true, neutral, _ = _synthetic_camera(seed=2)
    cal = fit_chart_matrix(rgb, model="root-polynomial")
    s = cal.summary()
    assert s["after"]["median"] < 1.0
    np.testing.assert_allclose(np.asarray(cal.neutral), neutral, atol=0.005)
    # a 3x brighter chart: the same colours (exposure invariance of the fitted map)
    x = jnp.asarray(rgb, jnp.float32)
    np.testing.assert_allclose(
        np.asarray(apply_chart_calibration(cal, 3 * x)),
        3 * np.asarray(apply_chart_calibration(cal, x)),
        rtol=1e-4,
        atol=1e-6,
    )
