"""Defaults that earlier fixes set on purpose, pinned through their effect (issue 28).

Each test calls a function *without* the option and compares with an independent reference
computed for the documented default (a closed form, or scikit-image), plus a negative control
showing that the next plausible value would give a different answer, so changing the default
fails here. ``tools/mutants.py`` holds one mutant per default (``defaults.*``).

* ``hdr.merge_radiance``: ``weighting="hat"``, ``time_power=2`` (commit 2b64734: hat x t^2,
  the inverse variance of ``x / t`` for exposure-independent noise; ``time_power=0`` let a
  short frame's near-black levels pull dark pixels too bright).
* ``image.canny``: ``sigma=1.0`` (and ``truncate=4``), scikit-image's defaults.
* ``optim.fit``: ``optimizer="adam"``, ``learning_rate=1e-2``, ``patience=10``.
"""

import jax.numpy as jnp
import numpy as np
import pytest
import skimage.draw as draw
from skimage.feature import canny as sk_canny

from jaxgfx import hdr
from jaxgfx.hdr import CameraResponse
from jaxgfx.image import canny
from jaxgfx.optim import fit

# ------------------------------------------------------------------ hdr.merge_radiance


def _hat(z):  # Debevec & Malik (1997): 2 min(z, 1 - z) on normalised levels
    return 2.0 * np.minimum(z, 1.0 - z)


def _merge_reference(z, t, time_power):
    """Closed form of the weighted merge with a linear response: sum w E / sum w,
    ``E_j = z_j / t_j``, ``w_j = hat(z_j) (t_j / t_max)^time_power``."""
    w = _hat(z) * (t / t.max())[:, None] ** time_power
    return np.sum(w * z / t[:, None], axis=0) / np.sum(w, axis=0)


def test_merge_default_is_hat_times_t_squared():
    # two frames per pixel that disagree (E = 0.25 vs 0.30, 0.10 vs 0.14): the weights decide
    z = np.array([[0.25, 0.10, 0.45], [0.60, 0.28, 0.70]], np.float32)  # (N=2, pixels)
    t = np.array([1.0, 2.0], np.float32)
    resp = CameraResponse.gamma(1.0, anchor="unit")
    got = np.asarray(hdr.merge_radiance(z[:, None, :], t, resp))[0]
    ref = _merge_reference(z.astype(np.float64), t.astype(np.float64), 2.0)
    np.testing.assert_allclose(got, ref, rtol=1e-6)
    # pixel 0 by hand: (0.5/4 * 0.25 + 0.8 * 0.30) / (0.5/4 + 0.8)
    assert got[0] == pytest.approx((0.125 * 0.25 + 0.8 * 0.3) / 0.925, rel=1e-6)
    # negative controls: time_power 1 or 0, or the Gaussian weight, are each >= 1 % away
    for other in (
        _merge_reference(z, t, 1.0),
        _merge_reference(z, t, 0.0),
        np.asarray(hdr.merge_radiance(z[:, None, :], t, resp, weighting="gaussian"))[0],
    ):
        assert np.max(np.abs(other / ref - 1)) > 0.01


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
