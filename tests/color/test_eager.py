"""An eager call of a public colour function validates its inputs in Python and then runs ONE
compiled program (its jitted core); a second call with new values but the same shapes (and a
new value of a continuous parameter) reuses that program: no tracing, no compilation."""

import logging

import colour
import jax
import jax.numpy as jnp
import numpy as np
from colour.difference import delta_E_CIE2000

import jaxgfx.color as jc
from jaxgfx.color import difference, spaces


def _compiled(caplog, fn, *args, **kwargs):
    """(result, names of the XLA programs compiled and messages of traces made by the call)."""
    caplog.clear()
    with jax.log_compiles(True), caplog.at_level(logging.WARNING, logger="jax"):
        out = jax.block_until_ready(fn(*args, **kwargs))
    msgs = caplog.messages
    compiled = [m.split(" of ")[1].split(" in ")[0] for m in msgs if "XLA compilation" in m]
    traced = [m for m in msgs if m.startswith("Finished tracing")]
    caplog.clear()
    return out, compiled, traced


def test_eager_call_is_one_program_and_does_not_recompile(caplog, rng):
    # JAX arrays in (jnp.asarray of a NumPy array is itself a small per-shape program)
    rgb1, rgb2 = (jnp.asarray(rng.uniform(0, 1, (5, 7, 3)), jnp.float32) for _ in range(2))
    lab = np.stack([rng.uniform(0, 100, (4, 6)), *rng.uniform(-80, 80, (2, 4, 6))], -1)
    labs = [jnp.asarray(lab + d, jnp.float32) for d in (0.0, rng.normal(0, 5, lab.shape))]
    labs += [jnp.asarray(lab[::-1] + d, jnp.float32) for d in (0.0, rng.normal(0, 5, lab.shape))]
    la1, la2, lb1, lb2 = labs

    spaces._rgb_to_hsv.clear_cache()
    difference._delta_e_2000.clear_cache()

    hsv1, compiled, _ = _compiled(caplog, jc.rgb_to_hsv, rgb1)
    assert compiled == ["jit(_rgb_to_hsv)"]
    hsv2, compiled, traced = _compiled(caplog, jc.rgb_to_hsv, rgb2)
    assert compiled == [] and traced == []
    assert spaces._rgb_to_hsv._cache_size() == 1

    de1, compiled, _ = _compiled(caplog, jc.delta_e_2000, la1, lb1)
    assert compiled == ["jit(_delta_e_2000)"]
    # new colours and kL = 2 (a traced parameter): the same program
    de2, compiled, traced = _compiled(caplog, jc.delta_e_2000, la2, lb2, kL=2.0)
    assert compiled == [] and traced == []
    assert difference._delta_e_2000._cache_size() == 1

    for rgb, hsv in ((rgb1, hsv1), (rgb2, hsv2)):
        ref = colour.RGB_to_HSV(np.asarray(rgb, np.float64))
        ref[..., 0] = np.where(ref[..., 0] == 1.0, 0.0, ref[..., 0])  # hue 1 == hue 0
        np.testing.assert_allclose(np.asarray(hsv), ref, atol=2e-6)
    # float32 CIEDE2000 against colour-science in float64 (textiles=True is kL = 2)
    ref1 = delta_E_CIE2000(np.asarray(la1, float), np.asarray(lb1, float))
    ref2 = delta_E_CIE2000(np.asarray(la2, float), np.asarray(lb2, float), textiles=True)
    np.testing.assert_allclose(np.asarray(de1), ref1, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(np.asarray(de2), ref2, rtol=1e-5, atol=1e-4)
