"""Shape and emitter ``id``s of Mitsuba XML scenes (and of descriptions) as parameter-path names:
``Scene.parameters()``, ``get`` / ``replace``, ``jaxgfx fit`` configs, the writer."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render.geometry.intersect import intersect_scene
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba import scene_to_desc, to_mitsuba_dict
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

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
  <shape type="sphere" id="ball"><float name="radius" value="0.5"/>
    <bsdf type="roughconductor"><float name="alpha" value="0.3"/></bsdf></shape>
  <shape type="sphere"><point name="center" value="2, 0, 0"/><float name="radius" value="0.25"/>
    <ref id="red_paint"/></shape>
  <shape type="rectangle" id="Plane.001"><transform name="to_world"><rotate x="1" angle="-90"/>
    <scale value="3"/><translate y="-0.5"/></transform><ref id="red_paint"/></shape>
  <shape type="sphere" id="bulb"><point name="center" value="0, 3, 0"/>
    <float name="radius" value="0.3"/>
    <emitter type="area" id="lamp"><rgb name="radiance" value="5, 5, 5"/></emitter></shape>
  <shape type="rectangle" id="panel"><transform name="to_world"><rotate x="1" angle="90"/>
    <translate y="4"/></transform>
    <emitter type="area"><rgb name="radiance" value="2, 2, 2"/></emitter></shape>
  <emitter type="point" id="sun"><point name="position" value="1, 5, 1"/>
    <rgb name="intensity" value="9, 9, 9"/></emitter>
  <emitter type="point"><point name="position" value="-1, 5, 1"/>
    <rgb name="intensity" value="3, 3, 3"/></emitter>
  <emitter type="constant" id="sky"><rgb name="radiance" value="0.2, 0.2, 0.2"/></emitter>
</scene>
"""


@pytest.fixture
def xml(tmp_path):
    p = tmp_path / "scene.xml"
    p.write_text(XML)
    return str(p)


def test_ids_name_shapes_and_emitters_in_parameters(xml):
    scene = load_scene(xml)
    got = [p.path for p in scene.parameters() if not p.path.startswith(("camera", "materials"))]
    # written out from the XML: the two spheres are one batch (shapes.0), whose unnamed row
    # keeps the batch's index path; 'Plane.001' cannot be a path name (a dot): index path;
    # the unnamed area emitter goes by its shape's id; the unnamed point light by the batch
    assert got == [
        "emitters.sun.positions",
        "emitters.sun.intensities",
        "emitters.point.positions",
        "emitters.point.intensities",
        "emitters.lamp.radiance",
        "emitters.panel.radiance",
        "emitters.sky.radiance",
        "shapes.ball.centers",
        "shapes.ball.radii",
        "shapes.0.centers",
        "shapes.0.radii",
        "shapes.1.centers",
        "shapes.1.edge_u",
        "shapes.1.edge_v",
        "shapes.bulb.centers",
        "shapes.bulb.radii",
        "shapes.panel.centers",
        "shapes.panel.edge_u",
        "shapes.panel.edge_v",
    ]
    # ids address the same leaves (a batch's row) as the index paths
    np.testing.assert_allclose(scene.get("shapes.ball.radii"), [0.5])
    np.testing.assert_allclose(scene.get("shapes.0.radii"), [0.5, 0.25])
    np.testing.assert_allclose(scene.get("emitters.sun.intensities"), [[9, 9, 9]])
    np.testing.assert_allclose(scene.get("emitters.lamp.radiance"), [5, 5, 5])
    np.testing.assert_allclose(scene.get("emitters.panel.radiance"), [2, 2, 2])
    np.testing.assert_allclose(scene.get("shapes.bulb.centers"), [[0, 3, 0]])
    # the shape's material (an unnamed BSDF inside it), like mi.traverse's ball.bsdf.*
    alpha = scene.get("shapes.ball.bsdf.distribution.alpha_u")
    assert float(alpha) == pytest.approx(0.3)
    s2 = scene.replace("shapes.ball.radii", 0.75)
    np.testing.assert_allclose(s2.get("shapes.0.radii"), [0.75, 0.25])  # only ball's row
    s3 = scene.replace("emitters.sun.positions", [0, 9, 0])
    np.testing.assert_allclose(s3.get("emitters.point.positions"), [[0, 9, 0], [-1, 5, 1]])
    s4 = scene.replace("shapes.ball.bsdf.alpha", 0.1)
    assert float(s4.get("shapes.ball.bsdf.distribution.alpha_v")) == pytest.approx(0.1)
    # every listed path round-trips through replace with its shape
    for p in scene.parameters():
        v = np.asarray(scene.get(p.path))
        assert v.shape == p.shape
        assert np.asarray(scene.replace(p.path, v).get(p.path)).shape == p.shape
    with pytest.raises(
        ValueError, match=r"shapes\.bal: unknown id 'bal'.*\['ball', 'bulb', 'panel'\]"
    ):
        scene.get("shapes.bal.radii")
    with pytest.raises(ValueError, match=r"shapes\.Plane: unknown id 'Plane'"):
        scene.get("shapes.Plane.001.edge_u")  # a dotted id is not a name


def test_id_paths_are_differentiable_closed_form(xml, x64):
    """A camera ray through the centre of ``ball`` hits it at ``t = |o - c| - r``: the derivative
    through the id path is ``dt/dr = -1`` (AD and central differences, float64), under jit."""
    scene = load_scene(xml, dtype=jnp.float64)
    o = jnp.array([[0.0, 0.0, -4.0]])
    d = jnp.array([[0.0, 0.0, 1.0]])

    def t_of(r):  # the sphere batch (shapes.0) holds ball's row
        return intersect_scene((scene.replace("shapes.ball.radii", r).shapes[0],), o, d).t[0]

    t_and_grad = jax.jit(jax.value_and_grad(t_of))
    t, ad = t_and_grad(0.5)
    assert float(t) == pytest.approx(3.5, abs=1e-12)
    h = 1e-4
    fd = (t_and_grad(0.5 + h)[0] - t_and_grad(0.5 - h)[0]) / (2 * h)
    assert float(ad) == pytest.approx(-1.0, abs=1e-9) and float(fd) == pytest.approx(-1.0, abs=1e-7)


def test_duplicate_and_unusable_ids_are_refused(tmp_path):
    dup = XML.replace('<shape type="sphere" id="bulb">', '<shape type="sphere" id="ball">')
    p = tmp_path / "dup.xml"
    p.write_text(dup)
    line = dup[: dup.index('id="ball"', dup.index('id="ball"') + 1)].count("\n") + 1
    msg = rf"dup\.xml:{line}: <shape type='sphere' id='ball'>: id 'ball' already defined at "
    with pytest.raises(ValueError, match=msg + r".*dup\.xml:11"):
        read_xml(str(p))
    cam = {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4}
    ball = {"type": "sphere", "center": [0, 0, 0], "radius": 1, "id": "a"}
    desc = {"camera": cam, "shapes": [ball, {**ball, "center": [2, 0, 0]}]}
    with pytest.raises(
        ValueError, match=r"shapes\[1\]\.id: duplicate id 'a' \(first given at shapes\[0\]\)"
    ):
        load_scene(desc)
    for bad, why in (("a.b", "contains '.'"), ("3", "is a number"), ("area", "is reserved")):
        d = {**desc, "shapes": [{**desc["shapes"][0], "id": bad}]}
        with pytest.raises(ValueError, match=rf"shapes\[0\]\.id: '{bad}' {why}"):
            load_scene(d)
    # shapes and emitters are separate namespaces in jaxgfx paths, but Mitsuba's ids are global
    point = {"type": "point", "position": [0, 3, 0], "intensity": 1, "id": "a"}
    d = {**desc, "shapes": desc["shapes"][:1], "emitters": [point]}
    assert [e[0] for e in load_scene(d).object_ids] == ["a", "a"]
    with pytest.raises(ValueError, match=r"emitters\[0\]\.id: 'a' is also the id of another"):
        to_mitsuba_dict(d)


def test_ids_survive_save_and_load(xml, tmp_path):
    scene = load_scene(xml)
    out = save_scene(scene, tmp_path / "saved.xml")
    with open(out) as f:
        text = f.read()
    assert '<shape type="sphere" id="ball">' in text and '<emitter type="area" id="lamp">' in text
    assert 'id="shape_' not in text and 'id="emitter_' not in text  # unnamed ones stay unnamed
    back = load_scene(out)
    assert back.object_ids == scene.object_ids
    assert [p.path for p in back.parameters()] == [p.path for p in scene.parameters()]
    points = [e for e in scene_to_desc(back)["emitters"] if e["type"] == "point"]
    assert [e.get("id") for e in points] == ["sun", None]


def test_fit_config_names_parameters_by_id(xml):
    from jaxgfx.config import load_config
    from jaxgfx.pipelines.fit import FitConfig, prepare_fit

    cfg = load_config(
        FitConfig,
        {
            "scene": xml,
            "target": {
                "synthetic": {"emitters.lamp.radiance": [8.0, 6.0, 4.0], "shapes.ball.radii": 0.6}
            },  # fmt: skip
            "params": {
                "emitters.lamp.radiance": {"init": 3.0, "min": 0.0, "max": 20.0},
                "shapes.ball.radii": {"init": 0.4, "min": 0.1, "max": 1.0},
                "shapes.ball.bsdf.alpha": {"min": 0.05, "max": 1.0},
            },
            "render": {"spp": 2, "width": 4, "height": 3},
            "optimizer": {"steps": 1},
            "progress": False,
        },
    )
    prep = prepare_fit(cfg)
    assert prep.paths == ["emitters.lamp.radiance", "shapes.ball.radii", "shapes.ball.bsdf.alpha"]
    np.testing.assert_allclose(prep.init["emitters.lamp.radiance"], [3.0] * 3)
    np.testing.assert_allclose(prep.init["shapes.ball.radii"], [0.4])
    np.testing.assert_allclose(prep.init["shapes.ball.bsdf.alpha"], 0.3, rtol=1e-6)
    fitted = prep.scene.replace("shapes.ball.radii", prep.init["shapes.ball.radii"])
    np.testing.assert_allclose(fitted.get("shapes.0.radii"), [0.4, 0.25], rtol=1e-6)
    bad = load_config(FitConfig, {**cfg.__dict__, "params": {"shapes.bal.radii": {}}})
    with pytest.raises(ValueError, match=r"params\.shapes\.bal\.radii: .*unknown id 'bal'"):
        prepare_fit(bad)
