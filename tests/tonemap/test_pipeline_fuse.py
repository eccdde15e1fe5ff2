"""The exposure-fusion job and CLI (jaxgfx fuse FRAMES... OUT): output equals the library's
fusion of the same frames, and bad input gives one error naming the argument or file."""

import numpy as np
import pytest

from jaxgfx import io
from jaxgfx.cli import FUSE_CLI_PARAMS, main
from jaxgfx.hdr import exposure_fusion
from jaxgfx.pipelines.fuse import FUSE_PARAMETERS, FuseJob, run_fuse
from tests.tonemap._refs import synthetic_hdr


def test_cli_parameter_list_matches_the_job():
    assert set(FUSE_CLI_PARAMS) == set(FUSE_PARAMETERS)


@pytest.fixture(scope="module")
def bracket(tmp_path_factory):
    d = tmp_path_factory.mktemp("bracket")
    hdr = synthetic_hdr(24, 32)
    frames = []
    for k, t in enumerate((0.02, 0.2, 2.0)):
        f = np.clip(hdr * t / np.median(hdr), 0, 1) ** (1 / 2.2)
        f8 = np.round(f * 255).astype(np.uint8)
        io.write_png(d / f"f{k}.png", f8)
        frames.append(f8)
    return d, np.stack(frames)


# 3.3 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_cli_fuse_writes_the_library_result(bracket, tmp_path, capsys):
    d, frames = bracket
    ref = np.asarray(exposure_fusion(frames, sigma=0.3))
    out = tmp_path / "fused.png"
    files = [str(d / f"f{k}.png") for k in range(3)]
    assert main(["fuse", *files, str(out), "--sigma", "0.3"]) == 0
    assert "3 frames" in capsys.readouterr().out
    got = io.read_image(out, as_float=True)
    assert np.abs(got - ref).max() <= 0.5 / 255 + 1e-6  # 8-bit PNG rounding only
    # a directory of the frames gives the same image; 16-bit TIFF keeps more precision
    tif = tmp_path / "fused.tif"
    assert main(["fuse", str(d), str(tif), "--sigma", "0.3"]) == 0
    got16 = io.read_image(tif, as_float=True)
    assert np.abs(got16 - ref).max() <= 0.5 / 65535 + 1e-6
    # an existing output is refused without --overwrite, replaced with it
    assert main(["fuse", str(d), str(out)]) == 1
    assert "exists" in capsys.readouterr().err
    assert main(["fuse", str(d), str(out), "--overwrite"]) == 0


def test_fuse_bad_input_names_the_argument(bracket, tmp_path, capsys):
    d, _ = bracket
    f0 = str(d / "f0.png")
    out = str(tmp_path / "o.png")
    with pytest.raises(ValueError, match="at least 2 frames"):
        run_fuse(FuseJob((f0,), out))
    with pytest.raises(ValueError, match="--sigma"):
        run_fuse(FuseJob((str(d),), out, {"sigma": 0.0}))
    with pytest.raises(ValueError, match="--contrast-weight"):
        run_fuse(FuseJob((str(d),), out, {"contrast_weight": -1.0}))
    with pytest.raises(ValueError, match="output"):
        run_fuse(FuseJob((str(d),), str(tmp_path / "o.exr")))
    with pytest.raises(FileNotFoundError):
        run_fuse(FuseJob((f0, str(tmp_path / "missing.png")), out))
    exr = tmp_path / "x.exr"
    io.write_exr(exr, np.ones((4, 4, 3), np.float32))
    with pytest.raises(ValueError, match="LDR"):
        run_fuse(FuseJob((f0, str(exr)), out))
    small = tmp_path / "small.png"
    io.write_png(small, np.zeros((4, 4, 3), np.uint8))
    with pytest.raises(ValueError, match="differ in size"):
        run_fuse(FuseJob((f0, str(small)), out))
    with pytest.raises(ValueError, match="also an input"):
        run_fuse(FuseJob((f0, str(d / "f1.png")), str(d / "f1.png"), overwrite=True))
    assert not (tmp_path / "o.png").exists()
    assert main(["fuse", f0]) == 2  # usage: no OUTPUT
    assert main(["fuse", f0, out]) == 1
    err = capsys.readouterr().err
    assert err.count("error:") == 2 and "jaxgfx fuse: error: inputs" in err
