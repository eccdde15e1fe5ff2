"""mitsuba-data's ``projector`` and ``spot_light`` scenes (tests/data/mitsuba, see its ORIGIN.md)
rendered by jaxgfx and compared with Mitsuba's reference images, as
``tests/render/test_mitsuba_xml_render.py`` does (its ``compare`` / ``render_xml``). The
scenes' own ``_var.exr`` images are negative in 23 % (projector constant), 6 % (textured) and
16 % (spot) of the pixels, so the tolerances use ``_samplevar.exr`` from
``tools/mitsuba_sample_variance.py`` (256 Mitsuba 3.9.1 renders x 32 spp, ORIGIN.md)."""

from __future__ import annotations

import os

import numpy as np
import pytest

from jaxgfx import io
from tests.render.test_mitsuba_xml_render import compare, render_xml

SCENES = os.path.join(os.path.dirname(__file__), "..", "data", "mitsuba", "tests", "scenes")


def _refs(stem):
    ref = io.read_any(stem + ".exr")[..., :3].astype(np.float64)
    var = io.read_any(stem + "_samplevar.exr")[..., :3].astype(np.float64)
    return ref, var


@pytest.mark.slow  # ~30 s measured here (48², 16 spp, a 480 x 270 texture; compile)
def test_textured_spot_matches_mitsubas_reference():
    """A spot (cutoff 20, beam 15) projecting the de Bruijn pattern onto a wall, plus a constant
    environment of 0.1, ``direct`` integrator."""
    spp = 16
    img = render_xml(os.path.join(SCENES, "spot_light", "test_spot_direct.xml"), spp)
    ref, var = _refs(os.path.join(SCENES, "spot_light", "refs", "test_spot_ref_rgb"))
    c = compare(img, ref, var, spp)
    print(c, img.mean((0, 1)), ref.mean((0, 1)))
    assert np.all(np.abs(c["z_mean"]) < 4), c
    assert c["z_rms"] < 1.5 and c["frac_3_5"] >= 0.97, c


@pytest.mark.slow  # ~20 s each measured here (48², 16 spp; compile)
@pytest.mark.parametrize("name", ["constant", "textured"])
def test_projector_matches_mitsubas_reference(name):
    """A projector (fov 165) facing a white diffuse plane at distance 1, seen by a fov-170
    camera from the same point: inside the frustum the closed form is ``E(uv)`` exactly
    (irradiance pi E, radiance rho / pi times it); jaxgfx gives 1.0000 for the constant one,
    Mitsuba's reference 1.0009 (its 8192-spp re-render with 3.9.1: image mean 0.44167 against
    the reference's 0.44179 and jaxgfx's 0.44111). Where the sample variance is 0 (the
    frustum's interior) a block z is meaningless, so the image means are compared with a
    relative tolerance of 0.4 % (measured: 0.21 % constant, 0.30 % textured: an open
    discrepancy of the same sign, not noise) and the blocks
    by relative RMSE."""
    spp = 16
    stem = f"test_projector_{name}"
    img = render_xml(os.path.join(SCENES, "projector", f"{stem}_direct.xml"), spp)
    ref, var = _refs(os.path.join(SCENES, "projector", "refs", f"{stem}_ref_rgb"))
    c = compare(img, ref, var, spp)
    print(c, img.mean((0, 1)), ref.mean((0, 1)))
    np.testing.assert_allclose(img.mean((0, 1)), ref.mean((0, 1)), rtol=4e-3)
    assert c["rel_rmse"] < 0.012, c  # measured 0.78 % / 0.88 %
    if name == "constant":  # the interior: the closed form, rho E / z^2 = 1
        np.testing.assert_allclose(img[14:34, 14:34], 1.0, rtol=1e-5)
