"""White balance vs NumPy closed forms of the lecture's formulas and colour-science CATs."""

import re

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
    white_balance_brightest_pixel,
    white_balance_brightest_pixel_gains,
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
    qs = (1.0, 0.9, 0.5, 0.0)
    gains = jax.jit(lambda x: [white_balance_white_patch_gains(x, quantile=q) for q in qs])(img)
    for q, g in zip(qs, gains, strict=True):
        e = np.quantile(flat, q, axis=0)
        np.testing.assert_allclose(np.asarray(g), e.mean() / e, rtol=1e-5)
    mask = np.all(img < 0.99, axis=-1)
    e = np.quantile(img[mask].astype(np.float64), 0.95, axis=0)
    f = jax.jit(
        lambda x: (
            white_balance_white_patch_gains(x, quantile=0.95, saturation=0.99),
            white_balance_white_patch(x, quantile=1.0, saturation=0.99),
        )
    )
    g, out = f(img)
    np.testing.assert_allclose(np.asarray(g), e.mean() / e, rtol=1e-5)
    # a grey highlight becomes neutral: quantile=1 maps each channel max to the mean max
    out = np.asarray(out)
    top = out[mask].max(0)
    np.testing.assert_allclose(top, top.mean(), rtol=1e-5)


def _np_brightest(img, q, mask=None):
    px = img.reshape(-1, 3) if mask is None else img[mask]
    lum = px @ np.array([0.2126, 0.7152, 0.0722])
    e = px[lum >= np.quantile(lum, q)].mean(0)
    return e.mean() / e


def test_brightest_pixel(rng):
    img = _cast_image(rng)
    f = jax.jit(
        lambda x: (
            white_balance_brightest_pixel_gains(x, quantile=1.0),
            white_balance_brightest_pixel_gains(x, quantile=0.9),
            white_balance_brightest_pixel_gains(x, quantile=0.95, saturation=0.99),
            white_balance_brightest_pixel(x, quantile=0.95, saturation=0.99),
        )
    )
    g1, g9, gm, out = f(img)
    img64 = img.astype(np.float64)
    mask = np.all(img < 0.99, axis=-1)
    # quantile=1: the clipped white block is the brightest -> gains 1 (it is already neutral)
    np.testing.assert_allclose(np.asarray(g1), 1.0, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(g9), _np_brightest(img64, 0.9), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(gm), _np_brightest(img64, 0.95, mask), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(out), img * np.asarray(gm), rtol=1e-6)
    if jax.default_backend() == "cpu":
        # the quantile's top_k stays a top_k under jit: reading one rank of its values made
        # XLA CPU sort all H * W pixels instead (15x slower at 512 x 512; structure, not timing)
        hlo = f.lower(img).compile().as_text()
        assert not re.search(rf"\[\d+,{img.shape[0] * img.shape[1]}\]\S* sort\(", hlo)


@jax.jit
def _stretch_all(x):
    kw = dict(low=0.02, high=0.97)
    return (
        white_balance_stretch(x, **kw),
        white_balance_stretch(x, clip=False, **kw),
        white_balance_stretch_limits(x, **kw),
    )


def test_stretch(rng):
    img = _cast_image(rng)
    flat = img.reshape(-1, 3).astype(np.float64)
    lo, hi = np.quantile(flat, 0.02, axis=0), np.quantile(flat, 0.97, axis=0)
    out, raw, (L, H) = _stretch_all(img)
    np.testing.assert_allclose(np.asarray(out), np.clip((img - lo) / (hi - lo), 0, 1), atol=2e-6)
    np.testing.assert_allclose(np.asarray(L), lo, rtol=1e-6)
    np.testing.assert_allclose(np.asarray(H), hi, rtol=1e-6)
    raw = np.asarray(raw)
    assert raw.min() < 0 and raw.max() > 1
    np.testing.assert_allclose(raw, (img - lo) / (hi - lo), atol=2e-6)
    # a constant channel is left unchanged
    img2 = img.copy()
    img2[..., 1] = 0.3
    out2 = np.asarray(_stretch_all(img2)[0])
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
    gv = np.asarray(jax.jit(jax.vmap(white_balance_grey_world_gains))(imgs))
    np.testing.assert_allclose(gv, g, rtol=1e-6)
    wp = np.asarray(_wp(imgs, quantile=0.9))
    e = np.quantile(imgs[1].reshape(-1, 3).astype(np.float64), 0.9, axis=0)
    np.testing.assert_allclose(wp[1], e.mean() / e, rtol=1e-5)
    out = np.asarray(jax.jit(apply_white_balance)(imgs, g))
    np.testing.assert_allclose(out, imgs * g[:, None, None, :], rtol=1e-6)
    # batched von Kries whites, one per image
    src = np.array([[1.2, 1.0, 0.7], [0.7, 1.0, 1.2]], np.float32)
    vk = jax.jit(white_balance_von_kries)(imgs, src)
    vk_single = jax.jit(jax.vmap(white_balance_von_kries))(imgs, src)  # vmap == batch
    np.testing.assert_allclose(np.asarray(vk), np.asarray(vk_single), rtol=1e-5)
    wb = jax.jit(lambda x: white_balance(x, method="white_patch", quantile=0.9))(imgs)
    np.testing.assert_allclose(np.asarray(wb), imgs * wp[:, None, None, :], rtol=1e-6)


def test_gradients(rng, x64):
    img = jnp.asarray(rng.uniform(0.1, 0.9, (4, 4, 3)))

    # all estimators in one program (one compile); the random cotangent probes every output
    @jax.jit
    def f(x, gains):
        return jnp.concatenate(
            [
                white_balance_grey_world(x).ravel(),
                white_balance_white_patch(x, quantile=0.8).ravel(),
                white_balance_brightest_pixel(x, quantile=0.7).ravel(),
                white_balance_stretch(x, low=0.1, high=0.9, clip=False).ravel(),
                apply_white_balance(x, gains).ravel(),
            ]
        )

    check_grads(f, (img, jnp.array([1.1, 1.0, 0.9])), order=1, modes=["rev"])


@jax.jit
def _all_gains(x):
    return jnp.stack(
        [
            white_balance_grey_world_gains(x),
            white_balance_white_patch_gains(x, quantile=1.0),
            white_balance_grey_world_gains(x, saturation=0.99),
            white_balance_white_patch_gains(x, quantile=0.5, saturation=0.99),
            white_balance_brightest_pixel_gains(x, quantile=1.0, saturation=0.99),
        ]
    )


def test_degenerate_images():
    black = jnp.zeros((4, 4, 3))
    np.testing.assert_array_equal(np.asarray(_all_gains(black)), 1.0)
    sat = jnp.ones((4, 4, 3))
    np.testing.assert_array_equal(np.asarray(_all_gains(sat))[2:], 1.0)  # all pixels masked
    g = jax.jit(jax.grad(lambda x: jnp.sum(white_balance_grey_world(x))))(black)
    assert np.all(np.isfinite(np.asarray(g)))
    one_zero = jnp.full((4, 4, 3), 0.5).at[..., 2].set(0.0)  # empty channel: gains fall back to 1
    np.testing.assert_array_equal(np.asarray(_all_gains(one_zero)), 1.0)


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
