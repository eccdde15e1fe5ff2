"""fit / fit_least_squares against closed-form optima, NumPy lstsq and SciPy least_squares."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest
import scipy.optimize

from jaxgfx.optim import FAST_COMPILE_OPTIONS, fit, fit_least_squares


def test_adam_quadratic_matches_closed_form(x64):
    # 0.5 x^T A x - b^T x has its minimum at A^{-1} b
    rng = np.random.default_rng(1)
    m = rng.normal(size=(3, 3))
    a = m @ m.T + 3 * np.eye(3)
    b = rng.normal(size=3)

    def loss(p, args):
        aa, bb = args
        return 0.5 * p["x"] @ aa @ p["x"] - bb @ p["x"]

    res = fit(
        loss,
        {"x": np.zeros(3)},
        steps=1500,
        learning_rate=0.05,
        args=(a, b),
        progress=False,
        tol=1e-12,
    )
    np.testing.assert_allclose(np.asarray(res.params["x"]), np.linalg.solve(a, b), atol=1e-5)
    # history: entry 0 is the start, loss[k] is the loss at history[k]
    assert res.history["x"].shape == (res.n_steps + 1, 3)
    np.testing.assert_allclose(res.loss[0], 0.0)
    assert res.seconds.shape == (res.n_steps,) and np.all(res.seconds > 0)
    assert res.loss[-1] < res.loss[0]


def test_bounded_fit_optimum_inside_and_outside(x64):
    # target inside (0.001, 1): reached; target outside (-0.5): approaches the bound, stays
    # inside, stays finite
    loss = lambda p: (p["a"] - 0.37) ** 2 + (p["b"] + 0.5) ** 2
    res = fit(
        loss,
        {"a": 0.9, "b": 0.5},
        steps=800,
        learning_rate=0.05,
        bounds={"a": (1e-3, 1.0), "b": (1e-3, 1.0)},
        progress=False,
    )
    np.testing.assert_allclose(float(res.params["a"]), 0.37, atol=1e-4)
    b = float(res.params["b"])
    assert 1e-3 < b < 1e-2
    assert np.all(np.isfinite(res.loss))


def test_start_on_the_bound_escapes(x64):
    loss = lambda p: (p["alpha"] - 0.2) ** 2
    res = fit(
        loss,
        {"alpha": 1e-3},
        steps=600,
        learning_rate=0.05,
        bounds={"alpha": (1e-3, 1.0)},
        progress=False,
    )
    np.testing.assert_allclose(float(res.params["alpha"]), 0.2, atol=1e-4)


def test_zero_gradient_parameter_stays_put():
    loss = lambda p: jnp.sum((p["x"] - 1.0) ** 2) + 0.0 * p["unused"]
    res = fit(
        loss,
        {"x": jnp.zeros(2), "unused": jnp.asarray(0.25)},
        steps=50,
        learning_rate=0.1,
        bounds={"x": None, "unused": (0.0, 1.0)},
        progress=False,
    )
    assert float(res.params["unused"]) == pytest.approx(0.25, abs=1e-6)
    assert np.all(np.isfinite(res.history["unused"]))


def test_nan_loss_raises_with_the_step():
    # the loss becomes NaN once x passes 1 (sqrt of a negative number)
    loss = lambda p: jnp.sqrt(1.0 - p["x"]) + (p["x"] - 3.0) ** 2
    with pytest.raises(FloatingPointError, match=r"not finite at step \d+"):
        fit(loss, {"x": 0.0}, steps=200, learning_rate=0.2, progress=False)


def test_fresh_key_per_step_gives_the_sample_mean():
    # SGD with step 1/(k+1) on 0.5 (x - z_k)^2 makes x the running mean of z_0..z_{n-1};
    # z_k = 1 + N(fold_in(key, k)) is drawn independently here
    key = jax.random.key(3)
    n = 64

    def loss(p, k):
        z = 1.0 + jax.random.normal(k)
        return 0.5 * (p["x"] - z) ** 2

    tx = optax.sgd(lambda count: 1.0 / (count + 1.0))
    res = fit(loss, {"x": 5.0}, optimizer=tx, steps=n, key=key, progress=False)
    z = np.array([1.0 + float(jax.random.normal(jax.random.fold_in(key, k))) for k in range(n)])
    np.testing.assert_allclose(float(res.params["x"]), z.mean(), rtol=1e-5)
    assert abs(z.mean() - z[0]) > 0.05  # a repeated key would have given z_0


def test_callback_and_tol_stop_early():
    seen = []
    res = fit(
        lambda p: p["x"] ** 2,
        {"x": 1.0},
        steps=100,
        learning_rate=0.1,
        callback=lambda i, p, l: seen.append(i) or i == 4,
        progress=False,
    )
    assert res.stop_reason == "callback" and res.n_steps == 5 and seen == [0, 1, 2, 3, 4]
    res = fit(
        lambda p: (p["x"] - 2.0) ** 2,
        {"x": 1.0},
        steps=5000,
        learning_rate=0.05,
        tol=1e-3,
        progress=False,
    )
    assert res.stop_reason == "tol" and res.n_steps < 5000


def test_bad_arguments():
    with pytest.raises(ValueError, match="steps"):
        fit(lambda p: p**2, 1.0, steps=0)
    with pytest.raises(ValueError, match="optimizer"):
        fit(lambda p: p**2, 1.0, steps=2, optimizer="newton")
    with pytest.raises(ValueError, match="outside its bounds"):
        fit(lambda p: p["a"] ** 2, {"a": 2.0}, steps=2, bounds={"a": (0.0, 1.0)})
    with pytest.raises(ValueError, match="scalar"):
        fit(lambda p: p["a"] * jnp.ones(3), {"a": 2.0}, steps=2, progress=False)
    with pytest.raises(TypeError, match="float array"):
        fit(lambda p: p["a"] ** 2, {"a": "x"}, steps=2)


@pytest.mark.parametrize("solver", ["lm", "gauss_newton"])
def test_linear_least_squares_matches_lstsq(x64, solver):
    rng = np.random.default_rng(2)
    a = rng.normal(size=(30, 4))
    y = rng.normal(size=30)
    res = fit_least_squares(
        lambda p, args: args[0] @ p - args[1], np.zeros(4), solver=solver, args=(a, y)
    )
    ref = np.linalg.lstsq(a, y, rcond=None)[0]
    np.testing.assert_allclose(np.asarray(res.params), ref, rtol=1e-8, atol=1e-10)
    assert res.stop_reason == "converged"
    np.testing.assert_allclose(res.loss[1], 0.5 * np.sum((a @ ref - y) ** 2), rtol=1e-10)


@pytest.mark.parametrize("solver", ["lm", "gauss_newton"])
def test_least_squares_out_of_steps_reports_max_steps(x64, solver):
    # Rosenbrock residuals from (-1.2, 1): no solver reaches the minimum (1, 1) in 2 steps;
    # the documented stop reason is "max_steps" (optimistix calls it
    # nonlinear_max_steps_reached), not "failed"
    res = fit_least_squares(
        lambda p: jnp.stack([10 * (p[1] - p[0] ** 2), 1 - p[0]]),
        np.array([-1.2, 1.0]),
        solver=solver,
        max_steps=2,
    )
    assert res.stop_reason == "max_steps"
    assert np.max(np.abs(np.asarray(res.params) - 1.0)) > 1e-3


def _traced_linear_residuals(p, args):
    _TRACES.append(1)  # runs once per trace, not per call
    return args[0] @ p - args[1]


_TRACES = []


def test_least_squares_solve_is_compiled_once_for_new_data_and_starts(x64):
    # a second fit with other data and another start reuses the compiled solve (no retrace)
    # and both still match numpy.linalg.lstsq
    rng = np.random.default_rng(5)
    _TRACES.clear()
    for k in range(2):
        a = rng.normal(size=(20, 3))
        y = rng.normal(size=20)
        res = fit_least_squares(_traced_linear_residuals, np.full(3, float(k)), args=(a, y))
        ref = np.linalg.lstsq(a, y, rcond=None)[0]
        np.testing.assert_allclose(np.asarray(res.params), ref, rtol=1e-8, atol=1e-10)
        if k == 0:
            n_first = len(_TRACES)
    assert n_first > 0 and len(_TRACES) == n_first


def test_logistic_fit_matches_scipy_least_squares(x64):
    # noisy logistic data; both solvers minimise the same sum of squares
    rng = np.random.default_rng(4)
    t = np.linspace(-3, 3, 40)
    y = 2.0 / (1.0 + np.exp(-1.7 * (t - 0.4))) + 0.05 * rng.normal(size=t.size)

    def r_np(th):
        return th[0] / (1.0 + np.exp(-th[1] * (t - th[2]))) - y

    ref = scipy.optimize.least_squares(r_np, [1.0, 1.0, 0.0], xtol=1e-14, ftol=1e-14).x

    def r(p, args):
        tt, yy = args
        return p["k"] / (1.0 + jnp.exp(-p["s"] * (tt - p["t0"]))) - yy

    res = fit(
        r,
        {"k": 1.0, "s": 1.0, "t0": 0.0},
        optimizer="lm",
        steps=200,
        args=(t, y),
        bounds={"k": (0.0, None), "s": (0.0, 10.0), "t0": None},
    )
    got = [float(res.params[k]) for k in ("k", "s", "t0")]
    np.testing.assert_allclose(got, ref, rtol=1e-6)


def test_exponential_fit_float32_under_lm():
    t = np.linspace(0, 2, 25, dtype=np.float32)
    y = (0.7 * np.exp(-1.3 * t)).astype(np.float32)
    res = fit_least_squares(
        lambda p, a: p[0] * jnp.exp(p[1] * a[0]) - a[1], jnp.asarray([1.0, 0.0]), args=(t, y)
    )
    np.testing.assert_allclose(np.asarray(res.params), [0.7, -1.3], rtol=1e-4)


def test_learning_rate_schedule_on_the_host():
    # SGD on 0.5 x^2 with rate r_k: x_{k+1} = (1 - r_k) x_k, so x_n = prod(1 - r_k) x_0
    rates = [0.5, 0.25, 0.125, 0.0625]
    res = fit(
        lambda p: 0.5 * p["x"] ** 2,
        {"x": 2.0},
        optimizer="sgd",
        steps=4,
        learning_rate=lambda k: rates[k],
        progress=False,
    )
    np.testing.assert_allclose(
        float(res.params["x"]), 2.0 * np.prod([1 - r for r in rates]), rtol=1e-6
    )


def test_compiler_options_reach_xla_and_fast_compile_fits_the_same():
    def loss(p):
        return jnp.sum((p["x"] - jnp.asarray([3.0, -1.0])) ** 2)

    kw = dict(steps=40, learning_rate=0.1, progress=False)
    ref = fit(loss, {"x": jnp.zeros(2)}, **kw)
    fast = fit(loss, {"x": jnp.zeros(2)}, compiler_options=FAST_COMPILE_OPTIONS, **kw)
    # the same Adam trajectory (float32 rounding apart), moving towards (3, -1)
    np.testing.assert_allclose(fast.loss, ref.loss, rtol=1e-5)
    np.testing.assert_allclose(fast.params["x"], ref.params["x"], rtol=1e-5)
    assert fast.loss[-1] < 0.5 * fast.loss[0]
    # the options are handed to XLA: a name it does not know is its error
    with pytest.raises(Exception, match="xla_no_such_option"):
        fit(loss, {"x": jnp.zeros(2)}, compiler_options={"xla_no_such_option": True}, **kw)
    with pytest.raises(TypeError, match="compiler_options: expected a dict"):
        fit(loss, {"x": jnp.zeros(2)}, compiler_options=[("a", 1)], **kw)
