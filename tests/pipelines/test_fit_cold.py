"""The cold fit's compile path (jaxgfx/pipelines/fit/job.py): the synthetic target rendered
by the report's program (mean of renders at the report's spp) and ``result.json`` unchanged
in its fields.

The renderer is replaced here by a cheap stand-in with a closed-form estimator (the mean of
``spp`` uniform numbers per pixel and channel: expectation 1/2, variance 1/(12 spp)), so these
tests compile no render; the real renderer's case is the slow test at the end."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxgfx.render
from jaxgfx.pipelines.fit import job

from ._helpers import SCENE, fit_cfg

# result.json's fields on main before this change (a synthetic linear target, no camera fit)
RESULT_FIELDS = {
    "adjoint", "camera", "compile_seconds", "config", "errors", "history", "init", "loss",
    "n_steps", "n_targets", "params", "seconds", "seconds_history", "seconds_per_step",
    "stop_reason", "target_seconds", "truth",
}


@pytest.fixture
def fake_render(monkeypatch):
    """``jaxgfx.render.render`` replaced by the mean of ``spp`` uniforms per pixel and channel
    (the scene's size); returns the list of the ``spp`` of each call."""
    calls = []

    def render(scene, key, *, spp, integrator=None, max_depth=None):
        del integrator, max_depth
        calls.append(spp)
        h, w = (8, 8) if scene is None else (scene.height, scene.width)
        return _uniform_mean(key, spp, h, w)

    monkeypatch.setattr(jaxgfx.render, "render", render)
    return calls


def _uniform_mean(key, spp, h=8, w=8):
    """The stand-in render: mean of ``spp`` uniforms, numbers from NumPy seeded by ``key``."""
    rng = np.random.default_rng(np.asarray(jax.random.key_data(key)).ravel().tolist())
    return rng.random((spp, h, w, 3), dtype=np.float32).mean(0)


def _mean_z2(img, spp):
    """Mean over the pixels of z² of ``img`` against the stand-in's closed form (1/2, 1/12)."""
    return float(np.mean((np.asarray(img, np.float64) - 0.5) ** 2 / (1 / 12 / spp)))


# 8x8x3 = 192 values: mean z² is 1 ± 0.10 (χ²/192); ±5 standard deviations
Z2_LO, Z2_HI = 1 - 5 * np.sqrt(2 / 192), 1 + 5 * np.sqrt(2 / 192)


def test_target_render_is_four_renders_of_the_report_program(fake_render, monkeypatch):
    cfg = fit_cfg()  # render.spp 4: the report renders at 64 spp
    assert job.show_spp(cfg) == 64
    key = jax.random.key(3)
    img = job._render(cfg, None, key, 256)
    assert fake_render == [64, 64, 64, 64]  # one program (one spp), four keys
    assert img.shape == (8, 8, 3) and img.dtype == np.float32
    # the same estimator as one 256-spp call: mean 1/2, variance 1/(12 · 256) per pixel
    assert Z2_LO < _mean_z2(img, 256) < Z2_HI
    # exactly the mean of the four renders with the keys fold_in(key, i)
    parts = [_uniform_mean(jax.random.fold_in(key, i), 64) for i in range(4)]
    np.testing.assert_allclose(img, np.mean(parts, 0), rtol=1e-6, atol=0)
    # power: one key four times (a 64-spp image) fails the same check, variance 4x
    assert _mean_z2(parts[0], 256) > Z2_HI
    # the old route (JAXGFX_FIT_SHARED_RENDER=0): one call at 256 spp, same statistics
    monkeypatch.setenv("JAXGFX_FIT_SHARED_RENDER", "0")
    fake_render.clear()
    old = job._render(cfg, None, key, 256)
    assert fake_render == [256] and Z2_LO < _mean_z2(old, 256) < Z2_HI
    # and the two routes' images differ by no more than their Monte Carlo error
    z = (img.astype(np.float64) - old) / np.sqrt(2 / 12 / 256)
    assert float(np.mean(z**2)) < Z2_HI


@pytest.mark.parametrize(("spp", "calls"), [(64, [64]), (32, [32]), (100, [100])])
def test_other_spp_render_in_one_call(fake_render, spp, calls):
    """At the report's spp, below it or not a multiple of it: one call, as before."""
    job._render(fit_cfg(), None, jax.random.key(0), spp)
    assert fake_render == calls


def _toy_loss(p, key, args):
    """A cheap loss of the fit's signature: α to the target's mean / 3 (truth-free)."""
    del key
    _, target, _ = args
    a = p["scene"]["materials.metal.alpha"]
    return (a - jnp.mean(target) / 3.0) ** 2


def _run_cli(tmp_path, name, monkeypatch):
    from jaxgfx.cli import main
    from jaxgfx.pipelines.fit import report

    monkeypatch.setattr(job, "cached_loss", lambda *a, **k: _toy_loss)
    # curves.png: matplotlib's import and plot (~1 s CPU) are not what this test checks
    monkeypatch.setattr(report, "plot_curves", lambda path, *a: open(path, "wb").close())
    cfg = tmp_path / "fit.yaml"
    cfg.write_text(
        f"scene: {SCENE}\n"
        "target: {synthetic: {materials.metal.alpha: 0.15}, spp: 256, seed: 7}\n"
        "params: {materials.metal.alpha: {init: 0.5, min: 0.01, max: 1.0}}\n"
        "render: {spp: 4, width: 8, height: 8}\n"
        "optimizer: {steps: 3, lr: 0.05}\n"
    )
    out = tmp_path / name
    assert main(["fit", str(cfg), "--out", str(out), "--quiet"]) == 0
    with open(out / "result.json") as f:
        return json.load(f)


def test_cli_result_json_fields_and_one_render_program(tmp_path, fake_render, monkeypatch):
    """``jaxgfx fit`` writes the fields it wrote before; the 256-spp target (four calls) and
    the two previews are renders of one spp, so one compiled forward program."""
    res = _run_cli(tmp_path, "out", monkeypatch)
    assert set(res) == RESULT_FIELDS
    assert fake_render == [64] * 6  # target: 4 x 64 spp; previews before / after: 64 spp
    assert res["compile_seconds"] > 0 and res["n_steps"] == 3
    assert res["loss"][-1] < res["loss"][0]
    # the old route renders the target in one 256-spp call: two programs
    monkeypatch.setenv("JAXGFX_FIT_SHARED_RENDER", "0")
    fake_render.clear()
    _run_cli(tmp_path, "old", monkeypatch)
    assert fake_render == [256, 64, 64]


@pytest.mark.slow
def test_shared_target_render_matches_one_call_real_renderer():
    # slow: two compiles of the direct-light render of configs/scenes/inverse.yaml (8x8):
    # ~15 s CPU (14 s wall with a core to itself, 61 s at load 9.5)
    """The real renderer: the 256-spp target as 4 x 64 spp (the report's program) against one
    256-spp call, per 2x2 block, z from the four sub-renders' spread (a conservative bound:
    one call's stratified samples vary less)."""
    import os

    from jaxgfx.pipelines.fit import prepare_fit

    cfg = fit_cfg()
    scene = prepare_fit(cfg).scene
    key = jax.random.key(7)
    parts = [job._render(cfg, scene, jax.random.fold_in(key, i), 64) for i in range(4)]
    shared = job._render(cfg, scene, key, 256)
    np.testing.assert_allclose(shared, np.mean(parts, 0), rtol=1e-6, atol=1e-7)
    os.environ["JAXGFX_FIT_SHARED_RENDER"] = "0"
    try:
        old = job._render(cfg, scene, key, 256)
    finally:
        del os.environ["JAXGFX_FIT_SHARED_RENDER"]

    def blocks(x):
        return np.asarray(x, np.float64).reshape(*x.shape[:-3], 4, 2, 4, 2, 3).mean((-4, -2))

    b = np.stack([blocks(p) for p in parts])  # (4, 4, 4, 3)
    var = 2 * b.var(0, ddof=1) / 4 + (1e-4 * blocks(old)) ** 2
    z = np.abs(blocks(shared) - blocks(old)) / np.sqrt(var + 1e-12)
    assert z.max() < 6, z.max()
    ratio = blocks(shared).mean() / blocks(old).mean()
    assert abs(ratio - 1) < 0.03, ratio
    assert abs(1.1 * ratio - 1) > 0.03  # power: a 10 % bias would fail
