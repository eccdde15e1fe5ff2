"""`make test` compiles with XLA:CPU's legacy emitters (`--xla_cpu_use_fusion_emitters=false`,
the Makefile's TEST_XLA_FLAGS; docs/testing.md "Third round"). That is only sound while both
code generators compute the same math: float32 elementwise functions of a given argument agree
bit for bit, and fused arithmetic around them within a few ulp (float32 rounding)."""

import jax
import jax.numpy as jnp
import jax.scipy.special as jss
import numpy as np

# function, argument made on the host from x
FUNCTIONS = {
    "sin": (jnp.sin, lambda x: x),
    "cos": (jnp.cos, lambda x: x),
    "exp": (jnp.exp, lambda x: x / 4),
    "log": (jnp.log, lambda x: jnp.abs(x) + 1e-3),
    "tanh": (jnp.tanh, lambda x: x),
    "sqrt": (jnp.sqrt, jnp.abs),
    "pow": (lambda a: a**2.4, lambda x: jnp.abs(x) / 10),
    "atan2": (lambda a: jnp.arctan2(a, 1.3 - a), lambda x: x),
    "expm1": (jnp.expm1, lambda x: x / 10),
    "log1p": (jnp.log1p, jnp.abs),
    "erf": (jss.erf, lambda x: x / 10),
    "acos": (jnp.arccos, lambda x: x / 51),
}


def _run(fn, x, fusion_emitters: bool):
    # compile options override XLA_FLAGS; that XLA honours this one is measured by
    # `python -m benchmarks.render_compile --variants default,no_fusion_emitters` (its compile
    # time drops by ~20 %), as the optimised HLO text is the same under both
    compiled = (
        jax.jit(fn)
        .lower(x)
        .compile(compiler_options={"xla_cpu_use_fusion_emitters": fusion_emitters})
    )
    return np.asarray(compiled(x))


def _x():
    rng = np.random.default_rng(0)
    return np.concatenate([rng.uniform(-50, 50, 20000), rng.uniform(-1, 1, 20000)]).astype(
        np.float32
    )


def test_elementwise_functions_are_bitwise_equal_under_both_emitters():
    x = _x()
    for name, (f, arg) in FUNCTIONS.items():  # each alone: 24 small programs
        a = jax.device_put(np.asarray(arg(x), np.float32))  # the argument, made outside
        on, off = (_run(f, a, e) for e in (True, False))
        differ = int(np.count_nonzero(on != off))
        assert differ == 0, f"{name}: {differ} of {x.size} values differ between the emitters"
    # and the values are the functions (not two equally wrong programs): sin against float64
    sin = _run(jnp.sin, jnp.asarray(x), False)
    np.testing.assert_allclose(sin, np.sin(x.astype(np.float64)), rtol=0, atol=1e-6)


def test_fused_programs_differ_by_float32_rounding_only():
    # all twelve in one program (fused with their arguments' arithmetic and the stack): erf
    # differs in ~280 of 40 000 values, by at most 3 ulp (2026-12-06); the bound is 8 ulp
    xj = jnp.asarray(_x())

    def all_functions(a):
        return jnp.stack([f(jnp.asarray(arg(a))) for f, arg in FUNCTIONS.values()])

    on, off = (_run(all_functions, xj, e) for e in (True, False))
    ulp = np.abs(on.astype(np.float64) - off) / np.spacing(np.maximum(np.abs(on), 1e-30))
    assert np.max(ulp) <= 8
