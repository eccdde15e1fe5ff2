"""The fit job (jaxgfx/pipelines/fit/): clear errors before rendering; end-to-end (slow)."""

import json

import numpy as np
import pytest

from jaxgfx.pipelines.fit import FitJob, apply_camera, prepare_fit, run_fit

from ._helpers import SCENE, fit_cfg


def test_prepare_accepts_a_valid_config():
    prep = prepare_fit(fit_cfg())
    assert prep.paths == ["materials.metal.alpha"]
    np.testing.assert_allclose(prep.init["materials.metal.alpha"], 0.5)
    assert prep.scene.width == 8 and not prep.ldr


@pytest.mark.parametrize(
    ("over", "match"),
    [
        ({"params": {"materials.gold.alpha": {"init": 0.2}}}, r"params\.materials\.gold\.alpha"),
        ({"params": {"materials.metal.roughness": {}}}, "unknown parameter path"),
        (
            {"params": {"materials.metal.alpha": {"init": 0.5, "min": 0.6, "max": 1.0}}},
            "exclude the init",
        ),
        (
            {"params": {"materials.clay.reflectance": {"init": [0.5, 0.5]}}},
            r"reflectance\.init: shape",
        ),
        ({"target": {"synthetic": {"materials.metal.alpah": 0.1}}}, "target.synthetic"),
        (
            {"camera": {"response": {"model": "gamma"}}},
            "only LDR targets",
        ),
        (
            {"target": {"synthetic": {}, "camera": {"response": "gamma"}}},
            "needs a camera section",
        ),
    ],
)
def test_bad_configs_fail_before_rendering(over, match):
    with pytest.raises(ValueError, match=match):
        prepare_fit(fit_cfg(**over))


def test_target_file_size_mismatch_and_missing(tmp_path):
    np.save(tmp_path / "t.npy", np.zeros((10, 12, 3), np.float32))
    with pytest.raises(ValueError, match="12x10.*differs.*8x8"):
        prepare_fit(fit_cfg(target=str(tmp_path / "t.npy")))
    with pytest.raises(FileNotFoundError, match="target"):
        prepare_fit(fit_cfg(target=str(tmp_path / "nope.exr")))


def test_config_field_errors():
    with pytest.raises(ValueError, match="camera.response.model"):
        fit_cfg(camera={"response": {"model": "cubic"}})
    with pytest.raises(ValueError, match="render.estimator"):
        fit_cfg(render={"estimator": "both"})
    with pytest.raises(ValueError, match="unknown config key"):
        fit_cfg(optimiser={"steps": 3})


def test_apply_camera_matches_closed_forms():
    x = np.array([0.0, 0.01, 0.25, 1.0, 2.0])
    np.testing.assert_allclose(
        np.asarray(apply_camera(x, 2.0, 2.0, model="gamma")), np.sqrt(2.0 * x), rtol=1e-6
    )
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.abs(x) ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(
        np.asarray(apply_camera(x, 1.0, 0.0, model="srgb"))[:4], srgb[:4], rtol=1e-5, atol=1e-7
    )


@pytest.mark.slow
def test_run_fit_end_to_end(tmp_path):
    out = run_fit(FitJob(fit_cfg(optimizer={"steps": 4}), str(tmp_path)))
    for name in ("result.json", "curves.png", "before.png", "after.png", "target.png"):
        assert (tmp_path / name).exists(), name
    with open(tmp_path / "result.json") as f:
        res = json.load(f)
    assert len(res["loss"]) == 4 and res["n_steps"] == 4
    assert isinstance(res["params"]["materials.metal.alpha"], float)
    assert res["truth"]["materials.metal.alpha"] == pytest.approx(0.15)
    assert out["errors"]["materials.metal.alpha"] >= 0


def test_cli_fit_reports_config_errors_before_rendering(tmp_path, capsys):
    from jaxgfx.cli import main

    cfg = tmp_path / "bad.yaml"
    cfg.write_text(
        f"scene: {SCENE}\n"
        "target: {synthetic: {materials.metal.alpha: 0.2}}\n"
        "params: {materials.gold.alpha: {init: 0.5}}\n"
    )
    out = tmp_path / "out"
    assert main(["fit", str(cfg), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "jaxgfx fit: error: params.materials.gold.alpha: unknown parameter path" in err
    assert not out.exists()


def test_pipeline_holds_no_parser():
    import inspect

    import jaxgfx.pipelines.fit as fit_mod

    assert "argparse" not in inspect.getsource(fit_mod)


def test_render_adjoint_option_reaches_the_integrator():
    """``render: {adjoint: replay}`` selects path replay for the fit's renders; a bad value or
    an integrator without an adjoint option is refused before rendering."""
    cfg = fit_cfg(render={"spp": 4, "width": 8, "height": 8, "integrator": "path",
                          "adjoint": "replay"})  # fmt: skip
    assert cfg.render.integrator_spec == {"type": "path", "adjoint": "replay"}
    assert fit_cfg().render.integrator_spec == "direct"
    with pytest.raises(ValueError, match="render.adjoint"):
        fit_cfg(render={"adjoint": "backprop"})
    with pytest.raises(ValueError, match="render.adjoint.*path or direct"):
        fit_cfg(render={"integrator": "aov", "adjoint": "replay"})
