"""Defects found by issue 12's probe, in HDR response recovery and merging (jaxgfx.hdr):
one test each (every one failed before its fix), grouped by the code they exercise (the
D-numbers are the probe's).

References: scikit-image (``canny``, ``equalize_hist``), SciPy (``gaussian_laplace``), the
closed-form derivative of the LoG kernel at a vanishing sigma, the project's own readers for
files written by the CLI (format by content, not by name).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx import hdr

from ._util import assert_one_line_error, no_partial_files, read_only_sys, run_cli

READ_ONLY = "/sys/jaxgfx-reliability"  # sysfs: not writable, even by root


def _read_only_available() -> bool:
    return read_only_sys()


# --------------------------------------------------------------- D1 all-clipped bracket


@pytest.mark.parametrize("level", [255, 0], ids=["saturated", "black"])
@pytest.mark.parametrize("method", sorted(hdr.RESPONSE_METHODS))
def test_d01_clipped_bracket_is_an_error(method, level):
    stack = np.full((3, 16, 16, 3), level, np.uint8)
    with pytest.raises(ValueError, match=r"too few usable pixels.*at least 16"):
        hdr.recover_response(stack, [1.0, 2.0, 4.0], method=method)


def test_d01_cli_clipped_bracket_fails_and_writes_nothing(files, tmp_path):
    out = tmp_path / "out"
    code, _, err = run_cli(["calibrate", files["saturated"], "--out", out, "--quiet"])
    assert_one_line_error(code, err, "too few usable pixels")
    assert not out.exists() and no_partial_files(tmp_path)


def test_d01_threshold_is_the_stated_one():
    # 16 usable pixels pass the check, 15 do not (the rest of the frame clipped)
    stack = np.full((3, 16, 16, 1), 255, np.uint8)
    stack[:, 0, :16, 0] = np.array([[40], [80], [160]], np.uint8)
    hdr.response._check_usable(stack, 255.0)
    stack[:, 0, 15, 0] = 255
    with pytest.raises(ValueError, match="15 per channel"):
        hdr.response._check_usable(stack, 255.0)
    assert hdr.MIN_USABLE_PIXELS == 16


# --------------------------------------------------------------- D5 checks under tracing


def _merge_inputs():
    imgs = (np.random.default_rng(0).random((3, 8, 8, 3)) * 255).astype(np.uint8)
    return imgs, hdr.CameraResponse.gamma(1.0, anchor="unit")


@pytest.mark.parametrize("transform", ["jit", "grad"])
def test_d05_merge_zero_time_under_tracing_raises(transform):
    imgs, resp = _merge_inputs()
    f = lambda t: hdr.merge_radiance(imgs, t, resp).sum()  # noqa: E731
    f = jax.jit(f) if transform == "jit" else jax.grad(f)
    with pytest.raises(RuntimeError, match="exposure_times: expected finite values > 0"):
        jax.block_until_ready(f(jnp.array([0.0, 1.0, 2.0])))
    # valid times still work under the same transformation and agree with eager
    good = jnp.array([0.5, 1.0, 2.0])
    eager = hdr.merge_radiance(imgs, good, resp).sum()
    if transform == "jit":
        np.testing.assert_allclose(float(f(good)), float(eager), rtol=1e-6)
    else:
        assert np.all(np.isfinite(np.asarray(f(good))))


def test_d05_gamma_fit_zero_time_under_jit_raises():
    imgs, _ = _merge_inputs()
    f = jax.jit(lambda t: hdr.recover_response(imgs, t, method="gamma").params)
    with pytest.raises(RuntimeError, match="exposure_times: expected finite values > 0"):
        jax.block_until_ready(f(jnp.array([0.0, 1.0, 2.0])))
