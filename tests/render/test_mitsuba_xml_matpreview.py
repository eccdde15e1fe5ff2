"""Mitsuba's material-preview scene (mitsuba-data ``scenes/matpreview``, reduced copy in
``tests/data/mitsuba/scenes/matpreview``: ``tools/make_matpreview_data.py``, ORIGIN.md) loaded
from its XML with the preview material replaced, rendered by jaxgfx and by Mitsuba 3 from the
same files in the same run."""

from __future__ import annotations

import os
import re

import numpy as np
import pytest

from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba_xml import read_xml
from tests.render._mitsuba import (
    assert_channels_and_blocks_agree,
    jaxgfx_replicates,
    mitsuba_fixture,
    mitsuba_replicates,
)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DIR = os.path.join(ROOT, "tests", "data", "mitsuba", "scenes", "matpreview")
XML = os.path.join(DIR, "matpreview.xml")

MATERIALS = {
    "diffuse": '<bsdf type="diffuse" id="bsdf-matpreview">'
    '<rgb name="reflectance" value="0.94, 0.271, 0.361"/></bsdf>',
    "roughconductor": '<bsdf type="roughconductor" id="bsdf-matpreview">'
    '<string name="material" value="Au"/><float name="alpha" value="0.2"/></bsdf>',
    "roughplastic": '<bsdf type="roughplastic" id="bsdf-matpreview">'
    '<rgb name="diffuse_reflectance" value="0.94, 0.271, 0.361"/>'
    '<float name="alpha" value="0.1"/><float name="int_ior" value="1.9"/></bsdf>',
}


def _with_material(tmp_path, name):
    """The scene with ``bsdf-matpreview`` replaced, written next to the data files' copies."""
    with open(XML) as f:
        text = f.read()
    text = re.sub(r'<bsdf type="plastic" id="bsdf-matpreview">.*?</bsdf>', MATERIALS[name], text,
                  flags=re.S)  # fmt: skip
    for fn in os.listdir(DIR):
        if fn != "matpreview.xml":
            os.symlink(os.path.join(DIR, fn), tmp_path / fn)
    p = tmp_path / f"matpreview_{name}.xml"
    p.write_text(text)
    return str(p)


def test_matpreview_reads_with_its_ids_and_the_reduced_data():
    desc = read_xml(XML, width=8, height=6).desc
    assert set(desc["materials"]) == {"bsdf-diffuse", "bsdf-plane", "bsdf-matpreview"}
    assert desc["materials"]["bsdf-matpreview"]["type"] == "plastic"
    assert desc["materials"]["bsdf-plane"]["reflectance"]["scale"] == 8.0
    shapes = {s["id"]: s for s in desc["shapes"]}
    assert [shapes[k]["material"] for k in ("plane", "interior", "exterior")] == [
        "bsdf-plane", "bsdf-diffuse", "bsdf-matpreview"]  # fmt: skip
    assert len(shapes["exterior"]["faces"]) == 8282  # tools/make_matpreview_data.py
    assert desc["emitters"][0]["type"] == "envmap"


mi = mitsuba_fixture()


@pytest.mark.mitsuba
@pytest.mark.slow  # slow: 38 s diffuse, 59 s roughconductor, 79 s roughplastic on 2 cores (compile)
@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_matpreview_renders_like_mitsuba(mi, name, tmp_path):
    k, spp, w, h, depth = 4, 64, 32, 24, 4
    p = _with_material(tmp_path, name)
    params = dict(width=w, height=h, spp=spp, max_depth=depth)
    ms = mi.load_file(p, **{a: str(b) for a, b in params.items()})
    b = mitsuba_replicates(mi, ms, k, spp)
    a = jaxgfx_replicates(load_scene(p, **params), 7, k, spp=spp, max_depth=depth)
    zc, zb = assert_channels_and_blocks_agree(a, b)
    print(name, "channel means", a.mean((0, 1, 2)), b.mean((0, 1, 2)), "z", zc,
          "block |z|<4", np.mean(np.abs(zb) < 4))  # fmt: skip
