"""``jaxgfx.optim.compile_step``: the fit step compiled ahead (for shapes), then ``fit(...,
step=...)``; the same fit as ``fit`` compiling it itself."""

import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.optim import CompiledStep, compile_step, fit


def _loss(p, key, args):
    target, w = args
    noise = 0.01 * jax.random.normal(key, target.shape)
    return jnp.sum(w * (p["x"] + noise - target) ** 2) + (p["y"] - 0.25) ** 2


TARGET = np.array([0.5, -1.0, 2.0], np.float32)
ARGS = (TARGET, np.float32(1.5))
P0 = {"x": np.zeros(3, np.float32), "y": np.float32(0.8)}
BOUNDS = {"x": None, "y": (0.0, 1.0)}
KW = dict(steps=20, learning_rate=0.1, key=jax.random.key(4), bounds=BOUNDS, progress=False)


def test_precompiled_step_fits_exactly_as_fit():
    ref = fit(_loss, P0, args=ARGS, **KW)
    # compiled for the target's shape and dtype only, in another thread
    shapes = (jax.ShapeDtypeStruct(TARGET.shape, TARGET.dtype), np.float32(0.0))
    box = {}
    th = threading.Thread(target=lambda: box.update(step=compile_step(
        _loss, P0, key=KW["key"], bounds=BOUNDS, args=shapes)))
    th.start()
    th.join()
    step = box["step"]
    assert isinstance(step, CompiledStep) and step.compile_seconds > 0
    res = fit(_loss, P0, args=ARGS, step=step, **KW)
    np.testing.assert_array_equal(res.loss, ref.loss)
    for k in P0:
        np.testing.assert_array_equal(res.params[k], ref.params[k])
    assert res.compile_seconds == step.compile_seconds
    # the closed-form optimum (noise aside): x -> target, y -> 0.25; 20 steps of lr 0.1
    assert float(res.loss[-1]) < 0.05 * float(res.loss[0])


def test_precompiled_step_refuses_another_fit():
    step = compile_step(_loss, P0, key=KW["key"], bounds=BOUNDS, args=ARGS)
    with pytest.raises(ValueError, match="shapes or dtypes"):
        fit(_loss, P0, args=(np.zeros(4, np.float32), np.float32(1)), step=step, **KW)
    with pytest.raises(ValueError, match="another loss"):
        fit(lambda p, k, a: _loss(p, k, a), P0, args=ARGS, step=step, **KW)
    with pytest.raises(ValueError, match="another bounds"):
        fit(_loss, P0, args=ARGS, step=step, **{**KW, "bounds": None})
    with pytest.raises(ValueError, match="another compiler_options"):
        fit(_loss, P0, args=ARGS, step=step, compiler_options={"xla_cpu_enable_fast_math": False},
            **KW)
    with pytest.raises(TypeError, match="step: expected a CompiledStep"):
        fit(_loss, P0, args=ARGS, step=object(), **KW)


def test_compile_step_errors():
    with pytest.raises(ValueError, match="loss: expected a scalar"):
        compile_step(lambda p: p["x"], {"x": np.zeros(2, np.float32)})
    with pytest.raises(ValueError, match="first-order"):
        compile_step(_loss, P0, optimizer="lm")
