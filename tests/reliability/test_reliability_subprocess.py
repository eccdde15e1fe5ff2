"""A handful of true subprocess runs of ``python -m jaxgfx.cli`` (the entry point users have):
exit status, one stderr line, no traceback, nothing written — and one good run checked against
the library. The processes run concurrently (each pays a JAX import)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from jaxgfx import image, io

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _start(args, cwd=ROOT):
    env = {**os.environ, "PYTHONPATH": ROOT, "JAX_PLATFORMS": "cpu"}
    return subprocess.Popen(
        [sys.executable, *args], cwd=cwd, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip


@pytest.mark.slow  # issue 9: ~9 s of a loaded 2-core run; out of make test
def test_cli_subprocesses(files, tmp_path):
    cli = ["-m", "jaxgfx.cli"]
    runs = {
        "times": [*cli, "calibrate", "--times", "1/0,1,4", "--out", str(tmp_path / "c")],
        "bmp": [*cli, "render", str(files["scene"]), str(tmp_path / "r.bmp")],
        "debug": [*cli, "--debug", "filter", str(files["png"]), str(files["dir_png"])],
        "experiment": ["-m", "experiments.calibrate", "--times", "0,1", "--out", str(tmp_path)],
        "good": [*cli, "filter", str(files["png"]), str(tmp_path / "box.exr"), "--op", "box"]
        + ["--radius", "1"],
    }
    procs = {k: _start(a) for k, a in runs.items()}
    res = {k: (p.wait(timeout=300), *p.communicate()) for k, p in procs.items()}

    for k, needle in [("times", "--times [0]"), ("bmp", "'.bmp'"), ("experiment", "--times [0]")]:
        code, out, err = res[k]
        lines = err.strip().splitlines()
        assert code == 1 and len(lines) == 1 and needle in lines[0], (k, code, err)
        assert lines[0].startswith("jaxgfx ") and "Traceback" not in err
    code, out, err = res["debug"]
    assert code == 1 and "Traceback (most recent call last)" in err
    assert err.strip().splitlines()[-1].startswith("jaxgfx filter: error: ")
    assert sorted(os.listdir(tmp_path)) == ["box.exr"]  # the failures wrote nothing

    code, out, err = res["good"]
    assert code == 0, err
    img = io.read_image(str(files["png"]), as_float=True)
    want = np.asarray(image.box_blur(img, 3))
    np.testing.assert_allclose(io.read_exr(str(tmp_path / "box.exr")), want, atol=1e-6)
