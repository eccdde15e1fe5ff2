"""The ``jaxgfx`` command: filter ops on files against the library functions, clear errors."""

import numpy as np
import pytest

from jaxgfx import image, io
from jaxgfx.cli import main
from jaxgfx.pipelines.filter_ops import FILTER_OPS, apply_filter


@pytest.fixture
def png(tmp_path, rng):
    img = (rng.random((24, 20, 3)) * 255).astype(np.uint8)
    path = tmp_path / "in.png"
    io.write_png(str(path), img)
    return path, img.astype(np.float32) / 255.0


# issue 9: ~4 s of a loaded 2-core default run; the other CLI subcommands' tests stay in the
# default run
@pytest.mark.slow
def test_filter_gaussian_png_matches_library(png, tmp_path, capsys):
    src, img = png
    dst = tmp_path / "out" / "blur.exr"
    assert main(["filter", str(src), str(dst), "--op", "gaussian", "--sigma", "1.5"]) == 0
    out = io.read_exr(str(dst))
    np.testing.assert_allclose(out, np.asarray(image.gaussian_blur(img, 1.5)), atol=1e-6)
    assert "wrote" in capsys.readouterr().out


@pytest.mark.slow  # issue 9: ~7 s of a loaded 2-core run; out of make test
def test_filter_box_radius_and_canny(png, tmp_path):
    src, img = png
    dst = tmp_path / "box.exr"
    assert main(["filter", str(src), str(dst), "--op", "box", "--radius", "1"]) == 0
    np.testing.assert_allclose(io.read_exr(str(dst)), np.asarray(image.box_blur(img, 3)), atol=1e-6)
    edges = apply_filter(img, "canny", sigma=1.0, low=0.05, high=0.2)
    assert edges.dtype == np.float32 and set(np.unique(edges)) <= {0.0, 1.0}


def test_filter_list_and_errors(png, tmp_path, capsys):
    assert main(["filter", "--list"]) == 0
    listed = capsys.readouterr().out
    assert all(name in listed for name in FILTER_OPS)
    src, _ = png
    assert main(["filter", str(src), str(tmp_path / "o.png"), "--op", "blurr"]) == 1
    assert "op: expected one of" in capsys.readouterr().err
    assert main(["filter", str(src), str(tmp_path / "o.png"), "--op", "sobel", "--sigma", "2"]) == 1
    assert "--sigma" in capsys.readouterr().err
    assert main(["filter", str(tmp_path / "missing.png"), str(tmp_path / "o.png")]) == 1


def test_no_command_prints_help(capsys):
    assert main([]) == 2
    assert "calibrate" in capsys.readouterr().out
