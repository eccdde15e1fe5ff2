"""A rotated environment map (Mitsuba's envmap ``to_world``): lookup, importance sampling and
density in the map's frame, the YAML / XML readers and writers, gradients w.r.t. its texels
and scale, the unrotated program unchanged, and Mitsuba 3 rendering the same scene."""

from __future__ import annotations

import math
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.emitters import EnvironmentMap
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import ad_fd_per_key

MUSEUM = os.path.join(os.path.dirname(__file__), "..", "data", "mitsuba", "common", "textures",
                      "museum.exr")  # fmt: skip


def _rot_y(phi):
    """Rotation by ``phi`` about +y (right-handed)."""
    c, s = math.cos(phi), math.sin(phi)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _rot_axis(axis, deg):
    a = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = math.radians(deg)
    return np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * k @ k


def _image(h=8, w=16, seed=0):
    return np.random.default_rng(seed).random((h, w, 3)) + 0.05


def _dirs(n, seed=1):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    return jnp.asarray(d / np.linalg.norm(d, axis=1, keepdims=True))


def test_rotation_about_y_by_whole_texels_is_a_column_roll(x64):
    """Turning the map by ``phi = 2 pi k / W`` about +y moves every texel ``k`` columns: with
    ``u = atan2(d_x, -d_z) / 2 pi`` the local direction ``R^T d`` of a world direction at
    ``u`` is at ``u + k / W``, so the rotated map equals the unrotated map of the image rolled
    by ``-k`` columns: radiance and density, at random directions, under ``jit`` (independent
    reference: ``np.roll``)."""
    img, k = _image(), 3
    rot = EnvironmentMap.create(img, 1.7, _rot_y(2 * math.pi * k / img.shape[1]))
    rolled = EnvironmentMap.create(np.roll(img, -k, axis=1), 1.7)
    # the same program for both: the rolled map with an explicit identity rotation
    rolled = eqx.tree_at(lambda e: e.to_world, rolled, jnp.eye(3), is_leaf=lambda x: x is None)
    d = _dirs(500)
    f = jax.jit(lambda e, d: (e.eval(d), e.pdf(d)))
    (ea, pa), (eb, pb) = f(rot, d), f(rolled, d)
    np.testing.assert_allclose(ea, eb, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(pa, pb, rtol=1e-10)
    assert EnvironmentMap.create(img, 1.0, np.eye(4)).to_world is None


def _pdf_eval(env, u):
    wi = env.sample(u)[0]
    return env.pdf(wi), env.eval(wi)


def test_rotated_samples_are_consistent_and_unbiased(x64):
    """Samples of a map turned about a tilted axis: the returned density and radiance are
    ``pdf(wi)`` and ``eval(wi)`` at the returned (world) direction, and ``E[max(0, a.wi) /
    pdf] = pi`` for any unit ``a`` (the cosine integral), within 4 standard errors of the
    estimator."""
    r = _rot_axis([1.0, 1.0, 0.3], 70.0)
    env = EnvironmentMap.create(_image(seed=2), 2.0, r)
    u = jax.random.uniform(jax.random.key(3), (50_000, 2), jnp.float64)
    wi, pdf, li, pdf2, li2 = jax.jit(lambda e, u: (*e.sample(u), *_pdf_eval(e, u)))(env, u)
    np.testing.assert_allclose(pdf, pdf2, rtol=1e-6)
    np.testing.assert_allclose(li, li2, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(jnp.linalg.norm(wi, axis=-1), 1.0, rtol=1e-12)
    for a in ([0.0, 1.0, 0.0], [0.6, -0.8, 0.0], [0.0, 0.0, -1.0]):
        f = np.asarray(jnp.maximum(wi @ jnp.asarray(a), 0.0) / pdf)
        se = f.std() / math.sqrt(len(f))
        assert abs(f.mean() - math.pi) < 4 * se, (a, f.mean(), se)


def test_bad_to_world_is_refused_naming_it():
    with pytest.raises(ValueError, match=r"emitters\[1\]\.to_world: expected a rotation"):
        load_scene(_scene(np.diag([2.0, 1.0, 1.0]).tolist()))
    with pytest.raises(ValueError, match=r"emitters\[1\]\.to_world: expected a finite 3x3"):
        load_scene(_scene([[1.0, 0.0], [0.0, 1.0]]))


def _scene(to_world=None, image=None, w=6):
    env = {"type": "envmap", "image": _image(4, 8, 4) if image is None else image, "scale": 1.5}
    if to_world is not None:
        env["to_world"] = to_world
    return {
        "camera": {"origin": [0, 0.6, 3], "target": [0, 0.4, 0], "fov": 40, "width": w,
                   "height": w},  # fmt: skip
        "shapes": [
            {"type": "sphere", "center": [-0.5, 0.4, 0], "radius": 0.4, "material": "d"},
            {"type": "sphere", "center": [0.5, 0.4, 0], "radius": 0.4, "material": "g"},
        ],
        "materials": {"d": {"type": "diffuse", "reflectance": 0.6},
                      "g": {"type": "roughconductor", "alpha": 0.3, "reflectance": 0.9}},
        "emitters": [{"type": "point", "position": [0, 3, 2], "intensity": 0.5}, env],
    }  # fmt: skip


def test_identity_rotation_lowers_to_the_same_program():
    """``to_world`` = identity is stored as none: the lowered program text is byte-identical to
    the scene without ``to_world`` (a real rotation is kept)."""

    def text(s):
        f = jax.jit(lambda s, k: render(s, k, spp=1, integrator="path", max_depth=1))
        return f.lower(s, jax.random.key(0)).as_text()

    assert text(load_scene(_scene(np.eye(4).tolist()))) == text(load_scene(_scene()))
    assert load_scene(_scene(_rot_y(0.5).tolist())).environment.to_world is not None


@pytest.mark.slow  # ~10-12 s process CPU each, measured under load 19 (2 compiles, 6² renders)
@pytest.mark.parametrize("integrator", ["path", "ptracer"])
def test_rotated_render_equals_the_rolled_image(integrator):
    """Path (envmap NEE + BSDF hits) and ptracer (environment emission) renders of the map
    turned by 2 texel columns about +y against renders of the unrotated map with its image
    rolled by -2 columns (the same light field): channel means of 4 independent renders each
    within 4 standard errors (the spread of both sets)."""
    img = _image(4, 8, 4)
    rot = load_scene(_scene(_rot_y(2 * math.pi * 2 / 8).tolist(), img))
    rolled = load_scene(_scene(None, np.roll(img, -2, axis=1)))
    f = jax.jit(lambda s, k: render(s, k, spp=8, integrator=integrator, max_depth=3))
    a = np.stack([np.asarray(f(rot, jax.random.key(i))).mean((0, 1)) for i in range(4)])
    b = np.stack([np.asarray(f(rolled, jax.random.key(50 + i))).mean((0, 1)) for i in range(4)])
    se = np.sqrt(a.var(0, ddof=1) / 4 + b.var(0, ddof=1) / 4)
    assert np.all(np.abs(a.mean(0) - b.mean(0)) < 4 * se + 1e-6), (a.mean(0), b.mean(0), se)
    assert np.all(np.isfinite(a)) and a.mean() > 0


def _loss(x, key, scene):
    """Mean of a 4x4 path render of the rotated map; ``x`` = (scale, texels...)."""
    env = scene.environment
    img = x[1:].reshape(env.image.shape)
    s = scene.replace("emitters.environment.scale", x[0]).replace("emitters.environment.image",
                                                                  img)  # fmt: skip
    return jnp.mean(render(s, key, spp=2, integrator="path", max_depth=2))


def _env_loss(x, key, env):
    """A light-sampling estimate (64 samples) of the cosine-weighted integral about a tilted
    axis of the rotated map; ``x`` = (scale, texels...)."""
    e = eqx.tree_at(lambda e: (e.scale, e.image), env, (x[0], x[1:].reshape(env.image.shape)))
    wi, pdf, li = e.sample(jax.random.uniform(key, (64, 2), x.dtype))
    cos = jnp.maximum(wi @ jnp.asarray([0.3, 0.8, -0.52], x.dtype), 0.0)
    return jnp.mean(li.sum(-1) * cos / pdf) + jnp.sum(e.eval(_dirs(16, 7).astype(x.dtype)))


@pytest.mark.slow  # ~5.5 s process CPU measured under load 19 (two compiled FD programs)
def test_emitter_texel_and_scale_gradients_match_finite_differences(x64):
    """Gradients of the rotated map's sampled radiance and lookup w.r.t. scale and its 2x4x3
    texels against central differences with the same keys in float64 (the sampling density
    is frozen, so the estimate is smooth in both): relative 1e-7 of the largest component."""
    img = _image(2, 4, 6)
    env = EnvironmentMap.create(img, 1.5, _rot_axis([0.2, 1.0, 0.5], 40.0))
    x = jnp.concatenate([jnp.array([1.5]), jnp.asarray(img).reshape(-1)])
    keys = jax.random.split(jax.random.key(0), 3)
    _, ad, fd = ad_fd_per_key(_env_loss, x, keys, 1e-5, args=(env,))
    assert np.all(np.isfinite(ad)) and np.abs(ad[:, 1:]).min() >= 0 and np.abs(ad).max() > 0
    np.testing.assert_allclose(ad, fd, atol=1e-7 * np.abs(fd).max())


@pytest.mark.slow  # ~13 s process CPU, load 19 (value+gradient, 2 x 25 perturbed renders)
def test_texel_and_scale_gradients_match_finite_differences(x64):
    """Reverse-mode gradients of a rotated map's render w.r.t. its scale and its 2x4x3 texels
    against central differences with the same keys (the render is linear in the texels for
    fixed sampled directions: the light-sampling density is frozen, the radiance is not), in
    float64: per key, relative 1e-6 of the largest component."""
    img = _image(2, 4, 6)
    scene = load_scene(_scene(_rot_axis([0.2, 1.0, 0.5], 40.0).tolist(), img, w=4))
    x = jnp.concatenate([jnp.array([1.5]), jnp.asarray(img).reshape(-1)])
    keys = jax.random.split(jax.random.key(0), 2)
    _, ad, fd = ad_fd_per_key(_loss, x, keys, 1e-5, args=(scene,))
    assert np.all(np.isfinite(ad)) and np.abs(ad).max() > 0
    np.testing.assert_allclose(ad, fd, atol=1e-6 * np.abs(fd).max())


def test_xml_reads_a_rotation_and_writes_it_back(tmp_path):
    from jaxgfx.io import write_exr
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    write_exr(str(tmp_path / "env.exr"), _image(4, 8).astype(np.float32))
    xml = tmp_path / "s.xml"
    xml.write_text(_XML.format(env="env.exr", rot='<rotate x="0.6" y="0.8" angle="50"/>',
                               w=8, spp=4))  # fmt: skip
    x = read_xml(str(xml))
    env = [e for e in x.desc["emitters"] if e["type"] == "envmap"][0]
    np.testing.assert_allclose(env["to_world"], _rot_axis([0.6, 0.8, 0], 50.0), atol=1e-6)
    scene = load_scene(x.desc)
    out = save_scene(scene, str(tmp_path / "w.xml"))
    env2 = [e for e in read_xml(out).desc["emitters"] if e["type"] == "envmap"][0]
    np.testing.assert_allclose(env2["to_world"], env["to_world"], atol=1e-6)
    # a scaling to_world: one error naming the file, line and parameter
    xml.write_text(_XML.format(env="env.exr", rot='<scale value="2"/>', w=8, spp=4))
    with pytest.raises(ValueError, match=r"s\.xml:\d+.*to_world.*must be a rotation"):
        read_xml(str(xml))


_XML = """<scene version="3.0.0">
    <integrator type="path"><integer name="max_depth" value="3"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="40"/>
        <transform name="to_world">
            <lookat origin="0, 0.6, 3" target="0, 0.4, 0" up="0, 1, 0"/>
        </transform>
        <film type="hdrfilm"><integer name="width" value="{w}"/>
            <integer name="height" value="{w}"/><rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    </sensor>
    <emitter type="envmap">
        <string name="filename" value="{env}"/>
        <transform name="to_world">{rot}</transform>
    </emitter>
    <bsdf type="diffuse" id="d"><rgb name="reflectance" value="0.6"/></bsdf>
    <bsdf type="roughconductor" id="g"><float name="alpha" value="0.3"/>
        <string name="distribution" value="ggx"/>
        <rgb name="specular_reflectance" value="0.9"/></bsdf>
    <shape type="sphere"><point name="center" value="-0.5, 0.4, 0"/>
        <float name="radius" value="0.4"/><ref id="d"/></shape>
    <shape type="sphere"><point name="center" value="0.5, 0.4, 0"/>
        <float name="radius" value="0.4"/><ref id="g"/></shape>
</scene>
"""


@pytest.mark.mitsuba
@pytest.mark.slow  # ~10 s process CPU, load 19 (32², jaxgfx and Mitsuba 8 x 32 spp each)
def test_rotated_museum_matches_mitsuba_same_run(tmp_path):
    """Mitsuba's museum HDRI turned by 70 degrees about (0.6, 0.8, 0) then 25 about z lighting a
    diffuse and a rough-conductor sphere (path, depth 3): jaxgfx's renders against Mitsuba 3's
    (scalar_rgb) in the same run; channel z and 4x4-block z from the spread of both sets of
    renders. (Unit axes: Mitsuba 3.9 does not normalise a ``rotate`` axis, so ``x="1"
    y="1"`` gives it a non-orthogonal matrix, where jaxgfx's reader normalises the axis.)"""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from tests.render.test_mitsuba_xml_render_projector import _ours, block_z

    rot = '<rotate x="0.6" y="0.8" angle="70"/><rotate z="1" angle="25"/>'
    xml = tmp_path / "rot.xml"
    xml.write_text(_XML.format(env=os.path.abspath(MUSEUM), rot=rot, w=32, spp=32))
    ours = _ours(str(xml), 32, 8)
    ms = mi.load_file(str(xml))
    theirs = np.stack([np.asarray(mi.render(ms, spp=32, seed=s), np.float64)[..., :3]
                       for s in range(8)])  # fmt: skip
    c = block_z(ours, theirs)
    print(c, ours.mean((0, 1, 2)), theirs.mean((0, 1, 2)))
    assert np.all(np.abs(c["z_mean"]) < 4), c
    assert c["z_rms"] < 1.5 and c["frac_3_5"] >= 0.97, c
