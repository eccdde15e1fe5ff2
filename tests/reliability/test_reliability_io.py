"""Defects found by issue 12's probe, in readers and writers (jaxgfx.io) and scene files:
one test each (every one failed before its fix), grouped by the code they exercise (the
D-numbers are the probe's).

References: scikit-image (``canny``, ``equalize_hist``), SciPy (``gaussian_laplace``), the
closed-form derivative of the LoG kernel at a vanishing sigma, the project's own readers for
files written by the CLI (format by content, not by name).
"""

from __future__ import annotations

import numpy as np
import pytest

from jaxgfx import io

from ._util import read_only_sys

READ_ONLY = "/sys/jaxgfx-reliability"  # sysfs: not writable, even by root


def _read_only_available() -> bool:
    return read_only_sys()


# --------------------------------------------------------------- D13 messages that mislead


def test_d13_exif_exposure_time_zero_is_not_missing(files):
    paths = sorted(str(p) for p in files["exif_zero"].iterdir())
    with pytest.raises(ValueError, match=r"EXIF ExposureTime is 0 s") as e:
        io.read_ldr_stack(paths)
    assert "no EXIF" not in str(e.value)


def test_d13_bmp_is_not_listed_as_writable(tmp_path):
    with pytest.raises(ValueError) as e:
        io.write_any(str(tmp_path / "x.bmp"), np.zeros((2, 2, 3), np.float32))
    msg = str(e.value)
    assert "cannot write '.bmp'" in msg and ".bmp" not in msg.split("writable:")[1]


def test_d13_nan_mesh_vertex_names_file_and_shape(files, tmp_path):
    from jaxgfx.render import load_obj, load_scene

    with pytest.raises(ValueError, match=r"nan\.obj: 1 vertices have NaN/Inf.*vertex 1"):
        load_obj(str(files["nan_obj"]))
    desc = {
        "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4},
        "shapes": [{"type": "mesh", "file": str(files["nan_obj"])}],
    }
    with pytest.raises(ValueError, match=r"shapes\[0\]\.file: .*nan\.obj"):
        load_scene(desc)
    desc["shapes"] = [{"type": "mesh", "vertices": [[0, 0, 0], [1, 0, np.nan], [0, 1, 0]],
                       "faces": [[0, 1, 2]]}]  # fmt: skip
    with pytest.raises(ValueError, match=r"shapes\[0\]\.vertices: expected finite"):
        load_scene(desc)
