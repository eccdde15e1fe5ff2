"""CIEDE2000 / CIE 1976 vs Sharma et al. (2005) data and colour-science."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from colour.difference import delta_E_CIE1976, delta_E_CIE2000
from jax.test_util import check_grads

from jaxgfx.color import delta_e_1976, delta_e_2000, delta_e_2000_residuals

from .sharma2005 import SHARMA_2005

_de00 = jax.jit(delta_e_2000)


def test_sharma_2005_table(x64):
    lab1, lab2, ref = SHARMA_2005[:, :3], SHARMA_2005[:, 3:6], SHARMA_2005[:, 6]
    assert len(ref) == 34
    # the table is printed to 4 decimals
    np.testing.assert_allclose(np.asarray(_de00(lab1, lab2)), ref, rtol=0, atol=5e-5 + 1e-12)
    np.testing.assert_allclose(np.asarray(_de00(lab2, lab1)), ref, rtol=0, atol=5e-5 + 1e-12)
    np.testing.assert_allclose(
        np.asarray(_de00(lab1, lab2)), delta_E_CIE2000(lab1, lab2), rtol=0, atol=1e-10
    )


def test_residual_vector_norm_is_delta_e_2000(x64, rng):
    """The least-squares form: ||r|| = CIEDE2000 on the Sharma table and on random pairs, and
    r is finite with a finite Jacobian where the two colours coincide (unlike the cone)."""
    lab1 = np.concatenate([SHARMA_2005[:, :3], rng.uniform(-60, 90, (100, 3))])
    lab2 = np.concatenate([SHARMA_2005[:, 3:6], lab1[34:] + rng.normal(0, 5, (100, 3))])
    r = jax.jit(delta_e_2000_residuals)(lab1, lab2)
    assert r.shape == (134, 3)
    np.testing.assert_allclose(
        np.linalg.norm(np.asarray(r), axis=-1), np.asarray(_de00(lab1, lab2)), rtol=1e-12
    )
    same = jnp.array([50.0, 10.0, -20.0])
    jac = jax.jacfwd(lambda a: delta_e_2000_residuals(a, same))(same)
    assert np.all(np.isfinite(np.asarray(jac))) and np.abs(np.asarray(jac)).max() > 0


def test_sharma_float32():
    # pairs 9-15 sit exactly on the 180-degree hue-difference switch, which float32 rounding
    # may put on either side (the formula is discontinuous there): float64 only
    keep = np.r_[0:8, 15:34]
    lab1 = SHARMA_2005[keep, :3].astype(np.float32)
    lab2 = SHARMA_2005[keep, 3:6].astype(np.float32)
    out = _de00(lab1, lab2)
    assert out.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(out), SHARMA_2005[keep, 6], rtol=0, atol=2e-4)


def test_random_vs_colour_and_textiles(rng, x64):
    lab1 = np.stack([rng.uniform(0, 100, 200), *rng.uniform(-100, 100, (2, 200))], -1)
    lab2 = lab1 + rng.normal(0, 8, (200, 3))
    np.testing.assert_allclose(
        np.asarray(_de00(lab1, lab2)), delta_E_CIE2000(lab1, lab2), rtol=0, atol=1e-10
    )
    # colour-science's textiles=True is kL = 2
    np.testing.assert_allclose(
        np.asarray(_de00(lab1, lab2, kL=2.0)),
        delta_E_CIE2000(lab1, lab2, textiles=True),
        rtol=0,
        atol=1e-10,
    )
    np.testing.assert_allclose(
        np.asarray(jax.jit(delta_e_1976)(lab1, lab2)), delta_E_CIE1976(lab1, lab2), atol=1e-12
    )


# 4.9 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_grads_away_from_hue_discontinuity(rng, x64):
    lab1 = np.stack([rng.uniform(20, 80, 6), *rng.uniform(-60, 60, (2, 6))], -1)
    lab2 = lab1 + rng.normal(0, 5, (6, 3))
    # keep |h1 - h2| well away from 180 deg (where CIEDE2000 jumps)
    h1 = np.arctan2(lab1[:, 2], lab1[:, 1])
    h2 = np.arctan2(lab2[:, 2], lab2[:, 1])
    dh = np.abs(np.angle(np.exp(1j * (h1 - h2))))
    assert np.all(dh < 2.5)
    f = jax.jit(lambda a, b, kl, kc, kh: delta_e_2000(a, b, kL=kl, kC=kc, kH=kh))
    check_grads(f, (jnp.asarray(lab1), jnp.asarray(lab2), 1.0, 1.2, 0.8), order=1, modes=["rev"])
    check_grads(jax.jit(delta_e_1976), (jnp.asarray(lab1), jnp.asarray(lab2)), 1, modes=["rev"])


def test_grads_finite_at_singular_points(x64):
    pairs = jnp.array(
        [
            [[50.0, 10.0, -20.0], [50.0, 10.0, -20.0]],  # identical: 0 (subgradient)
            [[50.0, 0.0, 0.0], [55.0, 0.0, 0.0]],  # both achromatic
            [[50.0, 0.0, 0.0], [50.0, 3.0, 4.0]],  # one achromatic
            [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]],
        ]
    )
    vg = jax.jit(jax.value_and_grad(lambda p: jnp.sum(delta_e_2000(p[:, 0], p[:, 1]))))
    _, g = vg(pairs)
    g = np.asarray(g)
    assert np.all(np.isfinite(g))
    np.testing.assert_array_equal(g[0], 0.0)
    np.testing.assert_array_equal(g[3], 0.0)
    # achromatic pair differing only in L: dE = |dL| / SL with SL at Lbar = 52.5, and no
    # gradient w.r.t. a*, b*
    v, g1 = vg(pairs[1:2])
    assert float(v) == pytest.approx(5.0 / (1 + 0.015 * 2.5**2 / np.sqrt(20 + 2.5**2)), rel=1e-12)
    np.testing.assert_array_equal(np.asarray(g1)[0, :, 1:], 0.0)


def test_vmap_batch(rng):
    lab1 = rng.uniform(-50, 50, (3, 4, 3)).astype(np.float32)
    lab2 = lab1 + 1.0
    out = jax.jit(jax.vmap(delta_e_2000))(lab1, lab2)
    assert out.shape == (3, 4)
    np.testing.assert_allclose(
        np.asarray(out), delta_E_CIE2000(lab1.astype(float), lab2.astype(float)), atol=1e-4
    )


def test_bad_arguments():
    with pytest.raises(ValueError, match="kL"):
        delta_e_2000(np.zeros(3), np.ones(3), kL=0.0)
    with pytest.raises(ValueError, match="kH"):
        delta_e_2000(np.zeros(3), np.ones(3), kH=-1.0)
    with pytest.raises(ValueError, match="^lab2: .*shape"):
        delta_e_2000(np.zeros(3), np.ones(4))
    with pytest.raises(ValueError, match="^lab1: .*NaN"):
        delta_e_1976(np.array([np.nan, 0, 0]), np.ones(3))


# ----------------------------------------------- kL, kC, kH: closed forms (Sharma 2005, (22))


def _S_C(c_mean):
    return 1.0 + 0.045 * c_mean


@pytest.mark.parametrize("kC, kH", [(1.2, 0.8), (0.7, 1.5)])
def test_pure_chroma_difference_closed_form(x64, kC, kH):
    # a* = 0: a' = (1 + G) a* = 0, so C' = |b*| and h' = 90 deg for both colours; the pair
    # differs only in chroma and dE00 = |dC'| / (kC S_C), S_C = 1 + 0.045 mean(C'),
    # independent of kH (and of G, T, R_T)
    b1 = np.array([5.0, 20.0, 40.0, 70.0])
    b2 = b1 + np.array([3.0, 6.0, -9.0, 12.0])
    lab1 = np.stack([np.full(4, 60.0), np.zeros(4), b1], -1)
    lab2 = np.stack([np.full(4, 60.0), np.zeros(4), b2], -1)
    want = np.abs(b2 - b1) / (kC * _S_C(0.5 * (b1 + b2)))
    got = np.asarray(_de00(lab1, lab2, kC=kC, kH=kH))
    np.testing.assert_allclose(got, want, rtol=1e-12)
    # and with kC = 1 it is colour-science's value
    np.testing.assert_allclose(
        np.asarray(_de00(lab1, lab2, kH=kH)), delta_E_CIE2000(lab1, lab2), rtol=1e-12
    )


@pytest.mark.parametrize("kC, kH", [(1.2, 0.8), (0.7, 1.5)])
def test_pure_hue_difference_scales_with_one_over_kH(x64, kC, kH):
    # (L, -a, b) vs (L, a, b): same C' (G is shared), dC' = 0, dL' = 0, so dE00 = |dH'| /
    # (kH S_H): exactly colour-science's reference-condition value divided by kH, whatever kC
    a = np.array([4.0, 15.0, 30.0, -25.0])
    b = np.array([10.0, -20.0, 5.0, 40.0])
    lab1 = np.stack([np.full(4, 45.0), -a, b], -1)
    lab2 = np.stack([np.full(4, 45.0), a, b], -1)
    ref = delta_E_CIE2000(lab1, lab2)
    assert np.all(ref > 1.0)
    got = np.asarray(_de00(lab1, lab2, kC=kC, kH=kH))
    np.testing.assert_allclose(got, ref / kH, rtol=1e-12)


def test_weights_are_homogeneous_where_R_T_is_active(x64):
    # blue pairs (h' near 275 deg, where the rotation term R_T couples dC' and dH'):
    # dE00(kL = kC = kH = k) = dE00(1, 1, 1) / k exactly
    lab1 = np.array([[50.0, 2.6772, -79.7751], [40.0, -10.0, -50.0], [70.0, 5.0, -30.0]])
    lab2 = np.array([[50.0, 0.0, -82.7485], [42.0, -2.0, -58.0], [68.0, 12.0, -26.0]])
    ref = delta_E_CIE2000(lab1, lab2)
    for k in (0.5, 1.3):
        np.testing.assert_allclose(
            np.asarray(_de00(lab1, lab2, kL=k, kC=k, kH=k)), ref / k, rtol=1e-12
        )
