"""``configs/scenes/cbox.xml``: the Cornell box from Cornell's published data, loaded from XML,
named by its ids, rendered by jaxgfx and by Mitsuba 3 in the same run, and through the CLI."""

from __future__ import annotations

import os

import numpy as np
import pytest

from jaxgfx.render.scene import load_scene
from tests.render._mitsuba import (
    assert_channels_and_blocks_agree,
    jaxgfx_replicates,
    mitsuba_fixture,
    mitsuba_replicates,
)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CBOX = os.path.join(ROOT, "configs", "scenes", "cbox.xml")


def test_cbox_is_cornells_published_geometry_named_by_its_ids():
    scene = load_scene(CBOX, res=8)
    # corners of the floor and the light as listed on Cornell's data page (mm), light 0.5 mm down
    floor = np.asarray(scene.get("shapes.floor.vertices")) * 1000
    np.testing.assert_allclose(floor, [[552.8, 0, 0], [0, 0, 0], [0, 0, 559.2], [549.6, 0, 559.2]],
                               atol=1e-3)  # fmt: skip
    light = np.asarray(scene.get("shapes.light.vertices")) * 1000
    np.testing.assert_allclose(light[0], [343.0, 548.3, 227.0], atol=1e-3)
    np.testing.assert_allclose(scene.get("emitters.lamp.radiance"), [17, 12, 4])
    np.testing.assert_allclose(scene.get("materials.red.reflectance"), [0.63, 0.065, 0.05])
    assert float(scene.camera.fov) == pytest.approx(39.3077, abs=1e-4)
    assert scene.get("shapes.tallbox.vertices").shape == (20, 3)


mi = mitsuba_fixture()


@pytest.mark.mitsuba
@pytest.mark.slow  # slow: ~68 s on 2 cores (jaxgfx compile dominates)
def test_cbox_renders_like_mitsuba(mi):
    k, spp, res, depth = 4, 64, 32, 6  # interreflection: paths of up to 6 vertices
    ms = mi.load_file(CBOX, res=str(res), spp=str(spp), max_depth=str(depth))
    b = mitsuba_replicates(mi, ms, k, spp)
    a = jaxgfx_replicates(load_scene(CBOX, res=res), 5, k, spp=spp, max_depth=depth)
    zc, zb = assert_channels_and_blocks_agree(a, b)
    print("cbox channel means", a.mean((0, 1, 2)), b.mean((0, 1, 2)), "z", zc,
          "block |z|<4", np.mean(np.abs(zb) < 4))  # fmt: skip


@pytest.mark.slow  # slow: ~36 s on 2 cores (the CLI compiles the path program: 35 s)
def test_cli_renders_cbox_xml(tmp_path):
    from jaxgfx.cli import main
    from jaxgfx.io import read_exr

    out = tmp_path / "cbox.exr"
    assert main(["render", CBOX, str(out), "--spp", "1", "--max-depth", "3"]) == 0
    img = read_exr(str(out))
    assert img.shape[:2] == (256, 256) and np.all(np.isfinite(img))
    # the red wall is on the image's left, the green one on its right
    left, right = img[96:160, 8:24].mean((0, 1)), img[96:160, 232:248].mean((0, 1))
    assert left[0] > 2 * left[1] and right[1] > 2 * right[0]
