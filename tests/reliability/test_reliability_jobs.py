"""Defects found by issue 12's probe, in the jobs' outputs and the CLI runner
(jaxgfx.pipelines, jaxgfx.cli):
one test each (every one failed before its fix), grouped by the code they exercise (the
D-numbers are the probe's).

References: scikit-image (``canny``, ``equalize_hist``), SciPy (``gaussian_laplace``), the
closed-form derivative of the LoG kernel at a vanishing sigma, the project's own readers for
files written by the CLI (format by content, not by name).
"""

from __future__ import annotations

import json
import os

import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx import hdr, io
from jaxgfx.pipelines import calibrate as calibrate_mod
from jaxgfx.pipelines.calibrate import ldr as calibrate_ldr
from jaxgfx.pipelines.calibrate import plots as calibrate_plots

from ._util import assert_one_line_error, no_partial_files, read_only_sys, run_cli, snapshot

READ_ONLY = "/sys/jaxgfx-reliability"  # sysfs: not writable, even by root


def _read_only_available() -> bool:
    return read_only_sys()


# --------------------------------------------------------------- D7 render output formats


@pytest.fixture
def fake_render(monkeypatch):
    """Replace the renderer by a known HDR image (values up to 4): these tests are about what
    the job writes, not about rendering."""
    import jaxgfx.render

    calls = []
    img = np.linspace(0.0, 4.0, 6 * 8 * 3, dtype=np.float32).reshape(6, 8, 3)

    def render(scene, key, **kw):
        calls.append(kw)
        return jnp.asarray(img)

    monkeypatch.setattr(jaxgfx.render, "render", render)
    return img, calls


def test_d07_hdr_output_is_radiance_rgbe(files, tmp_path, fake_render):
    img, _ = fake_render
    code, out, err = run_cli(["render", files["scene"], tmp_path / "out.hdr"])
    assert code == 0, err
    back = io.read_hdr(str(tmp_path / "out.hdr"))  # would fail on EXR bytes
    np.testing.assert_allclose(back, img, rtol=2e-2, atol=2e-2)  # RGBE: 8-bit mantissa
    assert sorted(os.listdir(tmp_path)) == ["out.hdr", "out.png"]


def test_d07_png_output_never_collides(files, tmp_path, fake_render):
    from jaxgfx.color import linear_to_srgb

    img, _ = fake_render
    code, out, err = run_cli(["render", files["scene"], tmp_path / "out.png"])
    assert code == 0, err
    assert sorted(os.listdir(tmp_path)) == ["out.png"]
    assert out.count("out.png") == 1
    want = np.round(np.asarray(linear_to_srgb(np.clip(img, 0, 1))) * 255)
    np.testing.assert_array_equal(io.read_image(str(tmp_path / "out.png")), want)


def test_d07_preview_equal_to_output_is_refused_before_rendering(files, tmp_path, fake_render):
    _, calls = fake_render
    out = tmp_path / "x.png"
    code, _, err = run_cli(["render", files["scene"], out, "--preview", out])
    assert_one_line_error(code, err, "same file")
    assert calls == [] and os.listdir(tmp_path) == []


# --------------------------------------------------------------- D8 failed runs leave nothing


SMALL = "synthetic: {height: 16, width: 16}\nresponse: {method: debevec, compare: []}\n"


@pytest.fixture
def small_config(tmp_path, monkeypatch):
    """A config, and the job's computation replaced by a fixed result: D8/D9 test what
    ``run_calibrate`` does with its outputs (the science is tested in
    tests/pipelines/test_calibrate.py); writing, the plot and the report stay real."""
    p = tmp_path / "small.yaml"
    p.write_text(SMALL)
    rad = np.linspace(0.01, 2.0, 16 * 16 * 3, dtype=np.float32).reshape(16, 16, 3)
    resp = hdr.CameraResponse.gamma(2.2)

    def load(cfg, files, sidecar, steps, result_kw):
        result_kw.update(times=np.array([1.0, 4.0]), image_shape=(2, 16, 16, 3))
        return None, None, None

    def fit(cfg, images, times, truth, steps, result_kw):
        return calibrate_mod.CalibrateResult(
            radiance=rad, variance=0.01 * rad, response=resp, curves={"debevec": resp},
            **result_kw,
        )  # fmt: skip

    monkeypatch.setattr(calibrate_ldr, "_load_ldr", load)
    monkeypatch.setattr(calibrate_ldr, "_fit_ldr", fit)
    return p


def _fail_late(monkeypatch):
    """Make the last step (the response plot) fail, after the images were written."""

    def boom(*a, **k):
        raise OSError(28, "No space left on device", "response.png")

    monkeypatch.setattr(calibrate_plots, "_plot_response", boom)


def test_d08_failed_calibrate_creates_no_out(tmp_path, small_config, monkeypatch):
    _fail_late(monkeypatch)
    out = tmp_path / "new" / "out"
    code, _, err = run_cli(["calibrate", "--config", small_config, "--out", out, "--quiet"])
    assert_one_line_error(code, err, "No space left on device", "response.png")
    assert not (tmp_path / "new").exists()  # not even the parent the job would have created
    assert no_partial_files(tmp_path)


def test_d08_failed_calibrate_leaves_previous_run_untouched(tmp_path, small_config, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    for name in ("report.json", "preview.png", "response.png"):
        (out / name).write_text(f"previous run: {name}")
    before = snapshot(tmp_path)
    _fail_late(monkeypatch)
    argv = ["calibrate", "--config", small_config, "--out", out, "--quiet", "--overwrite"]
    code, _, err = run_cli(argv)
    assert code == 1
    assert snapshot(tmp_path) == before


# --------------------------------------------------------------- D9 rerun into a full --out


def test_d09_rerun_refused_without_overwrite_then_replaced(tmp_path, small_config):
    out = tmp_path / "out"
    argv = ["calibrate", "--config", small_config, "--out", out, "--quiet"]
    code, _, err = run_cli(argv)
    assert code == 0, err
    first = snapshot(tmp_path)
    code, _, err = run_cli(argv)
    assert_one_line_error(code, err, "holds the results of a previous run", "--overwrite")
    assert snapshot(tmp_path) == first
    (out / "radiance.exr").write_bytes(b"stale")
    code, stdout, err = run_cli([*argv, "--overwrite"])
    assert code == 0, err
    assert "replaced the previous results" in stdout
    np.testing.assert_array_equal(
        io.read_exr(str(out / "radiance.exr")),
        np.linspace(0.01, 2.0, 16 * 16 * 3, dtype=np.float32).reshape(16, 16, 3),
    )
    rep = json.loads((out / "report.json").read_text())
    assert set(os.listdir(out)) == {os.path.basename(p) for p in rep["outputs"].values()}


def test_d09_overwrite_removes_stale_outputs_of_the_previous_run(tmp_path):
    from jaxgfx.pipelines._output import StagedDir

    out = tmp_path / "out"
    out.mkdir()
    (out / "response.png").write_text("from an older LDR run")
    (out / "notes.txt").write_text("the user's file")  # not ours: kept
    with StagedDir(out, calibrate_mod.OUTPUT_NAMES, overwrite=True) as st:
        (open(os.path.join(st.path, "radiance.exr"), "w")).close()
    assert sorted(os.listdir(out)) == ["notes.txt", "radiance.exr"]
    assert st.replaced == ["response.png"]


# --------------------------------------------------------------- D10 outputs checked first


def test_d10_render_checks_output_before_rendering(files, tmp_path, fake_render):
    _, calls = fake_render
    for target, needle in [
        (tmp_path / "out.bmp", "unsupported extension '.bmp'"),
        (files["a_file"] / "out.exr", "a_file"),
        (tmp_path / "out.hdr", None),  # fine, rendered below
    ]:
        code, _, err = run_cli(["render", files["scene"], target])
        if needle is None:
            assert code == 0, err
            assert len(calls) == 1
        else:
            assert_one_line_error(code, err, needle)
            assert calls == []


def test_d10_filter_checks_extension_before_creating_folders(files, tmp_path):
    code, _, err = run_cli(["filter", files["png"], tmp_path / "new" / "sub" / "x.bmp"])
    assert_one_line_error(code, err, "x.bmp", "unsupported extension")
    assert os.listdir(tmp_path) == []


# --------------------------------------------------------------- D11 no raw tracebacks


def test_d11_os_errors_are_one_line(files, tmp_path):
    cases = [
        (["calibrate", "--out", files["a_file"]], "a_file"),  # NotADirectoryError
        (["filter", files["png"], files["a_file"] / "x.png"], "a_file"),
        (["filter", files["png"], files["dir_png"]], "folder.png"),  # IsADirectoryError
        (["calibrate", "--times", "1/0,1,4"], "--times [0]"),  # was ZeroDivisionError
        (["filter", files["dir_png"], tmp_path / "o.png"], "folder.png"),
    ]
    if _read_only_available():
        cases.append((["filter", files["png"], f"{READ_ONLY}/x.png"], READ_ONLY))
        cases.append((["calibrate", "--out", f"{READ_ONLY}/out"], READ_ONLY))
    for argv, needle in cases:
        code, _, err = run_cli(argv)
        assert_one_line_error(code, err, needle)
    assert os.listdir(tmp_path) == []


def test_d11_debug_shows_the_traceback(files):
    code, _, err = run_cli(["filter", files["png"], files["dir_png"], "--debug"])
    assert code == 1 and "Traceback (most recent call last)" in err
    code, _, err = run_cli(["--debug", "calibrate", "--times", "1/0"])
    assert code == 1 and "Traceback (most recent call last)" in err


def test_d11_unexpected_errors_are_one_line_too(files, tmp_path, monkeypatch):
    import jaxgfx.pipelines.filter_ops as fo

    def broken(*a, **k):
        raise KeyError("internal")

    monkeypatch.setattr(fo, "run_filter", broken)
    code, _, err = run_cli(["filter", files["png"], tmp_path / "o.png"])
    assert_one_line_error(code, err, "KeyError", "--debug")


# --------------------------------------------------------------- D12 writers fail alike


@pytest.mark.parametrize("ext", [".png", ".hdr", ".exr", ".tif"])
def test_d12_writers_raise_the_same_os_errors(ext, files, tmp_path):
    img = np.zeros((2, 2, 3), np.float32)
    writers = {".png": io.write_png, ".hdr": io.write_hdr, ".exr": io.write_exr}
    fns = [io.write_any] + ([writers[ext]] if ext in writers else [])
    for fn in fns:
        target = tmp_path / f"folder{ext}"
        target.mkdir(exist_ok=True)
        with pytest.raises(IsADirectoryError, match=f"folder{ext}"):
            fn(str(target), img)
        with pytest.raises(NotADirectoryError, match="a_file"):
            fn(str(files["a_file"] / f"x{ext}"), img)
        if _read_only_available():
            with pytest.raises(PermissionError, match=READ_ONLY):
                fn(f"{READ_ONLY}{ext}", img)


# --------------------------------------------------------------- D13 messages that mislead


def test_d13_box_radius_names_the_option(files, tmp_path):
    code, _, err = run_cli(
        ["filter", files["png"], tmp_path / "o.png", "--op", "box", "--radius", "-3"]
    )
    assert_one_line_error(code, err, "--radius: expected an integer >= 0, got -3")
    assert "size" not in err
