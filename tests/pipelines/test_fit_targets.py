"""Fit targets given as files — the path real users take (a photo is always a file): every
photo format is read, checked and fitted; bad targets fail before anything compiles."""

import os

import numpy as np
import pytest
from PIL import Image

from jaxgfx.config import load_config
from jaxgfx.io import write_exr, write_png
from jaxgfx.pipelines.fit import FitConfig, FitJob, prepare_fit, run_fit

from ._helpers import SCENE, fit_cfg

N = 8
# the shared small fit from a photo file: its gamma curve and exposure fitted, 2 steps
PHOTO_FIT = {
    "render": {"spp": 4, "width": N, "height": N},
    "optimizer": {"steps": 2},
    "camera": {"response": {"model": "gamma", "fit": True}, "exposure": {"fit": True}},
}


def _cfg(target, **over):
    return fit_cfg(PHOTO_FIT, target=str(target), **over)


def _codes(bits=8, channels=3, seed=0):
    rng = np.random.default_rng(seed)
    hi = 2**bits - 1
    a = rng.integers(1, hi, size=(N, N, channels))
    return a.astype(np.uint16 if bits == 16 else np.uint8)


def _photo(tmp_path, kind):
    """(path, expected codes (H, W, C) float, bits, grey, has mask) of a photo file."""
    if kind == "png8":
        a = _codes()
        p = tmp_path / "t.png"
        write_png(p, a)
        return p, a, 8, False, False
    if kind == "png16":
        a = _codes(16)
        p = tmp_path / "t16.png"
        write_png(p, a, bits=16)
        return p, a, 16, False, False
    if kind == "grey":
        a = _codes(channels=1)[..., 0]
        p = tmp_path / "g.png"
        Image.fromarray(a, mode="L").save(p)
        return p, a[..., None], 8, True, False
    if kind == "rgba":
        a = _codes(channels=4)
        a[..., 3] = 255
        a[:2, :, 3] = 0  # two masked rows
        p = tmp_path / "t.png"
        Image.fromarray(a, mode="RGBA").save(p)
        return p, a[..., :3], 8, False, True
    if kind == "jpeg":
        p = tmp_path / "t.jpg"
        Image.fromarray(_codes()).save(p, quality=95)
        return p, np.asarray(Image.open(p)), 8, False, False
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["png8", "png16", "grey", "rgba", "jpeg"])
def test_photo_targets_are_read_with_their_depth_channels_and_mask(tmp_path, kind):
    path, codes, bits, grey, masked = _photo(tmp_path, kind)
    over = {"camera": {"bits": bits, "response": {"model": "gamma", "fit": True}}}
    prep = prepare_fit(_cfg(path, **over))
    t = prep.target
    assert prep.ldr and t.bits == bits and t.grey == grey and (t.mask is not None) == masked
    np.testing.assert_array_equal(t.pixels, codes.astype(np.float32))
    if masked:
        assert t.mask.shape == (N, N, 1) and t.mask[:2].sum() == 0 and t.mask[2:].min() == 1


def test_photo_bit_depth_must_match_the_camera(tmp_path):
    path, *_ = _photo(tmp_path, "png16")
    with pytest.raises(ValueError, match=r"camera.bits: the target .*t16.png is a 16-bit photo"):
        prepare_fit(_cfg(path))  # camera.bits defaults to 8


@pytest.mark.parametrize("level", [0, 255])
def test_photo_without_information_is_refused(tmp_path, level):
    p = tmp_path / "flat.png"
    write_png(p, np.full((N, N, 3), level, np.uint8))
    with pytest.raises(ValueError, match=r"target: .*flat.png: every pixel is"):
        prepare_fit(_cfg(p))


def test_radiance_targets_are_checked_before_compiling(tmp_path):
    cfg = {"camera": None}
    img = np.full((N, N, 3), 0.2, np.float32)
    img[1, 2, 0] = np.inf
    img[3, 3, :] = np.nan
    write_exr(tmp_path / "bad.exr", img)
    with pytest.raises(ValueError, match=r"target: .*bad.exr: 2 pixel\(s\) are NaN or infinite"):
        prepare_fit(_cfg(tmp_path / "bad.exr", **cfg))
    np.save(tmp_path / "grey.npy", np.full((N, N), 0.3, np.float32))
    prep = prepare_fit(_cfg(tmp_path / "grey.npy", **cfg))
    assert prep.target.grey and prep.target.pixels.shape == (N, N, 1)
    trunc = tmp_path / "trunc.png"
    write_png(trunc, _codes())
    trunc.write_bytes(trunc.read_bytes()[:-20])
    with pytest.raises(ValueError, match=r"trunc.png"):
        prepare_fit(_cfg(trunc))


def test_relative_paths_resolve_against_the_config_folder(tmp_path, monkeypatch):
    write_png(tmp_path / "photo.png", _codes())
    (tmp_path / "scenes").mkdir()
    with open(SCENE, "rb") as f:
        (tmp_path / "scenes" / "s.yaml").write_bytes(f.read())
    cfg = tmp_path / "fit.yaml"
    cfg.write_text(
        "scene: scenes/s.yaml\ntarget: photo.png\n"
        "params: {materials.metal.alpha: {init: 0.5, min: 0.01, max: 1.0}}\n"
        f"render: {{spp: 4, width: {N}, height: {N}}}\ncamera: {{response: {{model: srgb}}}}\n"
    )
    monkeypatch.chdir(tmp_path.parent)  # anywhere but the config's folder
    prep = prepare_fit(load_config(FitConfig, cfg), base_dir=str(tmp_path))
    assert prep.target.path == str(tmp_path / "photo.png")
    with pytest.raises(FileNotFoundError, match=r"scene: file not found: nope.yaml \(looked in"):
        prepare_fit(_cfg(tmp_path / "photo.png", scene="nope.yaml"), base_dir=str(tmp_path))


_FRESH_TRACE = r"""
import sys
import jax, numpy as np
from jaxgfx.config import load_config
from jaxgfx.pipelines.fit import FitConfig, make_loss, prepare_fit
from jaxgfx.pipelines.fit.job import _initial
cfg = load_config(FitConfig, {
    "scene": sys.argv[1], "target": sys.argv[2], "progress": False,
    "params": {"materials.metal.alpha": {"init": 0.5, "min": 0.01, "max": 1.0}},
    "render": {"spp": 4, "width": 8, "height": 8},
    "camera": {"response": {"model": "gamma", "fit": True}, "exposure": {"fit": True}}})
prep = prepare_fit(cfg)
loss = make_loss(cfg, prep.paths, prep.ldr)
params, _, cam = _initial(cfg, prep)
args = (prep.scene, jax.numpy.asarray(prep.target.pixels), cam)
out = jax.eval_shape(jax.value_and_grad(loss), params, jax.random.key(0), args)
print("traced", out[0].shape, sorted(out[1]["camera"]))
"""


# cost: 20-70 s (a fresh interpreter importing and tracing the fit step); the default run keeps
# tests/test_imports.py::test_every_module_imports_inside_a_trace, the general guard
@pytest.mark.slow
def test_fit_step_of_a_photo_target_traces_in_a_fresh_interpreter(tmp_path):
    """The crash of the documented `target: photo.png` path: tracing the fit step raised
    ConcretizationTypeError because `jaxgfx.hdr` was first imported *inside* the trace (an
    array op at its import time). Only a fresh interpreter shows it (the test session has long
    imported `jaxgfx.hdr`); the whole fit of each photo format runs in the slow tests below."""
    import subprocess
    import sys

    path, *_ = _photo(tmp_path, "png8")
    r = subprocess.run(
        [sys.executable, "-c", _FRESH_TRACE, SCENE, str(path)],
        capture_output=True, text=True, timeout=300,
        env={**os.environ, "JAX_PLATFORMS": "cpu"},
    )
    assert r.returncode == 0, r.stderr[-2000:]
    assert "traced () ['curve', 'exposure', 'gamma', 'photo_exposure', 'white_balance']" in (
        r.stdout
    )


# cost: ~20 s quiet, 120 s at load 8 on 2 cores (one compiled fit step shared by both files)
@pytest.mark.slow
def test_fit_of_an_8bit_png_and_a_jpeg_photo_runs_end_to_end(tmp_path):
    for kind in ("png8", "jpeg"):
        path, *_ = _photo(tmp_path, kind)
        out = run_fit(FitJob(_cfg(path), str(tmp_path / f"out_{kind}")))
        assert out["n_steps"] == 2 and np.all(np.isfinite(out["loss"]))
        assert set(out["camera"]["fitted"]) == {"exposure", "gamma"}
        assert (tmp_path / f"out_{kind}" / "after.png").exists()


# cost: ~25 s on 2 cores (three more compiled fit steps: 16-bit codes, grey luminance, mask)
@pytest.mark.slow
@pytest.mark.parametrize("kind", ["png16", "grey", "rgba"])
def test_fit_of_16bit_grey_and_rgba_photos_runs_end_to_end(tmp_path, kind):
    path, _, bits, _, _ = _photo(tmp_path, kind)
    over = {"camera": {"bits": bits, "response": {"model": "gamma", "fit": True}}}
    out = run_fit(FitJob(_cfg(path, **over), None))
    assert out["n_steps"] == 2 and np.all(np.isfinite(out["loss"]))


# 3.1 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_masked_pixels_do_not_change_the_loss():
    """The alpha mask is honoured by the censored linear loss: codes under alpha 0 do not
    change it, a visible code does; with an all-ones mask it equals the unmasked loss."""
    import jax.numpy as jnp

    from jaxgfx.hdr import CameraResponse
    from jaxgfx.pipelines.fit import level_table
    from jaxgfx.pipelines.fit.loss import censored_linear_loss

    rng = np.random.default_rng(1)
    img = jnp.asarray(rng.uniform(0.0, 1.2, (N, N, 3)), jnp.float32)
    codes = np.asarray(rng.integers(0, 256, (N, N, 3)), np.float32)
    mask = np.ones((N, N, 1), np.float32)
    mask[:2] = 0.0
    table = level_table(CameraResponse.gamma(2.2, anchor="unit"), 8)

    def value(c, m):
        return float(censored_linear_loss(img, jnp.asarray(c), table, 1.3, 255.0, m))

    v0 = value(codes, mask)
    hidden, visible = codes.copy(), codes.copy()
    hidden[:2] = 7.0
    visible[5, 5] = 7.0 if codes[5, 5, 0] != 7.0 else 9.0
    assert value(hidden, mask) == v0
    assert abs(value(visible, mask) - v0) > 1e-4 * v0
    assert value(codes, np.ones_like(mask)) == pytest.approx(value(codes, None), rel=1e-6)


def test_a_parameter_driven_out_of_its_domain_is_named_before_any_preview():
    """lr 1000 without bounds drove α to -5302 and only the final preview failed, discarding
    the run: the fitted values are checked first and the message names the parameter, its
    value and the cure."""
    from jaxgfx.pipelines.fit.job import _check_fitted

    cfg = load_config(
        FitConfig,
        {
            "scene": SCENE,
            "target": {"synthetic": {}},
            "params": {"materials.metal.alpha": {"init": 0.5}},
            "optimizer": {"lr": 1000.0},
        },
    )
    prep = prepare_fit(cfg)
    _check_fitted(prep, {"materials.metal.alpha": np.float32(0.3)}, cfg)  # valid: no error
    with pytest.raises(ValueError, match=r"params.materials.metal.alpha: the fit drove it to "
                       r"-5302.0, outside its valid range .*bounds.*optimizer.lr \(1000.0\)"):
        _check_fitted(prep, {"materials.metal.alpha": np.float32(-5302.0)}, cfg)
    with pytest.raises(FloatingPointError, match="non-finite"):
        _check_fitted(prep, {"materials.metal.alpha": np.float32(np.nan)}, cfg)


@pytest.mark.parametrize(
    ("over", "match"),
    [
        ({"loss": {"kind": "l3"}}, r"loss.kind: expected one of \('l2'"),
        ({"loss": {"space": "xyz"}}, r"loss.space: expected one of"),
        ({"render": {"width": 0}}, r"render.width: expected a positive integer, got 0"),
        ({"render": {"integrator": "bdpt"}}, r"render.integrator: expected one of"),
        ({"target": {"synthetic": {}, "spp": 0}}, r"target.spp: expected a positive integer"),
        ({"optimizer": {"name": "lm"}}, r"optimizer.name: expected one of \('adam'"),
        ({"optimizer": {"lr": 0.01, "lr_final": 0.1}}, r"optimizer.lr_final: expected 0 < "),
        ({"optimizer": {"fast_compile": "yes"}}, r"optimizer.fast_compile: expected true/false"),
        ({"params": {"materials.metal.alpha": {"init": "x"}}}, r"params.materials.metal.alpha"
         r".init: 'x'"),
        ({"seed": 1.5}, r"seed: expected an integer"),
    ],
)
def test_config_errors_carry_their_section(over, match):
    base = {"scene": SCENE, "target": {"synthetic": {}},
            "params": {"materials.metal.alpha": {"init": 0.5}}}  # fmt: skip
    base.update(over)
    with pytest.raises(ValueError, match=match):
        prepare_fit(load_config(FitConfig, base))


def test_configs_built_in_python_are_validated_too():
    from jaxgfx.pipelines.fit import OptimizerConfig

    with pytest.raises(ValueError, match="optimizer.lr_final"):
        OptimizerConfig(lr=0.01, lr_final=0.1)


def test_fast_compile_selects_the_fast_compile_options():
    from jaxgfx.optim import FAST_COMPILE_OPTIONS
    from jaxgfx.pipelines.fit import OptimizerConfig

    with pytest.raises(ValueError, match="optimizer.fast_compile: expected true/false"):
        OptimizerConfig(fast_compile=1)
    assert OptimizerConfig().compiler_options() is None
    opts = OptimizerConfig(fast_compile=True).compiler_options()
    assert opts == FAST_COMPILE_OPTIONS and opts["xla_cpu_use_fusion_emitters"] is False
