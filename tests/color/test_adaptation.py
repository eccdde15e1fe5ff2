"""Chromatic adaptation vs colour-science's von Kries implementation."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from colour.adaptation import chromatic_adaptation_VonKries, matrix_chromatic_adaptation_VonKries
from jax.test_util import check_grads

from jaxgfx.color import (
    WHITEPOINTS,
    chromatic_adaptation,
    chromatic_adaptation_matrix,
    whitepoint_xyz,
)

COLOUR_CAT = {"bradford": "Bradford", "von_kries": "Von Kries", "cat02": "CAT02"}
PAIRS = [("D65", "D50"), ("A", "D65"), ("E", "D65"), ("D50", "A"), ((0.40, 0.38), "D65")]


def _xyz(w):
    return colour.xy_to_XYZ(np.asarray(WHITEPOINTS[w] if isinstance(w, str) else w))


@pytest.mark.parametrize("method", list(COLOUR_CAT))
def test_matrix_vs_colour(method, x64):
    for src, dst in PAIRS:
        ours = chromatic_adaptation_matrix(src, dst, method=method, dtype=jnp.float64)
        ref = matrix_chromatic_adaptation_VonKries(_xyz(src), _xyz(dst), COLOUR_CAT[method])
        np.testing.assert_allclose(np.asarray(ours), ref, rtol=0, atol=1e-12)


def test_lindbloom_bradford_d65_d50(x64):
    # Lindbloom's published Bradford D65 -> D50 matrix (brucelindbloom.com). He uses the ASTM
    # E308 white XYZ, we the rounded xy of IEC 61966-2-1 / ISO 22028-2: agreement to ~2e-4
    ref = np.array(
        [
            [1.0478112, 0.0228866, -0.0501270],
            [0.0295424, 0.9904844, -0.0170491],
            [-0.0092345, 0.0150436, 0.7521316],
        ]
    )
    M = np.asarray(chromatic_adaptation_matrix("D65", "D50", dtype=jnp.float64))
    np.testing.assert_allclose(M, ref, atol=3e-4)


def test_apply_vs_colour_and_white_mapping(rng, x64):
    xyz = rng.uniform(0, 1, (16, 3))
    f = jax.jit(chromatic_adaptation, static_argnames=("src_white", "dst_white", "method"))
    out = f(xyz, src_white="A", dst_white="D65", method="cat02")
    ref = chromatic_adaptation_VonKries(xyz, _xyz("A"), _xyz("D65"), "CAT02")
    np.testing.assert_allclose(np.asarray(out), ref, atol=1e-12)
    # the source white maps to the destination white exactly, for every method
    for m in ("bradford", "von_kries", "cat02", "xyz_scaling"):
        w = chromatic_adaptation(whitepoint_xyz("D50", like=xyz), "D50", "A", method=m)
        np.testing.assert_allclose(np.asarray(w), _xyz("A"), atol=1e-14)
    # identity when the whites agree
    np.testing.assert_allclose(np.asarray(chromatic_adaptation(xyz, "D65", "D65")), xyz, atol=1e-15)
    # XYZ scaling is the diagonal ratio of the whites
    M = chromatic_adaptation_matrix("D65", "E", method="xyz_scaling", dtype=jnp.float64)
    np.testing.assert_allclose(np.asarray(M), np.diag(_xyz("E") / _xyz("D65")), atol=1e-15)


def test_custom_white_gradients(x64):
    @jax.jit
    def f(s, d, x):
        return jnp.concatenate(
            [
                chromatic_adaptation_matrix(s, d).ravel(),
                chromatic_adaptation(x, s, "D50", method="cat02").ravel(),
            ]
        )

    xyz = jnp.array([[0.2, 0.3, 0.4], [0.7, 0.6, 0.5]])
    args = (jnp.array([0.33, 0.34]), jnp.array([0.9, 1.0, 0.8]), xyz)
    check_grads(f, args, order=1, modes=["rev"])


def test_dtype_and_vmap(rng):
    xyz = rng.uniform(0, 1, (2, 8, 8, 3)).astype(np.float32)
    out = jax.vmap(lambda x: chromatic_adaptation(x, "D65", "D50"))(xyz)
    assert out.dtype == jnp.float32 and out.shape == xyz.shape
    M = matrix_chromatic_adaptation_VonKries(_xyz("D65"), _xyz("D50"), "Bradford")
    np.testing.assert_allclose(np.asarray(out), xyz.astype(float) @ M.T, atol=1e-6)


def test_bad_arguments():
    with pytest.raises(ValueError, match="method"):
        chromatic_adaptation(np.ones(3), "D65", "D50", method="cat16")
    with pytest.raises(ValueError, match="src_white"):
        chromatic_adaptation(np.ones(3), "D63", "D50")
    with pytest.raises(ValueError, match="dst_white"):
        chromatic_adaptation_matrix("D65", (0.3, -0.1))
    with pytest.raises(ValueError, match="dst_white"):
        chromatic_adaptation_matrix("D65", np.array([0.9, 0.0, 1.0]))
    with pytest.raises(ValueError, match="^xyz: .*NaN"):
        chromatic_adaptation(np.array([np.nan, 1, 1]), "D65", "D50")
