"""dtype follows the input: float32 stays float32 even with x64 on; float64 stays float64."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgfx.color as jc


@jax.jit
def _everything(rgb, img):
    xyz = jc.rgb_to_xyz(rgb)
    lab = jc.xyz_to_lab(xyz)
    outs = {
        "srgb": jc.linear_to_srgb(rgb),
        "srgb_inv": jc.srgb_to_linear(rgb),
        "rec709": jc.linear_to_rec709(rgb),
        "rec709_inv": jc.rec709_to_linear(rgb),
        "adobe": jc.linear_to_adobe_rgb(rgb),
        "adobe_inv": jc.adobe_rgb_to_linear(rgb),
        "prophoto": jc.linear_to_prophoto(rgb),
        "prophoto_inv": jc.prophoto_to_linear(rgb),
        "gamma": jc.gamma_encode(rgb, 2.2),
        "gamma_inv": jc.gamma_decode(rgb, 2.2),
        "xyz": xyz,
        "rgb": jc.xyz_to_rgb(xyz, space="rec2020"),
        "lab": lab,
        "lab_d50": jc.xyz_to_lab(xyz, white="D50"),
        "xyz_back": jc.lab_to_xyz(lab),
        "xyY": jc.xyz_to_xyY(xyz),
        "xyY_inv": jc.xyY_to_xyz(xyz),
        "xy_to_xyz": jc.xy_to_xyz(rgb[..., :2] * 0.3 + 0.1),
        "hsv": jc.rgb_to_hsv(rgb),
        "hsv_inv": jc.hsv_to_rgb(rgb),
        "yiq": jc.rgb_to_yiq(rgb),
        "yiq_inv": jc.yiq_to_rgb(rgb),
        "cmyk": jc.rgb_to_cmyk(rgb),
        "cmyk_inv": jc.cmyk_to_rgb(jc.rgb_to_cmyk(rgb)),
        "lum": jc.luminance(rgb),
        "rgb_to_rgb": jc.rgb_to_rgb(rgb),
        "de00": jc.delta_e_2000(lab, lab + 1.0),
        "de76": jc.delta_e_1976(lab, lab + 1.0),
        "cat": jc.chromatic_adaptation(xyz, "D65", "A", method="cat02"),
        "gw": jc.white_balance_grey_world(img, saturation=0.99),
        "wp": jc.white_balance_white_patch(img),
        "stretch": jc.white_balance_stretch(img),
        "vk": jc.white_balance_von_kries(img, rgb[0]),
    }
    return outs


@pytest.mark.parametrize(
    "dtype",
    # float32 under x64 is the leak check; float64 outputs are also asserted across the suite
    [np.float32, pytest.param(np.float64, marks=pytest.mark.slow)],
)
def test_dtype_follows_input(dtype, rng, x64):
    rgb = rng.uniform(0.01, 1, (5, 3)).astype(dtype)
    img = rng.uniform(0.01, 1, (4, 4, 3)).astype(dtype)
    outs = _everything(rgb, img)
    for name, v in outs.items():
        assert v.dtype == dtype, name
        assert np.all(np.isfinite(np.asarray(v))), name


def test_xy_to_xyz_and_whitepoints(x64):
    import colour

    xy = np.array([[0.3127, 0.329], [0.44758, 0.40745]])
    np.testing.assert_allclose(np.asarray(jc.xy_to_xyz(xy)), colour.xy_to_XYZ(xy), atol=1e-15)
    for name, v in jc.WHITEPOINTS.items():
        w = np.asarray(jc.whitepoint_xyz(name, like=jnp.zeros((), jnp.float64)))
        np.testing.assert_allclose(w, colour.xy_to_XYZ(np.asarray(v)), atol=1e-15, err_msg=name)
