"""Writing Mitsuba 3 XML (``save_scene``), the shared conventions table and named conductors.

Default tests (no Mitsuba): XML -> description -> XML -> description gives equal descriptions;
YAML scenes -> XML -> description keep their parameters; ``scene_to_desc`` of a built scene
rebuilds the same pytree; ``to_mitsuba_dict`` accepts every schema key; the stored
``CONDUCTOR_IOR`` values are recomputed from Mitsuba's spectral data (copies in
tests/data/mitsuba/ior, ORIGIN.md). ``mitsuba`` marker: Mitsuba 3.9.1 loads the written XML to
the same objects and renders it like jaxgfx renders the YAML (Monte Carlo tolerance), and its
named conductors equal the stored table.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax
import numpy as np
import pytest

from jaxgfx.config import read_yaml
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba import scene_to_desc, to_mitsuba_dict
from jaxgfx.render.scene.mitsuba_conventions import (
    CONDUCTOR_IOR,
    PLUGINS,
    conductor_ior_from_spd,
    rectangle_to_world,
)
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene, to_xml
from tests.render._mitsuba import (
    assert_channels_and_pixels_agree,
    jaxgfx_replicates,
    mitsuba_fixture,
    mitsuba_replicates,
)

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SCENES = os.path.join(ROOT, "configs", "scenes")
IOR_DIR = os.path.join(ROOT, "tests", "data", "mitsuba", "ior")

OBJ = """v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0.5
vt 0 0
vt 1 0
vt 1 1
vt 0 1
f 1/1 2/2 3/3
f 1/1 3/3 4/4
"""

XML = """<scene version="3.0.0">
  <default name="spp" value="4"/>
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <string name="fov_axis" value="y"/>
    <transform name="to_world"><lookat origin="0.3, 1, -6" target="0, 0.2, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="10"/>
    </film>
    <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
  </sensor>
  <integrator type="path"><integer name="max_depth" value="4"/></integrator>
  <bsdf type="twosided" id="gold"><bsdf type="roughconductor">
    <string name="material" value="Au"/><float name="alpha" value="0.2"/>
    <string name="distribution" value="ggx"/></bsdf></bsdf>
  <bsdf type="dielectric" id="glass"><string name="int_ior" value="water"/></bsdf>
  <bsdf type="roughplastic" id="plastic"><rgb name="diffuse_reflectance" value="0.2, 0.4, 0.6"/>
    <float name="alpha" value="0.3"/></bsdf>
  <shape type="sphere"><point name="center" value="0.5, 0.5, 0"/>
    <float name="radius" value="0.4"/><ref id="gold"/></shape>
  <shape type="sphere"><transform name="to_world"><scale value="0.3"/>
    <translate x="-0.8" y="0.3"/></transform><ref id="glass"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/>
    <matrix value="3 1 0 0  0 3 0 0  0 0 1 0  0 0 0 1"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.6, 0.5"/></bsdf></shape>
  <shape type="cube"><transform name="to_world"><scale value="0.2"/><rotate y="1" angle="30"/>
    <translate x="0.2" y="0.2" z="-1"/></transform><ref id="plastic"/></shape>
  <shape type="obj"><string name="filename" value="quad.obj"/>
    <transform name="to_world"><rotate z="1" angle="20"/><translate x="-1" z="1"/></transform>
    <ref id="plastic"/></shape>
  <shape type="disk"><transform name="to_world"><scale value="0.3"/><rotate x="1" angle="90"/>
    <translate y="2"/></transform>
    <emitter type="area"><rgb name="radiance" value="8, 7, 6"/></emitter></shape>
  <emitter type="point"><point name="position" value="1, 2, -1"/>
    <rgb name="intensity" value="3, 3, 3"/></emitter>
  <emitter type="constant"><rgb name="radiance" value="0.1, 0.2, 0.3"/></emitter>
</scene>
"""


def _write_xml(tmp_path):
    (tmp_path / "quad.obj").write_text(OBJ)
    p = tmp_path / "scene.xml"
    p.write_text(XML)
    return str(p)


def assert_same(a, b, where="desc", rtol=1e-6, atol=1e-6):
    """Recursive equality of two descriptions; numbers to rtol / atol (PLY is float32)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and sorted(a) == sorted(b), (where, sorted(a), sorted(b))
        for k in a:
            assert_same(a[k], b[k], f"{where}.{k}", rtol, atol)
    elif isinstance(a, (list, tuple)) and a and isinstance(a[0], dict):
        assert len(a) == len(b), (where, len(a), len(b))
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]", rtol, atol)
    elif isinstance(a, str) or isinstance(a, bool) or a is None:
        assert a == b, (where, a, b)
    else:
        x, y = np.asarray(a, np.float64), np.asarray(b, np.float64)
        assert x.shape == y.shape, (where, x.shape, y.shape)
        np.testing.assert_allclose(x, y, rtol=rtol, atol=atol, err_msg=where)


def test_xml_to_desc_to_xml_to_desc_is_the_same_description(tmp_path):
    src = _write_xml(tmp_path)
    first = read_xml(src)
    out = save_scene(first.desc, str(tmp_path / "out" / "again.xml"), spp=4, max_depth=4)
    second = read_xml(out)
    # mesh vertices and normals went through a float32 PLY: 1e-6 relative
    assert_same(first.desc, second.desc)
    assert (second.spp, second.integrator, second.max_depth, second.rr_depth) == (4, "path", 4, 5)
    # the generated files are next to the XML, referenced relatively
    text = Path(out).read_text()
    assert 'value="again_files/' in text and str(tmp_path) not in text
    # the named conductor became its RGB eta, k; the material names are the XML ids
    d = second.desc["materials"]
    assert d["gold"]["eta"] == pytest.approx(CONDUCTOR_IOR["Au"][0], rel=1e-6)
    assert {"gold", "glass", "plastic"} <= set(d)
    # a third pass writes the same file
    again = save_scene(second.desc, str(tmp_path / "out" / "again2.xml"), spp=4, max_depth=4)
    assert Path(again).read_text().replace("again2_files", "again_files") == text


def _small_yaml(name, size=16):
    desc = read_yaml(os.path.join(SCENES, f"{name}.yaml"))
    desc["camera"] = {**desc["camera"], "width": size, "height": size}
    return desc


@pytest.mark.parametrize("name", ["example", "inverse", "mesh"])
def test_yaml_scenes_to_xml_keep_every_parameter(tmp_path, name):
    desc = _small_yaml(name)
    out = save_scene(desc, str(tmp_path / f"{name}.xml"), base_dir=SCENES)
    back = read_xml(out).desc
    a, b = load_scene(desc, base_dir=SCENES), load_scene(back)
    for n in desc["materials"]:  # same material parameters under the same names
        assert_same(scene_to_desc(a)["materials"][n], scene_to_desc(b)["materials"][n], n)
    np.testing.assert_allclose(a.camera.origin, b.camera.origin, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(a.camera.fov, b.camera.fov, rtol=1e-6)
    da, db = (np.asarray(c.target - c.origin) for c in (a.camera, b.camera))  # XML: unit distance
    np.testing.assert_allclose(da / np.linalg.norm(da), db, rtol=1e-6, atol=1e-6)
    # the same geometry and emitters: every float leaf of the camera, lights and shapes
    la = [np.asarray(x) for x in jax.tree_util.tree_leaves((a.shapes, a.area_lights))]
    lb = [np.asarray(x) for x in jax.tree_util.tree_leaves((b.shapes, b.area_lights))]
    assert len(la) == len(lb)
    for x, y in zip(la, lb, strict=True):
        if x.dtype.kind == "f":
            np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-5)


def test_scene_to_desc_rebuilds_the_same_scene(tmp_path):
    s = load_scene(_small_yaml("example"), base_dir=SCENES)
    d = scene_to_desc(s)
    s2 = load_scene(d)
    fa, fb = jax.tree_util.tree_leaves(s), jax.tree_util.tree_leaves(s2)
    assert len(fa) == len(fb)
    for x, y in zip(fa, fb, strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-6, atol=1e-7)
    assert s2.material_names == ("metal", "glass", "floor", "__black__")  # the default again
    # and a Scene can be saved directly
    out = save_scene(s.replace("materials.metal.alpha", 0.45), str(tmp_path / "fitted.xml"))
    assert read_xml(out).desc["materials"]["metal"]["alpha"] == pytest.approx(0.45)


def test_to_mitsuba_dict_accepts_every_schema_key(tmp_path):
    eu, ev = [2.0, 0.0, 0.5], [0.0, 1.0, 0.0]
    tw = [[0, -1, 0, 1.0], [1, 0, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]
    desc = {
        "camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40, "width": 8, "height": 8},
        "shapes": [
            {"type": "rectangle", "center": [0, 1, 0], "edge_u": eu, "edge_v": ev},
            {
                "type": "mesh",
                "vertices": [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                "faces": [[0, 1, 2]],
                "normals": [[0, 0, 1]] * 3,
                "uvs": [[0, 0], [1, 0], [0, 1]],
                "translate": [1, 2, 3],
                "to_world": tw,
            },  # fmt: skip
        ],
    }
    d = to_mitsuba_dict(desc, work_dir=str(tmp_path))
    m = np.asarray(d["shape_0"]["to_world"])
    n = np.cross(eu, ev) / np.linalg.norm(np.cross(eu, ev))
    np.testing.assert_allclose(m[:3, :3], np.stack([np.array(eu) / 2, np.array(ev) / 2, n], 1))
    np.testing.assert_allclose(m[:3, 3], [0, 1, 0])
    np.testing.assert_allclose(m, rectangle_to_world([0, 1, 0], eu, ev))
    # to_world after translate (as schema.mesh_from_desc); normals and uvs in the PLY
    want = np.asarray(tw) @ np.array([[1, 0, 0, 1], [0, 1, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1.0]])
    np.testing.assert_allclose(np.asarray(d["shape_1"]["to_world"]), want)
    from jaxgfx.render.geometry import mesh_io

    ply = mesh_io.load_ply(d["shape_1"]["filename"])
    np.testing.assert_allclose(np.asarray(ply.uvs), [[0, 0], [1, 0], [0, 1]])
    np.testing.assert_allclose(np.asarray(ply.normals), [[0, 0, 1]] * 3)
    assert d["shape_1"]["face_normals"] is False


def test_to_xml_writes_each_value_kind():
    text = to_xml({"type": "scene", "s": {"type": "sphere", "radius": 0.1, "center": [1, 2, 3],
                   "bsdf": {"type": "ref", "id": "m"}, "flip_normals": False}})  # fmt: skip
    assert text.splitlines() == [
        '<scene version="3.0.0">',
        '    <shape type="sphere" id="s">',
        '        <float name="radius" value="0.1"/>',
        '        <point name="center" value="1.0, 2.0, 3.0"/>',
        '        <ref id="m"/>',
        '        <boolean name="flip_normals" value="false"/>',
        "    </shape>",
        "</scene>",
    ]


@pytest.mark.parametrize("name", ["Au", "Ag", "Al", "Cu", "Cr"])
def test_stored_conductor_iors_are_mitsubas_spectra_reduced_to_rgb(name):
    eta, k = conductor_ior_from_spd(IOR_DIR, name)
    np.testing.assert_allclose(CONDUCTOR_IOR[name][0], eta, rtol=1e-5)
    np.testing.assert_allclose(CONDUCTOR_IOR[name][1], k, rtol=1e-5)


def test_every_named_conductor_loads_from_xml(tmp_path):
    body = "".join(
        f'<shape type="sphere"><point name="center" value="{3 * i}, 0, 10"/>'
        f'<bsdf type="conductor" id="m{i}"><string name="material" value="{n}"/></bsdf></shape>'
        for i, n in enumerate(CONDUCTOR_IOR)
    )
    p = tmp_path / "c.xml"
    p.write_text(f'<scene version="3.0.0"><sensor type="perspective"/>{body}</scene>')
    mats = read_xml(str(p)).desc["materials"]
    for i, n in enumerate(CONDUCTOR_IOR):
        assert mats[f"m{i}"]["eta"] == list(CONDUCTOR_IOR[n][0])
        assert mats[f"m{i}"]["k"] == list(CONDUCTOR_IOR[n][1])
    assert len(CONDUCTOR_IOR) == 71 and ("bsdf", "conductor") in PLUGINS


# -------------------------------------------------------------------------------------------
# against Mitsuba 3


mi = mitsuba_fixture()


@pytest.mark.mitsuba
def test_named_conductors_equal_mitsubas(mi):
    worst = 0.0
    for name, (eta, k) in CONDUCTOR_IOR.items():
        p = mi.traverse(mi.load_dict({"type": "conductor", "material": name}))
        for got, want in ((p["eta.value"], eta), (p["k.value"], k)):
            err = np.abs(np.array(got) - np.array(want)) / np.maximum(np.abs(want), 0.05)
            worst = max(worst, float(err.max()))
    # Mitsuba integrates its own fit of the CIE 1931 CMFs, colour-science the tabulated ones:
    # measured max 2.9e-3 (relative, or absolute below 0.05; Cu) over the 71 names x 6 values
    assert worst < 5e-3, worst


@pytest.mark.mitsuba
def test_mitsuba_loads_the_written_xml_to_the_same_objects(mi, tmp_path):
    src = _write_xml(tmp_path)
    desc = read_xml(src).desc
    out = save_scene(desc, str(tmp_path / "w.xml"), spp=4)
    scene = mi.load_file(out)
    p = mi.traverse(scene)
    # the camera, the rectangle's and the mesh shapes' world-space vertices
    sensor = scene.sensors()[0]
    m = np.array(sensor.world_transform().matrix)
    cam = desc["camera"]
    np.testing.assert_allclose(m[:3, 3], cam["origin"], atol=1e-5)
    np.testing.assert_allclose(m[:3, 2], np.subtract(cam["target"], cam["origin"]), atol=1e-5)
    js = load_scene(desc)
    meshes = [s for s in js.shapes if hasattr(s, "faces") or hasattr(s, "mesh")]
    ours = sorted(np.asarray(getattr(s, "mesh", s).vertices).sum() for s in meshes)
    theirs = sorted(
        float(np.array(p[k]).sum())
        for k in p.keys()
        if k.endswith("vertex_positions") and "rectangle" not in k
    )
    assert len(theirs) == len(ours) and np.allclose(theirs, ours, rtol=1e-5, atol=1e-5)
    (key,) = [k for k in p.keys() if k.startswith("gold") and k.endswith("eta.value")]
    eta = np.array(p[key])
    np.testing.assert_allclose(eta, CONDUCTOR_IOR["Au"][0], rtol=1e-5)


K, SPP, RES = 4, 64, 16


def _jaxgfx_replicates(desc, base_dir, max_depth):
    return jaxgfx_replicates(load_scene(desc, base_dir=base_dir), 7, K, spp=SPP,
                             max_depth=max_depth)  # fmt: skip


@pytest.mark.mitsuba
@pytest.mark.slow  # 78 s measured here (32 s + 46 s; 16², 4 x 64 spp each side; compile dominates)
@pytest.mark.parametrize("name", ["example", "inverse"])
def test_yaml_scene_saved_as_xml_renders_in_mitsuba_like_jaxgfx(mi, tmp_path, name):
    desc = _small_yaml(name, RES)
    out = save_scene(desc, str(tmp_path / f"{name}.xml"), spp=SPP, max_depth=3, base_dir=SCENES)
    b = mitsuba_replicates(mi, mi.load_file(out), K, SPP)
    assert_channels_and_pixels_agree(_jaxgfx_replicates(desc, SCENES, 3), b)


# -------------------------------------------------------------------------------------------
# plastic and roughdielectric

NEW_BSDFS = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="35"/>
    <transform name="to_world"><lookat origin="0, 0.6, -5" target="0, 0.2, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
    </film></sensor>
  <bsdf type="plastic" id="shiny"><rgb name="diffuse_reflectance" value="0.1, 0.3, 0.6"/>
    <float name="int_ior" value="1.6"/><boolean name="nonlinear" value="true"/></bsdf>
  <bsdf type="roughdielectric" id="frosted"><float name="alpha" value="0.25"/>
    <string name="int_ior" value="water"/><rgb name="specular_transmittance" value="1, 0.9, 0.8"/>
  </bsdf>
  <bsdf type="roughdielectric" id="ggx_glass"><string name="distribution" value="ggx"/>
    <float name="alpha_u" value="0.15"/><float name="alpha_v" value="0.15"/>
    <float name="ext_ior" value="1.2"/><boolean name="sample_visible" value="false"/></bsdf>
  <shape type="sphere"><point name="center" value="-0.6, 0.3, 0"/>
    <float name="radius" value="0.5"/><ref id="shiny"/></shape>
  <shape type="sphere"><point name="center" value="0.6, 0.3, 0"/>
    <float name="radius" value="0.5"/><ref id="frosted"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/>
    <scale value="3"/><translate y="-0.2"/></transform><ref id="ggx_glass"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/>
    <translate y="3"/></transform>
    <emitter type="area"><rgb name="radiance" value="6, 6, 6"/></emitter></shape>
  <emitter type="constant"><rgb name="radiance" value="0.3, 0.35, 0.4"/></emitter>
</scene>
"""


def _new_bsdfs_xml(tmp_path):
    p = tmp_path / "new_bsdfs.xml"
    p.write_text(NEW_BSDFS)
    return str(p)


def test_plastic_and_roughdielectric_load_and_round_trip(tmp_path):
    from jaxgfx.render import bsdf as B
    from jaxgfx.render.scene.mitsuba_conventions import IOR_TABLE

    first = read_xml(_new_bsdfs_xml(tmp_path))
    m = first.desc["materials"]
    assert m["shiny"] == {"type": "plastic", "eta": pytest.approx(1.6 / IOR_TABLE["air"]),
                          "diffuse_reflectance": [0.1, 0.3, 0.6],
                          "specular_reflectance": [1.0] * 3, "nonlinear": True,
                          "one_sided": True}  # fmt: skip
    # Mitsuba's default distribution (beckmann) is stated: jaxgfx's own default is ggx
    fr = m["frosted"]
    assert (fr["type"], fr["distribution"], fr["alpha"]) == ("roughdielectric", "beckmann", 0.25)
    assert fr["eta"] == pytest.approx(IOR_TABLE["water"] / IOR_TABLE["air"])
    g = m["ggx_glass"]
    assert (g["distribution"], g["alpha"], g["sample_visible"]) == ("ggx", 0.15, False)
    assert g["eta"] == pytest.approx(IOR_TABLE["bk7"] / 1.2)
    scene = load_scene(first.desc)
    kinds = dict(zip(scene.material_names, map(type, scene.materials), strict=False))
    assert kinds["shiny"] is B.SmoothPlastic and kinds["frosted"] is B.RoughDielectric
    out = save_scene(first.desc, str(tmp_path / "out" / "again.xml"))
    text = Path(out).read_text()
    # not in twosided in the file: one-sided, written back as it was (no twosided wrapper)
    assert '<bsdf type="plastic" id="shiny">' in text and "twosided" not in text
    assert '<bsdf type="roughdielectric" id="frosted">' in text
    assert_same(first.desc, read_xml(out).desc)
    # a built scene saves the same materials (scene_to_desc reads the BSDF objects)
    back = read_xml(save_scene(scene, str(tmp_path / "built.xml"))).desc["materials"]
    for n in ("shiny", "frosted", "ggx_glass"):
        assert_same(back[n], m[n], n)


def test_anisotropic_roughdielectric_is_refused_with_its_place(tmp_path):
    p = tmp_path / "a.xml"
    p.write_text('<scene version="3.0.0"><sensor type="perspective"/>\n<shape type="sphere">'
                 '<bsdf type="roughdielectric" '
                 'id="r"><float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/>'
                 "</bsdf></shape></scene>")  # fmt: skip
    with pytest.raises(ValueError, match=r"a\.xml:2: <bsdf type='roughdielectric' id='r'>.*"
                                         r"anisotropic roughness is not supported"):  # fmt: skip
        read_xml(str(p))


@pytest.mark.mitsuba
def test_mitsuba_loads_plastic_and_roughdielectric_to_the_same_parameters(mi, tmp_path):
    desc = read_xml(_new_bsdfs_xml(tmp_path)).desc
    p = mi.traverse(mi.load_file(save_scene(desc, str(tmp_path / "w.xml"))))
    m = desc["materials"]
    # a one-sided material is written bare, a two-sided one inside `twosided` (brdf_0)
    pre = "shiny." if m["shiny"].get("one_sided") else "shiny.brdf_0."
    np.testing.assert_allclose(p[pre + "eta"], m["shiny"]["eta"], rtol=1e-6)
    np.testing.assert_allclose(p[pre + "diffuse_reflectance.value"],
                               m["shiny"]["diffuse_reflectance"], rtol=1e-6)  # fmt: skip
    for n in ("frosted", "ggx_glass"):
        np.testing.assert_allclose(p[f"{n}.eta"], m[n]["eta"], rtol=1e-6)
        np.testing.assert_allclose(p[f"{n}.alpha.value"], m[n]["alpha"], rtol=1e-6)
        np.testing.assert_allclose(p[f"{n}.specular_transmittance.value"],
                                   m[n]["specular_transmittance"], rtol=1e-6)  # fmt: skip


@pytest.mark.mitsuba
@pytest.mark.slow  # 50 s measured here (16², 4 x 64 spp each side, max_depth 6; compile dominates)
def test_plastic_and_roughdielectric_scene_renders_in_mitsuba_like_jaxgfx(mi, tmp_path):
    """The floor is rendered with ``sample_visible=true``: Mitsuba 3's roughdielectric with
    ``sample_visible=false`` draws normals from a widened alpha but weights them as if from the
    unwidened one, so its sample weight is not its eval / pdf and its floor is ~1.6 % brighter at
    grazing angles (tests/render/test_bsdf_mitsuba_plugins.py measures it; docs/render_mitsuba.md).
    jaxgfx renders the same image with either setting (the loading tests above keep ``false``)."""
    xml = NEW_BSDFS.replace('<boolean name="sample_visible" value="false"/>', "")
    assert xml != NEW_BSDFS
    p = tmp_path / "new_bsdfs.xml"
    p.write_text(xml)
    desc = read_xml(str(p)).desc
    assert desc["materials"]["ggx_glass"]["sample_visible"] is True
    out = save_scene(desc, str(tmp_path / "w.xml"), spp=SPP, max_depth=6)
    b = mitsuba_replicates(mi, mi.load_file(out), K, SPP)
    assert_channels_and_pixels_agree(_jaxgfx_replicates(desc, None, 6), b)


# -------------------------------------------------------------------------------------------
# principled

PRINCIPLED = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="35"/>
    <transform name="to_world"><lookat origin="0, 0.6, -5" target="0, 0.2, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
    </film></sensor>
  <bsdf type="principled" id="paint"><rgb name="base_color" value="0.8, 0.1, 0.05"/>
    <float name="metallic" value="0.2"/><float name="roughness" value="0.3"/>
    <float name="spec_tint" value="0.4"/><float name="sheen" value="0.5"/>
    <float name="sheen_tint" value="0.25"/><float name="clearcoat" value="0.9"/>
    <float name="clearcoat_gloss" value="0.7"/><float name="specular" value="0.6"/>
    <float name="spec_trans" value="0"/><float name="clearcoat_sampling_rate" value="0.5"/>
  </bsdf>
  <bsdf type="twosided" id="metal"><bsdf type="principled"><float name="metallic" value="1"/>
    <float name="eta" value="1.33"/>
    <texture type="checkerboard" name="base_color"><rgb name="color0" value="0.9, 0.6, 0.2"/>
    </texture></bsdf></bsdf>
  <bsdf type="principled" id="plain"/>
  <shape type="sphere"><float name="radius" value="0.5"/><ref id="paint"/></shape>
  <shape type="sphere"><point name="center" value="1, 0, 0"/><ref id="metal"/></shape>
  <shape type="sphere"><point name="center" value="-1, 0, 0"/><ref id="plain"/></shape>
  <emitter type="constant"/>
</scene>
"""


def test_principled_loads_and_round_trips(tmp_path):
    """Mitsuba's names and defaults; eta or specular; a textured base colour; the writer wraps
    it in twosided (one-sided in Mitsuba) and reads back to the same description."""
    from jaxgfx.render import bsdf as B

    p = tmp_path / "principled.xml"
    p.write_text(PRINCIPLED)
    first = read_xml(str(p))
    m = first.desc["materials"]
    paint = m["paint"]
    assert paint["type"] == "principled" and paint["base_color"] == [0.8, 0.1, 0.05]
    assert (paint["clearcoat"], paint["specular"], paint["clearcoat_sampling_rate"]) == (
        0.9, 0.6, 0.5)  # fmt: skip
    assert "eta" not in paint and "spec_trans" not in paint
    assert m["metal"]["eta"] == 1.33 and "specular" not in m["metal"]
    assert m["metal"]["base_color"]["type"] == "checkerboard"
    plain = m["plain"]  # Mitsuba's defaults
    assert (plain["base_color"], plain["roughness"], plain["specular"], plain["metallic"]) == (
        [0.5] * 3, 0.5, 0.5, 0.0)  # fmt: skip
    scene = load_scene(first.desc)
    kinds = dict(zip(scene.material_names, scene.materials, strict=False))
    assert isinstance(kinds["paint"], B.Principled) and type(kinds["metal"]).__name__ == "Textured"
    # untextured materials save and read back the same (textures are not exported)
    del first.desc["materials"]["metal"]
    first.desc["shapes"] = [s for s in first.desc["shapes"] if s.get("material") != "metal"]
    out = save_scene(first.desc, str(tmp_path / "out" / "again.xml"))
    text = Path(out).read_text()
    # paint is not in twosided in the file: one-sided, written back without the wrapper
    assert '<bsdf type="principled" id="paint">' in text and 'id="paint">' not in text.replace(
        '<bsdf type="principled" id="paint">', "")  # fmt: skip
    assert_same(first.desc, read_xml(out).desc)
    scene = load_scene(first.desc)
    back = read_xml(save_scene(scene, str(tmp_path / "built.xml"))).desc["materials"]
    for n in ("paint", "plain"):
        assert_same(back[n], m[n], n)


@pytest.mark.parametrize(
    "params,msg",
    [('<float name="eta" value="1.5"/><float name="specular" value="0.5"/>',
      "'eta': give either eta or specular"),
     ('<float name="subsurface" value="0.5"/>', "'subsurface' is not supported")],
)  # fmt: skip
def test_principled_refusals_name_the_parameter(tmp_path, params, msg):
    p = tmp_path / "a.xml"
    p.write_text('<scene version="3.0.0"><sensor type="perspective"/>\n<shape type="sphere">'
                 f'<bsdf type="principled" id="r">{params}</bsdf></shape></scene>')  # fmt: skip
    with pytest.raises(ValueError, match=r"<bsdf type='principled' id='r'>: parameter " + msg):
        read_xml(str(p))


def test_anisotropic_principled_export_is_refused_on_spheres():
    desc = {
        "camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "fov": 40, "width": 4, "height": 4},
        "materials": {"m": {"type": "principled", "anisotropic": 0.5}},
        "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1, "material": "m"}],
    }
    with pytest.raises(NotImplementedError, match="anisotropic 'm' on a sphere"):
        to_mitsuba_dict(desc)
    desc["materials"]["m"]["anisotropic"] = 0.0
    assert to_mitsuba_dict(desc)["shape_0"]["bsdf"]["bsdf"]["type"] == "principled"
