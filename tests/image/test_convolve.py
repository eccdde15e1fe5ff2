"""Padding and convolution against np.pad, scipy.ndimage, OpenCV and a NumPy reference."""

import importlib

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.ndimage as ndi
from jax.test_util import check_grads

from jaxgfx.image import PADDING_MODES, convolve, convolve_separable, pad_image, separable_factors

NP_MODE = {
    "zero": "constant",
    "edge": "edge",
    "reflect": "reflect",
    "symmetric": "symmetric",
    "wrap": "wrap",
}
SCIPY_MODE = {
    "zero": "constant",
    "edge": "nearest",
    "reflect": "mirror",
    "symmetric": "reflect",
    "wrap": "grid-wrap",
}


def np_convolve(x, k, mode):
    """Independent reference: np.pad, then the convolution sum written out."""
    kh, kw = k.shape
    ci, cj = kh // 2, kw // 2
    pad = [(kh - 1 - ci, ci), (kw - 1 - cj, cj)] + [(0, 0)] * (x.ndim - 2)
    xp = np.pad(x.astype(np.float64), pad, mode=NP_MODE[mode])
    H, W = x.shape[:2]
    out = np.zeros(x.shape, np.float64)
    for i in range(kh):
        for j in range(kw):
            out += k[i, j] * xp[kh - 1 - i : kh - 1 - i + H, kw - 1 - j : kw - 1 - j + W]
    return out


@pytest.mark.parametrize("mode", PADDING_MODES)
@pytest.mark.parametrize("pads", [((1, 2), (3, 0)), ((7, 5), (9, 11))])
def test_pad_image_matches_np_pad(mode, pads, rng):
    x = rng.random((4, 5, 2)).astype(np.float32)
    got = pad_image(x, pads[0], pads[1], mode=mode)
    want = np.pad(x, [pads[0], pads[1], (0, 0)], mode=NP_MODE[mode])
    np.testing.assert_array_equal(np.asarray(got), want)


def test_reflect_vs_symmetric_definition():
    row = jnp.array([[1.0, 2.0, 3.0, 4.0]])
    np.testing.assert_array_equal(pad_image(row, 0, 2, mode="reflect")[0], [3, 2, 1, 2, 3, 4, 3, 2])
    np.testing.assert_array_equal(
        pad_image(row, 0, 2, mode="symmetric")[0], [2, 1, 1, 2, 3, 4, 4, 3]
    )


@pytest.mark.parametrize("mode", PADDING_MODES)
@pytest.mark.parametrize("method", ["direct", "fft"])
def test_convolve_matches_scipy(mode, method, rng):
    x = rng.random((24, 19, 2)).astype(np.float32)
    k = rng.standard_normal((5, 3)).astype(np.float32)
    want = np.stack([ndi.convolve(x[..., c], k, mode=SCIPY_MODE[mode]) for c in range(2)], -1)
    got = convolve(x, k, padding=mode, method=method)
    np.testing.assert_allclose(np.asarray(got), want, atol=1e-5)


def test_convolve_is_flipped_correlation_cv2(rng):
    x = rng.random((20, 21)).astype(np.float32)
    k = rng.standard_normal((3, 5)).astype(np.float32)
    want = cv2.filter2D(x, -1, k[::-1, ::-1].copy(), borderType=cv2.BORDER_REFLECT_101)
    np.testing.assert_allclose(np.asarray(convolve(x, k)), want, atol=1e-5)


@pytest.mark.parametrize("mode", PADDING_MODES)
def test_kernel_bigger_than_image(mode, rng):
    x = rng.random((3, 4)).astype(np.float32)
    k = rng.random((9, 7)).astype(np.float32)
    want = np_convolve(x, k, mode)
    for method in ("direct", "fft"):
        got = convolve(x, k, padding=mode, method=method)
        np.testing.assert_allclose(np.asarray(got), want, atol=1e-5, err_msg=method)


# issue 9: ~3 s of a loaded 2-core default run; each method against SciPy stays in the default run
@pytest.mark.slow
def test_methods_agree_to_1e5(rng):
    x = rng.random((32, 32, 3)).astype(np.float32)
    kv = rng.random(9).astype(np.float32)
    kh = rng.random(9).astype(np.float32)
    k = np.outer(kv, kh) / np.outer(kv, kh).sum()
    ref = convolve(x, k, method="direct")
    for method in ("separable", "fft", "auto"):
        np.testing.assert_allclose(np.asarray(convolve(x, k, method=method)), ref, atol=1e-5)
    got = convolve_separable(x, kv / kv.sum(), kh / kh.sum(), method="fft")
    np.testing.assert_allclose(np.asarray(got), ref, atol=1e-5)


def test_separable_factors():
    sob = np.outer([1.0, 2.0, 1.0], [-1.0, 0.0, 1.0])
    kv, kh = separable_factors(sob)
    np.testing.assert_allclose(np.outer(kv, kh), sob, atol=1e-12)
    assert separable_factors(np.array([[1.0, 0.0], [0.0, 1.0]])) is None


def test_long_kernel_fori_path(rng):
    # 1x81 and 9x9 kernels exceed the unrolling limit: fori_loop path must stay exact.
    x = rng.random((12, 30)).astype(np.float32)
    k = rng.random((9, 9)).astype(np.float32)
    np.testing.assert_allclose(
        np.asarray(convolve(x, k, method="direct")), np_convolve(x, k, "reflect"), atol=1e-4
    )
    k1 = rng.random(81).astype(np.float32)
    got = convolve_separable(x, np.ones(1, np.float32), k1, method="direct", padding="wrap")
    np.testing.assert_allclose(
        np.asarray(got), np_convolve(x, k1[None], "wrap"), rtol=1e-5, atol=1e-4
    )


def test_jit_vmap_and_batch(rng):
    x = rng.random((3, 16, 16, 2)).astype(np.float32)
    k = rng.random((3, 3)).astype(np.float32)
    f = jax.jit(lambda im, ker: convolve(im, ker, padding="wrap"))
    batched = f(x, k)
    mapped = jax.vmap(f, in_axes=(0, None))(x, k)
    np.testing.assert_allclose(np.asarray(batched), np.asarray(mapped), atol=1e-6)
    want = np.stack([np_convolve(x[0][..., c], k, "wrap") for c in range(2)], -1)
    np.testing.assert_allclose(np.asarray(batched[0]), want, atol=1e-5)


def test_constant_and_tiny_images():
    k = np.full((5, 5), 1 / 25, np.float32)
    for mode in ("edge", "reflect", "symmetric", "wrap"):
        np.testing.assert_allclose(
            np.asarray(convolve(jnp.full((6, 7, 3), 0.3), k, padding=mode)), 0.3, rtol=1e-6
        )
        np.testing.assert_allclose(
            np.asarray(convolve(jnp.full((1, 1), 2.0), k, padding=mode)), 2.0
        )
    assert float(convolve(jnp.full((1, 1), 2.0), k, padding="zero")[0, 0]) == pytest.approx(0.08)


def test_dtype_follows_input(x64, rng):
    x = rng.random((8, 8))
    out = convolve(x, np.ones((3, 3)) / 9)
    assert out.dtype == jnp.float64
    np.testing.assert_allclose(
        np.asarray(out), np_convolve(x, np.ones((3, 3)) / 9, "reflect"), atol=1e-13
    )


@pytest.mark.parametrize("method", ["direct", "fft"])
def test_grads_image_and_kernel(x64, rng, method):
    x = jnp.asarray(rng.random((6, 5)))
    k = jnp.asarray(rng.random((3, 3)))
    f = jax.jit(lambda a, b: convolve(a, b, method=method))
    check_grads(f, (x, k), order=1, modes=["rev"])


def test_bad_inputs():
    k = np.ones((3, 3))
    with pytest.raises(ValueError, match="image"):
        convolve(np.ones(5), k)
    with pytest.raises(ValueError, match="padding"):
        convolve(np.ones((4, 4)), k, padding="mirror")
    with pytest.raises(ValueError, match="method"):
        convolve(np.ones((4, 4)), k, method="winograd")
    with pytest.raises(ValueError, match="kernel"):
        convolve(np.ones((4, 4)), np.ones((3, 3, 3)))
    with pytest.raises(ValueError, match="image"):
        convolve(np.array([[1.0, np.nan]]), k)
    with pytest.raises(ValueError, match="kernel"):
        convolve(np.ones((4, 4)), np.array([[1.0, np.inf]]))
    with pytest.raises(ValueError, match="separable"):
        convolve(np.ones((4, 4)), np.eye(3), method="separable")
    with pytest.raises(ValueError, match="pad_h"):
        pad_image(np.ones((4, 4)), -1, 0)
    with pytest.raises(TypeError, match="image"):
        convolve("abc", k)


def test_jit_pad_and_separable(rng):
    x = rng.random((7, 6, 2)).astype(np.float32)
    f = jax.jit(lambda a: pad_image(a, (2, 9), (0, 3), mode="symmetric"))
    want = np.pad(x, [(2, 9), (0, 3), (0, 0)], mode="symmetric")
    np.testing.assert_array_equal(np.asarray(f(x)), want)
    kv, kh = rng.random(3).astype(np.float32), rng.random(5).astype(np.float32)
    g = jax.jit(lambda a, v, h: convolve_separable(a, v, h, padding="edge"))
    want = np.stack([np_convolve(x[..., c], np.outer(kv, kh), "edge") for c in range(2)], -1)
    np.testing.assert_allclose(np.asarray(g(x, kv, kh)), want, atol=1e-5)


def test_eager_convolve_compiles_once_for_new_kernel_values(rng):
    """Eager convolve runs one jitted core per shape / padding / method: new kernel values
    of the same shape reuse the compiled program. Values: scipy.ndimage.convolve."""
    conv_mod = importlib.import_module("jaxgfx.image.convolve")  # the module, not the function

    x = rng.random((13, 22, 2)).astype(np.float32)  # a shape no other test uses
    n0 = conv_mod._convolve_core._cache_size()
    for _ in range(2):
        k = rng.standard_normal((3, 4)).astype(np.float32)  # rank 2: not separable
        want = np.stack([ndi.convolve(x[..., c], k, mode="mirror") for c in range(2)], -1)
        np.testing.assert_allclose(np.asarray(convolve(x, k)), want, atol=1e-5)
    assert conv_mod._convolve_core._cache_size() - n0 == 1
