"""``normalmap`` and ``bumpmap`` against Mitsuba 3 (``mitsuba`` marker; skips without it).

* BSDF level: Mitsuba's plugins (``mi.load_dict``) evaluated at hand-made surface interactions
  (``uv``, ``dp/du``, ``dp/dv``, shading frame) against jaxgfx's wrappers with the same bitmap,
  both options on (Mitsuba's default) and off.
* Hit geometry: ``uv``, ``dp/du``, ``dp/dv`` and the shading tangent at rectangle and sphere hits
  against Mitsuba's ``ray_intersect``.
* Renders: the same XML scene (a diffuse rectangle or sphere under a point light) by both
  renderers with several independent seeds each; per 4x4 block, the difference of the two
  means is compared with the standard error estimated from each renderer's spread over its
  seeds (per-pixel variances pooled over the block), at a Šidák-corrected 1 % level.
"""

from __future__ import annotations

import math
from statistics import NormalDist

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.bsdf import BumpMap, Diffuse, NormalMap, RoughConductor, TangentSpace
from jaxgfx.render.bsdf.textured import texture_from_dict
from jaxgfx.render.geometry import intersect_scene
from jaxgfx.render.geometry.tangent import surface_tangents
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba_xml import read_xml

pytestmark = pytest.mark.mitsuba
mi = pytest.importorskip("mitsuba")

W = 32
SPP = 32
SEEDS = 6
ALBEDO = "0.2, 0.5, 0.8"


def _normal_map(path):
    """A 8x8 RGB map of normals tilted up to ~40 degrees in varying directions."""
    j, i = np.meshgrid(np.arange(8), np.arange(8))
    n = np.stack(
        [0.6 * np.sin(1.3 * j + 0.4), 0.5 * np.cos(0.9 * i + 0.2 * j), np.ones((8, 8))], -1
    )
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    mi.Bitmap(((n + 1) / 2).astype(np.float32)).write(str(path))


def _height_map(path):
    j, i = np.meshgrid(np.arange(8), np.arange(8))
    h = 0.5 + 0.5 * np.sin(0.8 * j) * np.cos(0.6 * i)
    mi.Bitmap(h[..., None].astype(np.float32)).write(str(path))


# --- BSDF level -------------------------------------------------------------------------------

N_DIRS = 300


def _dirs(rng, n):
    w = rng.normal(size=(n, 3))
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


def _mitsuba_eval_pdf(plugin, uv, dpdu, dpdv, S, T, wo, wi):
    """Mitsuba's ``eval`` / ``pdf`` with the shading frame ``(S, T, +z)`` (Mitsuba's
    ``initialize_sh_frame`` of ``dp/du``); ``wo`` (viewer), ``wi`` (light) in world = the local
    frame of jaxgfx."""
    ctx = mi.BSDFContext()
    f, p = np.zeros((len(wo), 3)), np.zeros(len(wo))
    loc = lambda v: mi.Vector3f(v @ S, v @ T, v[2])  # noqa: E731
    for k in range(len(wo)):
        si = mi.SurfaceInteraction3f()
        si.n = mi.Normal3f(0, 0, 1)
        si.sh_frame = mi.Frame3f(mi.Vector3f(*S), mi.Vector3f(*T), mi.Vector3f(0, 0, 1))
        si.uv = mi.Point2f(*uv[k])
        si.dp_du, si.dp_dv = mi.Vector3f(*dpdu), mi.Vector3f(*dpdv)
        si.wi = loc(wo[k])
        f[k] = np.array(plugin.eval(ctx, si, loc(wi[k])))
        p[k] = plugin.pdf(ctx, si, loc(wi[k]))
    return f, p


@jax.jit
def _ours_eval_pdf(m, uv, tg, wo, wi):
    mm = m.at(uv, tg)
    return mm.eval(wo, wi), mm.pdf(wo, wi)


@pytest.mark.parametrize("kind", ["normalmap", "bumpmap"])
@pytest.mark.parametrize("flags", [True, False])
@pytest.mark.parametrize("nested", ["diffuse", "roughconductor"])
def test_bsdf_level_matches_mitsuba(tmp_path, kind, flags, nested):
    """eval and pdf of the wrappers equal Mitsuba 3's plugins (float32 there: 2e-6 relative)
    at random uv and directions on a surface whose ``dp/du`` (length 2, turned 0.7 rad, with a
    normal component) and ``dp/dv`` are not orthonormal. Isotropic nested BSDFs: for
    ``bumpmap`` Mitsuba builds the tangent from world-space ``dp/du`` (docs/render.md)."""
    mi.set_variant("scalar_rgb")
    rng = np.random.default_rng(7)
    if kind == "normalmap":
        _normal_map(tmp_path / "m.exr")
    else:
        _height_map(tmp_path / "m.exr")
    tex_d = {"type": "bitmap", "filename": str(tmp_path / "m.exr"), "raw": True}
    nest_d = {
        "diffuse": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.5, 0.8]}},
        "roughconductor": {"type": "roughconductor", "alpha": 0.3, "distribution": "ggx",
                           "material": "none"},
    }[nested]  # fmt: skip
    ours_nested = {"diffuse": Diffuse(jnp.array([0.2, 0.5, 0.8])),
                   "roughconductor": RoughConductor(0.3)}[nested]  # fmt: skip
    opts = {"flip_invalid_normals": flags, "use_shadowing_function": flags}
    tex = texture_from_dict({"type": "bitmap", "file": str(tmp_path / "m.exr"), "raw": True},
                            channels=3 if kind == "normalmap" else 1)  # fmt: skip
    if kind == "normalmap":
        plugin = mi.load_dict({"type": kind, "normalmap": tex_d, "bsdf": nest_d, **opts})
        ours = NormalMap(ours_nested, tex, **opts)
    else:
        plugin = mi.load_dict({"type": kind, "h": tex_d, "scale": 0.3, "bsdf": nest_d, **opts})
        ours = BumpMap(ours_nested, tex, 0.3, **opts)
    a = 0.7
    dpdu = np.array([2 * math.cos(a), 2 * math.sin(a), 0.3])
    dpdv = np.array([-0.5 * math.sin(a) + 0.2, 0.5 * math.cos(a), -0.1])
    S = dpdu * [1, 1, 0] / np.linalg.norm(dpdu[:2])
    T = np.cross([0.0, 0.0, 1.0], S)
    uv = rng.uniform(size=(N_DIRS, 2))
    wo, wi = _dirs(rng, N_DIRS), _dirs(rng, N_DIRS)
    wo[:, 2] = np.abs(wo[:, 2])
    f_ref, p_ref = _mitsuba_eval_pdf(plugin, uv, dpdu, dpdv, S, T, wo, wi)
    du, dv = jnp.array([dpdu @ S, dpdu @ T]), jnp.array([dpdv @ S, dpdv @ T])
    tg = TangentSpace(s=jnp.asarray(S), t=jnp.asarray(T), du=du, dv=dv)
    tg = jax.tree.map(lambda x: jnp.broadcast_to(x, (N_DIRS, *x.shape)), tg)
    f, p = (np.asarray(x) for x in _ours_eval_pdf(ours, jnp.asarray(uv), tg, wo, wi))
    assert (f_ref[:, 1] > 0).mean() > 0.2
    np.testing.assert_allclose(f, f_ref, rtol=2e-5, atol=2e-6 * f_ref.max())
    np.testing.assert_allclose(p, p_ref, rtol=2e-5, atol=2e-6 * p_ref.max())
    # the options matter at these inputs (else the comparison could not tell them apart)
    other = {k: not v for k, v in opts.items()}
    alt = (NormalMap(ours_nested, tex, **other) if kind == "normalmap"
           else BumpMap(ours_nested, tex, 0.3, **other))  # fmt: skip
    f_alt = np.asarray(_ours_eval_pdf(alt, jnp.asarray(uv), tg, wo, wi)[0])
    assert np.abs(f_alt - f_ref).max() > 100 * 2e-6 * f_ref.max()


def _hit_and_tangents(shapes, o, d):
    hit = intersect_scene(shapes, o, d)
    return hit, surface_tangents(shapes, hit)


def test_hit_geometry_matches_mitsuba(tmp_path):
    """uv, dp/du, dp/dv, the shading tangent (dp/du projected, normalised) and the normal at
    hits on a scaled, rotated, translated rectangle and on a sphere equal Mitsuba's
    ``ray_intersect`` (float32 there)."""
    mi.set_variant("scalar_rgb")
    xml = """<scene version="3.0.0">
  <sensor type="perspective"><transform name="to_world">
    <lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform></sensor>
  <shape type="rectangle"><transform name="to_world"><scale x="1.5" y="0.7"/>
    <rotate x="1" angle="30"/><rotate z="1" angle="50"/><translate x="-1.2"/></transform></shape>
  <shape type="sphere"><point name="center" x="1.2" y="0.1" z="0"/>
    <float name="radius" value="0.8"/></shape>
</scene>"""
    path = tmp_path / "g.xml"
    path.write_text(xml)
    ms = mi.load_file(str(path))
    scene = load_scene(read_xml(str(path)).desc)
    rng = np.random.default_rng(0)
    o = np.array([0.0, 0.0, 5.0])
    tgt = np.stack([rng.uniform(-2.2, 2.2, 300), rng.uniform(-1, 1, 300), np.zeros(300)], -1)
    d = tgt - o
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    hit, (du, dv) = jax.jit(_hit_and_tangents)(
        scene.shapes, jnp.broadcast_to(jnp.asarray(o), d.shape), d
    )
    ng = np.asarray(hit.ng)
    seen = set()
    for k in range(len(d)):
        si = ms.ray_intersect(mi.Ray3f(mi.Point3f(*o), mi.Vector3f(*d[k])))
        assert bool(si.is_valid()) == bool(hit.valid[k])
        if not si.is_valid():
            continue
        seen.add(int(hit.shape_id[k]))
        s = np.asarray(du[k]) - (np.asarray(du[k]) @ ng[k]) * ng[k]
        s /= np.linalg.norm(s)
        for ours, theirs in ((hit.uv[k], si.uv), (du[k], si.dp_du), (dv[k], si.dp_dv),
                             (s, si.sh_frame.s), (ng[k], si.sh_frame.n)):  # fmt: skip
            np.testing.assert_allclose(np.asarray(ours), np.array(theirs), atol=1e-5)
    assert seen == {0, 1}


# --- renders ----------------------------------------------------------------------------------


def _scene(bsdf, shape):
    return f"""<scene version="3.0.0">
  <integrator type="direct"/>
  <sensor type="perspective">
    <float name="fov" value="50"/>
    <transform name="to_world"><lookat origin="0.2, -0.3, 2.6" target="0, 0, 0" up="0, 1, 0"/>
    </transform>
    <sampler type="independent"><integer name="sample_count" value="{SPP}"/></sampler>
    <film type="hdrfilm"><integer name="width" value="{W}"/><integer name="height" value="{W}"/>
      <rfilter type="box"/></film>
  </sensor>
  <emitter type="point"><point name="position" x="0.6" y="0.4" z="1.2"/>
    <rgb name="intensity" value="3"/></emitter>
  <shape type="{shape}">{bsdf}</shape>
</scene>"""


def _mean_and_se(imgs, b=4):
    """Per-block mean over seeds and its standard error (per-pixel variances over the seeds,
    pooled over the block's pixels, which are independent)."""
    blocks = lambda a: a.reshape(W // b, b, W // b, b, 3).mean((1, 3))  # noqa: E731
    var_pix = imgs.var(0, ddof=1)  # one seed's estimate
    return blocks(imgs.mean(0)), np.sqrt(blocks(var_pix) / (b * b) / len(imgs))


def _z(diff, se):
    """diff / se; 0 where both are 0 (blocks of background: no noise and no difference)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((diff == 0) & (se == 0), 0.0, diff / se)


def _mitsuba(tmp_path, bsdf, shape):
    mi.set_variant("scalar_rgb")
    path = tmp_path / "scene.xml"
    path.write_text(_scene(bsdf, shape))
    ms = mi.load_file(str(path))
    return np.stack([np.asarray(mi.render(ms, spp=SPP, seed=s), np.float64)[..., :3]
                     for s in range(SEEDS)])  # fmt: skip


def _ours(tmp_path, bsdf, shape):
    path = tmp_path / "scene.xml"
    path.write_text(_scene(bsdf, shape))
    x = read_xml(str(path))
    scene = load_scene(x.desc)
    f = jax.jit(lambda k: render(scene, k, spp=SPP, integrator=x.integrator,
                                 max_depth=x.max_depth))  # fmt: skip
    keys = jax.random.split(jax.random.key(1), SEEDS)
    return np.stack([np.asarray(f(k)) for k in keys]).astype(np.float64)


def _diffuse(extra=""):
    return f'<bsdf type="diffuse"><rgb name="reflectance" value="{ALBEDO}"/></bsdf>{extra}'


_NM = """<bsdf type="normalmap">{opts}
      <texture name="normalmap" type="bitmap"><string name="filename" value="nm.exr"/>
        <boolean name="raw" value="true"/></texture>
      {inner}</bsdf>"""
_BM = """<bsdf type="bumpmap">
      <texture type="bitmap"><string name="filename" value="h.exr"/>
        <boolean name="raw" value="true"/></texture>
      <float name="scale" value="0.3"/>
      {inner}</bsdf>"""
_OFF = ('<boolean name="flip_invalid_normals" value="false"/>'
        '<boolean name="use_shadowing_function" value="false"/>')  # fmt: skip

CASES = {
    "normalmap-rectangle": (_NM.format(opts="", inner=_diffuse()), "rectangle"),
    "normalmap-options-off": (_NM.format(opts=_OFF, inner=_diffuse()), "rectangle"),
    "bumpmap-rectangle": (_BM.format(inner=_diffuse()), "rectangle"),
    "normalmap-sphere": (_NM.format(opts="", inner=_diffuse()), "sphere"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_mapped_scene_matches_mitsuba(tmp_path, case):
    """Block means agree within the Monte Carlo error: every |z| (64 blocks x 3 channels) and
    the channel means' |z| below the Šidák-corrected two-sided 1 % bound. The test can fail:
    Mitsuba's image without the map, and with ``flip_invalid_normals`` /
    ``use_shadowing_function`` toggled, is far outside that bound from jaxgfx's."""
    bsdf, shape = CASES[case]
    _normal_map(tmp_path / "nm.exr")
    _height_map(tmp_path / "h.exr")
    ours, ref = _ours(tmp_path, bsdf, shape), _mitsuba(tmp_path, bsdf, shape)
    m_o, se_o = _mean_and_se(ours)
    m_r, se_r = _mean_and_se(ref)
    se = np.sqrt(se_o**2 + se_r**2)
    z = _z(m_o - m_r, se)
    n_tests = z.size + 3
    bound = NormalDist().inv_cdf(1 - (1 - 0.99 ** (1 / n_tests)) / 2)  # ~4.0
    se_c2 = (ours.var(0, ddof=1).mean((0, 1)) + ref.var(0, ddof=1).mean((0, 1))) / (W * W)
    z_c = _z(ours.mean((0, 1, 2)) - ref.mean((0, 1, 2)), np.sqrt(se_c2 / SEEDS))
    # power: Mitsuba without the map, and with the two options toggled, differ from jaxgfx
    flat = _mean_and_se(_mitsuba(tmp_path, _diffuse(), shape))[0]
    if "normalmap" in case:
        head = '<bsdf type="normalmap">'
        toggled = bsdf.replace(_OFF, "") if _OFF in bsdf else bsdf.replace(head, head + _OFF)
    else:
        toggled = bsdf.replace('<bsdf type="bumpmap">', '<bsdf type="bumpmap">' + _OFF)
    m_t = _mean_and_se(_mitsuba(tmp_path, toggled, shape))[0]
    z_flat, z_tog = np.abs(_z(flat - m_o, se)).max(), np.abs(_z(m_t - m_o, se)).max()
    print(case, "max |z| block", np.abs(z).max(), "channel z", z_c, "bound", bound,
          "max |block diff| / peak", np.abs(m_o - m_r).max() / m_r.max(),
          "vs no map max |z|", z_flat, "vs options toggled max |z|", z_tog)  # fmt: skip
    assert np.abs(z).max() < bound
    assert np.abs(z_c).max() < bound
    assert z_flat > 10 * bound
    assert z_tog > 2 * bound


def test_mitsuba_loads_the_saved_xml(tmp_path):
    """save_scene of normal- and bump-mapped materials writes XML that Mitsuba 3 loads into
    twosided normalmap / bumpmap plugins holding the same texels, nested parameters and scale
    (the options are not exposed by ``mi.traverse``; the jaxgfx round trip checks them)."""
    from jaxgfx.render.scene.mitsuba_xml import save_scene
    from tests.render.test_bsdf_normalmap import _mapped_scene_desc

    mi.set_variant("scalar_rgb")
    desc = _mapped_scene_desc(tmp_path)
    xml = save_scene(desc, tmp_path / "out" / "s.xml", base_dir=str(tmp_path))
    ms = mi.load_file(xml)
    p = mi.traverse(ms)
    scene = load_scene(desc, base_dir=str(tmp_path))
    mats = dict(zip(scene.material_names, scene.materials, strict=True))
    np.testing.assert_allclose(np.array(p["m.brdf_0.normalmap.data"]),
                               np.asarray(mats["m"].normalmap.image), rtol=1e-7)  # fmt: skip
    np.testing.assert_allclose(np.array(p["b.brdf_0.nested_texture.data"]),
                               np.asarray(mats["b"].height.image), rtol=1e-7)  # fmt: skip
    np.testing.assert_allclose(np.array(p["m.brdf_0.nested_bsdf.reflectance.value"]),
                               [0.2, 0.5, 0.8], rtol=1e-6)  # fmt: skip
    assert float(p["b.brdf_0.scale"]) == pytest.approx(0.4)
    assert float(p["b.brdf_0.nested_bsdf.alpha.value"]) == pytest.approx(0.2)
    # the load_dict path (render_mitsuba) too
    from jaxgfx.render.scene.mitsuba import to_mitsuba_dict

    d = to_mitsuba_dict(desc, base_dir=str(tmp_path), work_dir=tmp_path / "w", mi=mi)
    assert mi.traverse(mi.load_dict(d))["shape_0.bsdf.brdf_0.normalmap.data"].shape == (3, 4, 3)
    heads = sorted(str(s.bsdf()).split("\n")[1].strip() for s in ms.shapes())
    assert [str(s.bsdf()).startswith("TwoSided[") for s in ms.shapes()] == [True, True]
    assert heads == ["brdf[0] = BumpMap[", "brdf[0] = NormalMap["]
