"""White balance vs NumPy closed forms of the lecture's formulas and colour-science CATs."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from colour.adaptation import matrix_chromatic_adaptation_VonKries
from jax.test_util import check_grads

from jaxgfx.color import (
    apply_white_balance,
    rgb_to_xyz_matrix,
    white_balance,
    white_balance_grey_world,
    white_balance_grey_world_gains,
    white_balance_stretch,
    white_balance_stretch_limits,
    white_balance_von_kries,
    white_balance_von_kries_matrix,
    white_balance_white_patch,
    white_balance_white_patch_gains,
)

_gw = jax.jit(white_balance_grey_world_gains, static_argnames=("saturation",))
_wp = jax.jit(white_balance_white_patch_gains, static_argnames=("quantile", "saturation"))


def _cast_image(rng, shape=(24, 32)):
    """A random scene under a warm cast, with a few clipped highlights."""
    img = rng.uniform(0.05, 0.8, (*shape, 3)) * np.array([1.3, 1.0, 0.6])
    img[:3, :5] = 1.0  # clipped
    return img.astype(np.float32)


def _np_grey_world(img, mask=None):
    px = img.reshape(-1, 3) if mask is None else img[mask]
    m = px.mean(0)
    return m.mean() / m


def test_grey_world_formula(rng):
    img = _cast_image(rng)
    g = np.asarray(_gw(img))
    np.testing.assert_allclose(g, _np_grey_world(img.astype(np.float64)), rtol=1e-5)
    out = np.asarray(jax.jit(white_balance_grey_world)(img))
    means = out.reshape(-1, 3).mean(0)
    np.testing.assert_allclose(means, img.reshape(-1, 3).mean(), rtol=1e-5)  # all equal Avg
    # saturation mask: statistics over pixels with every channel < 0.99
    g = np.asarray(_gw(img, saturation=0.99))
    mask = np.all(img < 0.99, axis=-1)
    assert mask.sum() < img.shape[0] * img.shape[1]
    np.testing.assert_allclose(g, _np_grey_world(img.astype(np.float64), mask), rtol=1e-5)


def test_white_patch_quantiles(rng):
    img = _cast_image(rng)
    flat = img.reshape(-1, 3).astype(np.float64)
    for q in (1.0, 0.9, 0.5, 0.0):
        e = np.quantile(flat, q, axis=0)
        np.testing.assert_allclose(np.asarray(_wp(img, quantile=q)), e.mean() / e, rtol=1e-5)
    mask = np.all(img < 0.99, axis=-1)
    e = np.quantile(img[mask].astype(np.float64), 0.95, axis=0)
    g = _wp(img, quantile=0.95, saturation=0.99)
    np.testing.assert_allclose(np.asarray(g), e.mean() / e, rtol=1e-5)
    # a grey highlight becomes neutral: quantile=1 maps each channel max to the mean max
    out = np.asarray(white_balance_white_patch(img, quantile=1.0, saturation=0.99))
    top = out[mask].max(0)
    np.testing.assert_allclose(top, top.mean(), rtol=1e-5)


def test_stretch(rng):
    img = _cast_image(rng)
    flat = img.reshape(-1, 3).astype(np.float64)
    lo, hi = np.quantile(flat, 0.02, axis=0), np.quantile(flat, 0.97, axis=0)
    f = jax.jit(white_balance_stretch, static_argnames=("low", "high", "saturation", "clip"))
    out = np.asarray(f(img, low=0.02, high=0.97))
    np.testing.assert_allclose(out, np.clip((img - lo) / (hi - lo), 0, 1), atol=2e-6)
    L, H = white_balance_stretch_limits(img, low=0.02, high=0.97)
    np.testing.assert_allclose(np.asarray(L), lo, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(H), hi, rtol=1e-6)
    raw = np.asarray(f(img, low=0.02, high=0.97, clip=False))
    assert raw.min() < 0 and raw.max() > 1
    # a constant channel is left unchanged
    img2 = img.copy()
    img2[..., 1] = 0.3
    out2 = np.asarray(f(img2, low=0.02, high=0.97))
    np.testing.assert_allclose(out2[..., 1], 0.3, rtol=1e-6)


def test_von_kries_vs_colour(rng, x64):
    img = rng.uniform(0, 1, (8, 8, 3))
    src = np.array([1.2, 1.0, 0.7])
    dst = np.array([0.9, 1.0, 1.1])
    M = rgb_to_xyz_matrix("srgb")
    cat = matrix_chromatic_adaptation_VonKries(M @ src, M @ dst, "Bradford")
    ref_m = np.linalg.inv(M) @ cat @ M
    ours_m = np.asarray(white_balance_von_kries_matrix(src, dst))
    np.testing.assert_allclose(ours_m, ref_m, atol=1e-13)
    out = np.asarray(white_balance_von_kries(img, src, dst))
    np.testing.assert_allclose(out, img @ ref_m.T, atol=1e-13)
    # the illuminant colour becomes the target; default target is neutral with src luminance
    np.testing.assert_allclose(ours_m @ src, dst, atol=1e-13)
    neutral = np.asarray(white_balance_von_kries_matrix(src)) @ src
    y_src = M[1] @ src
    np.testing.assert_allclose(neutral, np.full(3, y_src), atol=1e-13)
    check_grads(
        jax.jit(lambda s: white_balance_von_kries(jnp.asarray(img[:2, :2]), s)),
        (jnp.asarray(src),),
        order=1,
        modes=["rev"],
    )


def test_batch_and_vmap(rng):
    imgs = np.stack([_cast_image(rng, (8, 8)), _cast_image(rng, (8, 8))[..., ::-1]])
    g = np.asarray(_gw(imgs))
    assert g.shape == (2, 3)
    for i in range(2):
        np.testing.assert_allclose(g[i], _np_grey_world(imgs[i].astype(np.float64)), rtol=1e-5)
    gv = np.asarray(jax.vmap(white_balance_grey_world_gains)(imgs))
    np.testing.assert_allclose(gv, g, rtol=1e-6)
    wp = np.asarray(_wp(imgs, quantile=0.9))
    np.testing.assert_allclose(wp[1], np.asarray(_wp(imgs[1], quantile=0.9)), rtol=1e-6)
    out = np.asarray(apply_white_balance(imgs, g))
    np.testing.assert_allclose(out, imgs * g[:, None, None, :], rtol=1e-6)
    # batched von Kries whites, one per image
    src = np.array([[1.2, 1.0, 0.7], [0.7, 1.0, 1.2]], np.float32)
    vk = np.asarray(white_balance_von_kries(imgs, src))
    np.testing.assert_allclose(vk[1], np.asarray(white_balance_von_kries(imgs[1], src[1])), 1e-5)
    np.testing.assert_allclose(
        np.asarray(white_balance(imgs, method="white_patch", quantile=0.9)),
        imgs * wp[:, None, None, :],
        rtol=1e-6,
    )


def test_gradients(rng, x64):
    img = jnp.asarray(rng.uniform(0.1, 0.9, (4, 4, 3)))
    check_grads(jax.jit(white_balance_grey_world), (img,), order=1, modes=["rev"])
    f = jax.jit(lambda x: white_balance_white_patch(x, quantile=0.8))
    check_grads(f, (img,), order=1, modes=["rev"])
    f = jax.jit(lambda x: white_balance_stretch(x, low=0.1, high=0.9, clip=False))
    check_grads(f, (img,), order=1, modes=["rev"])
    check_grads(jax.jit(apply_white_balance), (img, jnp.array([1.1, 1.0, 0.9])), 1, modes=["rev"])


def test_degenerate_images():
    black = jnp.zeros((4, 4, 3))
    np.testing.assert_array_equal(np.asarray(_gw(black)), 1.0)
    np.testing.assert_array_equal(np.asarray(_wp(black, quantile=1.0)), 1.0)
    sat = jnp.ones((4, 4, 3))
    np.testing.assert_array_equal(np.asarray(_gw(sat, saturation=0.99)), 1.0)  # all masked
    np.testing.assert_array_equal(np.asarray(_wp(sat, quantile=0.5, saturation=0.99)), 1.0)
    g = jax.jit(jax.grad(lambda x: jnp.sum(white_balance_grey_world(x))))(black)
    assert np.all(np.isfinite(np.asarray(g)))
    one_zero = jnp.ones((4, 4, 3)).at[..., 2].set(0.0)  # empty channel: gains fall back to 1
    np.testing.assert_array_equal(np.asarray(_gw(one_zero)), 1.0)


def test_bad_arguments():
    img = np.full((4, 4, 3), 0.5, np.float32)
    with pytest.raises(ValueError, match="image"):
        white_balance_grey_world(np.ones((4, 4)))
    with pytest.raises(ValueError, match="image: .*NaN"):
        white_balance_grey_world(np.where(img > 0, np.nan, img))
    with pytest.raises(ValueError, match="quantile"):
        white_balance_white_patch(img, quantile=1.5)
    with pytest.raises(ValueError, match="low, high"):
        white_balance_stretch(img, low=0.9, high=0.1)
    with pytest.raises(ValueError, match="saturation"):
        white_balance_grey_world(img, saturation=-1.0)
    with pytest.raises(ValueError, match="method"):
        white_balance(img, method="gray_world")
    with pytest.raises(ValueError, match="method"):
        white_balance_von_kries(img, np.ones(3), method="sharp")
    with pytest.raises(ValueError, match="space"):
        white_balance_von_kries(img, np.ones(3), space="p3")
    with pytest.raises(ValueError, match="src_white_rgb"):
        white_balance_von_kries(img, np.ones(4))
    with pytest.raises(ValueError, match="gains"):
        apply_white_balance(img, np.ones(2))
