"""Mitsuba 3's ``aov`` integrator read from XML into jaxgfx's
:class:`~jaxgfx.render.integrators.AOVIntegrator` (chosen AOVs in Mitsuba's order, depth from
the near plane) and compared with Mitsuba rendering the same file."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba_xml import read_xml

_XML = """<scene version="3.0.0">
    <integrator type="aov"><string name="aovs" value="{aovs}"/></integrator>
    <sensor type="perspective"><float name="fov" value="40"/>
        <float name="near_clip" value="{near}"/>
        <transform name="to_world"><lookat origin="0, 1, 4" target="0, 0.3, 0" up="0, 1, 0"/>
        </transform>
        <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
            <rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
    </sensor>
    <shape type="sphere"><point name="center" value="0, 0.5, 0"/><float name="radius" value="0.5"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.6"/></bsdf></shape>
    <shape type="rectangle">
        <transform name="to_world"><scale value="3"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.7, 0.5, 0.3"/></bsdf></shape>
</scene>
"""
AOVS = "al:albedo,dd.y:depth,pp:position,gn:geo_normal,nn:sh_normal"


def _render(path, spp=64, k=4):
    x = read_xml(path)
    s = load_scene(x.desc)
    f = jax.jit(lambda s, key: render(s, key, spp=spp, integrator=x.integrator_spec))
    return np.stack([np.asarray(f(s, jax.random.key(i)), np.float64) for i in range(k)])


def test_reads_the_aovs_and_the_near_clip(tmp_path):
    """Channels in Mitsuba's order (albedo 3, depth 1, position 3, normals 3 + 3: 13); the
    depth starts at the near plane: an interior pixel's depth is ``t - near / cos`` with ``t``
    from the camera centre (checked against the same file read with near_clip 0.01 and the
    pixel's ray direction), under ``jit``; unsupported AOVs and nested integrators refused
    with file and line."""
    p = tmp_path / "a.xml"
    p.write_text(_XML.format(aovs=AOVS, near="1"))
    x = read_xml(str(p))
    assert x.integrator == "aov" and x.aovs == ("albedo", "depth", "position", "geo_normal",
                                               "sh_normal") and x.near_clip == 1.0  # fmt: skip
    img = _render(str(p), spp=1, k=1)[0]
    assert img.shape == (16, 16, 13)
    # the sphere's centre pixel: albedo, an outward normal facing the camera
    c = img[8, 8]
    np.testing.assert_allclose(c[:3], [0.2, 0.4, 0.6], rtol=1e-6)
    np.testing.assert_allclose(c[7:10], c[10:13], atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(c[7:10]), 1.0, rtol=1e-5)
    # depth: |p - eye| - near / cos(angle to the viewing axis)
    eye, fwd = np.array([0, 1, 4.0]), np.array([0, -0.7, -4.0])
    fwd /= np.linalg.norm(fwd)
    v = c[4:7] - eye
    t = np.linalg.norm(v)
    np.testing.assert_allclose(c[3], t - 1.0 / (v @ fwd / t), rtol=1e-5)
    p.write_text(_XML.format(aovs="al:albedo,ss:shape_index", near="1"))
    with pytest.raises(ValueError, match=r"a\.xml:\d+.*aovs.*'ss:shape_index'"):
        read_xml(str(p))


@pytest.mark.mitsuba  # ~2.2 s process CPU measured under load 17 (16², 8 x 64 spp each)
def test_aovs_match_mitsuba_same_run(tmp_path):
    """Both renderers sample the box pixel randomly, so a pixel's AOVs are means over its
    footprint: per-pixel means of 8 x 64 samples each, z from both spreads; a difference
    within float32 rounding (1e-5: e.g. the floor's normal x, exactly 0 here and ~1e-8 in
    Mitsuba's rotated rectangle) counts as 0; pixels where neither varies must agree to it."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    p = tmp_path / "a.xml"
    p.write_text(_XML.format(aovs=AOVS, near="1"))
    k = 8
    ours = _render(str(p), k=k)
    ms = mi.load_file(str(p))
    theirs = np.stack([np.asarray(mi.render(ms, spp=64, seed=i), np.float64) for i in range(k)])
    assert theirs.shape == ours.shape
    d = ours.mean(0) - theirs.mean(0)
    d = np.sign(d) * np.maximum(np.abs(d) - 1e-5, 0.0)
    se = np.sqrt(ours.var(0, ddof=1) / k + theirs.var(0, ddof=1) / k)
    exact = se == 0
    assert np.abs(d[exact]).max(initial=0) == 0
    z = d[~exact] / se[~exact]
    zc = [np.sqrt(np.mean((d[..., c][~exact[..., c]] / se[..., c][~exact[..., c]]) ** 2))
          for c in range(d.shape[-1])]  # fmt: skip
    print("exact", exact.mean(), "z rms", np.sqrt(np.mean(z**2)), "per channel",
          np.round(zc, 2), "frac<3.5", np.mean(np.abs(z) < 3.5))  # fmt: skip
    assert np.sqrt(np.mean(z**2)) < 1.5 and np.mean(np.abs(z) < 3.5) > 0.97
