"""Polyak–Ruppert iterate averaging of :func:`jaxgfx.optim.fit` (``average_from``) and the fit
config's ``optimizer.average``: against closed forms (a known iterate sequence; the stationary
variance of SGD on a quadratic with known gradient noise)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.optim import fit


def test_average_of_a_known_sequence(x64):
    # SGD on a linear loss g.x: x_k = x0 - k lr g exactly, so the mean of history[k0+1:] is
    # x0 - lr g (k0 + 1 + n) / 2
    g, lr, n, k0 = np.array([0.5, -2.0]), 0.1, 20, 12
    res = fit(lambda p: jnp.dot(p["x"], g), {"x": np.zeros(2)}, optimizer="sgd", steps=n,
              learning_rate=lr, average_from=k0, progress=False)
    np.testing.assert_allclose(res.history["x"][-1], -n * lr * g, atol=1e-12)
    np.testing.assert_allclose(np.asarray(res.params["x"]), -lr * g * (k0 + 1 + n) / 2,
                               atol=1e-12)
    assert res.n_averaged == n - k0
    # default: the last iterate, nothing averaged
    last = fit(lambda p: jnp.dot(p["x"], g), {"x": np.zeros(2)}, optimizer="sgd", steps=n,
               learning_rate=lr, progress=False)
    np.testing.assert_allclose(np.asarray(last.params["x"]), -n * lr * g, atol=1e-12)
    assert last.n_averaged == 0


def test_bounded_parameters_are_averaged_in_the_unconstrained_variable(x64):
    # loss (u - u*)^2 in the logit u of p in (lo, hi), SGD with lr 1: u_{k+1} = 2 u* - u_k
    # flips between u0 and 2 u* - u0, so the mean of an even number of iterates is u* exactly:
    # p = lo + (hi - lo) sigmoid(u*). The mean of the *values* p would be
    # (p(u0) + p(2 u* - u0)) / 2, 0.0117 away (a power check of the variable averaged in).
    lo, hi, u_star, p0 = 0.01, 1.0, -1.5, 0.5

    def loss(p):
        s = (p["a"] - lo) / (hi - lo)
        return (jnp.log(s / (1 - s)) - u_star) ** 2

    res = fit(loss, {"a": p0}, optimizer="sgd", steps=10, learning_rate=1.0,
              bounds={"a": (lo, hi)}, average_from=6, progress=False)

    def sig(u):
        return 1 / (1 + np.exp(-u))

    want = lo + (hi - lo) * sig(u_star)
    assert float(res.params["a"]) == pytest.approx(want, abs=1e-9)
    u0 = np.log((p0 - lo) / (hi - p0))
    values_mean = lo + (hi - lo) * 0.5 * (sig(u0) + sig(2 * u_star - u0))
    assert abs(values_mean - want) > 0.01


def test_averaging_a_noisy_quadratic_matches_the_stationary_variance(x64):
    # SGD on 0.5 h (x - 1)^2 with gradient noise s N(0, 1), R independent coordinates: the
    # iterate is the AR(1) process e_{k+1} = r e_k - lr s xi_k, r = 1 - lr h, stationary
    # variance V = lr^2 s^2 / (1 - r^2); the mean of m consecutive stationary iterates has
    # variance V (m + 2 sum_{j<m} (m - j) r^j) / m^2. Measured over R = 4000 coordinates (a
    # variance's relative standard error is sqrt(2 / R) = 2.2 %; the tolerance is 10 %).
    R, h, s, lr, n, k0 = 4000, 1.0, 1.0, 0.1, 400, 200
    r = 1 - lr * h

    def loss(p, key):
        xi = jax.random.normal(key, (R,), p["x"].dtype)
        return jnp.sum(0.5 * h * (p["x"] - 1.0) ** 2 + s * xi * p["x"])

    res = fit(loss, {"x": np.ones(R)}, optimizer="sgd", steps=n, learning_rate=lr,
              key=jax.random.key(3), average_from=k0, progress=False)
    v = lr**2 * s**2 / (1 - r**2)
    m = n - k0
    v_mean = v * (m + 2 * sum((m - j) * r**j for j in range(1, m))) / m**2
    last = res.history["x"][-1] - 1.0
    avg = np.asarray(res.params["x"]) - 1.0
    assert np.var(last) == pytest.approx(v, rel=0.1)
    assert np.var(avg) == pytest.approx(v_mean, rel=0.1)
    assert v / v_mean > 10  # the averaging is worth something here: 11x less variance
    # unbiased: the mean error of the averaged estimate is 0 within 4 standard errors
    assert abs(np.mean(avg)) < 4 * np.sqrt(v_mean / R)


def test_average_from_is_validated():
    with pytest.raises(ValueError, match=r"average_from: expected a step in 0..9 \(steps = 10\)"):
        fit(lambda p: p["x"] ** 2, {"x": 1.0}, steps=10, average_from=10, progress=False)
    with pytest.raises(ValueError, match=r"average_from: expected an integer >= 0"):
        fit(lambda p: p["x"] ** 2, {"x": 1.0}, steps=10, average_from=-1, progress=False)
    with pytest.raises(ValueError, match=r"average_from: a least-squares solver returns its"):
        fit(lambda p: p["x"], {"x": 1.0}, optimizer="lm", steps=10, average_from=5)


def test_optimizer_average_config():
    from jaxgfx.pipelines.fit import OptimizerConfig

    assert OptimizerConfig(steps=300).average_from() is None
    assert OptimizerConfig(steps=300, average=0.5).average_from() == 150
    assert OptimizerConfig(steps=300, average=1).average_from() == 0
    assert OptimizerConfig(steps=10, average=0.01).average_from() is None  # rounds to none
    for bad in (1.5, -0.1, "half", True):
        with pytest.raises(ValueError, match=r"optimizer.average: expected the fraction of the "
                           r"steps, at the end, whose iterates are averaged"):
            OptimizerConfig(average=bad)
