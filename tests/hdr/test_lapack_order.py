"""The response fit's compiled program runs its LAPACK calls one after the other.

Two independent LAPACK custom calls in one XLA CPU program may run side by side on the 2-thread
pool, and that deadlocked intermittently (every thread in a futex wait): the instanced queries'
batched ``inv`` (issue 24) and the Debevec default's candidate fits on 256x256 real brackets
(issue 26; about 1 call in 5). Since then the small curve-space solve is LAPACK-free
(``_math.spd_solve_small``) and the table's solves form one chain of data dependencies."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxgfx._math import spd_solve_small
from jaxgfx.hdr import response as R
from jaxgfx.testing import unordered_lapack_calls


def _stack():
    rng = np.random.default_rng(0)
    e = np.exp(rng.normal(0, 1.5, (48, 48, 3)))
    t = np.array([1 / 8, 1 / 2, 2.0, 8.0])
    z = np.clip((e[None] * t[:, None, None, None]) ** (1 / 2.2) * 60, 0, 255).astype(np.uint8)
    return jnp.asarray(z), jnp.asarray(t, jnp.float32)


# slow: ~4.4 s of the default run (2026-12-06, quiet: one compile of the Debevec program with
# its prior); the checker and the solver stay in the default run (the two tests below)
@pytest.mark.slow
def test_the_debevec_program_with_the_prior_orders_its_lapack_calls():
    z, t = _stack()
    text = (
        R._recover_jit.lower(z, t, jax.random.key(0), method="debevec", code_max=255, opts=())
        .compile()
        .as_text()
    )
    calls, unordered = unordered_lapack_calls(text)
    # the default (smooth_prior="auto"): two solves of the (3, 256, 256) tables, each one getrf
    # and two trsm: the end-weighted fit, and the one solve in the lax.scan over every
    # inverse-slope refit (3 plain, then 3 + 3 with the curve-space prior at lam and 10 lam);
    # the loop's input is the first solve's output, so the two are ordered. smooth_prior="none"
    # is the same program with a shorter loop. (Unrolled, the refits were 21 calls with one
    # prior'd chain; the main of before that had 36 pairs unordered.)
    assert calls == 6, calls
    assert unordered == 0


def test_the_check_sees_two_independent_solves():
    a = jnp.eye(4) * 2.0
    text = (
        jax.jit(lambda a, b, c: (jnp.linalg.solve(a, b), jnp.linalg.solve(a + 1.0, c)))
        .lower(a, jnp.ones(4), jnp.ones(4))
        .compile()
        .as_text()
    )
    calls, unordered = unordered_lapack_calls(text)
    assert calls == 6 and unordered == 9, (calls, unordered)


def test_spd_solve_small_equals_numpy_and_its_gradient_finite_differences(x64):
    rng = np.random.default_rng(1)
    for k in (1, 3, 5):
        m = rng.normal(size=(k, k))
        a = m @ m.T + 0.1 * np.eye(k)
        b = rng.normal(size=k)
        x = jax.jit(spd_solve_small)(jnp.asarray(a), jnp.asarray(b))
        np.testing.assert_allclose(np.asarray(x), np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
    f = lambda a, b: jnp.sum(jnp.sin(spd_solve_small(a @ a.T + 0.1 * jnp.eye(3), b)))  # noqa: E731
    # f under jit: eagerly, check_grads' op-by-op evaluations made 73 small compiles
    check_grads(jax.jit(f), (jnp.asarray(m[:3, :3]), jnp.asarray(b[:3])), order=1,
                modes=("rev",), eps=1e-6, atol=1e-6, rtol=1e-6)  # fmt: skip
    # singular: finite, no NaN
    assert np.all(np.isfinite(np.asarray(spd_solve_small(jnp.zeros((3, 3)), jnp.ones(3)))))
