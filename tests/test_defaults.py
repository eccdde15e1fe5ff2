"""Defaults that earlier fixes set on purpose, pinned through their effect (issue 28).

Each test calls a function *without* the option and compares with an independent reference
computed for the documented default (a closed form, or scikit-image), plus a negative control
showing that the next plausible value would give a different answer, so changing the default
fails here. ``tools/mutants.py`` holds one mutant per default (``defaults.*``).

* ``hdr.merge_radiance``: ``weighting="slope"``, ``time_power=2`` (commit 2b64734: hat x t^2,
  the inverse variance of ``x / t`` for exposure-independent noise; ``time_power=0`` let a
  short frame's near-black levels pull dark pixels too bright; issue 26: the ``slope`` factor
  ``rho^2 / (x'^2 + rho^2)`` for noise in levels, docs/hdr.md "The merge weight").
* ``image.canny``: ``sigma=1.0`` (and ``truncate=4``), scikit-image's defaults.
* ``optim.fit``: ``optimizer="adam"``, ``learning_rate=1e-2``, ``patience=10``.
* ``hdr.merge_deghosted``: ``threshold=4``, ``sigma=2``, ``region_sigma=4``,
  ``saturation=0.98`` (commit f45ac79, docs/hdr.md).
* ``tonemap.tonemap_contrast_inversion``: ``k=4``, ``strength=0.3`` (commit 7cdd24a: the
  partial division keeps the order of regions).
* ``tonemap.tonemap_Reinhard2002``: ``white=None``, the image maximum (commit ea6698c).
* ``tonemap.tonemap_Reinhard2005``: ``intensity`` limited to [-8, 8] (commit ea6698c: 100 was
  accepted and gave a black image).
"""

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.ndimage as ndi
import skimage.draw as draw
from skimage.feature import canny as sk_canny

from jaxgfx import hdr
from jaxgfx import tonemap as tm
from jaxgfx.hdr import CameraResponse, NoiseModel
from jaxgfx.image import canny
from jaxgfx.optim import fit

# ------------------------------------------------------------------ hdr.merge_radiance


def _hat(z):  # Debevec & Malik (1997): 2 min(z, 1 - z) on normalised levels
    return 2.0 * np.minimum(z, 1.0 - z)


def _merge_reference(z, t, time_power, gamma=1.0, rho=None):
    """Closed form of the weighted merge with the response ``x = z^gamma``: sum w E / sum w,
    ``E_j = x(z_j) / t_j``, ``w_j = hat(z_j) (t_j / t_max)^time_power``, times the slope
    factor ``rho^2 / (x'^2 + rho^2)`` with ``x' = gamma z^(gamma - 1) / 255`` per 8-bit level
    when ``rho`` is given."""
    w = _hat(z) * (t / t.max())[:, None] ** time_power
    if rho is not None:
        dx = gamma * z ** (gamma - 1.0) / 255.0
        w = w * rho**2 / (dx * dx + rho**2)
    return np.sum(w * z**gamma / t[:, None], axis=0) / np.sum(w, axis=0)


def test_merge_default_is_slope_times_t_squared():
    # two frames per pixel that disagree (E = 0.25 vs 0.30, 0.10 vs 0.14): the weights decide
    z = np.array([[0.25, 0.10, 0.45], [0.60, 0.28, 0.70]], np.float32)  # (N=2, pixels)
    t = np.array([1.0, 2.0], np.float32)
    zd, td = z.astype(np.float64), t.astype(np.float64)
    # a linear response: the slope factor is the same for every level, so hat x t^2
    resp = CameraResponse.gamma(1.0, anchor="unit")
    got = np.asarray(hdr.merge_radiance(z[:, None, :], t, resp))[0]
    ref = _merge_reference(zd, td, 2.0)
    np.testing.assert_allclose(got, ref, rtol=1e-6)
    # pixel 0 by hand: (0.5/4 * 0.25 + 0.8 * 0.30) / (0.5/4 + 0.8)
    assert got[0] == pytest.approx((0.125 * 0.25 + 0.8 * 0.3) / 0.925, rel=1e-6)
    # negative controls: time_power 1 or 0, or the Gaussian weight, are each >= 1 % away
    for other in (
        _merge_reference(zd, td, 1.0),
        _merge_reference(zd, td, 0.0),
        np.asarray(hdr.merge_radiance(z[:, None, :], t, resp, weighting="gaussian"))[0],
    ):
        assert np.max(np.abs(other / ref - 1)) > 0.01
    # a curved response x = z^2: the slope factor (rho = hdr.SLOPE_NOISE_RATIO) weighs the
    # frames differently; the implementation differentiates a 256-level table (rtol 2e-3)
    resp2 = CameraResponse.gamma(2.0, anchor="unit")
    got2 = np.asarray(hdr.merge_radiance(z[:, None, :], t, resp2))[0]
    ref2 = _merge_reference(zd, td, 2.0, gamma=2.0, rho=hdr.SLOPE_NOISE_RATIO)
    np.testing.assert_allclose(got2, ref2, rtol=2e-3)
    hat2 = np.asarray(hdr.merge_radiance(z[:, None, :], t, resp2, weighting="hat"))[0]
    assert np.max(np.abs(hat2 / ref2 - 1)) > 0.01  # the old default is told apart


# ------------------------------------------------------------------ image.canny


def _shapes(n=64, noise=0.05):
    rng = np.random.default_rng(7)
    im = np.zeros((n, n), np.float32)
    rr, cc = draw.disk((22, 24), 11, shape=im.shape)
    im[rr, cc] = 1.0
    rr, cc = draw.polygon([40, 62, 58], [6, 20, 50], shape=im.shape)
    im[rr, cc] = 0.6
    im[6:16, 40:60] = 0.8
    return im + noise * rng.standard_normal(im.shape).astype(np.float32)


def test_canny_default_sigma_is_skimages():
    im = _shapes()
    mine = np.asarray(canny(im, low=0.1, high=0.3))  # sigma and truncate left at defaults
    ref = sk_canny(im, 1.0, 0.1, 0.3, mode="mirror")  # scikit-image: sigma 1, truncate 4
    assert ref.sum() > 100
    np.testing.assert_array_equal(mine, ref)  # measured: identical maps (240 edge pixels)
    # negative controls: sigma 0.9 or 1.1 already move >= 5 pixels (measured 6 and 9)
    for s in (0.9, 1.1):
        assert (sk_canny(im, s, 0.1, 0.3, mode="mirror") != ref).sum() >= 5


# ------------------------------------------------------------------ optim.fit


def test_fit_default_adam_first_step():
    # Adam's first update is lr * g / (|g| + eps) = lr (bias-corrected moments, any |g|);
    # SGD would move by lr * g = 0.01 * 600 = 6
    res = fit(
        lambda p: 100.0 * (p["x"] - 3.0) ** 2, {"x": jnp.float32(0.0)}, steps=1, progress=False
    )
    assert float(res.params["x"]) == pytest.approx(0.01, rel=1e-5)


def test_fit_default_patience_with_tol():
    # a flat loss: the relative change over `patience` steps is 0, so the fit stops as soon
    # as `patience` earlier losses exist, after patience + 1 = 11 evaluations
    res = fit(
        lambda p: 0.0 * p["x"] + 1.0, {"x": jnp.float32(0.0)}, steps=100, tol=1e-6, progress=False
    )
    assert (res.stop_reason, res.n_steps) == ("tol", 11)


# ------------------------------------------------------------------ hdr.merge_deghosted
# Linear RAW frames with read noise only (variance READ at every level): frame j's estimate
# E_j = x_j / t_j has variance READ / t_j^2, so its consistency statistic against the
# reference (frame 0, t = 1, E = 0.3) is exactly d = (E_j - 0.3)^2 / (READ / t_j^2 + READ)
# per pixel, and its window average is the Gaussian blur of d (uniform d: d itself).

READ, E0 = 1e-4, 0.3


def _raw_level(t, d):
    """The RAW level of a frame of exposure ``t`` whose statistic against the reference is
    ``d`` (its estimate above the reference's)."""
    return (E0 + np.sqrt(d * (READ / t**2 + READ))) * t


def _deghost(frames, times):
    noise = NoiseModel(jnp.array([0.0]), jnp.array([READ]))
    z, t = np.asarray(frames, np.float32), np.asarray(times, np.float32)
    return hdr.merge_deghosted(z, t, None, noise=noise, reference=0)


def test_merge_deghosted_default_threshold_window_and_saturation():
    n = 33
    spike = np.zeros((n, n))
    spike[16, 16] = 10.0  # below the per-pixel cap (4 x threshold = 16)
    frames = [
        np.full((n, n), E0),  # the reference
        np.full((n, n), _raw_level(2.0, 3.8)),  # d = 3.8: merged (threshold 4)
        np.full((n, n), _raw_level(2.0, 4.2)),  # d = 4.2: dropped
        _raw_level(2.0, spike),  # the window average of one inconsistent pixel
        np.full((n, n), E0 * 3.25),  # level 0.975: consistent and below saturation 0.98
        np.full((n, n), E0 * 0.985 / 0.3),  # level 0.985: clipped, so not used
    ]
    r = _deghost(frames, [1.0, 2.0, 2.0, 2.0, 3.25, 0.985 / 0.3])
    stat, used = np.asarray(r.statistic), np.asarray(r.used)
    np.testing.assert_allclose(stat[1], 3.8, rtol=1e-5)
    np.testing.assert_allclose(stat[2], 4.2, rtol=1e-5)
    assert used[1].all() and not used[2].any()  # threshold 4: 3.5 or 4.5 would flip one
    # sigma 2: the statistic is d blurred by a Gaussian of 2 px (the blur's 3-sigma kernel)
    ref = ndi.gaussian_filter(spike, 2.0, mode="mirror", truncate=3.0)
    np.testing.assert_allclose(stat[3], ref, atol=1e-5)
    for s in (1.8, 2.2):  # negative control: the centre moves by >= 0.07 (0.399 at 2)
        other = ndi.gaussian_filter(spike, s, mode="mirror", truncate=3.0)
        assert abs(other[16, 16] - ref[16, 16]) > 0.05
    # saturation 0.98: level 0.975 is merged, level 0.985 is clipped
    assert used[4].all() and not used[5].any()


def test_merge_deghosted_default_region_window():
    # frame 0 (the reference, t = 4) is clipped in four stripes 4-7 px wide; frame 1 (t = 1)
    # sees everything. The reference moves to frame 1 where the fraction of valid reference
    # pixels in a Gaussian window of region_sigma = 4 px falls below 1/2
    h, w = 2, 160
    valid = np.ones((h, w))
    x0 = 10
    for width in (4, 5, 6, 7):
        valid[:, x0 : x0 + width] = 0.0
        x0 += width + 30
    frames = [np.where(valid > 0, 0.8, 1.0), np.full((h, w), 0.2)]
    r = _deghost(frames, [4.0, 1.0])
    frac = ndi.gaussian_filter(valid, 4.0, mode="mirror", truncate=3.0)
    expect = np.where(frac >= 0.5, 0, 1)
    assert 0 < expect.sum() < valid.size - valid.sum()  # some stripes keep frame 0, some not
    np.testing.assert_array_equal(np.asarray(r.reference), expect)
    for s in (3.5, 4.5):  # negative control: another window moves the switch
        other = ndi.gaussian_filter(valid, s, mode="mirror", truncate=3.0)
        assert (np.where(other >= 0.5, 0, 1) != expect).sum() >= 2


# ------------------------------------------------------------------ tonemap


def test_contrast_inversion_defaults_k4_strength_0_3():
    # two flat regions 64 px wide, L = 1 and 16 (log-average 4: L_w = 0.25 and 4); 48 px from
    # the border (6 sigma, past the 3-sigma kernel) the blur is L_w itself, so
    # y = L_w / (k (L_w + 1e-6 mean(L_w))^c) and L_d = y / (1 + y)
    img = np.ones((4, 128), np.float32)
    img[:, 64:] = 16.0
    got = np.asarray(tm.tonemap_contrast_inversion(img, encode="linear"))[0, [16, 112]]

    def ref(k, c):
        lw = np.array([0.25, 4.0])
        y = lw / (k * (lw + 1e-6 * lw.mean()) ** c)
        return y / (1 + y)

    np.testing.assert_allclose(got, ref(4.0, 0.3), rtol=1e-5)  # measured: 0.0865, 0.3975
    for k, c in ((4.4, 0.3), (4.0, 0.35)):  # negative controls: >= 4 % away
        assert np.max(np.abs(ref(k, c) / ref(4.0, 0.3) - 1)) > 0.04


def test_reinhard_default_white_is_the_image_maximum():
    # L_white = the largest scaled luminance: the brightest pixel maps to exactly 1, the rest
    # follow eq. 4 with that white (a fixed white of 4, what `--list` once showed, maps the
    # maximum, L_m = 1.01 here, to 0.53)
    img = np.array([[1.0, 1.0, 1.0, 10.0]], np.float32)
    got = np.asarray(tm.tonemap_Reinhard2002(img, encode="linear"))[0]
    lm = 0.18 * img[0] / 10.0**0.25  # key 0.18, log-average 10^(1/4)
    lw = lm.max()
    np.testing.assert_allclose(got, lm * (1 + lm / lw**2) / (1 + lm), rtol=1e-4)
    assert got[3] == pytest.approx(1.0, abs=1e-6)
    assert lm[3] * (1 + lm[3] / 16) / (1 + lm[3]) < 0.6


def test_reinhard_devlin_intensity_is_limited_to_plus_minus_8():
    # the range ends at +-8, where the image still spans [0, 1] with many levels; past it
    # (100: every pixel the same, then black after the min-max normalisation) it is refused
    x = np.random.default_rng(0).lognormal(0.0, 1.5, (8, 8, 3)).astype(np.float32)
    for f in (-8.0, 8.0):
        out = np.asarray(tm.tonemap_Reinhard2005(x, intensity=f, encode="linear"))
        assert out.min() == 0.0 and out.max() == pytest.approx(1.0)
        assert np.unique(np.round(out, 3)).size > 50  # measured 147 and 93
    for f in (-8.5, 8.5, 100.0):
        with pytest.raises(ValueError, match=r"^intensity: "):
            tm.tonemap_Reinhard2005(x, intensity=f)
