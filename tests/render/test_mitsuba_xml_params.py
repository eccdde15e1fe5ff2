"""Mitsuba 3 XML scenes as users drive them: ``Scene.parameters()`` (XML ids as path names),
``jaxgfx render scene.xml out.exr`` and ``jaxgfx fit`` with ``scene: x.xml``."""

from __future__ import annotations

import numpy as np
import pytest

from jaxgfx.cli import main
from jaxgfx.io import read_exr
from jaxgfx.render.scene import load_scene

XML = """<scene version="3.0.0">
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0.5, -4" target="0, 0.3, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="6"/>
      <rfilter type="box"/></film>
  </sensor>
  <bsdf type="twosided" id="red_paint"><bsdf type="diffuse">
    <rgb name="reflectance" value="0.7, 0.2, 0.1"/></bsdf></bsdf>
  <bsdf type="roughconductor" id="brass"><float name="alpha" value="0.3"/>
    <string name="material" value="Cu"/></bsdf>
  <shape type="sphere"><float name="radius" value="0.5"/><ref id="brass"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/>
    <scale value="3"/><translate y="-0.5"/></transform><ref id="red_paint"/></shape>
  <shape type="sphere"><point name="center" value="0, 3, 0"/><float name="radius" value="0.3"/>
    <emitter type="area"><rgb name="radiance" value="5, 5, 5"/></emitter></shape>
  <emitter type="constant"><rgb name="radiance" value="0.2, 0.2, 0.2"/></emitter>
</scene>
"""


@pytest.fixture
def xml(tmp_path):
    p = tmp_path / "scene.xml"
    p.write_text(XML)
    return str(p)


def test_parameters_list_every_leaf_with_xml_ids_as_names(xml):
    scene = load_scene(xml)
    got = {p.path: (p.shape, p.bounds) for p in scene.parameters()}
    inf = float("inf")
    # written out from the XML above (the light gets Mitsuba's default black BSDF of an emitter)
    want = {
        "camera.origin": ((3,), (-inf, inf)),
        "camera.target": ((3,), (-inf, inf)),
        "camera.up": ((3,), (-inf, inf)),
        "camera.fov": ((), (0.0, 180.0)),
        "materials.brass.distribution.alpha_u": ((), (0.0, inf)),
        "materials.brass.distribution.alpha_v": ((), (0.0, inf)),
        "materials.brass.reflectance": ((3,), (0.0, 1.0)),
        "materials.brass.eta": ((3,), (0.0, inf)),
        "materials.brass.k": ((3,), (0.0, inf)),
        "materials.red_paint.reflectance": ((3,), (0.0, 1.0)),
        "materials.mitsuba_default_emitter.reflectance": ((3,), (0.0, 1.0)),
        "emitters.area.0.radiance": ((3,), (0.0, inf)),
        "emitters.environment.radiance": ((3,), (0.0, inf)),
        "shapes.0.centers": ((1, 3), (-inf, inf)),
        "shapes.0.radii": ((1,), (0.0, inf)),
        "shapes.1.centers": ((1, 3), (-inf, inf)),
        "shapes.1.edge_u": ((1, 3), (-inf, inf)),
        "shapes.1.edge_v": ((1, 3), (-inf, inf)),
        "shapes.2.centers": ((1, 3), (-inf, inf)),
        "shapes.2.radii": ((1,), (0.0, inf)),
    }
    assert got == want
    np.testing.assert_allclose(scene.get("materials.red_paint.reflectance"), [0.7, 0.2, 0.1])
    # every listed path works with replace (same shape, a value inside the bounds)
    for p in scene.parameters():
        v = np.asarray(scene.get(p.path))
        assert v.shape == p.shape and v.dtype == p.dtype
        lo, hi = p.bounds
        assert np.all(v >= lo) and np.all(v <= hi), p
        s2 = scene.replace(p.path, v * 0.5 + 0.5 * np.clip(v, lo, min(hi, 1.0)))
        assert np.asarray(s2.get(p.path)).shape == p.shape


def test_parameters_of_a_textured_material_are_its_texels():
    tex = {"type": "bitmap", "image": [[0.05, 0.4, 0.05, 0.4], [0.4, 0.05, 0.4, 0.05]]}
    scene = load_scene({
        "camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4},
        "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1, "material": "brushed"}],
        "materials": {"brushed": {"type": "roughconductor", "alpha": tex}},
    })  # fmt: skip
    paths = [p.path for p in scene.parameters() if p.path.startswith("materials.brushed")]
    # the alpha texture replaces both distribution alphas: they are not listed
    assert paths == ["materials.brushed.alpha.image", "materials.brushed.reflectance"]
    (tex,) = [p for p in scene.parameters() if p.path == "materials.brushed.alpha.image"]
    assert tex.shape == (2, 4, 1) and tex.bounds == (0.0, float("inf"))


@pytest.mark.slow  # 40 s measured here (the CLI's render compiles the scene's program)
def test_cli_renders_an_xml_scene(xml, tmp_path, capsys):
    out = tmp_path / "out.exr"
    assert main(["render", xml, str(out), "--spp", "2", "--integrator", "direct"]) == 0
    img = read_exr(str(out))
    assert img.shape[:2] == (6, 8) and np.all(np.isfinite(img)) and img.mean() > 0
    assert "wrote" in capsys.readouterr().out


def test_fit_accepts_an_xml_scene(xml, tmp_path):
    from jaxgfx.config import load_config
    from jaxgfx.pipelines.fit import FitConfig, prepare_fit

    cfg = load_config(
        FitConfig,
        {
            "scene": xml,
            "target": {"synthetic": {"materials.red_paint.reflectance": [0.3, 0.5, 0.2]}},
            "params": {"materials.red_paint.reflectance": {"init": 0.5, "min": 0.0, "max": 1}},
            "render": {"spp": 2, "width": 4, "height": 3},
            "optimizer": {"steps": 1},
            "progress": False,
        },
    )
    prep = prepare_fit(cfg)
    assert (prep.scene.width, prep.scene.height) == (4, 3)  # render.width/height override
    assert prep.paths == ["materials.red_paint.reflectance"]
    np.testing.assert_allclose(prep.init["materials.red_paint.reflectance"], [0.5] * 3)
    bad = load_config(FitConfig, {**cfg.__dict__, "params": {"materials.paint.reflectance": {}}})
    with pytest.raises(ValueError, match=r"params\.materials\.paint\.reflectance: unknown"):
        prepare_fit(bad)
