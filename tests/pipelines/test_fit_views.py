"""Several views in one fit (issue 25): photos with their own camera pose share the scene's
materials and lights; each distinct pose is rendered once per step, the photos' losses summed.

Default tests check the config, the views and the loss's per-photo terms without compiling a
render; the render through stacked cameras, its gradient against finite differences, the
texture recovered from several views (and not from one) and the hostile case (a textured
mesh under a glossy sphere from JPEG photos through a camera curve) are slow-marked."""

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

from jaxgfx.io import write_exr, write_png
from jaxgfx.pipelines.fit import FitJob, prepare_fit, run_fit
from jaxgfx.pipelines.fit.job import tile_views
from jaxgfx.pipelines.fit.loss import (
    censored_linear_loss,
    photo_losses,
    render_views,
    stack_cameras,
)
from jaxgfx.render.camera import PerspectiveCamera

from ._helpers import fit_cfg

TEX = "materials.plane.reflectance.image"
POSES = [
    {"origin": [-0.7, 1.6, -0.7], "target": [-0.5, 0, -0.5], "up": [0, 0, -1], "fov": 42},
    {"origin": [0.7, 1.6, -0.7], "target": [0.5, 0, -0.5], "up": [0, 0, -1], "fov": 42},
    {"origin": [-0.7, 1.6, 0.7], "target": [-0.5, 0, 0.5], "up": [0, 0, -1], "fov": 42},
    {"origin": [0.7, 1.6, 0.7], "target": [0.5, 0, 0.5], "up": [0, 0, -1], "fov": 42},
]
"""Four views of the 2x2 plane, each seeing about a third of it (configs/multiview.yaml)."""


def _plane(tmp_path, texture, size):
    """A 2x2 plane with the albedo ``texture`` (nearest), lit straight down so that its
    radiance is the albedo (configs/scenes/multiview_plane.yaml), seen at ``size`` pixels."""
    scene = {
        "camera": {
            "origin": [0, 3, 0.01],
            "target": [0, 0, 0],
            "up": [0, 0, -1],
            "fov": 40,
            "width": size,
            "height": size,
        },
        "shapes": [
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 1, 0],
                "size": [2, 2],
                "material": "plane",
            }
        ],
        "materials": {
            "plane": {
                "type": "diffuse",
                "reflectance": {
                    "type": "bitmap",
                    "image": np.asarray(texture).tolist(),
                    "filter": "nearest",
                },
            }
        },
        "emitters": [{"type": "directional", "direction": [0, -1, 0], "irradiance": np.pi}],
    }
    path = tmp_path / "plane.yaml"
    path.write_text(yaml.safe_dump(scene))
    return str(path)


def _blocks(n, seed=3, blocks=4):
    rng = np.random.default_rng(seed)
    b = rng.uniform(0.1, 0.9, (blocks, blocks, 3))
    return np.kron(b, np.ones((n // blocks, n // blocks, 1)))


def _views_cfg(**over):
    return fit_cfg(
        {
            "target": {
                "synthetic": {"materials.metal.alpha": 0.15},
                "spp": 16,
                "views": [{}, {"origin": [1.5, 1.2, 3.7]}],
            }
        },
        **over,
    )


# ------------------------------------------------------------------- config and views


def test_synthetic_views_prepare_without_rendering():
    cam = {"response": "gamma", "gamma": 2.0, "exposures": [0.5, 2.0]}
    cfg = _views_cfg(
        target={
            "synthetic": {},
            "views": [{}, {"origin": [1.5, 1.2, 3.7], "fov": 30}],
            "camera": cam,
        },
        camera={"response": {"model": "gamma", "fit": True}},
    )
    prep = prepare_fit(cfg)
    assert prep.n_views == 2 and prep.n_targets == 4
    np.testing.assert_array_equal(prep.view_of, [0, 0, 1, 1])  # each view at every exposure
    np.testing.assert_allclose(prep.exposures, [1.0, 4.0, 1.0, 4.0])
    # view 0 is the scene's camera; view 1 the scene camera's description with origin and fov
    # replaced (configs/scenes/inverse.yaml: target (0, 0.6, 0), up y, 8x8 from render)
    ref = PerspectiveCamera.look_at([1.5, 1.2, 3.7], [0, 0.6, 0], [0, 1, 0], 30.0, 8, 8)
    v = prep.views[1]
    for f in ("origin", "target", "up", "fov"):
        np.testing.assert_allclose(np.asarray(getattr(v, f)), np.asarray(getattr(ref, f)))
    assert (v.width, v.height) == (8, 8)
    np.testing.assert_allclose(np.asarray(prep.views[0].origin), [0, 1.2, 4])
    assert prep.view_poses == [{}, {"origin": [1.5, 1.2, 3.7], "fov": 30}]


def _pngs(tmp_path, sizes):
    out = []
    for i, (w, h) in enumerate(sizes):
        p = tmp_path / f"v{i}.png"
        write_png(p, np.full((h, w, 3), 60 + 40 * i, np.uint8))
        out.append(str(p))
    return out


def test_photos_of_one_pose_share_a_view(tmp_path):
    p = _pngs(tmp_path, [(8, 8)] * 4)
    pose = {"origin": [1.5, 1.2, 3.7]}
    cfg = fit_cfg(
        target=[
            {"file": p[0], "exposure": 1.0, "view": pose},
            {"file": p[1], "exposure": 2.0, "view": dict(pose)},  # a bracket of that view
            {"file": p[2], "exposure": 1.0},  # the scene's camera
            {"file": p[3], "exposure": 1.0, "view": {"origin": [-1.5, 1.2, 3.7]}},
        ],
        camera={"response": "srgb"},
    )
    prep = prepare_fit(cfg)
    assert prep.n_views == 3
    np.testing.assert_array_equal(prep.view_of, [0, 0, 1, 2])
    np.testing.assert_allclose(prep.exposures, [1, 2, 1, 1])
    np.testing.assert_allclose(np.asarray(prep.views[1].origin), [0, 1.2, 4])
    # one photo per view needs no exposure (all equal); a bracket of a view does
    prep = prepare_fit(
        fit_cfg(target=[{"file": p[0]}, {"file": p[1], "view": pose}], camera={"response": "srgb"})
    )
    np.testing.assert_allclose(prep.exposures, [1, 1])
    with pytest.raises(ValueError, match=r"target\[0\]: .*v0.png: no exposure information"):
        prepare_fit(
            fit_cfg(
                target=[{"file": p[0], "view": pose}, {"file": p[1], "view": pose}],
                camera={"response": "srgb"},
            )
        )


@pytest.mark.parametrize(
    "pose, match",
    [
        (
            {"width": 16},
            r"target\[1\].view: unknown key\(s\) \['width'\]; a view takes the scene "
            r"camera's keys .*its size is the scene camera's",
        ),
        ({"position": [0, 0, 1]}, r"target\[1\].view: unknown key\(s\) \['position'\]"),
        ({"fov": 200}, r"target\[1\].view.fov: expected a scalar in \(0, 180\)"),
        ({"origin": [0, 0.6, 0]}, r"target\[1\].view.target: must differ from origin"),
        ({"origin": [1, 2]}, r"target\[1\].view.origin: expected 3 numbers"),
        (
            {"fov_axis": "y"},
            r"target\[1\].view.fov_axis: every view of a fit has the scene "
            r"camera's fov_axis \('x'\)",
        ),
        ([1, 2, 3], r"target\[1\].view: expected a mapping of camera keys"),
    ],
)
def test_a_bad_pose_is_named_before_rendering(tmp_path, pose, match):
    p = _pngs(tmp_path, [(8, 8)] * 2)
    with pytest.raises(ValueError, match=match):
        prepare_fit(
            fit_cfg(
                target=[{"file": p[0]}, {"file": p[1], "view": pose}], camera={"response": "srgb"}
            )
        )


def test_synthetic_view_errors_and_sizes(tmp_path):
    with pytest.raises(ValueError, match=r"target.views\[1\].fov: expected a scalar"):
        prepare_fit(_views_cfg(target={"synthetic": {}, "views": [{}, {"fov": -1}]}))
    with pytest.raises(ValueError, match=r"target.views: expected a list of camera poses"):
        prepare_fit(_views_cfg(target={"synthetic": {}, "views": {"origin": [0, 0, 1]}}))
    with pytest.raises(ValueError, match=r"target.views\[0\]: expected a mapping"):
        prepare_fit(_views_cfg(target={"synthetic": {}, "views": ["front"]}))
    p = _pngs(tmp_path, [(8, 8), (9, 8)])
    with pytest.raises(
        ValueError,
        match=r"target\[1\]: .*v1.png: size 9x8 .* differs from the "
        r"scene camera's 8x8",
    ):
        prepare_fit(
            fit_cfg(
                target=[{"file": p[0]}, {"file": p[1], "view": {"fov": 30}}],
                camera={"response": "srgb"},
            )
        )


def test_radiance_targets_need_distinct_views(tmp_path):
    paths = []
    for i in range(3):
        paths.append(str(tmp_path / f"r{i}.exr"))
        write_exr(paths[-1], np.full((8, 8, 3), 0.2 + 0.1 * i, np.float32))
    prep = prepare_fit(
        fit_cfg(target=[{"file": paths[0]}, {"file": paths[1], "view": {"fov": 30}}])
    )
    assert not prep.ldr and prep.n_views == 2 and prep.n_targets == 2
    with pytest.raises(ValueError, match=r"several radiance targets must be of distinct views"):
        prepare_fit(
            fit_cfg(
                target=[
                    {"file": paths[0]},
                    {"file": paths[1], "view": {"fov": 30}},
                    {"file": paths[2], "view": {"fov": 30}},
                ]
            )
        )


# ------------------------------------------------------------------ the loss's pieces


def _fake_render(scene, key):
    """A stand-in render: the camera's origin and fov and a uniform of the key, per pixel."""
    c = scene.camera
    base = jnp.concatenate([c.origin[:2], c.fov[None]]) + jax.random.uniform(key, (3,))
    return jnp.broadcast_to(base, (c.height, c.width, 3))


@pytest.mark.parametrize("batching", ["vmap", "loop"])
def test_render_views_renders_each_camera_with_its_own_key(batching):
    prep = prepare_fit(
        _views_cfg(
            target={
                "synthetic": {},
                "views": [{}, {"origin": [1.5, 1.2, 3.7], "fov": 30}, {"origin": [-1, 1, 3]}],
            }
        )
    )
    cams = stack_cameras(prep.views)
    key = jax.random.key(4)
    f = jax.jit(lambda s, c, k: render_views(s, c, k, _fake_render, batching))
    out = np.asarray(f(prep.scene, cams, key))
    keys = jax.random.split(key, 3)
    for v, cam in enumerate(prep.views):  # reference: each camera alone, key v of the split
        c = np.asarray(jnp.concatenate([cam.origin[:2], cam.fov[None]]))
        ref = c + np.asarray(jax.random.uniform(keys[v], (3,)))
        np.testing.assert_allclose(out[v], np.broadcast_to(ref, (8, 8, 3)), rtol=1e-6)


def test_per_photo_terms_of_several_views_are_each_photos_own_loss():
    """The censored linear loss of N photos, each with its own view's render, term by term
    equals the loss of that photo alone against that render (and sums to the total)."""
    from jaxgfx import hdr
    from jaxgfx.pipelines.fit.camera import level_table

    rng = np.random.default_rng(0)
    imgs = jnp.asarray(rng.uniform(0.05, 1.5, (3, 4, 5, 3)), jnp.float32)
    gains = jnp.asarray([[1.0] * 3, [0.5] * 3, [2.0] * 3], jnp.float32)
    # photo j of image j + 1 (another view) through gamma 2.2, some codes clipped
    x = np.asarray(gains)[:, None, None, :] * np.roll(np.asarray(imgs), -1, axis=0) * 1.1
    codes = jnp.asarray(np.round(255 * np.clip(x, 0, 1) ** (1 / 2.2)), jnp.float32)
    assert float(jnp.max(codes)) == 255.0
    table = level_table(hdr.CameraResponse.gamma(2.2, anchor="unit"), 8)
    f = jax.jit(lambda i: censored_linear_loss(i, codes, table, gains, 255.0, per_photo=True))
    terms = np.asarray(f(imgs))
    for j in range(3):
        alone = censored_linear_loss(imgs[j], codes[j][None], table, gains[j][None], 255.0)
        assert terms[j] == pytest.approx(float(alone), rel=1e-5)  # float32 sums
    total = censored_linear_loss(imgs, codes, table, gains, 255.0)
    assert float(total) == pytest.approx(terms.sum(), rel=1e-5)
    assert np.all(terms > 0)


def test_a_clipped_pixel_is_measured_only_by_photos_of_its_own_view():
    """``camera.clipped: unmeasured`` drops a clipped code's bound only where another photo
    *of the same view* measures that pixel: pixel (i, j) of another view is another point.
    Two views, one photo each, the first clipped where the second is not: each term equals
    that photo's loss alone (nothing else measures its pixels); pooling the photos across
    views (the behaviour before ``view_of``) drops the first photo's bounds."""
    from jaxgfx import hdr
    from jaxgfx.pipelines.fit.camera import level_table

    rng = np.random.default_rng(1)
    imgs = jnp.asarray(rng.uniform(0.05, 0.6, (2, 4, 5, 3)), jnp.float32)
    codes = np.asarray(np.round(255 * np.asarray(imgs) ** (1 / 2.2)), np.float32)
    codes[0, :2] = 255.0  # view 0: the top rows clipped (the render is below the bound there)
    codes = jnp.asarray(codes)
    table = level_table(hdr.CameraResponse.gamma(2.2, anchor="unit"), 8)
    gains = jnp.ones((2, 3), jnp.float32)
    f = jax.jit(
        lambda i, v: censored_linear_loss(
            i, codes, table, gains, 255.0, unmeasured_only=1.0, per_photo=True, view_of=v
        )
    )
    terms = np.asarray(f(imgs, jnp.asarray([0, 1])))
    for j in range(2):
        alone = censored_linear_loss(
            imgs[j], codes[j][None], table, gains[j][None], 255.0, unmeasured_only=1.0
        )
        assert terms[j] == pytest.approx(float(alone), rel=1e-5)
    assert terms[0] > 0.05  # the bound of the clipped rows counts
    pooled = censored_linear_loss(
        imgs, codes, table, gains, 255.0, unmeasured_only=1.0, per_photo=True
    )
    assert float(pooled[0]) < 0.5 * terms[0]  # pooled across views: the bounds are dropped
    # a bracket of one view (same view_of) still drops a bound another photo measures
    both = np.asarray(f(imgs, jnp.asarray([0, 0])))
    np.testing.assert_allclose(both, np.asarray(pooled), rtol=1e-6)


def test_auto_exposure_of_several_views_uses_each_photos_own_view():
    """``camera.exposure.auto`` with views: each photo is compared with the render of its own
    view. Two views of different radiance, view 1 a bracket (ratios 1, 4), photos through the
    "camera" response at exposure 0.126 (clipped, quantised): the estimate is 0.126 within 2 %;
    with view 0's render for every photo (one view's path) it is far off."""
    from jaxgfx import hdr
    from jaxgfx.pipelines.fit.camera import level_table
    from jaxgfx.pipelines.fit.job import auto_exposure

    rng = np.random.default_rng(2)
    views = rng.uniform(0.02, 5.0, (2, 12, 12, 3)).astype(np.float32)
    views[1] *= 0.2  # the second view sees a darker side
    view_of, r = np.asarray([0, 1, 1]), np.asarray([1.0, 0.5, 4.0])
    resp = hdr.CameraResponse.analytic("camera", anchor="unit")
    e = 0.5
    codes = np.stack(
        [
            np.asarray(hdr.Camera(resp, jnp.asarray(e * ri), bits=8).capture(views[v]))
            for v, ri in zip(view_of, r, strict=True)
        ]
    ).astype(np.float32)
    assert (codes == 255).mean() > 0.05
    table = level_table(resp, 8)
    got = auto_exposure(views[view_of], codes, table, r, 255.0)
    assert abs(got / e - 1) < 0.02
    wrong = auto_exposure(views[0], codes, table, r, 255.0)
    assert abs(wrong / e - 1) > 0.3


def test_radiance_photo_terms_are_mean_squared_errors():
    cfg = _views_cfg()
    img = jnp.asarray(np.arange(2 * 2 * 3 * 3, dtype=np.float32).reshape(2, 2, 3, 3) / 10)
    target = img + jnp.asarray([0.1, 0.3], jnp.float32)[:, None, None, None]
    terms = jax.jit(lambda i, t: photo_losses(cfg, False, i, t, None, None, None))(img, target)
    np.testing.assert_allclose(np.asarray(terms), [0.01, 0.09], rtol=1e-5)  # l2: mean (I - T)^2


def test_tile_views_puts_views_side_by_side():
    a = np.zeros((3, 4, 5, 3), np.uint8)
    a[1] = 7
    t = tile_views(a, gap=2)
    assert t.shape == (4, 3 * 5 + 2 * 2, 3)
    assert np.all(t[:, 5:7] == 255) and np.all(t[:, 7:12] == 7) and np.all(t[:, 12:14] == 255)
    assert tile_views(a[:1]).shape == (4, 5, 3)


# -------------------------------------------------------------------------------- slow


# slow: ~12 s on 2 cores at load 4 (direct renders through stacked cameras, and each alone)
@pytest.mark.slow
def test_vmap_and_loop_render_every_view_as_rendering_it_alone(tmp_path):
    import equinox as eqx

    from jaxgfx.render import render

    prep = prepare_fit(
        fit_cfg(
            scene=_plane(tmp_path, _blocks(8), 6),
            target={"synthetic": {}, "views": POSES[:3]},
            params={TEX: {"init": 0.5}},
        )
    )
    cams = stack_cameras(prep.views)

    def r(s, k):
        return render(s, k, spp=2, integrator="direct", max_depth=2)

    key = jax.random.key(1)
    keys = jax.random.split(key, 3)
    ref = [
        np.asarray(jax.jit(r)(eqx.tree_at(lambda s: s.camera, prep.scene, c), keys[v]))
        for v, c in enumerate(prep.views)
    ]
    for batching in ("vmap", "loop"):
        out = jax.jit(lambda s, c, k, b=batching: render_views(s, c, k, r, b))(
            prep.scene, cams, key
        )
        np.testing.assert_allclose(np.asarray(out), np.stack(ref), rtol=1e-5, atol=1e-6)
    assert not np.allclose(ref[0], ref[1])  # the views differ


# slow: ~11 s on 2 cores at load 4 (float64 2-view loss, its gradient, 96 perturbed forwards)
@pytest.mark.slow
def test_several_views_loss_gradient_matches_finite_differences(tmp_path, x64):
    """d loss / d texels of the summed two-view loss (correlated estimator, so a key fixes
    the image): reverse mode equals central differences at the same key."""
    from jaxgfx.pipelines.fit.job import _initial, _target
    from jaxgfx.pipelines.fit.loss import make_loss
    from jaxgfx.testing import ad_fd_per_key

    cfg = fit_cfg(
        scene=_plane(tmp_path, _blocks(4) * 0.0 + 0.5, 4),
        target={"synthetic": {TEX: _blocks(4).tolist()}, "spp": 8, "views": POSES[:2]},
        params={TEX: {"init": 0.5, "min": 0.0, "max": 1.0}},
        render={"spp": 2, "integrator": "direct", "max_depth": 2, "estimator": "correlated"},
    )
    prep = prepare_fit(cfg)
    target = _target(cfg, prep)[0]
    _, _, cam_args = _initial(cfg, prep)
    loss = make_loss(cfg, prep.paths, False, views=True)

    def f(x, key, scene, pixels, args):
        return loss({"scene": {TEX: x}, "camera": {}}, key, (scene, pixels, args))

    x = jnp.asarray(np.random.default_rng(1).uniform(0.2, 0.8, (4, 4, 3)))
    keys = jax.random.split(jax.random.key(0), 2)
    _, ad, fd = ad_fd_per_key(
        f, x, keys, 1e-5, args=(prep.scene, jnp.asarray(target.pixels, jnp.float64), cam_args)
    )
    assert np.abs(ad).max() > 1e-3
    np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-9)


# slow: 26 s wall at load ~4 on 2 cores (the 4-photo target's renders, the initial render of
# both views, one fit step compiled)
@pytest.mark.slow
def test_auto_exposure_with_views_end_to_end():
    """``camera.exposure.auto: true`` in a fit of two views, each a bracket (0.3 x (1, 4))
    through gamma 2.2: at the true roughness the exposure the fit starts from (one step at lr
    1e-9) is the target's 0.3 (measured 0.30024: 64-spp target, 16-spp initial render)."""
    cfg = fit_cfg(
        target={
            "synthetic": {"materials.metal.alpha": 0.15},
            "spp": 64,
            "views": [{}, {"origin": [1.5, 1.2, 3.7]}],
            "camera": {"response": "gamma", "gamma": 2.2, "exposure": 0.3, "exposures": [1, 4]},
        },
        params={"materials.metal.alpha": {"init": 0.15, "min": 0.01, "max": 1.0}},
        camera={
            "response": {"model": "gamma", "init": 2.2},
            "exposure": {"init": 1.0, "fit": True, "auto": True},
        },
        optimizer={"steps": 1, "lr": 1e-9},
    )
    res = run_fit(FitJob(cfg, None))
    assert res["n_targets"] == 4 and len(res["views"]["loss_after"]) == 2
    assert res["camera"]["exposure"] == pytest.approx(0.3, rel=0.01)


def _seen(prep, spp=8):
    """(V, H, W): texels with a non-zero gradient of each view's summed render."""
    import equinox as eqx

    from jaxgfx.render import render

    def total(img, cam):
        s = eqx.tree_at(lambda sc: sc.camera, prep.scene.replace(TEX, img), cam)
        return jnp.sum(render(s, jax.random.key(0), spp=spp, integrator="direct", max_depth=2))

    g = jax.jit(jax.grad(total))
    tex = jnp.asarray(prep.scene.get(TEX))
    return np.stack([np.any(np.asarray(g(tex, c)) != 0, axis=-1) for c in prep.views])


def _psnr(a, b, mask):
    e = (np.asarray(a, np.float64) - b)[mask]
    return 10 * np.log10(1 / np.mean(e * e))


# slow: ~18-27 s on 2 cores at load 4 (two fits of 150 steps, a 4-view and a 1-view program, and the
# visibility gradients); the 64x64 case runs in experiments.multiview (docs/inverse.md)
@pytest.mark.slow
def test_a_texture_hidden_in_each_view_is_recovered_from_four(tmp_path):
    """A 16x16 albedo texture seen by four 16x16 views (each sees ~1/3 of it): the fit with a
    tv prior recovers every seen texel to >= 30 dB; from the first view alone, the texels it
    does not see stay at the start (PSNR of the 0.5 init), those it sees are recovered."""
    truth = _blocks(16)
    cfg = {
        "scene": _plane(tmp_path, truth, 16),
        "target": {"synthetic": {}, "spp": 64, "seed": 7, "views": POSES},
        "params": {TEX: {"init": 0.5, "min": 0.0, "max": 1.0, "prior": {"tv": 1e-3}}},
        "optimizer": {"name": "adam", "lr": 0.05, "lr_final": 0.005, "steps": 150},
        "render": {"spp": 4, "integrator": "direct", "max_depth": 2},
        "progress": False,
    }
    res = run_fit(FitJob.load(cfg, str(tmp_path / "four")))
    prep = prepare_fit(FitJob.load(cfg).config)
    seen = _seen(prep)
    union, first = seen.any(axis=0), seen[0]
    assert union.all() and 0.2 < first.mean() < 0.5  # each view sees part of it
    fit4 = np.asarray(res["params"][TEX])
    assert _psnr(fit4, truth, union) >= 30.0
    # every view's loss fell; result.json and the tiled previews list the four views
    assert all(
        a < 0.1 * b
        for a, b in zip(res["views"]["loss_after"], res["views"]["loss_before"], strict=True)
    )
    from PIL import Image

    with Image.open(tmp_path / "four" / "after.png") as im:
        assert im.size == (4 * 16 + 3 * 2, 16)

    cfg["target"] = dict(cfg["target"], views=POSES[:1])
    fit1 = np.asarray(run_fit(FitJob.load(cfg, None))["params"][TEX])
    init = _psnr(np.full_like(truth, 0.5), truth, union & ~first)
    # measured: four views 37.4 dB; one view 33.7 dB seen, 13.2 dB hidden (init 12.8 dB)
    assert _psnr(fit1, truth, first) >= 30.0
    assert _psnr(fit1, truth, union & ~first) < init + 1.0 < 20.0


# ------------------------------------------------- the hostile case: a textured mesh

MESH_SCENE = os.path.join(
    os.path.dirname(__file__), "..", "..", "configs", "scenes", "multiview_mesh.yaml"
)
MESH_TEX = "materials.surface.reflectance.image"
MESH_VIEWS = [  # configs/multiview_mesh.yaml: 30 degrees above the mean plane, four sides
    {"origin": [sx * 2.021, 1.65, sz * 2.021], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 32}
    for sx, sz in ((1, 1), (-1, 1), (-1, -1), (1, -1))
]
MESH_EXPOSURES = [1.0, 0.6, 1.6, 2.5]  # one photo per view (the last clips ~10 % of pixels)


def _mesh_scene(tmp_path, texture):
    """configs/scenes/multiview_mesh.yaml (bumpy height-field mesh, rough gold sphere shadowing
    it, area + constant light) with the albedo ``texture`` inline (nearest)."""
    with open(MESH_SCENE) as fh:
        d = yaml.safe_load(fh)
    d["shapes"][0]["file"] = os.path.abspath(
        os.path.join(os.path.dirname(MESH_SCENE), d["shapes"][0]["file"])
    )
    d["materials"]["surface"]["reflectance"] = {
        "type": "bitmap",
        "image": np.asarray(texture).tolist(),
        "filter": "nearest",
    }
    path = tmp_path / "mesh.yaml"
    path.write_text(yaml.safe_dump(d))
    return str(path)


def _coverage(scene, cameras, keys=8):
    """(V, H, W): pixels each camera puts on each texel of the mesh's texture (one-sample AOV
    renders of a texture that holds each texel's index and a marker; occlusion by the sphere
    and by the mesh itself is the renderer's)."""
    import equinox as eqx

    from jaxgfx.render import render

    h, w = np.asarray(scene.get(MESH_TEX)).shape[:2]
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    ids = np.stack([(cols + 0.5) / w, (rows + 0.5) / h, np.full((h, w), 0.3125)], -1)
    s_id = scene.replace(MESH_TEX, jnp.asarray(ids, jnp.float32))
    aov = jax.jit(lambda s, k: render(s, k, spp=1, integrator="aov"))
    out = np.zeros((len(cameras), h, w))
    for v, cam in enumerate(cameras):
        sc = eqx.tree_at(lambda q: q.camera, s_id, cam)
        for k in range(keys):
            a = np.asarray(aov(sc, jax.random.key(k)))
            hit = np.abs(a[..., 2] - 0.3125) < 1e-4
            c = np.clip(np.floor(a[..., 0][hit] * w).astype(int), 0, w - 1)
            r = np.clip(np.floor(a[..., 1][hit] * h).astype(int), 0, h - 1)
            np.add.at(out[v], (r, c), 1.0 / keys)
    return out


def mesh_case(
    tmp_path, seed, steps, size=24, n_tex=16, target_spp=64, loss=None, one=True, blocks=4
):
    """The hostile several-views case at small size: four ``size``² photos of the bumpy mesh
    (one per view, exposures :data:`MESH_EXPOSURES`, synthetic "camera" response, shot and read
    noise, JPEG 90 4:2:0; target ``seed``) written as PNG files and fitted as ``{file,
    exposure, view}`` photos through the fixed "camera" response; then view 0's photo alone.
    ``loss``: the fits' loss section (e.g. ``{jpeg_chroma: "4:2:0"}``); ``one=False`` skips
    the one-view fit (None); ``blocks``: the truth's uniform colour blocks per side
    (:func:`_blocks`). Returns (truth, visible, hidden from view 0, four-view fit, one-view
    fit)."""
    from jaxgfx.pipelines.fit.job import _target

    truth = _blocks(n_tex, blocks=blocks)
    scene = _mesh_scene(tmp_path, truth)
    base = {
        "scene": scene,
        "params": {MESH_TEX: {"init": 0.5, "min": 0.0, "max": 1.0, "prior": {"tv": 1e-3}}},
        "optimizer": {"name": "adam", "lr": 0.05, "lr_final": 0.005, "steps": steps},
        "render": {"spp": 4, "integrator": "direct", "max_depth": 2, "width": size, "height": size},
        "progress": False,
        **({"loss": loss} if loss else {}),
    }
    camera = {
        "response": "camera",
        "exposure": {"init": 1.0},
        "clip_code": 245,
        "clipped": "unmeasured",
    }
    synth = FitJob.load(
        {
            **base,
            "camera": camera,
            "target": {
                "synthetic": {},
                "spp": target_spp,
                "seed": seed,
                "views": MESH_VIEWS,
                "camera": {
                    "response": "camera",
                    "exposures": MESH_EXPOSURES,
                    "noise": {"gain": 2e-4, "read_sigma": 1e-3},
                    "jpeg": 90,
                },
            },
        }
    ).config
    prep = prepare_fit(synth)
    photos = _target(synth, prep)[0].pixels  # (16, H, W, 3): each view at every exposure
    entries = []
    for v in range(4):
        p = tmp_path / f"s{seed}_view{v}.png"
        write_png(p, np.asarray(photos[v * 4 + v]).astype(np.uint8))
        entries.append({"file": str(p), "exposure": MESH_EXPOSURES[v], "view": MESH_VIEWS[v]})
    cov = _coverage(prep.scene, prep.views)
    visible = cov.sum(0) >= 0.5
    hidden0 = visible & (cov[0] == 0)
    fits = []
    for sel in (entries, entries[:1]) if one else (entries,):
        res = run_fit(FitJob.load({**base, "target": sel, "camera": camera}, None))
        fits.append(np.asarray(res["params"][MESH_TEX], np.float64))
    return truth, visible, hidden0, fits[0], fits[1] if one else None


# slow: 43 s on 2 cores at load 4 (209 s at load 8.6; two fit programs compiled, a 4-view and
# a 1-view one, 100 steps each; the photos' 64-spp renders; the AOV coverage renders)
@pytest.mark.slow
def test_a_hostile_textured_mesh_is_recovered_from_four_views_not_from_one(tmp_path):
    """The hostile case at small size (docs/inverse.md, "Several views: a textured mesh"): a
    16x16 texture on the bumpy mesh from four 24x24 JPEG photos (:func:`mesh_case`). Measured
    over target seeds 1-4 (100 steps): four views 20.47, 20.45, 20.45, 20.34 dB over the
    visible texels (mean 20.43, sd 0.06; the bound is the mean - 5 sd); view 0 alone leaves the
    37 % of texels it does not see within 1.5 dB of the start (12.8 dB: the tv prior spreads
    its neighbours a little) while four views put them at 21.4-21.7 dB."""
    truth, visible, hidden0, fit4, fit1 = mesh_case(tmp_path, seed=1, steps=100)
    assert visible.mean() > 0.95 and 0.3 < hidden0.mean() < 0.45
    start = np.full_like(truth, 0.5)
    assert _psnr(fit4, truth, visible) >= 20.1 > _psnr(start, truth, visible) + 6.0
    init_hidden = _psnr(start, truth, hidden0)
    one_hidden = _psnr(fit1, truth, hidden0)
    assert one_hidden < init_hidden + 2.0
    assert _psnr(fit1, truth, visible & ~hidden0) > one_hidden + 2.5  # it recovers what it sees
    assert _psnr(fit4, truth, hidden0) > one_hidden + 5.0


# slow: 80-93 s of process CPU (user + sys of the pytest run, two runs), 128-389 s wall at load
# 6-10 on the 2-core machine (the 16 target photos at 256 spp, the coverage renders, a 4-view
# and a 1-view fit of 150 steps at 56x56, two compiled programs)
@pytest.mark.slow
def test_a_small_analogue_of_the_192_px_mesh_fit_reaches_30_db(tmp_path):
    """Issue 25's 30 dB texture bar, scaled down (docs/inverse.md, "30 dB at 192×192"): the
    same hostile chain (four views, JPEG 90 4:2:0 with ``loss.jpeg_chroma: "4:2:0"``, shot
    and read noise, the "camera" curve, per-view exposures with clipping, occlusion by the
    sphere and the mesh) with a 16x16 texture of 8-texel colour blocks (the 64x64 one's block
    size) from four 56x56 photos: ~29 pixels per visible texel, against 21 at 192x192 (the
    same 21 — 24x24 texels from 72x72 photos — gives 29.8 dB in 300 steps: the bar itself,
    no margin). Measured (150 steps, 256-spp targets), target seeds 1 and 2: four views
    32.69 / 32.70 dB over the visible texels (bound 32.0: the bar with a 2 dB margin), view 0
    alone 23.1 / 23.6 dB (30 % of the texels are hidden from it); without the chroma model
    the four views give 30.2 dB (seed 1), so that contrast is documented, not tested."""
    truth, visible, hidden0, fit4, fit1 = mesh_case(
        tmp_path,
        seed=1,
        steps=150,
        size=56,
        n_tex=16,
        target_spp=256,
        loss={"jpeg_chroma": "4:2:0"},
        blocks=2,
    )
    assert visible.mean() > 0.95 and 0.25 < hidden0.mean() < 0.35  # measured 1.0, 0.297
    four, one = _psnr(fit4, truth, visible), _psnr(fit1, truth, visible)
    assert four >= 32.0, four
    assert one < 26.0, one  # view 0 alone: the texels it does not see stay near the start
