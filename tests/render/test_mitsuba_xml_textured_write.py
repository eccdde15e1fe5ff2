"""Textured materials in the Mitsuba writer (``save_scene`` / ``to_mitsuba_dict``).

Default tests: an XML scene with bitmap (8-bit sRGB PNG and float EXR) and checkerboard
textures on reflectance, roughness, a blend weight and a normal map's nested BSDF -> our load ->
save -> our load gives equal leaves; texels go to PNG when they are an 8-bit sRGB image, else
EXR; filter and wrap modes are kept; what Mitsuba cannot take is refused naming the field.
``mitsuba`` + ``slow``: Mitsuba 3 loads the saved XML and renders it like jaxgfx renders the
same scene (same run, tolerances from the per-seed standard errors).
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np
import pytest

from jaxgfx.io import write_exr, write_png
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba import scene_to_desc, to_mitsuba_dict
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene
from tests.render._mitsuba import assert_channels_and_blocks_agree as assert_agree
from tests.render._mitsuba import jaxgfx_replicates, mitsuba_fixture, mitsuba_replicates

XML = """<scene version="3.0.0">
  <sensor type="perspective"><float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0, 1.2, -4" target="0, 0.4, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film></sensor>
  <bsdf type="twosided" id="floor"><bsdf type="diffuse">
    <texture type="bitmap" name="reflectance"><string name="filename" value="albedo.png"/>
      <string name="filter_type" value="nearest"/><string name="wrap_mode" value="mirror"/>
    </texture></bsdf></bsdf>
  <bsdf type="roughconductor" id="metal"><string name="material" value="Al"/>
    <texture type="bitmap" name="alpha"><string name="filename" value="rough.exr"/>
      <string name="wrap_mode" value="clamp"/><boolean name="raw" value="true"/></texture></bsdf>
  <bsdf type="twosided" id="wall"><bsdf type="diffuse">
    <texture type="checkerboard" name="reflectance"><rgb name="color0" value="0.7, 0.2, 0.1"/>
      <rgb name="color1" value="0.1, 0.3, 0.6"/>
      <transform name="to_uv"><scale x="4" y="4"/></transform></texture></bsdf></bsdf>
  <bsdf type="blendbsdf" id="mix">
    <texture type="checkerboard" name="weight"><float name="color0" value="0.9"/>
      <float name="color1" value="0.1"/><transform name="to_uv"><scale value="3"/></transform>
    </texture>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.8, 0.2"/></bsdf>
    <bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf></bsdf>
  <bsdf type="normalmap" id="bumpy">
    <texture type="bitmap" name="normalmap"><string name="filename" value="normals.exr"/>
      <boolean name="raw" value="true"/></texture>
    <bsdf type="diffuse"><texture type="bitmap" name="reflectance">
      <string name="filename" value="albedo.png"/></texture></bsdf></bsdf>
  <shape type="rectangle" id="ground"><transform name="to_world"><rotate x="1" angle="-90"/>
    <scale value="3"/></transform><ref id="floor"/></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="3"/>
    <translate y="1" z="2"/></transform><ref id="wall"/></shape>
  <shape type="sphere"><point name="center" value="-0.7, 0.5, 0"/>
    <float name="radius" value="0.5"/><ref id="metal"/></shape>
  <shape type="sphere"><point name="center" value="0.7, 0.5, 0"/>
    <float name="radius" value="0.5"/><ref id="mix"/></shape>
  <shape type="sphere"><point name="center" value="0, 0.3, -1"/>
    <float name="radius" value="0.3"/><ref id="bumpy"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/>
    <translate y="3"/></transform>
    <emitter type="area"><rgb name="radiance" value="6, 6, 6"/></emitter></shape>
  <emitter type="constant"><rgb name="radiance" value="0.2, 0.2, 0.25"/></emitter>
</scene>
"""


def _files(folder):
    rng = np.random.default_rng(3)
    write_png(str(folder / "albedo.png"), rng.integers(20, 235, (6, 8, 3)).astype(np.uint8))
    write_exr(str(folder / "rough.exr"), rng.uniform(0.05, 0.6, (4, 5, 1)).astype(np.float32))
    n = rng.normal(0, 0.15, (5, 5, 3)) + [0, 0, 1]
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    write_exr(str(folder / "normals.exr"), (0.5 * n + 0.5).astype(np.float32))


@pytest.fixture
def xml(tmp_path):
    _files(tmp_path)
    p = tmp_path / "textured.xml"
    p.write_text(XML)
    return str(p)


def _assert_same_leaves(a, b):
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    assert ta == tb
    for x, y in zip(la, lb, strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-6, atol=1e-6)


def test_textured_scene_saves_and_loads_to_the_same_leaves(xml, tmp_path):
    scene = load_scene(xml)
    out = save_scene(scene, tmp_path / "out" / "saved.xml")
    back = load_scene(out)
    _assert_same_leaves(scene, back)
    # the description (file textures by path) saves to the same leaves too
    out2 = save_scene(read_xml(xml).desc, tmp_path / "out2" / "saved.xml")
    _assert_same_leaves(scene, load_scene(out2))
    with open(out) as f:
        text = f.read()
    # texels from the 8-bit sRGB PNG go back to PNG (non-raw), float ones to EXR (raw)
    files = sorted(p.name for p in (tmp_path / "out" / "saved_files").iterdir())
    assert files == ["materials_bumpy.exr", "materials_bumpy_bsdf_reflectance.png",
                     "materials_floor_reflectance.png", "materials_metal_alpha.exr"]  # fmt: skip
    assert text.count('<string name="filter_type" value="nearest"/>') == 1
    assert text.count('<string name="wrap_mode" value="mirror"/>') == 1
    assert text.count('<string name="wrap_mode" value="clamp"/>') == 1
    assert text.count('<texture type="checkerboard"') == 2


def test_textures_mitsuba_cannot_take_are_refused_naming_the_field():
    desc = {"camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 40, "width": 4,
                       "height": 4},
            "shapes": [{"type": "sphere", "center": [0, 0, 0], "radius": 1, "material": "p"}],
            "materials": {"p": {"type": "roughplastic", "alpha": {
                "type": "checkerboard", "color0": 0.1, "color1": 0.3}}}}  # fmt: skip
    with pytest.raises(NotImplementedError, match=r"materials\.p\.alpha: Mitsuba's roughplastic"):
        to_mitsuba_dict(desc)
    with pytest.raises(NotImplementedError, match=r"materials\.p\.alpha: Mitsuba's roughplastic"):
        to_mitsuba_dict(scene_to_desc(load_scene(desc)))


def test_scalar_checkerboards_are_read_and_written_with_mitsubas_eval_1_colours(xml, tmp_path):
    """Mitsuba's checkerboard gives a scalar parameter (``eval_1``) ``color0`` where its RGB
    ``eval`` gives ``color1`` (``swap_scalar_checkerboard``): the blend weight's colours are
    swapped on reading and swapped back on writing; the RGB wall checkerboard is not."""
    from jaxgfx.render.scene.mitsuba_conventions import swap_scalar_checkerboard

    mats = read_xml(xml).desc["materials"]
    assert mats["mix"]["weight"]["color0"] == [0.1] * 3
    assert mats["mix"]["weight"]["color1"] == [0.9] * 3
    assert mats["wall"]["reflectance"]["color0"] == [0.7, 0.2, 0.1]
    text = Path(save_scene(load_scene(xml), tmp_path / "saved.xml")).read_text()
    weight = text.split('name="weight">')[1].split("</texture>")[0].split()
    assert weight[:6] == ["<rgb", 'name="color0"', 'value="0.9,', "0.9,", '0.9"/>', "<rgb"]
    wall = text.split('name="reflectance">')[2].split()  # [1]: the floor's bitmap
    assert wall[:5] == ["<rgb", 'name="color0"', 'value="0.7,', "0.2,", '0.1"/>']
    bitmap = {"type": "bitmap", "file": "a.png"}
    assert swap_scalar_checkerboard(bitmap) is bitmap


mi = mitsuba_fixture()


K, SPP = 4, 64


@pytest.mark.mitsuba
def test_saved_textured_scene_renders_in_mitsuba_like_the_original_xml(mi, xml, tmp_path):
    """The writer's round trip: Mitsuba renders our load -> save of the XML like the XML itself
    (same seeds on both sides would correlate them: seeds 0..K-1 vs K..2K-1)."""
    out = save_scene(load_scene(xml), tmp_path / "saved.xml", spp=SPP, max_depth=3)
    with open(xml) as f:
        integ = '<integrator type="path"><integer name="max_depth" value="3"/></integrator>'
        orig = f.read().replace('<scene version="3.0.0">', '<scene version="3.0.0">' + integ)
    (tmp_path / "orig.xml").write_text(orig)
    for name in ("albedo.png", "rough.exr", "normals.exr"):
        (tmp_path / name).write_bytes((Path(xml).parent / name).read_bytes())
    a, b = (mitsuba_replicates(mi, mi.load_file(str(p)), K, SPP, seed0=s0)
            for p, s0 in ((tmp_path / "orig.xml", 0), (out, K)))  # fmt: skip
    assert_agree(a, b)


@pytest.mark.mitsuba
def test_mitsubas_checkerboard_eval_1_is_the_complement_of_its_eval(mi):
    """Records Mitsuba 3's behaviour the loader and writer follow: one checkerboard, scalar
    ``eval_1`` = ``color1`` where the RGB ``eval`` = ``color0`` (and vice versa); jaxgfx's
    ``Checkerboard`` gives ``eval``'s pattern."""
    import jax.numpy as jnp

    from jaxgfx.render.bsdf.textured import Checkerboard, texture_eval

    t = mi.load_dict({"type": "checkerboard", "color0": 0.9, "color1": 0.1,
                      "to_uv": mi.ScalarTransform4f().scale([3, 3, 1])})  # fmt: skip
    ours = Checkerboard(jnp.array([0.9]), jnp.array([0.1]), 3.0)
    uv = np.random.default_rng(0).uniform(0, 1, (64, 2))
    e, e1 = [], []
    for u in uv:
        si = mi.SurfaceInteraction3f()
        si.uv = mi.Point2f(*u)
        e.append(np.array(t.eval(si))[0])
        e1.append(t.eval_1(si))
    want = np.asarray(texture_eval(ours, jnp.asarray(uv)))[:, 0]
    np.testing.assert_allclose(e, want, rtol=1e-6)
    np.testing.assert_allclose(e1, 1.0 - want, rtol=1e-6)  # the other colour
    assert 10 < np.sum(want > 0.5) < 54


@pytest.mark.mitsuba
@pytest.mark.parametrize("mat", ["mix", "metal_checker"])
def test_scalar_checkerboard_bsdfs_evaluate_like_mitsubas(mi, mat, tmp_path):
    """The XML's checkerboard blend weight, and a checkerboard roughness on a conductor, as
    loaded by jaxgfx: ``Textured.at(uv).eval`` equals Mitsuba's ``eval`` of the same XML
    ``<bsdf>`` at the same uv and random upper-hemisphere directions. GGX (Beckmann differs by
    0.6 %: Mitsuba's rational fit of Lambda, docs/render_bsdf.md); rtol 1e-3 (float32; measured
    5e-7 blend, 6e-6 Al). Before the colours were swapped on reading, jaxgfx used the other
    colour at every uv (blend weights 0.9 / 0.1 exchanged: the scene's 3.4 % difference)."""
    import jax.numpy as jnp

    from jaxgfx.render.scene.load import material_from_desc

    if mat == "mix":
        frag = XML.split('<bsdf type="blendbsdf" id="mix">')[1].split("</bsdf></bsdf>")[0]
        frag = '<bsdf type="blendbsdf">' + frag + "</bsdf></bsdf>"
        ggx = '<bsdf type="roughconductor"><string name="distribution" value="ggx"/>'
        frag = frag.replace('<bsdf type="roughconductor">', ggx)
    else:
        frag = ('<bsdf type="roughconductor"><string name="material" value="Al"/>'
                '<string name="distribution" value="ggx"/>'
                '<texture type="checkerboard" name="alpha"><float name="color0" value="0.05"/>'
                '<float name="color1" value="0.5"/><transform name="to_uv"><scale value="3"/>'
                "</transform></texture></bsdf>")  # fmt: skip
    named = frag.replace("<bsdf ", '<bsdf id="m" ', 1)
    sensor = XML.split("</film></sensor>")[0] + "</film></sensor>"
    shape = '<shape type="sphere"><ref id="m"/></shape>'
    (tmp_path / "b.xml").write_text(sensor + named + shape + "</scene>")
    ours = material_from_desc(read_xml(str(tmp_path / "b.xml")).desc["materials"]["m"])
    theirs = mi.load_string(frag.replace("<bsdf ", '<bsdf version="3.0.0" ', 1))
    rng = np.random.default_rng(1)
    uv = rng.uniform(0, 1, (200, 2))
    wo, wi = rng.normal(size=(2, 200, 3))
    wo[:, 2], wi[:, 2] = np.abs(wo[:, 2]), np.abs(wi[:, 2])  # upper hemisphere
    wo, wi = (v / np.linalg.norm(v, axis=1, keepdims=True) for v in (wo, wi))
    fm = []
    for u, a, c in zip(uv, wo, wi, strict=True):
        si = mi.SurfaceInteraction3f()
        si.uv, si.wi = mi.Point2f(*u), mi.Vector3f(a)
        si.sh_frame = mi.Frame3f(mi.Normal3f(0, 0, 1))
        fm.append(np.array(theirs.eval(mi.BSDFContext(), si, mi.Vector3f(c))))
    fm = np.array(fm)
    f = jax.jit(lambda m, uv, a, c: m.at(uv).eval(a, c))(ours, jnp.asarray(uv), jnp.asarray(wo),
                                                         jnp.asarray(wi))  # fmt: skip
    np.testing.assert_allclose(np.asarray(f), fm, rtol=1e-3, atol=1e-6)


@pytest.mark.mitsuba
@pytest.mark.slow  # slow: ~62-68 s on 2 cores (jaxgfx compile of the textured path program)
def test_saved_textured_scene_renders_in_mitsuba_like_jaxgfx(mi, xml, tmp_path):
    scene = load_scene(xml)
    out = save_scene(scene, tmp_path / "saved.xml", spp=SPP, max_depth=3)
    b = mitsuba_replicates(mi, mi.load_file(out), K, SPP)
    a = jaxgfx_replicates(scene, 11, K, spp=SPP, max_depth=3)
    zc, zb = assert_agree(a, b)
    print("textured channel means", a.mean((0, 1, 2)), b.mean((0, 1, 2)), "z", zc,
          "block |z|<4", np.mean(np.abs(zb) < 4))  # fmt: skip


