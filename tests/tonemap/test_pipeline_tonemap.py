"""The tonemap job and CLI (jaxgfx tonemap IN OUT --op ... / --list), calibrate --tonemap."""

import numpy as np
import pytest

from jaxgfx import io
from jaxgfx import tonemap as tm
from jaxgfx.cli import TONEMAP_CLI_PARAMS, main
from jaxgfx.pipelines.tonemap import TonemapJob, run_tonemap
from tests.tonemap._refs import synthetic_hdr


def test_cli_parameter_list_matches_registry():
    names = {n for spec in tm.TONEMAP_PARAMETERS.values() for n in spec}
    assert names == set(TONEMAP_CLI_PARAMS)


def test_cli_tonemap_writes_the_operator_output(tmp_path, capsys):
    hdr = synthetic_hdr(16, 16)
    src = tmp_path / "in.exr"
    io.write_exr(src, np.ascontiguousarray(hdr))
    out = tmp_path / "out.png"
    assert main(["tonemap", str(src), str(out), "--op", "drago", "--bias", "0.7"]) == 0
    got = io.read_image(out, as_float=True)
    ref = np.asarray(tm.tonemap_Drago2003(hdr, bias=0.7))
    assert np.abs(got - ref).max() <= 1 / 255 + 1e-6  # 8-bit PNG quantisation
    assert main(["tonemap", "--list"]) == 0
    assert "fattal" in capsys.readouterr().out


def test_job_rejects_bad_arguments(tmp_path):
    src = tmp_path / "in.exr"
    io.write_exr(src, np.ones((4, 4, 3), np.float32))
    with pytest.raises(ValueError, match="--key"):
        run_tonemap(TonemapJob(str(src), str(tmp_path / "o.png"), "drago", {"key": 0.2}))
    with pytest.raises(ValueError, match="op"):
        run_tonemap(TonemapJob(str(src), str(tmp_path / "o.png"), "nope"))
    with pytest.raises(ValueError, match="output"):
        run_tonemap(TonemapJob(str(src), str(tmp_path / "o.exr"), "drago"))
    with pytest.raises(FileNotFoundError):
        run_tonemap(TonemapJob(str(tmp_path / "missing.exr"), str(tmp_path / "o.png")))
    assert not (tmp_path / "o.png").exists()


def test_calibrate_config_checks_tonemap_names():
    from jaxgfx.config import load_config
    from jaxgfx.pipelines.calibrate import CalibrateConfig

    cfg = load_config(CalibrateConfig, {"tonemap": ["drago", "fattal"]})
    assert cfg.tonemap == ("drago", "fattal")
    with pytest.raises(ValueError, match=r"tonemap\[1\]"):
        load_config(CalibrateConfig, {"tonemap": ["drago", "nope"]})


@pytest.mark.slow
def test_calibrate_writes_one_png_per_operator(tmp_path):
    out = tmp_path / "cal"
    code = main(["calibrate", "--out", str(out), "--tonemap", "drago,reinhard_local", "--quiet"])
    assert code == 0
    radiance = io.read_exr(out / "radiance.exr")
    got = io.read_image(out / "tonemap_drago.png", as_float=True)
    ref = np.asarray(tm.tonemap_Drago2003(np.maximum(radiance, 0)))
    assert np.abs(got - ref).max() <= 1 / 255 + 1e-6
    assert (out / "tonemap_reinhard_local.png").exists()
