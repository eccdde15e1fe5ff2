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


def test_cli_list_shows_reinhard_white_as_the_image_maximum(capsys):
    # the default-run sibling of the slow test_registry_defaults_are_the_operator_defaults:
    # `--list` once showed `white=4`, but the default (None) is the image maximum (what it
    # does: tests/test_defaults.py::test_reinhard_default_white_is_the_image_maximum)
    assert main(["tonemap", "--list"]) == 0
    lines = capsys.readouterr().out.splitlines()
    line = next(x for x in lines if x.split()[0] == "reinhard")
    assert line.split() == [
        "reinhard",
        "tonemap_Reinhard2002",
        "key=0.18,",
        "white=image-max,",
        "saturation=1",
    ]


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


# ----------------------------------------------------------------- issue 28 (tone mapping)


def test_nonfinite_input_is_one_error_naming_the_file_and_count(tmp_path):
    img = np.ones((6, 5, 3), np.float32)
    img[1, 2, 0] = np.inf
    img[4, 3, 1] = np.nan
    src = tmp_path / "in.exr"
    io.write_exr(src, img)
    out = tmp_path / "o.png"
    with pytest.raises(ValueError) as e:
        run_tonemap(TonemapJob(str(src), str(out)))
    msg = str(e.value)
    assert "in.exr" in msg and "2 of 30 pixels" in msg and "row 1, column 2" in msg
    assert not out.exists()


def test_negative_values_are_clamped_and_counted(tmp_path, capsys):
    img = synthetic_hdr(8, 8)
    img[0, :3, 1] = -0.5
    src = tmp_path / "in.exr"
    io.write_exr(src, img)
    res = run_tonemap(TonemapJob(str(src), str(tmp_path / "o.png"), "reinhard"))
    assert res["negative_clamped"] == 3
    got = io.read_image(tmp_path / "o.png", as_float=True)
    ref = np.asarray(tm.tonemap_Reinhard2002(np.maximum(img, 0)))
    assert np.abs(got - ref).max() <= 1 / 255 + 1e-6
    assert main(["tonemap", str(src), str(tmp_path / "p.png"), "--op", "reinhard"]) == 0
    assert "clamped 3 negative values to 0" in capsys.readouterr().out


def test_display_input_is_refused_as_input_not_as_output(tmp_path, capsys):
    (tmp_path / "t01.png").write_bytes(b"")
    code = main(["tonemap", str(tmp_path / "t01.png"), str(tmp_path / "out.png")])
    err = capsys.readouterr().err
    assert code == 1
    assert "error: input: cannot read" in err and "t01.png" in err and "cannot write" not in err


def test_tif_output_is_16_bit_srgb_code_values(tmp_path):
    import tifffile

    hdr = synthetic_hdr(8, 8)
    src = tmp_path / "in.exr"
    io.write_exr(src, hdr)
    run_tonemap(TonemapJob(str(src), str(tmp_path / "o.tif"), "drago"))
    t = tifffile.imread(tmp_path / "o.tif")
    assert t.dtype == np.uint16 and t.shape == (8, 8, 3)
    ref = np.round(np.asarray(tm.tonemap_Drago2003(hdr), np.float64) * 65535)
    assert np.abs(t - ref).max() <= 1


def test_reinhard_devlin_intensity_range_library_and_cli(tmp_path, capsys):
    img = np.ones((4, 4, 3), np.float32)
    with pytest.raises(ValueError, match=r"^intensity: .*>= -8.0 and <= 8.0, got 100"):
        tm.tonemap_Reinhard2005(img, intensity=100.0)
    assert np.isfinite(np.asarray(tm.tonemap_Reinhard2005(img, intensity=8.0))).all()
    src = tmp_path / "in.exr"
    io.write_exr(src, img)
    out = tmp_path / "o.png"
    argv = ["tonemap", str(src), str(out), "--op", "reinhard_devlin", "--intensity", "100"]
    assert main(argv) == 1
    assert "error: --intensity: expected a finite value >= -8.0" in capsys.readouterr().err
    assert not out.exists()


# 7.1 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
@pytest.mark.parametrize("method", sorted(tm.TONEMAP_PARAMETERS))
def test_registry_defaults_are_the_operator_defaults(method, capsys):
    import inspect

    from jaxgfx.pipelines.tonemap import operator_help

    sig = inspect.signature(tm.TONEMAP_METHODS[method]).parameters
    specs = tm.TONEMAP_PARAMETERS[method]
    for name, spec in specs.items():
        assert spec.default == sig[name].default, (method, name)
    # calling with the listed defaults spelled out gives the default image
    hdr = synthetic_hdr(8, 8)
    explicit = {n: s.default for n, s in specs.items() if s.default is not None}
    np.testing.assert_array_equal(
        np.asarray(tm.TONEMAP_METHODS[method](hdr, **explicit)),
        np.asarray(tm.TONEMAP_METHODS[method](hdr)),
    )
    line = next(x for x in operator_help() if x.split()[0] == method)
    for name, spec in specs.items():
        shown = "image-max" if spec.default is None else f"{spec.default:g}"
        assert f"{name}={shown}" in line


def test_cli_offers_reinhard_local_phi_and_epsilon(tmp_path):
    hdr = synthetic_hdr(16, 16)
    src = tmp_path / "in.exr"
    io.write_exr(src, hdr)
    out = tmp_path / "o.png"
    argv = ["tonemap", str(src), str(out), "--op", "reinhard_local", "--phi", "1"]
    assert main([*argv, "--epsilon", "0.2"]) == 0
    ref = np.asarray(tm.tonemap_Reinhard2002_local(hdr, phi=1.0, epsilon=0.2))
    assert np.abs(io.read_image(out, as_float=True) - ref).max() <= 1 / 255 + 1e-6
