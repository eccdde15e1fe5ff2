"""Mitsuba 3's ``batch`` sensor (:class:`jaxgfx.render.camera.BatchCamera`): its rays are the
sub-cameras' rays, its render the sub-renders side by side, the XML reader / writer, gradients
of a sub-camera's parameters, and a same-run comparison with Mitsuba 3."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.camera import BatchCamera, MatrixCamera, PerspectiveCamera, ThinLensCamera
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import ad_fd_per_key
from tests.render._scenes import sensor_test_xml

_A = {"origin": [0, 1.5, 4], "target": [0, 0.4, 0], "fov": 45, "width": 4, "height": 3}
_B = {"origin": [2.5, 3, 0.5], "target": [0, 0, 0], "fov": 70, "width": 4, "height": 3}
_BASE = {
    "shapes": [
        {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5, "material": "m"},
        {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0], "size": [4, 4],
         "material": "m"},
    ],
    "materials": {"m": {"type": "diffuse", "reflectance": 0.5}},
    "emitters": [{"type": "constant", "radiance": [0.5, 1.0, 1.5]},
                 {"type": "point", "position": [1, 3, 1], "intensity": 4.0}],
    "film": {"filter": "box"},
}  # fmt: skip


def _batch(*cams):
    return load_scene({**_BASE, "camera": {"type": "batch", "cameras": list(cams)}})


def test_batch_rays_are_the_sub_cameras_rays():
    """Pixel ``(x, y)`` of sub-image ``i`` is camera ``i``'s pixel ``(x - i w, y)`` (same
    operations on the same numbers: equal to float32 rounding of ``x - i w``), a thin lens gets
    the first two lens numbers, and samples beyond the image belong to the first / last
    camera (Mitsuba clamps the index); under ``jit``."""
    a = PerspectiveCamera.look_at([0, 0, 0], [0, 0, -1], [0, 1, 0], 60.0, 4, 3)
    b = ThinLensCamera.look_at([1, 0, 0], [1, 2, -1], [0, 1, 0], 40.0, 4, 3,
                               aperture_radius=0.2, focus_distance=2.0)  # fmt: skip
    m = np.diag([2.0, 1.5, 1.0, 1.0])
    m[2, 3] = 3.0  # an orthographic view_proj_inverse: affine
    c = MatrixCamera.from_matrix(m, 4, 3)
    cam = BatchCamera.create([a, b, c])
    assert (cam.width, cam.height, cam.lens_uniforms) == (12, 3, 2)
    rng = np.random.default_rng(0)
    px = rng.uniform([-0.5, 0.0], [12.5, 3.0], (64, 2)).astype(np.float32)
    u = rng.uniform(size=(64, 2)).astype(np.float32)

    def rays(cam, p, u):  # the batch's rays, and each camera's at p shifted by its offset
        sh = [p - jnp.asarray([4.0 * i, 0.0], p.dtype) for i in range(3)]
        a, b, c = cam.cameras
        return cam.generate_ray(p, u), (a.generate_ray(sh[0]), b.generate_ray(sh[1], u),
                                        c.generate_ray(sh[2]))  # fmt: skip

    (o, d), subs = jax.jit(rays)(cam, px, u)
    for i in range(3):
        sel = np.clip(np.floor(px[:, 0] / 4), 0, 2) == i
        assert sel.sum() > 10
        oi, di = subs[i][0][sel], subs[i][1][sel]
        np.testing.assert_allclose(o[sel], oi, atol=1e-5)
        np.testing.assert_allclose(d[sel], di, atol=1e-5)
    assert np.all(np.isfinite(o)) and np.all(np.isfinite(d))


_R = jax.jit(lambda s, k: render(s, k, spp=64, integrator="path", max_depth=2))


@pytest.mark.slow  # slow: ~8 s on 2 cores, load 4.6 (2 compiles, 3 x 4 renders of 96 pixels)
def test_batch_render_is_the_single_renders_side_by_side():
    """The batch's image against the two single-camera images concatenated: not the same
    random numbers (the sample layout is the whole image's), so per pixel and channel
    ``z = (mean_batch - mean_single) / se`` over 4 keys x 64 spp each (se from both
    spreads): RMS of z below 1.5 and every |z| below 5 (288 values); the images differ from
    each other where the cameras see different things (the test can fail)."""
    keys = jax.random.split(jax.random.key(0), 4)
    batch = np.stack([np.asarray(_R(_batch(_A, _B), k), np.float64) for k in keys])
    singles = np.stack([np.concatenate([np.asarray(_R(load_scene({**_BASE, "camera": c}), k),
                                                   np.float64) for c in (_A, _B)], axis=1)
                        for k in jax.random.split(jax.random.key(1), 4)])  # fmt: skip
    assert batch.shape == singles.shape == (4, 3, 8, 3)
    se = np.sqrt(batch.var(0, ddof=1) / 4 + singles.var(0, ddof=1) / 4) + 1e-12
    z = (batch.mean(0) - singles.mean(0)) / se
    print(np.sqrt(np.mean(z**2)), np.abs(z).max())
    assert np.sqrt(np.mean(z**2)) < 1.5 and np.abs(z).max() < 5
    swapped = np.concatenate([singles[:, :, 4:], singles[:, :, :4]], axis=2)  # can it fail?
    assert np.abs((batch.mean(0) - swapped.mean(0)) / se).max() > 10


def test_batch_ray_gradients_match_finite_differences(x64):
    """d/d(camera 1's origin, fov, aperture, focus) of a weighted sum of the batch's rays
    (samples in both halves: camera 0's must not depend on them) against central differences
    in float64; rays of pixels on the seam and beyond the image are finite."""
    a = PerspectiveCamera.look_at([0, 0, 0], [0, 0, -1], [0, 1, 0], 60.0, 4, 3)
    b = ThinLensCamera.look_at([1, 0, 0], [1, 2, -1], [0, 1, 0], 40.0, 4, 3,
                               aperture_radius=0.2, focus_distance=2.0)  # fmt: skip
    rng = np.random.default_rng(1)
    px = jnp.asarray(np.concatenate([rng.uniform([0, 0], [8, 3], (16, 2)),
                                     [[4.0, 1.0], [-3.0, 1.0], [11.0, 2.0]]]))  # fmt: skip
    u = jnp.asarray(rng.uniform(size=(19, 2)))
    w = jnp.asarray(rng.normal(size=(19, 6)))

    def loss(x):
        bb = eqx.tree_at(lambda c: (c.origin, c.fov, c.aperture_radius, c.focus_distance), b,
                         (x[:3], x[3], x[4], x[5]))  # fmt: skip
        o, d = BatchCamera.create([a, bb]).generate_ray(px, u)
        return jnp.sum(w * jnp.concatenate([o, d], -1))

    x = jnp.concatenate([b.origin, jnp.stack([b.fov, b.aperture_radius, b.focus_distance])])
    x = x.astype(jnp.float64)
    ad = jax.jit(jax.grad(loss))(x)
    h = 1e-6
    steps = jnp.concatenate([jnp.eye(6), -jnp.eye(6)]) * h
    f = jax.jit(jax.vmap(lambda e: loss(x + e)))(steps)
    fd = np.asarray(f[:6] - f[6:]) / (2 * h)
    assert np.all(np.isfinite(ad)) and np.abs(ad).min() > 0
    np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-9)


def _depth_loss(x, key, scene):
    """The ``aov`` channels (depth, position, normals of the first hits: smooth in the
    camera's origin and field of view) of both sub-images."""
    s = scene.replace("camera.cameras.1.origin", x[:3]).replace("camera.cameras.1.fov", x[3])
    return jnp.sum(render(s, key, spp=1, integrator="aov"))


@pytest.mark.slow  # slow: ~7 s on 2 cores, load 4.6 (aov value + gradient, 16 perturbed renders)
def test_batch_render_gradients_match_finite_differences(x64):
    """AD against central differences (same keys) of camera 1's ``origin`` and ``fov``
    through a batch render (float64; the floor and sphere fill both sub-images)."""
    s = _batch({**_A, "width": 2, "height": 2}, {**_B, "width": 2, "height": 2})
    paths = [q.path for q in s.parameters()]
    assert paths[:8] == [f"camera.cameras.{i}.{f}" for i in (0, 1)
                         for f in ("origin", "target", "up", "fov")]  # fmt: skip
    x = jnp.concatenate([s.camera.cameras[1].origin, s.camera.cameras[1].fov[None]])
    _, ad, fd = ad_fd_per_key(_depth_loss, x.astype(jnp.float64),
                              jax.random.split(jax.random.key(2), 2), 1e-6,
                              args=(s,))  # fmt: skip
    assert np.abs(ad).max() > 0
    np.testing.assert_allclose(ad, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def test_bad_batches_are_refused_naming_the_field():
    with pytest.raises(ValueError, match=r"camera\.cameras\.1: every camera of a batch has "
                                         r"the same size, got 5 x 3 and 4 x 3"):  # fmt: skip
        _batch(_A, {**_B, "width": 5})
    with pytest.raises(ValueError, match=r"camera\.cameras\.0\.type: a batch holds"):
        _batch({"type": "radiancemeter", "origin": [0, 1, 0], "direction": [0, 0, 1]})
    with pytest.raises(ValueError, match=r"camera\.cameras: expected a non-empty list"):
        _batch()
    with pytest.raises(ValueError, match=r"camera\.cameras\.1\.fov"):
        _batch(_A, {**_B, "fov": 190})


_SENSOR = """<sensor type="batch">
        <sensor type="perspective" name="first">
            <float name="fov" value="45"/>
            <transform name="to_world">
                <lookat origin="0, 1.5, 4" target="0, 0.4, 0" up="0, 1, 0"/></transform>
        </sensor>
        <sensor type="thinlens">
            <float name="fov" value="50"/><string name="fov_axis" value="smaller"/>
            <float name="aperture_radius" value="0.05"/>
            <float name="focus_distance" value="4"/>
            <transform name="to_world">
                <lookat origin="3, 2, 2" target="0, 0.4, 0" up="0, 1, 0"/></transform>
            <film type="hdrfilm"><integer name="width" value="99"/></film>
        </sensor>
        <sensor type="orthographic">
            <transform name="to_world">
                <scale value="2"/><lookat origin="0, 4, 0.01" target="0, 0, 0" up="0, 0, -1"/>
            </transform>
        </sensor>{extra}
        <film type="hdrfilm"><integer name="width" value="{w}"/>
            <integer name="height" value="8"/><rfilter type="box"/></film>
        <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    </sensor>
"""


def _xml(w=24, spp=16, extra=""):
    return sensor_test_xml(_SENSOR.format(w=w, spp=spp, extra=extra))


def test_xml_reads_and_writes_the_batch(tmp_path):
    """Document order (the named sensor first), each nested sensor ``24 / 3`` x 8 whatever its
    own film says (so ``fov_axis="smaller"`` is the height's: ``y``), and the writer's
    ``batch`` reads back to the same cameras."""
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    p = tmp_path / "b.xml"
    p.write_text(_xml())
    x = read_xml(str(p))
    cams = x.desc["camera"]["cameras"]
    assert x.desc["camera"]["type"] == "batch" and x.spp == 16
    assert [c["width"] for c in cams] == [8, 8, 8] and [c["height"] for c in cams] == [8] * 3
    assert cams[0]["fov"] == 45 and cams[1]["aperture_radius"] == 0.05
    assert "view_proj_inverse" in cams[2]
    assert cams[1]["fov_axis"] == "x"  # 8 x 8: "smaller" is x (aspect not > 1)
    s = load_scene(x.desc)
    assert type(s.camera) is BatchCamera and (s.width, s.height) == (24, 8)
    assert [type(c) for c in s.camera.cameras] == [PerspectiveCamera, ThinLensCamera,
                                                   MatrixCamera]  # fmt: skip
    y = read_xml(save_scene(s, str(tmp_path / "w.xml")))
    assert y.desc["camera"]["type"] == "batch"
    for c, d in zip(cams, y.desc["camera"]["cameras"], strict=True):
        assert set(c) == set(d)
        for k in c:
            np.testing.assert_allclose(c[k], d[k], atol=1e-6) if k != "fov_axis" else None
    p.write_text(_xml(w=25))
    with pytest.raises(ValueError, match=r"b\.xml:\d+.*a batch of 3 sensors needs a film width "
                                         r"divisible by 3, got 25"):  # fmt: skip
        read_xml(str(p))
    p.write_text(_xml(extra='<sensor type="radiancemeter"/>'))
    with pytest.raises(ValueError, match=r"b\.xml:\d+.*sensor plugin 'radiancemeter' is not "
                                         r"supported in a batch"):  # fmt: skip
        read_xml(str(p))


@pytest.mark.mitsuba
@pytest.mark.slow  # slow: ~8 s on 2 cores, load 4.6 (8 + 16 Mitsuba and 8 jaxgfx renders x 256 spp)
def test_batch_matches_mitsuba_same_run(tmp_path):
    """The three-sensor batch (perspective, thin lens, orthographic; 24 x 8, box filter, path
    depth 3): mean of 8 jaxgfx renders against 8 Mitsuba 3 (scalar_rgb) renders of the same
    file (the light's black BSDF explicit: an emitting shape without one is black in Mitsuba
    3.9, grey in jaxgfx's reader, a difference outside this test). Each sub-image's channel
    means: |z| < 4 (z from both spreads); 2 x 2-pixel blocks:
    RMS of z below 1.5 (blocks that vary). And ``save_scene``'s ``batch`` file renders in
    Mitsuba as the original does (8 more renders, block z RMS below 1.5)."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

    spp = 256
    p = tmp_path / "b.xml"
    p.write_text(_xml(spp=spp))
    s = load_scene(read_xml(str(p)).desc)
    f = jax.jit(lambda s, k: render(s, k, spp=spp, integrator="path", max_depth=3))
    ours = np.stack([np.asarray(f(s, jax.random.key(i)), np.float64) for i in range(8)])
    ms = mi.load_file(str(p))
    theirs = np.stack([np.asarray(mi.render(ms, spp=spp, seed=i), np.float64)[..., :3]
                       for i in range(8)])  # fmt: skip
    assert ours.shape == theirs.shape == (8, 8, 24, 3)

    def z_of(a, b):
        """z of the means of 8 renders each; where neither varies (blocks that see only the
        constant environment) the means must be equal and z is left out."""
        diff, se = a.mean(0) - b.mean(0), np.sqrt(a.var(0, ddof=1) / 8 + b.var(0, ddof=1) / 8)
        assert np.all(np.abs(diff[se == 0]) < 1e-5)
        return diff[se > 0] / se[se > 0]

    for i in range(3):
        sub = (slice(None), slice(None), slice(8 * i, 8 * i + 8))
        zi = z_of(ours[sub].mean((1, 2)), theirs[sub].mean((1, 2)))
        print(i, ours[sub].mean((0, 1, 2)), theirs[sub].mean((0, 1, 2)), zi)
        assert np.all(np.abs(zi) < 4), zi

    def blocks(a):
        return a.reshape(8, 4, 2, 12, 2, 3).mean((2, 4))

    zb = z_of(blocks(ours), blocks(theirs))
    print("block z RMS", math.sqrt(np.mean(zb**2)), zb.size)
    assert math.sqrt(np.mean(zb**2)) < 1.5
    # the writer's `batch` renders in Mitsuba as the original file does
    ws = mi.load_file(save_scene(s, str(tmp_path / "w.xml"), spp=spp, max_depth=3))
    again = np.stack([np.asarray(mi.render(ws, spp=spp, seed=100 + i), np.float64)[..., :3]
                      for i in range(8)])  # fmt: skip
    zw = z_of(blocks(again), blocks(theirs))
    print("written: block z RMS", math.sqrt(np.mean(zw**2)))
    assert math.sqrt(np.mean(zw**2)) < 1.5
