"""Tiny input files shared by the reliability suite (built once per session)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from jaxgfx import io

SCENE = """\
camera: {origin: [0, 0, 3], target: [0, 0, 0], up: [0, 1, 0], fov: 45, width: 8, height: 6}
shapes:
  - {type: sphere, center: [0, 0, 0], radius: 1, material: m}
materials:
  m: {type: diffuse, reflectance: [0.5, 0.5, 0.5]}
emitters:
  - {type: constant, radiance: [1, 1, 1]}
"""


def _stack_dir(root, name, frames, times, *, sidecar=True):
    d = root / name
    d.mkdir()
    for i, f in enumerate(frames):
        io.write_png(str(d / f"f{i}.png"), f)
    if sidecar:
        (d / "exposure_times.txt").write_text(" ".join(str(t) for t in times) + "\n")
    return d


def _bracket(h=24, w=24):
    """A 3-frame 8-bit bracket of a smooth scene through a 1/2.2 gamma curve."""
    yy, xx = np.mgrid[0:h, 0:w]
    e = np.exp(np.log(1e-3) * (1 - (xx + yy) / (h + w - 2)))  # 1e-3 .. 1
    e = np.stack([e, 0.8 * e, 0.6 * e], -1)
    times = (1.0, 4.0, 16.0)
    frames = [
        np.round(255 * np.clip(e * t / 4.0, 0, 1) ** (1 / 2.2)).astype(np.uint8) for t in times
    ]
    return frames, times


@pytest.fixture(scope="session")
def files(tmp_path_factory):
    """Paths of the shared inputs (never written by tests: cases write under their own
    ``tmp_path``)."""
    root = tmp_path_factory.mktemp("reliability_inputs")
    p = {}
    rng = np.random.default_rng(0)
    img = (rng.random((16, 16, 3)) * 255).astype(np.uint8)
    p["png"] = root / "in.png"
    io.write_png(str(p["png"]), img)
    p["const_png"] = root / "const.png"
    io.write_png(str(p["const_png"]), np.full((32, 32), 128, np.uint8))
    p["one_px_png"] = root / "one.png"
    io.write_png(str(p["one_px_png"]), np.full((1, 1, 3), 7, np.uint8))
    p["exr"] = root / "in.exr"
    io.write_exr(str(p["exr"]), np.ascontiguousarray(img.astype(np.float32) / 255 * 4))
    bad = img.astype(np.float32) / 255 * 4
    bad[3, 4, 0], bad[9, 1, 2] = np.inf, np.nan
    p["inf_exr"] = root / "inf.exr"
    io.write_exr(str(p["inf_exr"]), bad)
    frames, times = _bracket()
    p["stack"] = _stack_dir(root, "stack", frames, times)
    p["saturated"] = _stack_dir(root, "saturated", [np.full((16, 16, 3), 255, np.uint8)] * 3, times)
    p["black"] = _stack_dir(root, "black", [np.zeros((16, 16, 3), np.uint8)] * 3, times)
    p["sizes"] = _stack_dir(root, "sizes", [frames[0], frames[1][:20]], times[:2])
    p["single"] = _stack_dir(root, "single", [frames[0]], times[:1])
    p["no_times"] = _stack_dir(root, "no_times", frames, times, sidecar=False)
    p["short_sidecar"] = _stack_dir(root, "short_sidecar", frames, times[:2])
    # JPEGs whose EXIF ExposureTime is 0
    d = root / "exif_zero"
    d.mkdir()
    for i, f in enumerate(frames):
        ex = Image.Exif()
        ex[0x829A] = 0.0
        Image.fromarray(f).save(d / f"f{i}.jpg", exif=ex)
    p["exif_zero"] = d
    # corrupt and empty files, one per extension
    good_png = p["png"].read_bytes()
    for ext in (".png", ".jpg", ".tif", ".exr", ".hdr", ".dng", ".bmp"):
        (root / f"garbage{ext}").write_bytes(b"this is not an image file at all" * 4)
        (root / f"empty{ext}").write_bytes(b"")
        p[f"garbage{ext}"] = root / f"garbage{ext}"
        p[f"empty{ext}"] = root / f"empty{ext}"
    p["trunc_png"] = root / "trunc.png"
    p["trunc_png"].write_bytes(good_png[: len(good_png) // 2])
    jpg = root / "good.jpg"
    Image.fromarray(img).save(jpg, quality=90)
    p["trunc_jpg"] = root / "trunc.jpg"
    p["trunc_jpg"].write_bytes(jpg.read_bytes()[:200])
    p["dir_png"] = root / "folder.png"
    p["dir_png"].mkdir()
    p["a_file"] = root / "a_file"
    p["a_file"].write_text("not a folder\n")
    # scenes
    p["scene"] = root / "scene.yaml"
    p["scene"].write_text(SCENE)
    p["nan_obj"] = root / "nan.obj"
    p["nan_obj"].write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    return p
