"""``method="subspace"``: Debevec–Malik's least squares restricted to the analytic curve
space ``1, ln z, ln(1 − z), P_1 … P_K`` (issue 26; jaxgfx/hdr/_subspace.py)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx import hdr
from jaxgfx.hdr._subspace import response_basis
from jaxgfx.testing import check_grads_fd

_recover = jax.jit(hdr.recover_response, static_argnames=("method", "n_poly"))


def _gamma2_stack(dtype):
    """Two float frames of ``x = z²`` (``g = 2 ln z``) with times 1 and 4: a pixel at level
    ``k`` in the short frame is at level ``2k`` in the long one, exactly on the knots, so the
    data are consistent with a curve in the span (``ln z``) and carry no quantisation error.
    8x8-pixel flat blocks (the sampler prefers flat pixels)."""
    k = 1 + np.arange(128) % 127  # levels 1..127 -> 2..254
    blocks = k.reshape(8, 16)
    z0 = np.kron(blocks, np.ones((8, 8))) / 255.0
    ims = np.stack([z0, 2.0 * z0])[..., None].astype(dtype)
    return ims, np.asarray([1.0, 4.0], dtype)


def test_basis_is_orthonormal_and_spans_gamma_and_logit():
    b = response_basis(256, 2)
    assert b.shape == (256, 5) and np.all(np.isfinite(b))
    np.testing.assert_allclose(b.T @ b, np.eye(5), atol=1e-12)
    z = np.clip(np.linspace(0, 1, 256), 0.5 / 255, 1 - 0.5 / 255)
    for curve in (2.2 * np.log(z), np.log(z) - np.log1p(-z), 1.0 + 0 * z):  # gamma, logit
        resid = curve - b @ (b.T @ curve)
        assert np.max(np.abs(resid)) < 1e-10


# slow: ~5 s on 2 cores, 9 s under load (compile of the sampler and the solve, float64)
@pytest.mark.slow
def test_subspace_recovers_a_curve_in_the_span_exactly(x64):
    """No smoothness (``lam=0``: λ·g'' would pull the curve off ``2 ln z``); every level,
    the extrapolated black and clipped ones included, within 1e-8 of the truth."""
    ims, t = _gamma2_stack(np.float64)
    r = hdr.recover_response(ims, t, method="subspace", n_poly=2, lam=0.0)
    assert r.params.dtype == jnp.float64
    lv = np.arange(1, 256)
    got = np.asarray(r.params)[lv, 0]
    # anchor: g(level 127) = 0; the basis clips z at 1 - 0.5/255 (the clipped level 255)
    want = 2.0 * np.log(np.minimum(lv, 254.5) / 127.0)
    np.testing.assert_allclose(got, want, atol=1e-8)
    assert float(r.diagnostics["residual_rms"][0]) < 1e-9
    assert r.diagnostics["coefficients"].shape == (1, 5)


# slow: ~15 s on 2 cores, 30 s under load (float64 compiles of the fit and its gradient)
@pytest.mark.slow
def test_subspace_gradient_in_exposure_times_matches_finite_differences(x64):
    """The table is linear in ``ln t`` through the normal equations: d table / d ln t_long
    by reverse mode against central differences (float64)."""
    ims, t = _gamma2_stack(np.float64)
    sel = jnp.asarray([20, 60, 100, 200])

    def f(log_t):
        r = hdr.recover_response(ims, jnp.exp(log_t), method="subspace", n_poly=1, lam=1e-6)
        return jnp.sum(r.params[sel, 0] * jnp.asarray([1.0, -0.5, 0.25, 2.0]))

    ok, g_ad, g_fd = check_grads_fd(f, jnp.log(jnp.asarray(t)), eps=1e-4, rtol=1e-6, jit=True)
    assert ok, (g_ad, g_fd)
    # and not trivially: the curve's scale follows ln(t_long / t_short)
    assert abs(g_ad[1]) > 0.1


# slow: ~8 s on 2 cores, 19 s under load (two compiles: eager and jitted)
@pytest.mark.slow
def test_subspace_under_jit_matches_eager():
    """``jax.jit`` of the public function (options static) gives the eager curve; float32."""
    ims, t = _gamma2_stack(np.float32)
    eager = hdr.recover_response(ims, t, method="subspace", n_poly=0)
    jitted = _recover(jnp.asarray(ims), jnp.asarray(t), method="subspace", n_poly=0)
    np.testing.assert_allclose(np.asarray(jitted.params), np.asarray(eager.params), atol=1e-5)


@pytest.mark.parametrize("bad", [-1, 9, 1.5, True])
def test_subspace_bad_n_poly(bad):
    ims, t = _gamma2_stack(np.float32)
    with pytest.raises(ValueError, match="n_poly"):
        hdr.recover_response(ims, t, method="subspace", n_poly=bad)


def test_subspace_unknown_option_names_the_option():
    ims, t = _gamma2_stack(np.float32)
    with pytest.raises(ValueError, match="reweight_passes"):
        hdr.recover_response(ims, t, method="subspace", reweight_passes=2)


def test_bracket_overlap_counts_pixels_well_exposed_in_two_frames():
    """Closed form on a 3-frame 2x3 stack: levels 16 and 239 count as well exposed, 15 and
    240 do not; per channel."""
    from jaxgfx.hdr._debevec import bracket_overlap

    lv = np.asarray(
        [
            # frame 0, 1, 2 levels of the 6 pixels (channel 0)
            [[16, 15, 100], [239, 240, 0]],
            [[239, 100, 15], [100, 240, 255]],
            [[255, 240, 240], [0, 100, 100]],
        ],
        np.float32,
    )
    z = np.stack([lv, np.full_like(lv, 128.0)], axis=-1) / 255.0  # channel 1: all inside
    got = np.asarray(bracket_overlap(jnp.asarray(z)))
    # pixel (0,0): 16, 239 -> yes; (0,1): 15, 100, 240 -> no; (0,2): 100, 15, 240 -> no;
    # (1,0): 239, 100 -> yes; (1,1): 240, 240, 100 -> no; (1,2): 0, 255, 100 -> no
    np.testing.assert_allclose(got, [2 / 6, 1.0], atol=1e-7)


@pytest.mark.parametrize("bad", [-0.1, 1.5, True, "x"])
def test_sparse_overlap_bad_input(bad):
    ims, t = _gamma2_stack(np.float32)
    with pytest.raises(ValueError, match="sparse_overlap"):
        hdr.recover_response(ims, t, sparse_overlap=bad)


def _doubling_levels(n_lev):
    """Pixels at level ``k`` in a frame of time 1 and ``2k`` in one of time 4: consistent
    with ``g = 2 ln z`` exactly (``g[2k] − g[k] = ln 4``); ``(P, 2)`` levels, unit weights."""
    k = np.arange(1, (n_lev - 1) // 2 + 1)
    lev = jnp.asarray(np.stack([k, 2 * k], axis=1), jnp.int32)
    return lev, jnp.ones(lev.shape, jnp.float64), jnp.log(jnp.asarray([1.0, 4.0]))


def test_smoothness_prior_leaves_a_consistent_prior_curve_unbent(x64):
    """``λ S(g − prior)`` with the prior = the true (anchored) curve: data, smoothness, anchor
    and ridge are all zero at the truth, so even a strong ``λ`` returns it, on every level
    (the unobserved 0 and L−1 included); Debevec's ``λ S(g)`` bends the same curve towards a
    straight line. Jitted; float64; levels ``(k, 2k)`` of ``g = 2 ln z``."""
    from jaxgfx.hdr._debevec import debevec_solve

    n = 64
    lev, w, log_t = _doubling_levels(n)
    m = (n - 1) // 2
    z = np.clip(np.arange(n) / (n - 1), 0.5 / (n - 1), 1.0)
    truth = 2.0 * np.log(z / z[m])  # anchored: g[m] = 0
    solve = jax.jit(debevec_solve, static_argnums=(3, 5))
    g = np.asarray(solve(lev, w, log_t, n, 1e-2, m, jnp.asarray(truth)))
    np.testing.assert_allclose(g, truth, atol=1e-9)
    plain = np.asarray(solve(lev, w, log_t, n, 1e-2, m))
    assert np.max(np.abs(plain - truth)) > 0.05


def test_smoothness_prior_gradient_matches_finite_differences(x64):
    """The solve is linear in the prior and in ``ln t``: reverse mode against central
    differences in both at once (float64, 16 levels, jitted: one compile each)."""
    from jaxgfx.hdr._debevec import debevec_solve

    n = 16
    lev, w, log_t = _doubling_levels(n)
    coef = jnp.linspace(-1.0, 1.0, n) ** 2
    prior0 = jnp.asarray(np.log(np.linspace(0.05, 1.0, n)) * 1.7)

    def f(x):
        return jnp.sum(coef * debevec_solve(lev, w, x[n:], n, 1e-2, 7, x[:n]))

    x0 = jnp.concatenate([prior0, log_t])
    ok, g_ad, g_fd = check_grads_fd(f, x0, eps=1e-5, rtol=1e-6, atol=1e-9, jit=True)
    assert ok, (g_ad, g_fd)
    assert np.max(np.abs(g_ad[:n])) > 1e-3  # the prior does move the solution
    assert abs(g_ad[n + 1]) > 1e-3  # and so does the long frame's time


@pytest.mark.parametrize("bad", ["curve", True, None])
def test_smooth_prior_bad_input(bad):
    ims, t = _gamma2_stack(np.float32)
    with pytest.raises(ValueError, match="smooth_prior"):
        hdr.recover_response(ims, t, smooth_prior=bad)
