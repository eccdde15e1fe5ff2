"""Colour spaces vs colour-science / scikit-image, closed forms, round trips, gradients."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads
from skimage.color import rgb2hsv, rgb2yiq

from jaxgfx.color import (
    RGB_SPACES,
    WHITEPOINTS,
    YIQ_MATRIX,
    cmyk_to_rgb,
    hsv_to_rgb,
    lab_to_xyz,
    luminance,
    normalised_primary_matrix,
    rgb_to_cmyk,
    rgb_to_hsv,
    rgb_to_rgb,
    rgb_to_xyz,
    rgb_to_xyz_matrix,
    rgb_to_yiq,
    xyY_to_xyz,
    xyz_to_lab,
    xyz_to_rgb,
    xyz_to_xyY,
    yiq_to_rgb,
)

COLOUR_NAMES = {
    "srgb": "sRGB",
    "rec709": "ITU-R BT.709",
    "rec2020": "ITU-R BT.2020",
    "adobe_rgb": "Adobe RGB (1998)",
    "prophoto": "ProPhoto RGB",
    "aces2065-1": "ACES2065-1",
    "acescg": "ACEScg",
}


@pytest.mark.parametrize("space", list(RGB_SPACES))
def test_matrices_vs_colour(space):
    cs = colour.RGB_COLOURSPACES[COLOUR_NAMES[space]]
    ours = rgb_to_xyz_matrix(space)
    # exact derivation from the same primaries/white
    ref = colour.normalised_primary_matrix(cs.primaries, cs.whitepoint)
    np.testing.assert_allclose(ours, ref, rtol=0, atol=1e-14)
    # published matrices (sRGB, Adobe, ProPhoto are printed to 4-5 decimals in their standards;
    # ROMM's uses the ICC D50 XYZ (0.9642, 1, 0.8249) instead of xy (0.3457, 0.3585))
    atol = 3e-4 if space == "prophoto" else 1e-4
    np.testing.assert_allclose(ours, cs.matrix_RGB_to_XYZ, rtol=0, atol=atol)
    np.testing.assert_allclose(ours @ np.ones(3), colour.xy_to_XYZ(cs.whitepoint), atol=1e-14)


def test_npm_differentiable_and_known(x64):
    prim = jnp.array([[0.64, 0.33], [0.30, 0.60], [0.15, 0.06]])
    w = jnp.array([0.3127, 0.3290])
    M = normalised_primary_matrix(prim, w)
    np.testing.assert_allclose(np.asarray(M), rgb_to_xyz_matrix("srgb"), atol=1e-15)
    check_grads(jax.jit(normalised_primary_matrix), (prim, w), order=1, modes=["rev"])
    with pytest.raises(ValueError, match="primaries"):
        normalised_primary_matrix(jnp.ones((2, 2)), w)


@pytest.mark.parametrize("space", ["srgb", "adobe_rgb", "prophoto"])
def test_rgb_xyz_random_round_trip(space, rng, x64):
    rgb = rng.uniform(-0.1, 1.5, (64, 3))
    xyz = rgb_to_xyz(rgb, space=space)
    ref = colour.RGB_to_XYZ(rgb, COLOUR_NAMES[space], illuminant=None)
    np.testing.assert_allclose(np.asarray(xyz), ref, atol=5e-4)  # colour uses rounded matrices
    np.testing.assert_allclose(np.asarray(xyz_to_rgb(xyz, space=space)), rgb, atol=1e-13)


def test_rgb_to_rgb_vs_colour(rng, x64):
    rgb = rng.uniform(0, 1, (32, 3))
    ours = rgb_to_rgb(rgb, src="srgb", dst="prophoto", adaptation="bradford")
    ref = colour.RGB_to_RGB(rgb, "sRGB", "ProPhoto RGB", chromatic_adaptation_transform="Bradford")
    np.testing.assert_allclose(np.asarray(ours), ref, atol=3e-4)
    back = rgb_to_rgb(ours, src="prophoto", dst="srgb", adaptation="bradford")
    np.testing.assert_allclose(np.asarray(back), rgb, atol=1e-12)
    # same white: no adaptation, exact matrix product
    ours = rgb_to_rgb(rgb, src="srgb", dst="adobe_rgb")
    ref = rgb @ (np.linalg.inv(rgb_to_xyz_matrix("adobe_rgb")) @ rgb_to_xyz_matrix("srgb")).T
    np.testing.assert_allclose(np.asarray(ours), ref, atol=1e-14)


@pytest.mark.parametrize("white", ["D65", "D50", "A", "E", (0.31, 0.33), (0.9, 1.0, 1.1)])
def test_lab_vs_colour(white, rng, x64):
    xyz = np.concatenate([rng.uniform(0, 1.2, (64, 3)), rng.uniform(0, 0.006, (8, 3))])
    if isinstance(white, str):
        ill = np.asarray(WHITEPOINTS[white])
    elif len(white) == 2:
        ill = np.asarray(white)
    else:
        ill = colour.XYZ_to_xy(np.asarray(white))
    wa = white if isinstance(white, str) else jnp.asarray(white)
    lab = xyz_to_lab(xyz, white=wa)
    scale = 1.0 if not (not isinstance(white, str) and len(white) == 3) else white[1]
    ref = colour.XYZ_to_Lab(xyz / scale, ill)
    np.testing.assert_allclose(np.asarray(lab), ref, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(np.asarray(lab_to_xyz(lab, white=wa)), xyz, rtol=1e-10, atol=1e-13)
    np.testing.assert_allclose(
        np.asarray(lab_to_xyz(ref, white=wa)), colour.Lab_to_XYZ(ref, ill) * scale, atol=1e-12
    )


def test_lab_named_values_and_zero(x64):
    # white -> (100, 0, 0); mid grey Y = 0.18 -> L* = 116 * 0.18^(1/3) - 16
    w = np.asarray(colour.xy_to_XYZ(WHITEPOINTS["D65"]))
    lab = np.asarray(jax.jit(xyz_to_lab)(np.stack([w, 0.18 * w, 0 * w])))
    np.testing.assert_allclose(lab[0], [100, 0, 0], atol=1e-12)
    np.testing.assert_allclose(lab[1], [116 * 0.18 ** (1 / 3) - 16, 0, 0], atol=1e-12)
    np.testing.assert_allclose(lab[2], [0, 0, 0], atol=1e-12)
    # gradient at black is finite and equals the linear branch slope kappa = 24389/27
    J = jax.jit(jax.jacrev(lambda x: xyz_to_lab(x)[0]))(jnp.zeros(3))
    np.testing.assert_allclose(np.asarray(J), [0, 24389 / 27 / w[1], 0], rtol=1e-12)
    # continuity of f at eps = 216/24389
    eps = 216 / 24389
    lo, hi = np.asarray(
        jax.jit(xyz_to_lab)(np.array([[0, eps * (1 - 1e-12), 0], [0, eps * (1 + 1e-12), 0]]))
    )
    assert abs(lo[0] - hi[0]) < 1e-9


# 3.4 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_check_grads_all_maps(rng, x64):
    """Every continuous map against finite differences, in one compiled program (outputs scaled
    to O(1) so that each map weighs in the random projection)."""
    # XYZ with t = X/Xn away from the C1-only switch at eps (FD would straddle it), plus a
    # deep-shadow colour on the linear branch
    xyz = jnp.asarray(np.concatenate([rng.uniform(0.2, 1, (4, 3)), [[0.001, 0.002, 0.0005]]]))
    lab = xyz_to_lab(xyz)
    rgb = jnp.asarray(rng.uniform(0.05, 1, (5, 3)))  # distinct channels: away from HSV ties
    hsv = rgb_to_hsv(rgb)
    cmyk = rgb_to_cmyk(rgb)
    white = jnp.array([0.95, 1.0, 1.05])

    @jax.jit
    def f(xyz, lab, rgb, hsv, cmyk, white):
        outs = [
            xyz_to_lab(xyz) / 100,
            lab_to_xyz(lab),
            xyz_to_lab(xyz, white=white) / 100,
            xyz_to_xyY(xyz),
            xyY_to_xyz(xyz_to_xyY(xyz)),
            rgb_to_xyz(rgb, space="prophoto"),
            xyz_to_rgb(xyz, space="adobe_rgb"),
            rgb_to_hsv(rgb),
            hsv_to_rgb(hsv),
            rgb_to_yiq(rgb),
            yiq_to_rgb(rgb),
            rgb_to_cmyk(rgb),
            cmyk_to_rgb(cmyk),
            luminance(rgb)[:, None],
            rgb_to_rgb(rgb, src="srgb", dst="prophoto"),
        ]
        return jnp.concatenate([o.reshape(-1) for o in outs])

    check_grads(f, (xyz, lab, rgb, hsv, cmyk, white), order=1, modes=["rev"], eps=1e-6)


def test_xyY(rng, x64):
    xyz = rng.uniform(0.01, 1, (32, 3))
    xyY = xyz_to_xyY(xyz)
    np.testing.assert_allclose(np.asarray(xyY), colour.XYZ_to_xyY(xyz), atol=1e-14)
    np.testing.assert_allclose(np.asarray(xyY_to_xyz(xyY)), xyz, atol=1e-14)
    # black -> white chromaticity (colour-science returns 0, 0 instead)
    np.testing.assert_allclose(np.asarray(xyz_to_xyY(np.zeros(3))), [0.3127, 0.329, 0], atol=1e-15)
    np.testing.assert_allclose(
        np.asarray(xyz_to_xyY(np.zeros(3), white="D50")), [0.3457, 0.3585, 0], atol=1e-15
    )
    g = jax.jit(jax.jacrev(xyz_to_xyY))(jnp.zeros(3))
    assert np.all(np.isfinite(np.asarray(g)))


def test_hsv_vs_colour_and_skimage(rng):
    rgb = rng.uniform(0, 1, (8, 8, 3)).astype(np.float32)
    rgb[0, :4] = [[0.5, 0.5, 0.5], [0, 0, 0], [1, 1, 1], [1, 0, 0]]
    rgb[1, :3] = [[1, 1, 0], [0, 1, 1], [1, 0, 1]]  # ties for the max
    hsv = np.asarray(jax.jit(rgb_to_hsv)(rgb))
    assert hsv.dtype == np.float32
    np.testing.assert_allclose(hsv, rgb2hsv(rgb), atol=2e-6)
    ref = colour.RGB_to_HSV(rgb.astype(np.float64))
    ref[..., 0] = np.where(ref[..., 0] == 1.0, 0.0, ref[..., 0])  # hue 1 == hue 0
    np.testing.assert_allclose(hsv, ref, atol=2e-6)
    assert np.all((hsv[..., 0] >= 0) & (hsv[..., 0] < 1))
    np.testing.assert_allclose(np.asarray(jax.jit(hsv_to_rgb)(hsv)), rgb, atol=2e-6)
    np.testing.assert_allclose(hsv[0, 0], [0, 0, 0.5])
    np.testing.assert_allclose(hsv[1, :3, 0], [1 / 6, 1 / 2, 5 / 6], atol=1e-7)
    # closed form of the continuous HSV -> RGB: hue 1/6 full saturation is yellow
    np.testing.assert_allclose(np.asarray(hsv_to_rgb(jnp.array([1 / 6, 1.0, 1.0]))), [1, 1, 0])


def test_hsv_grads(rng, x64):
    # grey and black pixels: finite gradients, V's gradient is exact
    jac = jax.jit(jax.jacrev(rgb_to_hsv))
    for px in ([0.5, 0.5, 0.5], [0.0, 0.0, 0.0], [1.0, 1.0, 0.2]):
        J = np.asarray(jac(jnp.asarray(px)))
        assert np.all(np.isfinite(J)), px
        assert J[2].sum() == pytest.approx(1.0)


def test_yiq(rng, x64):
    rgb = rng.uniform(0, 1, (32, 3))
    yiq = np.asarray(rgb_to_yiq(rgb))
    np.testing.assert_allclose(yiq, rgb @ np.asarray(YIQ_MATRIX).T, atol=1e-15)
    # the lecture's coefficients, and scikit-image's (more precise) FCC matrix to 3 decimals
    np.testing.assert_allclose(np.asarray(rgb_to_yiq(np.eye(3))).T, YIQ_MATRIX, atol=1e-15)
    np.testing.assert_allclose(yiq, rgb2yiq(rgb[None])[0], atol=2e-3)
    np.testing.assert_allclose(np.asarray(yiq_to_rgb(yiq)), rgb, atol=1e-13)
    np.testing.assert_allclose(np.asarray(rgb_to_yiq(np.ones(3))), [1, 0, 0], atol=1e-15)


def test_cmyk(rng, x64):
    rgb = rng.uniform(0, 1, (32, 3))
    rgb[0] = 0.0
    cmyk = np.asarray(rgb_to_cmyk(rgb))
    ref = colour.CMY_to_CMYK(colour.RGB_to_CMY(rgb[1:]))  # (colour warns on 0/0 at black)
    np.testing.assert_allclose(cmyk[1:], ref, atol=1e-14)
    np.testing.assert_allclose(cmyk[0], [0, 0, 0, 1])
    np.testing.assert_allclose(np.asarray(cmyk_to_rgb(cmyk)), rgb, atol=1e-14)
    assert np.all(np.isfinite(np.asarray(jax.jit(jax.jacrev(rgb_to_cmyk))(jnp.zeros(3)))))


def test_luminance(rng):
    rgb = rng.uniform(0, 1, (4, 5, 3)).astype(np.float32)
    y = np.asarray(jax.jit(luminance)(rgb))
    assert y.shape == (4, 5)
    # Rec.709 weights are the Y row of the derived sRGB matrix to 4 decimals
    np.testing.assert_allclose(y, rgb @ rgb_to_xyz_matrix("srgb")[1], atol=1e-4)
    y601 = np.asarray(luminance(rgb, weights="rec601"))
    np.testing.assert_allclose(y601, rgb @ np.array([0.299, 0.587, 0.114]), rtol=1e-6)
    np.testing.assert_allclose(y601, np.asarray(rgb_to_yiq(rgb))[..., 0], rtol=1e-6)


def test_jit_vmap_batch(rng):
    rgb = rng.uniform(0, 1, (3, 4, 4, 3)).astype(np.float32)
    f = jax.jit(lambda x: xyz_to_lab(rgb_to_xyz(x)))
    batched = np.asarray(jax.vmap(f)(rgb))
    np.testing.assert_allclose(batched, np.asarray(f(rgb)), rtol=1e-6, atol=1e-5)
    xyz = rgb.astype(np.float64) @ rgb_to_xyz_matrix("srgb").T
    ref = colour.XYZ_to_Lab(xyz, WHITEPOINTS["D65"])
    np.testing.assert_allclose(batched, ref, atol=1e-3)


def test_bad_arguments():
    with pytest.raises(ValueError, match="space"):
        rgb_to_xyz(np.ones(3), space="sRGB ")
    with pytest.raises(ValueError, match="space"):
        xyz_to_rgb(np.ones(3), space="p3")
    with pytest.raises(ValueError, match="white"):
        xyz_to_lab(np.ones(3), white="D66")
    with pytest.raises(ValueError, match="white"):
        lab_to_xyz(np.ones(3), white=(0.3, 0.0))
    with pytest.raises(ValueError, match="white"):
        xyz_to_lab(np.ones(3), white=(1.0, 2.0, 3.0, 4.0))
    with pytest.raises(ValueError, match="weights"):
        luminance(np.ones(3), weights="bt2020")
    with pytest.raises(ValueError, match="^rgb: .*shape"):
        rgb_to_hsv(np.ones((4, 4)))
    with pytest.raises(ValueError, match="^cmyk: .*shape"):
        cmyk_to_rgb(np.ones(3))
    with pytest.raises(ValueError, match="^xyz: .*NaN"):
        xyz_to_lab(np.array([0.1, np.nan, 0.2]))
    with pytest.raises(ValueError, match="^rgb: .*NaN"):
        rgb_to_yiq(np.array([[0.1, 0.2, np.inf]]))
