"""Defects found by issue 12's probe, in image operators (jaxgfx.image):
one test each (every one failed before its fix), grouped by the code they exercise (the
D-numbers are the probe's).

References: scikit-image (``canny``, ``equalize_hist``), SciPy (``gaussian_laplace``), the
closed-form derivative of the LoG kernel at a vanishing sigma, the project's own readers for
files written by the CLI (format by content, not by name).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx import image, io

from ._util import read_only_sys, run_cli

READ_ONLY = "/sys/jaxgfx-reliability"  # sysfs: not writable, even by root


def _read_only_available() -> bool:
    return read_only_sys()


# --------------------------------------------------------------- D2 canny on a flat image


@functools.cache
def _canny_quantiles():
    return jax.jit(lambda x, lo, hi: image.canny(x, 1.0, lo, hi, use_quantiles=True))


def test_d02_canny_flat_image_has_no_edges():
    from skimage.feature import canny as sk_canny

    flat = np.full((32, 32), 0.5, np.float32)
    ours = np.asarray(_canny_quantiles()(flat, 0.1, 0.2))
    # float64 for scikit-image: its float32 blur leaves rounding noise that it marks as edges
    ref = sk_canny(flat.astype(np.float64), 1.0, 0.1, 0.2, use_quantiles=True)
    assert ours.sum() == ref.sum() == 0
    # thresholds 0 (the quantile-0 of a flat magnitude is 0: the same comparisons as the
    # CLI's --low 0 --high 0): still no edges
    assert int(np.asarray(_canny_quantiles()(flat, 0.0, 0.0)).sum()) == 0


@pytest.mark.slow  # ~13 s: canny runs op by op in the CLI
def test_d02_cli_canny_flat_image(files, tmp_path):
    out = tmp_path / "edges.png"
    code, _, err = run_cli(
        ["filter", files["const_png"], out, "--op", "canny", "--low", "0", "--high", "0"]
    )
    assert code == 0, err
    assert int(io.read_image(str(out)).sum()) == 0


# --------------------------------------------------------------- D3 equalize a flat image


@pytest.mark.parametrize("value", [0.5, 0.0, -1.0])
def test_d03_equalize_flat_image_like_skimage(value):
    from skimage.exposure import equalize_hist

    flat = np.full((8, 8), value, np.float32)
    ours = np.asarray(image.equalize_histogram(flat))
    np.testing.assert_array_equal(ours, equalize_hist(flat).astype(np.float32))
    assert np.all(ours == 0.5)


# --------------------------------------------------------------- D6 LoG at a tiny sigma


def test_d06_log_sigma_gradient_at_1e_8_is_finite_and_exact():
    # at sigma << 1 the kernel is -2/sigma^2 at the centre, 0 elsewhere: d/dsigma = 4/sigma^3
    x = jnp.ones((5, 5))
    s = 1e-8
    g = jax.jit(jax.grad(lambda s: image.laplacian_of_gaussian(x, s, radius=1).sum()))(
        jnp.float32(s)
    )
    assert np.isfinite(float(g))
    np.testing.assert_allclose(float(g), 25 * 4 / s**3, rtol=1e-5)


def test_d06_log_unchanged_at_ordinary_sigma():
    from scipy.ndimage import gaussian_laplace

    x = np.random.default_rng(1).random((12, 13)).astype(np.float32)
    ours = np.asarray(image.laplacian_of_gaussian(x, 0.3))  # the log-space tail matters here
    np.testing.assert_allclose(ours, gaussian_laplace(x, 0.3, mode="mirror"), atol=2e-5)


def test_d06_log_tiny_sigma_error_names_sigma():
    with pytest.raises(ValueError, match=r"^sigma: expected >= "):
        image.laplacian_of_gaussian(jnp.ones((5, 5)), 1e-20)
