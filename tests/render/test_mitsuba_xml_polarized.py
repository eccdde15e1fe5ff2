"""Mitsuba's ``pplastic``, ``polarizer``, ``circular`` and ``retarder`` (issue 24) through the
XML reader, the scene description and the writers (``save_scene`` / ``to_mitsuba_dict``):
Mitsuba's defaults and names, its refusals (with file and line), one-sidedness, and the round
trips.
No rendering (the renders against Mitsuba: tests/render/test_bsdf_polarized_mitsuba.py)."""

import math
import re

import pytest

from jaxgfx.render.bsdf import PolarizedPlastic, Polarizer, Retarder
from jaxgfx.render.bsdf.textured import Textured
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba import to_mitsuba_dict
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

XML = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="40"/>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/>
    </film>
  </sensor>
  <shape type="sphere"><point name="center" x="0" y="0" z="5"/>
    {bsdf}
  </shape>
  <emitter type="constant"/>
</scene>
"""


def _read(tmp_path, bsdf):
    p = tmp_path / "s.xml"
    p.write_text(XML.format(bsdf=bsdf))
    return read_xml(str(p)), str(p)


def _material(tmp_path, bsdf):
    x, _ = _read(tmp_path, bsdf)
    (m,) = x.desc["materials"].values()
    return m


def test_pplastic_defaults_are_mitsubas(tmp_path):
    """A bare ``<bsdf type="pplastic"/>``: Beckmann, α 0.1, visible normals, η = polypropylene /
    air, kd 0.5, ks 1, one-sided (Mitsuba's FrontSide-only plugin outside ``twosided``)."""
    m = _material(tmp_path, '<bsdf type="pplastic"/>')
    assert m == {"type": "pplastic", "distribution": "beckmann", "alpha": 0.1,
                 "sample_visible": True, "eta": pytest.approx(1.49 / 1.000277),
                 "diffuse_reflectance": [0.5] * 3, "specular_reflectance": [1.0] * 3,
                 "one_sided": True}  # fmt: skip
    b = load_scene(_read(tmp_path, '<bsdf type="pplastic"/>')[0].desc).materials[0]
    assert isinstance(b, PolarizedPlastic) and b.distribution.type == "beckmann"
    two = _material(tmp_path, '<bsdf type="twosided"><bsdf type="pplastic"/></bsdf>')
    assert "one_sided" not in two


def test_pplastic_parameters(tmp_path):
    m = _material(tmp_path, """<bsdf type="pplastic"><float name="eta" value="1.3"/>
      <string name="distribution" value="ggx"/><float name="alpha" value="0.25"/>
      <boolean name="sample_visible" value="false"/>
      <rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/>
      <spectrum name="specular_reflectance" value="0.8"/></bsdf>""")
    assert (m["eta"], m["distribution"], m["alpha"], m["sample_visible"]) == (1.3, "ggx", 0.25,
                                                                              False)  # fmt: skip
    assert m["diffuse_reflectance"] == [0.1, 0.2, 0.3] and m["specular_reflectance"] == [0.8] * 3
    m = _material(tmp_path, '<bsdf type="pplastic"><float name="int_ior" value="1.6"/>'
                            '<string name="ext_ior" value="water"/></bsdf>')  # fmt: skip
    assert m["eta"] == pytest.approx(1.6 / 1.333)
    # anisotropic: in the dp/du frame (the identity normal map), as roughconductor
    m = _material(tmp_path, '<bsdf type="pplastic"><float name="alpha_u" value="0.1"/>'
                            '<float name="alpha_v" value="0.4"/></bsdf>')  # fmt: skip
    assert m["type"] == "normalmap" and (m["bsdf"]["alpha"], m["bsdf"]["alpha_v"]) == (0.1, 0.4)
    assert m["one_sided"] is True
    # a texture: a Textured material
    x, _ = _read(tmp_path, """<bsdf type="pplastic"><texture type="checkerboard"
      name="diffuse_reflectance"/></bsdf>""")
    assert isinstance(load_scene(x.desc).materials[0], Textured)


@pytest.mark.parametrize("body, name, msg", [
    ('<float name="eta" value="1.5"/><float name="int_ior" value="1.5"/>', "int_ior",
     "give either eta or int_ior / ext_ior, not both"),
    ('<float name="int_ior" value="1.333"/><string name="ext_ior" value="water"/>', "int_ior",
     "the interior and exterior IORs must differ"),
    ('<float name="eta" value="-1"/>', "eta", "expected a positive number"),
    ('<string name="distribution" value="phong"/>', "distribution", "'phong' is not supported"),
    ('<float name="alpha_u" value="0.1"/>', "alpha_v", "give both alpha_u and alpha_v"),
    ('<boolean name="nonlinear" value="true"/>', "nonlinear", "is not supported"),
])  # fmt: skip
def test_pplastic_refusals_name_the_file_line_and_parameter(tmp_path, body, name, msg):
    p = tmp_path / "s.xml"
    p.write_text(XML.format(bsdf=f'<bsdf type="pplastic">\n{body}</bsdf>'))
    with pytest.raises(ValueError, match=rf"{re.escape(str(p))}:\d+: .*'{name}'.*{msg}"):
        read_xml(str(p))


def test_polarizer_and_retarder(tmp_path):
    """Mitsuba's own example (``<spectrum name="theta" value="90"/>``), a grey
    ``transmittance``, ``polarizing``; the retarder's ``delta``; angles given as textures are
    read and dropped (no effect on unpolarised light); both stay two-sided."""
    m = _material(tmp_path, """<bsdf type="polarizer"><spectrum name="theta" value="90"/>
      <float name="transmittance" value="0.8"/><boolean name="polarizing" value="false"/>
      </bsdf>""")
    assert m == {"type": "polarizer", "transmittance": [0.8] * 3, "theta": 90.0,
                 "polarizing": False}  # fmt: skip
    m = _material(tmp_path, '<bsdf type="retarder"><float name="delta" value="45"/>'
                            '<rgb name="transmittance" value="0.9, 0.5, 0.1"/></bsdf>')
    assert m == {"type": "retarder", "transmittance": [0.9, 0.5, 0.1], "theta": 0.0,
                 "delta": 45.0}  # fmt: skip
    m = _material(tmp_path, '<bsdf type="retarder"><texture type="checkerboard" name="theta"/>'
                            '<integer name="delta" value="30"/></bsdf>')  # fmt: skip
    assert m == {"type": "retarder", "transmittance": [1.0] * 3, "delta": 30.0}
    m = _material(tmp_path, '<bsdf type="circular"><boolean name="left_handed" value="true"/>'
                            "</bsdf>")  # fmt: skip
    assert m == {"type": "circular", "transmittance": [1.0] * 3, "left_handed": True}
    x, _ = _read(tmp_path, '<bsdf type="polarizer"/>')
    b = load_scene(x.desc).materials[0]
    assert isinstance(b, Polarizer) and float(b.theta) == 0.0 and b.polarizing is True
    x, _ = _read(tmp_path, '<bsdf type="retarder"/>')
    assert float(load_scene(x.desc).materials[0].delta) == 90.0  # Mitsuba's default


@pytest.mark.parametrize("bsdf, msg", [
    ('<bsdf type="blendbsdf"><bsdf type="polarizer"/><bsdf type="diffuse"/></bsdf>',
     "a polarizer nested in a blendbsdf or mask is not supported"),
    ('<bsdf type="mask"><bsdf type="retarder"/></bsdf>',
     "a retarder nested in a blendbsdf or mask is not supported"),
    ('<bsdf type="polarizer"><float name="delta" value="3"/></bsdf>', "'delta' is not supported"),
    ('<bsdf type="circular"><float name="theta" value="3"/></bsdf>', "'theta' is not supported"),
    ('<bsdf type="polarizer"><float name="transmittance" value="-1"/></bsdf>', "transmittance"),
])  # fmt: skip
def test_pass_through_refusals(tmp_path, bsdf, msg):
    p = tmp_path / "s.xml"
    p.write_text(XML.format(bsdf=bsdf))
    with pytest.raises(ValueError, match=msg):
        load_scene(read_xml(str(p)).desc)


def test_pass_through_cannot_be_one_sided():
    desc = {"camera": {"origin": [0, 0, 0], "target": [0, 0, 1], "fov": 30, "width": 4,
                       "height": 4},
            "shapes": [{"type": "sphere", "center": [0, 0, 3], "radius": 1, "material": "m"}],
            "materials": {"m": {"type": "polarizer", "one_sided": True}}}  # fmt: skip
    with pytest.raises(ValueError, match=r"materials\.m\.one_sided: .*a pass-through \(Polar"):
        load_scene(desc)


_ROUND = [
    '<bsdf type="pplastic"><float name="eta" value="1.3"/><float name="alpha" value="0.2"/>'
    '<rgb name="diffuse_reflectance" value="0.1, 0.2, 0.3"/></bsdf>',
    '<bsdf type="twosided"><bsdf type="pplastic"><string name="distribution" value="ggx"/>'
    '</bsdf></bsdf>',
    '<bsdf type="pplastic"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.4"/>'
    "</bsdf>",
    '<bsdf type="polarizer"><float name="theta" value="30"/>'
    '<rgb name="transmittance" value="0.9, 0.5, 0.1"/></bsdf>',
    '<bsdf type="retarder"><float name="theta" value="10"/><float name="delta" value="45"/>'
    "</bsdf>",
    '<bsdf type="circular"><boolean name="left_handed" value="true"/>'
    '<float name="transmittance" value="0.7"/></bsdf>',
]


@pytest.mark.parametrize("bsdf", _ROUND)
def test_written_back_and_read_again(tmp_path, bsdf):
    """XML -> scene -> ``save_scene`` -> XML gives the same material description (the writer
    wraps a two-sided pplastic in ``twosided``, writes the anisotropic one's normal map)."""
    x, _ = _read(tmp_path, bsdf)
    scene = load_scene(x.desc)
    w = save_scene(scene, str(tmp_path / "w.xml"))
    (a,) = x.desc["materials"].values()
    (b,) = read_xml(w).desc["materials"].values()
    if a["type"] == "normalmap":  # the identity map is written as a texture file
        a, b = dict(a, normalmap=None), dict(b, normalmap=None)
    assert _approx(b) == _approx(a)


def _approx(d):
    if isinstance(d, dict):
        return {k: _approx(v) for k, v in d.items()}
    if isinstance(d, (list, tuple)):
        return [_approx(v) for v in d]
    return round(d, 5) if isinstance(d, float) and math.isfinite(d) else d


def test_to_mitsuba_dict_keys():
    desc = {"camera": {"origin": [0, 0, 0], "target": [0, 0, 1], "fov": 30, "width": 4,
                       "height": 4},
            "shapes": [{"type": "sphere", "center": [0, 0, 3], "radius": 1, "material": "p"},
                       {"type": "sphere", "center": [0, 2, 3], "radius": 1, "material": "q"},
                       {"type": "sphere", "center": [0, -2, 3], "radius": 1, "material": "r"}],
            "materials": {"p": {"type": "pplastic", "alpha": 0.3, "eta": 1.4},
                          "q": {"type": "polarizer", "transmittance": 0.5, "theta": 20},
                          "r": {"type": "retarder", "delta": 30}}}  # fmt: skip
    d = to_mitsuba_dict(desc)
    bs = [d[f"shape_{i}"]["bsdf"] for i in range(3)]
    assert bs[0]["type"] == "twosided"  # jaxgfx shades a plain description on both sides
    p = bs[0]["bsdf"]
    assert (p["type"], p["distribution"], p["alpha"], p["eta"]) == (
        "pplastic", "beckmann", pytest.approx(0.3), pytest.approx(1.4))
    assert bs[1] == {"type": "polarizer", "transmittance": {"type": "rgb", "value": [0.5] * 3},
                     "theta": 20.0, "polarizing": True}  # fmt: skip
    assert bs[2]["delta"] == 30.0 and bs[2]["theta"] == 0.0
    assert isinstance(load_scene(desc).materials[2], Retarder)


def test_specfilm_is_refused_as_mitsubas_rgb_variants_refuse_it(tmp_path):
    """Mitsuba's ``specfilm`` exists in its spectral variants only (``specfilm.cpp`` logs an
    error in the others); jaxgfx renders RGB as those do, so it refuses the film, saying so,
    with file and line, also nested in a sensor."""
    p = tmp_path / "f.xml"
    p.write_text(XML.replace('<film type="hdrfilm">', '<film type="specfilm">').format(bsdf=""))
    with pytest.raises(ValueError, match=rf"{re.escape(str(p))}:3: <film type='specfilm'>: film "
                       r"plugin 'specfilm' is not supported \(spectral variants only, as in "
                       r"Mitsuba, whose RGB variants refuse it too; jaxgfx renders RGB\)"):
        read_xml(str(p))


def test_mitsuba_docs_pplastic_in_matpreview(tmp_path):
    """The pplastic of Mitsuba's documentation scene (mitsuba-data ``docs/scenes/
    bsdf_pplastic.xml``: kd (0.05, 0.03, 0.1), α 0.06) as the material of the reduced
    matpreview scene (tests/data/mitsuba/scenes/matpreview) reads (its description; building
    the scene, 8282 faces and an environment map, is left to the matpreview tests)."""
    import os

    from tests.render.test_mitsuba_xml_matpreview import DIR
    from tests.render.test_mitsuba_xml_matpreview import XML as MATPREVIEW

    with open(MATPREVIEW) as f:
        text = re.sub(r'<bsdf type="plastic" id="bsdf-matpreview">.*?</bsdf>',
                      '<bsdf type="pplastic" id="bsdf-matpreview"><rgb name="diffuse_reflectance" '
                      'value="0.05, 0.03, 0.1"/><float name="alpha" value="0.06"/></bsdf>',
                      f.read(), flags=re.S)  # fmt: skip
    for fn in os.listdir(DIR):
        if fn != "matpreview.xml":
            os.symlink(os.path.join(DIR, fn), tmp_path / fn)
    p = tmp_path / "m.xml"
    p.write_text(text)
    desc = read_xml(str(p), width=8, height=6).desc
    m = desc["materials"]["bsdf-matpreview"]
    assert (m["type"], m["alpha"], m["diffuse_reflectance"], m["one_sided"]) == (
        "pplastic", 0.06, [0.05, 0.03, 0.1], True)


def test_textured_transmittance(tmp_path):
    """A checkerboard ``transmittance`` (Mitsuba's default colours 0.4 / 0.2): a ``Textured``
    polarizer whose per-hit lobe weighs 0.5 × the texel."""
    import jax.numpy as jnp
    import numpy as np

    x, _ = _read(tmp_path, '<bsdf type="polarizer"><texture type="checkerboard" '
                           'name="transmittance"/></bsdf>')  # fmt: skip
    m = load_scene(x.desc).materials[0]
    assert isinstance(m, Textured) and isinstance(m.bsdf, Polarizer)
    uv = jnp.array([[0.25, 0.25], [0.75, 0.25]])
    s = m.at(uv).sample(jnp.array([0.0, 0.0, 1.0]), jnp.zeros(2), jnp.zeros((2, 2)))
    np.testing.assert_allclose(np.asarray(s.weight), [[0.2] * 3, [0.1] * 3], rtol=1e-6)
