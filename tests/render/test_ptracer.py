"""The particle tracer (``ptracer``, Mitsuba 3's light tracer) against closed forms and the
path tracer; its gradients against finite differences; its errors.

Monte Carlo tolerances: every comparison renders ``K`` independent keys and measures the
standard error of the mean from their spread (z-scores, bound 4.5: a false alarm rate below
1e-4 per comparison for a normal statistic)."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import load_scene, render
from jaxgfx.render.integrators import INTEGRATORS, ParticleTracer, make_integrator
from tests.render._scenes import camera, rectangle, sphere


@pytest.fixture(autouse=True)
def _float64(x64):
    """float64 in every test of this module, restored after it (tests/conftest.py ``x64``)."""
    yield


RHO, INTENSITY = 0.5, 10.0
LIGHT = np.array([0.5, 0.3, 1.0])
Z_MAX = 4.5


def _plane_scene(n=8, **emitter):
    em = emitter or {"type": "point", "position": LIGHT.tolist(), "intensity": INTENSITY}
    return load_scene(
        {
            "camera": camera([0, 0, 3], [0, 0, 0], up=[0, 1, 0], fov=40, width=n),
            "shapes": [rectangle([0, 0, 0], [0, 0, 1], [10, 10], material="w")],
            "materials": {"w": {"type": "diffuse", "reflectance": RHO}},
            "emitters": [em],
        }
    )


def _plane_reference(scene, sub=16):
    """Pixel averages of the closed form ``rho / pi * I cos / r^2`` over a ``sub x sub`` grid
    of each pixel (the image of a point light over a diffuse plane z = 0)."""
    cam = scene.camera
    n = cam.width
    g = (np.arange(sub) + 0.5) / sub
    xs = (np.arange(n)[:, None] + g[None, :]).reshape(-1)
    px = np.stack(np.meshgrid(xs, xs), -1)  # (n sub, n sub, 2): (x, y)
    o, d = (np.asarray(a, np.float64) for a in cam.generate_ray(jnp.asarray(px)))
    t = -o[..., 2] / d[..., 2]
    x = o + t[..., None] * d
    v = LIGHT - x
    r2 = np.sum(v * v, -1)
    le = RHO / math.pi * INTENSITY * (v[..., 2] / np.sqrt(r2)) / r2
    return le.reshape(n, sub, n, sub).mean(axis=(1, 3))


def _renders(scene, keys, spp, integrator):
    return np.asarray(
        jax.jit(jax.vmap(lambda k: render(scene, k, spp=spp, integrator=integrator)))(keys)
    )


def _z(samples, ref, axis=0):
    m = samples.mean(axis)
    se = samples.std(axis, ddof=1) / math.sqrt(samples.shape[axis])
    return (m - ref) / np.where(se > 0, se, np.inf)


def _blocks(img, b):
    h, w = img.shape[-3:-1]
    return img.reshape(*img.shape[:-3], h // b, b, w // b, b, img.shape[-1]).mean(axis=(-4, -2))


@pytest.mark.slow  # slow: 4 s alone, ~15-20 s on 2 loaded cores
def test_point_light_over_diffuse_plane_closed_form():
    scene = _plane_scene()
    ref = _plane_reference(scene)
    imgs = _renders(scene, jax.random.split(jax.random.key(1), 8), 16, ParticleTracer(max_depth=2))
    # the three channels are the same estimate (grey scene)
    np.testing.assert_allclose(imgs[..., 1], imgs[..., 0], rtol=1e-12)
    z_mean = _z(imgs[..., 0].mean(axis=(1, 2)), ref.mean())
    assert abs(z_mean) < Z_MAX, (imgs[..., 0].mean(), ref.mean(), z_mean)
    z_blk = _z(_blocks(imgs[..., :1], 2)[..., 0], _blocks(ref[..., None], 2)[..., 0])
    assert np.max(np.abs(z_blk)) < Z_MAX, z_blk
    # the relative error of the mean is small: a wrong constant (2, pi) fails by far
    assert abs(imgs[..., 0].mean() / ref.mean() - 1) < 0.05


def _cornerish(glossy="roughconductor"):
    """A diffuse floor and back wall, a glossy sphere and a rectangle area light facing down,
    partly in view (the visible-emitter connection is tested too)."""
    mats = {
        "floor": {"type": "diffuse", "reflectance": [0.7, 0.5, 0.3]},
        "wall": {"type": "diffuse", "reflectance": 0.6},
        "gloss": {"type": "roughconductor", "alpha": 0.3}
        if glossy == "roughconductor"
        else {"type": "roughplastic", "alpha": 0.2, "diffuse_reflectance": 0.4},
    }
    return load_scene(
        {
            "camera": camera([0, 1.2, 4], [0, 0.8, 0], up=[0, 1, 0], fov=55, width=8),
            "shapes": [
                rectangle([0, 0, 0], [0, 1, 0], [6, 6], material="floor"),
                rectangle([0, 1.5, -1.5], [0, 0, 1], [6, 3], material="wall"),
                {"type": "sphere", "center": [0.3, 0.5, 0], "radius": 0.5, "material": "gloss"},
            ],
            "materials": mats,
            "emitters": [
                {
                    "type": "area",
                    "radiance": [6, 6, 6],
                    "shape": {
                        "type": "rectangle",
                        "center": [-0.6, 2.2, 0.2],
                        "normal": [0, -1, 0],
                        "size": [0.8, 0.8],
                    },
                },  # fmt: skip
            ],
        }
    )


@pytest.mark.slow  # slow: ~40 s on 2 cores under load ~15 (two integrators x 32 keys)
def test_equals_path_tracer_in_expectation_area_light():
    """Rough-metal sphere, diffuse floor and wall, a small area light partly in view (the
    visible-emitter connection too): 32 keys x 4 spp of each integrator; Welch z-scores of
    the channel means and of 4x4-pixel block means from the per-key standard errors (62
    degrees of freedom; bound 5: p < 1e-5 per comparison)."""
    scene = _cornerish("roughconductor")
    keys = jax.random.split(jax.random.key(2), 32)
    z_ch, z_blk, _, _ = _pt_vs_path(scene, keys=keys, spp=4, max_depth=3)
    assert np.max(np.abs(z_ch)) < 5.0, z_ch
    assert np.max(np.abs(z_blk)) < 5.0, z_blk


def _mirror_caustic_scene():
    """A point light between a diffuse floor (z = 0) and a perfect mirror wall (x = 1) that
    the camera does not see: the floor also receives the light of the mirror image of the
    light at (1.8, 0, 1), which a camera path can never complete (delta BSDF then delta
    light)."""
    return load_scene(
        {
            "camera": camera([0, 0, 3], [0, 0, 0], up=[0, 1, 0], fov=30, width=8),
            "shapes": [
                rectangle([0, 0, 0], [0, 0, 1], [10, 10], material="w"),
                rectangle([1, 0, 0], [-1, 0, 0], [10, 10], material="mirror"),
            ],
            "materials": {
                "w": {"type": "diffuse", "reflectance": RHO},
                "mirror": {"type": "conductor"},
            },  # fmt: skip
            "emitters": [{"type": "point", "position": [0.2, 0, 1], "intensity": INTENSITY}],
        }
    )


def _two_source_reference(scene, sources, sub=16):
    cam = scene.camera
    n = cam.width
    g = (np.arange(sub) + 0.5) / sub
    xs = (np.arange(n)[:, None] + g[None, :]).reshape(-1)
    px = np.stack(np.meshgrid(xs, xs), -1)
    o, d = (np.asarray(a, np.float64) for a in cam.generate_ray(jnp.asarray(px)))
    x = o + (-o[..., 2] / d[..., 2])[..., None] * d
    le = 0.0
    for s in sources:
        v = np.asarray(s) - x
        r2 = np.sum(v * v, -1)
        le = le + RHO / math.pi * INTENSITY * (v[..., 2] / np.sqrt(r2)) / r2
    return le.reshape(n, sub, n, sub).mean(axis=(1, 3))


@pytest.mark.slow  # slow: ~20 s on 2 cores under load ~15
def test_mirror_caustic_of_a_point_light_only_the_light_tracer_sees():
    scene = _mirror_caustic_scene()
    direct = _two_source_reference(scene, [[0.2, 0, 1]])
    both = _two_source_reference(scene, [[0.2, 0, 1], [1.8, 0, 1]])
    keys = jax.random.split(jax.random.key(3), 8)
    pt = _renders(scene, keys, 16, ParticleTracer(max_depth=3))[..., 0]
    z = _z(_blocks(pt[..., None], 2)[..., 0], _blocks(both[..., None], 2)[..., 0])
    assert np.max(np.abs(z)) < Z_MAX, z
    # the caustic is 20-30 % of the floor's radiance here: far outside the noise (z = 8.7)
    z_direct = _z(pt.mean(axis=(1, 2)), direct.mean())
    print(f"mirror caustic: the image mean is {z_direct:.1f} standard errors above direct light")
    assert z_direct > Z_MAX, z_direct
    # the path tracer misses it (its estimate has no variance from the delta light here)
    pa = np.asarray(render(scene, keys[0], spp=4, integrator="path", max_depth=3))[..., 0]
    np.testing.assert_allclose(pa.mean(), direct.mean(), rtol=0.02)


def _grad_loss(x, key, scene):
    s = (
        scene.replace("materials.floor.reflectance", x[:3])
        .replace("emitters.area.0.radiance", x[3:6])
        .replace("emitters.directional.0.irradiance", x[6:9])
        .replace("emitters.spot.0.intensity", x[9:12])
        .replace("emitters.environment.radiance", x[12:15])
    )
    img = render(s, key, spp=2, integrator=ParticleTracer(max_depth=3))
    return jnp.sum(img * jnp.linspace(0.5, 1.5, img.size).reshape(img.shape))


@pytest.mark.slow  # slow: ~83 s on 2 cores under load ~15 (AD + 30 perturbed renders, float64)
def test_gradients_radiance_and_albedo_match_finite_differences():
    from jaxgfx.testing import ad_fd_per_key

    scene = load_scene(
        {
            "camera": camera([0, 1, 3], [0, 0.5, 0], up=[0, 1, 0], fov=60, width=4),
            "shapes": [
                rectangle([0, 0, 0], [0, 1, 0], [4, 4], material="floor"),
                rectangle([0, 1, -1], [0, 0, 1], [4, 2], material="floor"),
            ],
            "materials": {"floor": {"type": "diffuse", "reflectance": [0.6, 0.5, 0.4]}},
            "emitters": [
                {
                    "type": "area",
                    "radiance": [3, 4, 5],
                    "shape": {
                        "type": "rectangle",
                        "center": [0, 1.8, 0],
                        "normal": [0, -1, 0],
                        "size": [0.6, 0.6],
                    },
                },
                {"type": "directional", "direction": [0.3, -1, -0.4], "irradiance": [1, 2, 3]},
                {
                    "type": "spot",
                    "position": [0.5, 1.5, 0.5],
                    "direction": [0, -1, 0],
                    "intensity": [2, 3, 4],
                    "cutoff_angle": 40,
                },  # fmt: skip
                {"type": "constant", "radiance": [0.3, 0.2, 0.1]},
            ],  # fmt: skip
        }
    )
    x = jnp.array([0.6, 0.5, 0.4, 3.0, 4.0, 5.0, 1, 2, 3, 2, 3, 4, 0.3, 0.2, 0.1])
    keys = jax.random.split(jax.random.key(4), 1)
    vals, ad, fd = ad_fd_per_key(_grad_loss, x, keys, 1e-4, args=(scene,))
    assert np.all(np.isfinite(ad)) and np.all(vals > 0)
    # per key the estimate is a polynomial in x (no sampling decision depends on it): AD and
    # central differences agree to float64 rounding of the FD step
    rel = np.abs(ad - fd) / np.maximum(np.abs(fd), 1e-9 * np.abs(fd).max())
    print(f"ptracer AD vs FD: max relative difference {rel.max():.2e} over {ad.size} parameters")
    np.testing.assert_allclose(ad, fd, rtol=1e-6, atol=1e-9 * np.abs(fd).max())
    assert np.all(np.abs(ad) > 1e-3)  # every parameter moves the image


def test_integrator_registration():
    assert INTEGRATORS["ptracer"] is ParticleTracer
    integ = make_integrator("ptracer", max_depth=4, rr_depth=2)
    assert (integ.max_depth, integ.rr_depth, integ.hide_emitters) == (4, 2, False)


@pytest.mark.slow  # slow: ~6-8 s on 2 loaded cores (two compiles)
def test_jit_deterministic_and_max_depth_one():
    scene = _plane_scene(n=4)
    f = jax.jit(lambda k: render(scene, k, spp=2, integrator="ptracer", max_depth=2))
    a, b = np.asarray(f(jax.random.key(0))), np.asarray(f(jax.random.key(0)))
    assert a.shape == (4, 4, 3) and np.all(np.isfinite(a)) and a.max() > 0
    np.testing.assert_array_equal(a, b)
    # max_depth 1: only directly visible emitters; a point light is never visible
    one = np.asarray(render(scene, jax.random.key(0), spp=2, integrator="ptracer", max_depth=1))
    assert np.all(one == 0)


@pytest.mark.parametrize(
    "change, match",
    [
        ({"camera_extra": {"aperture_radius": 0.1, "focus_distance": 3.0}}, "PerspectiveCamera"),
        ({"sdf": True}, r"shapes\[1\].*cannot bound a SDFShape"),
    ],
)
def test_unsupported_scenes_raise_one_clear_error(change, match):
    """A thin lens (no pinhole We); an environment over an SDF (no bounding sphere)."""
    desc = {
        "camera": {
            "origin": [0, 0, 3],
            "target": [0, 0, 0],
            "up": [0, 1, 0],
            "fov": 40,
            "width": 4,
            "height": 4,
            **change.get("camera_extra", {}),
        },  # fmt: skip
        "shapes": [
            {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 0, 1], "size": [4, 4]}
        ],  # fmt: skip
        "emitters": [{"type": "constant", "radiance": 1.0}],
    }
    if change.get("sdf"):
        desc["shapes"].append(
            {"type": "sdf", "expr": {"op": "sphere", "center": [0, 0, 1], "radius": 0.5}}
        )
    with pytest.raises(ValueError, match=match):
        render(load_scene(desc), jax.random.key(0), spp=1, integrator="ptracer")


def test_bad_options_and_camera_path_refused():
    with pytest.raises(ValueError, match="max_depth"):
        ParticleTracer(max_depth=0)
    with pytest.raises(ValueError, match="hide_emitters"):
        ParticleTracer(hide_emitters=1)
    with pytest.raises(TypeError, match="strategy"):
        make_integrator("ptracer", strategy="mis")
    with pytest.raises(TypeError, match="not along camera rays"):
        ParticleTracer()(None, None, None, None)


def test_xml_integrator_row_and_writer(tmp_path):
    from jaxgfx.render.scene.mitsuba import mitsuba_integrator
    from jaxgfx.render.scene.mitsuba_xml import read_xml

    xml = tmp_path / "s.xml"
    xml.write_text(
        """<scene version="3.0.0">
  <integrator type="ptracer"><integer name="max_depth" value="4"/>
    <integer name="samples_per_pass" value="4"/></integrator>
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 3" target="0, 0, 0" up="0, 1, 0"/>
    </transform>
    <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/>
    </film></sensor>
  <shape type="rectangle"><bsdf type="diffuse"/></shape>
  <emitter type="point"><point name="position" x="0" y="0" z="1"/></emitter>
</scene>"""
    )
    x = read_xml(str(xml))
    assert (x.integrator, x.max_depth, x.rr_depth) == ("ptracer", 4, 5)
    assert mitsuba_integrator("ptracer", max_depth=4, rr_depth=3) == {
        "type": "ptracer", "max_depth": 4, "rr_depth": 3}  # fmt: skip
    bad = tmp_path / "b.xml"
    spp_pass = '<integer name="samples_per_pass" value="4"/>'
    hide = '<boolean name="hide_emitters" value="true"/>'
    hidden = tmp_path / "h.xml"
    hidden.write_text(xml.read_text().replace(spp_pass, hide))
    assert read_xml(str(hidden)).hide_emitters and not x.hide_emitters
    # the writer: hide_emitters round-trips (ptracer only)
    from jaxgfx.render.scene.mitsuba_xml import save_scene

    desc = {"camera": {"origin": [0, 0, 3], "target": [0, 0, 0], "up": [0, 1, 0], "fov": 40,
                       "width": 4, "height": 4},
            "shapes": [{"type": "rectangle", "center": [0, 0, 0], "normal": [0, 0, 1]}],
            "emitters": [{"type": "point", "position": [0, 0, 1], "intensity": 1.0}]}  # fmt: skip
    out = save_scene(desc, str(tmp_path / "w.xml"), integrator="ptracer", max_depth=3,
                     hide_emitters=True)  # fmt: skip
    assert read_xml(out).hide_emitters and read_xml(out).integrator == "ptracer"
    with pytest.raises(ValueError, match="hide_emitters"):
        mitsuba_integrator("path", hide_emitters=True)
    bad.write_text(hidden.read_text().replace('"ptracer"', '"path"'))
    with pytest.raises(ValueError, match="hide_emitters"):
        read_xml(str(bad))


def _plane_two_lights(n=8, film=None):
    """A diffuse plane lit by a point light and a small downward-facing area light."""
    desc = {
        "camera": camera([0, 0, 3], [0, 0, 0], up=[0, 1, 0], fov=40, width=n),
        "shapes": [rectangle([0, 0, 0], [0, 0, 1], [4, 4], material="w")],
        "materials": {"w": {"type": "diffuse", "reflectance": [0.7, 0.5, 0.3]}},
        "emitters": [
            {"type": "point", "position": LIGHT.tolist(), "intensity": INTENSITY},
            {
                "type": "area",
                "radiance": [2, 2, 2],
                "shape": {
                    "type": "rectangle",
                    "center": [-0.4, 0, 1.2],
                    "normal": [0, 0, -1],
                    "size": [0.5, 0.5],
                },
            },  # fmt: skip
        ],
    }
    if film is not None:
        desc["film"] = film
    return desc


def _glass_and_spot(n=16):
    """Floor, back wall, a smooth glass sphere under a spot light (its caustic on the floor),
    a rough metal sphere and a tilted area light the camera sees."""
    return {
        "camera": camera([0, 1.5, 4], [0, 0.5, 0], up=[0, 1, 0], fov=50, width=n),
        "shapes": [
            rectangle([0, 0, 0], [0, 1, 0], [6, 6], material="floor"),
            rectangle([0, 1.5, -1.5], [0, 0, 1], [6, 3], material="wall"),
            {"type": "sphere", "center": [0.6, 0.5, 0.3], "radius": 0.45, "material": "glass"},
            {"type": "sphere", "center": [-0.7, 0.45, -0.2], "radius": 0.45, "material": "metal"},
        ],
        "materials": {
            "floor": {"type": "diffuse", "reflectance": [0.7, 0.6, 0.5]},
            "wall": {"type": "diffuse", "reflectance": 0.6},
            "glass": {"type": "dielectric", "eta": 1.5},
            "metal": {"type": "roughconductor", "alpha": 0.3},
        },
        "emitters": [
            {
                "type": "spot",
                "position": [0.6, 2.5, 0.3],
                "direction": [0, -1, 0],
                "intensity": 30,
                "cutoff_angle": 25,
                "beam_width": 15,
            },  # fmt: skip
            {
                "type": "area",
                "radiance": [5, 5, 5],
                "shape": {
                    "type": "rectangle",
                    "center": [-1.2, 1.8, -1.0],
                    "normal": [0.4, -0.6, 0.7],
                    "size": [0.6, 0.6],
                },
            },  # fmt: skip
        ],
    }


def _z_pair(a, b):
    """z-scores of ``mean(a) - mean(b)`` over axis 0 from the per-seed standard errors."""
    s = np.sqrt(a.var(0, ddof=1) / a.shape[0] + b.var(0, ddof=1) / b.shape[0])
    return (a.mean(0) - b.mean(0)) / np.where(s > 0, s, np.inf)


MI_SEEDS = 32  # seeds per renderer: the z-scores are Student-t with 62 dof (bound 5: p < 1e-5)


def _vs_mitsuba(desc, *, spp, max_depth, rr_depth=5, crop=0, block=4):
    """Same-run comparison: ``MI_SEEDS`` Mitsuba 3 ``ptracer`` renders (scalar_rgb, seeds 0..)
    and as many jaxgfx keys; z-scores of the image means per channel and of ``block``-pixel
    means (after cropping ``crop`` pixels at each border)."""
    from jaxgfx.render.scene.mitsuba import render_mitsuba

    mi_imgs = np.stack([
        render_mitsuba(desc, spp=spp, integrator="ptracer", max_depth=max_depth,
                       rr_depth=rr_depth, seed=s) for s in range(MI_SEEDS)
    ]).astype(np.float64)  # fmt: skip
    keys = jax.random.split(jax.random.key(6), MI_SEEDS)
    jx = _renders(load_scene(desc), keys, spp, ParticleTracer(max_depth=max_depth,
                                                              rr_depth=rr_depth))  # fmt: skip
    if crop:
        jx, mi_imgs = jx[:, crop:-crop, crop:-crop], mi_imgs[:, crop:-crop, crop:-crop]
    z_ch = _z_pair(jx.mean(axis=(1, 2)), mi_imgs.mean(axis=(1, 2)))
    z_blk = _z_pair(_blocks(jx, block), _blocks(mi_imgs, block))
    rel_se = jx.mean(axis=(1, 2)).std(0, ddof=1) / np.sqrt(MI_SEEDS) / jx.mean(axis=(0, 1, 2))
    print(f"means jaxgfx {jx.mean(axis=(0, 1, 2))} mitsuba {mi_imgs.mean(axis=(0, 1, 2))}; "
          f"z channels {np.round(z_ch, 2)}; block |z| max {np.abs(z_blk).max():.2f} over "
          f"{z_blk.size}; relative standard error of the jaxgfx mean {rel_se}")  # fmt: skip
    return z_ch, z_blk


@pytest.mark.mitsuba
@pytest.mark.slow  # slow: see the parameters' costs (measured under load ~14 on 2 cores)
@pytest.mark.parametrize(
    "case",
    [
        "plane_point_area",  # ~28 s
        "glass_spot_rr",  # ~24 s
        "tent",  # ~35 s
        "gaussian",  # ~49 s
        "distant",  # ~18 s
    ],
)
def test_same_run_mitsuba_ptracer(case):
    """jaxgfx's ``ptracer`` against Mitsuba 3's, same scene, ``MI_SEEDS`` seeds each:
    a point + area light over a diffuse plane; a spot light's caustic through a smooth glass
    sphere, a rough metal sphere and a directly visible area light at depth 5 with Russian
    roulette from depth 2 (the adjoint refraction and the roulette); the tent and Gaussian
    filters' normalised splatting (pixels within 2 of the border cropped: jaxgfx renormalises
    there, Mitsuba with ``sample_border`` drops the weight outside); a directional light and a
    constant sky over the plane seen at a grazing angle (sky in view)."""
    pytest.importorskip("mitsuba")
    if case == "plane_point_area":
        z_ch, z_blk = _vs_mitsuba(_plane_two_lights(), spp=64, max_depth=3)
    elif case == "glass_spot_rr":
        z_ch, z_blk = _vs_mitsuba(_glass_and_spot(), spp=8, max_depth=5, rr_depth=2)
    elif case == "tent":
        film = {"filter": "tent", "radius": 1.0}
        z_ch, z_blk = _vs_mitsuba(_plane_two_lights(16, film), spp=32, max_depth=3, crop=2)
    elif case == "distant":
        desc = _plane_two_lights(8)
        desc["camera"].update(origin=[0, -4, 1.0], target=[0, 0, 0.6], up=[0, 0, 1], fov=60)
        desc["emitters"] = [
            {"type": "directional", "direction": [-0.3, 0.2, -1], "irradiance": [2, 2, 2]},
            {"type": "constant", "radiance": [0.5, 0.6, 0.7]},
        ]
        z_ch, z_blk = _vs_mitsuba(desc, spp=128, max_depth=3)
    else:
        film = {"filter": "gaussian", "stddev": 0.5}
        z_ch, z_blk = _vs_mitsuba(_plane_two_lights(16, film), spp=32, max_depth=3, crop=2)
    assert np.max(np.abs(z_ch)) < 5.0, z_ch
    assert np.max(np.abs(z_blk)) < 5.0, z_blk


# -- spot light: closed form inside the beam, on the falloff ramp and outside ----------------

SPOT_POS = np.array([0.2, 0.1, 2.0])
SPOT_CUTOFF, SPOT_BEAM = 25.0, 12.0


def _spot_reference(scene, sub=16, ramp=True):
    """Pixel averages of ``rho / pi * I falloff(theta) cos / r^2`` on the plane z = 0 under a
    spot pointing down; ``falloff`` from Mitsuba 3's spot documentation: 1 inside
    ``beam_width``, linear in the angle to 0 at ``cutoff_angle``."""
    cam = scene.camera
    n = cam.width
    g = (np.arange(sub) + 0.5) / sub
    xs = (np.arange(n)[:, None] + g[None, :]).reshape(-1)
    px = np.stack(np.meshgrid(xs, xs), -1)
    o, d = (np.asarray(a, np.float64) for a in cam.generate_ray(jnp.asarray(px)))
    x = o + (-o[..., 2] / d[..., 2])[..., None] * d
    v = SPOT_POS - x
    r2 = np.sum(v * v, -1)
    cos_t = v[..., 2] / np.sqrt(r2)  # the angle at the spot to its axis (0, 0, -1) = at the plane
    theta = np.degrees(np.arccos(np.clip(cos_t, -1, 1)))
    fall = np.clip((SPOT_CUTOFF - theta) / (SPOT_CUTOFF - SPOT_BEAM), 0.0, 1.0)
    if not ramp:  # a hard-edged cone (for the sensitivity check)
        fall = np.where(theta < SPOT_CUTOFF, 1.0, 0.0)
    le = RHO / math.pi * INTENSITY * fall * cos_t / r2
    return le.reshape(n, sub, n, sub).mean(axis=(1, 3)), theta


@pytest.mark.slow  # slow: ~8 s on 2 cores under load ~15 (one compile, 16 keys)
def test_spot_light_over_diffuse_plane_closed_form():
    spot = {"type": "spot", "position": SPOT_POS.tolist(), "direction": [0, 0, -1],
            "intensity": INTENSITY, "cutoff_angle": SPOT_CUTOFF,
            "beam_width": SPOT_BEAM}  # fmt: skip
    scene = _plane_scene(n=16, **spot)
    ref, theta = _spot_reference(scene)
    imgs = _renders(scene, jax.random.split(jax.random.key(7), 16), 16,
                    ParticleTracer(max_depth=2))[..., 0]  # fmt: skip
    # the three regions are all in the image: full beam, ramp, outside the cone
    th = theta.reshape(16, 16, 16, 16)
    full = np.all(th < SPOT_BEAM, axis=(1, 3))
    ramp = np.all((th > SPOT_BEAM) & (th < SPOT_CUTOFF), axis=(1, 3))
    out = np.all(th > SPOT_CUTOFF, axis=(1, 3))
    assert full.sum() >= 4 and ramp.sum() >= 8 and out.sum() >= 8
    z = _z(imgs, ref)
    assert np.max(np.abs(z[full | ramp])) < 5.0, z
    assert np.all(imgs[:, out] == 0)  # no light outside the cone, exactly
    zb = _z(_blocks(imgs[..., None], 2)[..., 0], _blocks(ref[..., None], 2)[..., 0])
    assert np.max(np.abs(zb)) < 5.0, zb
    # the ramp is resolved: a hard-edged cone is rejected there by far
    z_hard = _z(imgs, _spot_reference(scene, ramp=False)[0])
    assert np.median(np.abs(z_hard[ramp])) > 20.0, z_hard[ramp]


# -- the light tracer against the path tracer: Russian roulette, refraction, shading normals --


def _pt_vs_path(scene, *, keys, spp, max_depth, rr_depth=5, block=4):
    """z-scores (per channel image means, ``block``-pixel means) of ``ptracer - path`` from
    the per-key standard errors of both; the path tracer with NEE + MIS."""
    pt = _renders(scene, keys, spp, ParticleTracer(max_depth=max_depth, rr_depth=rr_depth))
    pa = _renders(scene, keys, spp, make_integrator("path", max_depth=max_depth,
                                                    rr_depth=rr_depth))  # fmt: skip
    z_ch = _z_pair(pt.mean(axis=(1, 2)), pa.mean(axis=(1, 2)))
    z_blk = _z_pair(_blocks(pt, block), _blocks(pa, block))
    print(f"means ptracer {pt.mean(axis=(0, 1, 2))} path {pa.mean(axis=(0, 1, 2))}; "
          f"z channels {np.round(z_ch, 2)}; block |z| max {np.abs(z_blk).max():.2f} "
          f"over {z_blk.size}")  # fmt: skip
    return z_ch, z_blk, pt, pa


def _uv_sphere(center, r, n_theta=6, n_phi=10):
    """A coarse triangulated sphere with the exact sphere normals at its vertices (smooth
    shading: the shading normal differs from the facets' by up to ~20 degrees)."""
    verts, norms = [], []
    for i in range(n_theta + 1):
        th = math.pi * i / n_theta
        for j in range(n_phi):
            ph = 2 * math.pi * j / n_phi
            nrm = [math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th)]
            norms.append(nrm)
            verts.append([c + r * a for c, a in zip(center, nrm, strict=True)])
    faces = []
    for i in range(n_theta):
        for j in range(n_phi):
            a, b = i * n_phi + j, i * n_phi + (j + 1) % n_phi
            c, d = a + n_phi, b + n_phi
            if i > 0:
                faces.append([a, c, b])
            if i < n_theta - 1:
                faces.append([b, c, d])
    return {"type": "mesh", "vertices": verts, "faces": faces, "normals": norms}


def _tilted_quad(half, normal, material):
    """The square ``|x|, |y| <= half`` at z = 0 as two triangles whose vertex normals are all
    ``normal`` (tilted: shading and geometric normals differ by ~25 degrees everywhere)."""
    v = [[-half, -half, 0], [half, -half, 0], [half, half, 0], [-half, half, 0]]
    n = (np.asarray(normal) / np.linalg.norm(normal)).tolist()
    return {"type": "mesh", "vertices": v, "faces": [[0, 1, 2], [0, 2, 3]],
            "normals": [n] * 4, "material": material}  # fmt: skip


def _glass_scene():
    """Camera over a diffuse floor (z = 0). A small area light facing up sits inside a rough
    glass sphere (eta 1.5, in view): the light leaves the glass into air, where the radiance
    is ``1 / eta^2`` of the one inside: the path tracer gets that factor from radiance-mode
    refraction, the light tracer from the geometry of its particles (importance-mode
    refraction, no factor); a missing or doubled eta^2 correction is off by 2.25 (with the
    correction patched out of ``_bounce`` / ``_eta2_eval`` by hand, the light tracer's mean
    came out 2.2x the path tracer's here, z = 11.3). The floor's shading normals are tilted
    by ~25 degrees and a smooth-shaded coarse mesh sphere stands on it (both diffuse; the
    shading-normal factor is checked sharply by the closed form test below: patching it out
    moved this test's block z only to 4.4, at 16x16 pixels). A
    smooth glass sphere outside the view focuses the light of a second area light onto the
    floor: a caustic (the path tracer finds it by BSDF sampling, the light tracer through two
    sampled refractions)."""
    return load_scene(
        {
            "camera": camera([0, 0, 3], [0, 0, 0], up=[0, 1, 0], fov=30, width=8),
            "shapes": [
                _tilted_quad(3.0, [0.45, 0.2, 1.0], material="floor"),
                sphere([-0.3, 0.25, 0.45], 0.3, material="rough_glass"),
                dict(_uv_sphere([0.35, -0.3, 0.3], 0.3), material="white"),
                sphere([1.1, 0, 0.8], 0.35, material="glass"),
            ],
            "materials": {
                "floor": {"type": "diffuse", "reflectance": [0.7, 0.6, 0.5]},
                "white": {"type": "diffuse", "reflectance": 0.8},
                "rough_glass": {"type": "roughdielectric", "alpha": 0.3, "eta": 1.5},
                "glass": {"type": "dielectric", "eta": 1.5},
            },
            "emitters": [
                {
                    "type": "area",
                    "radiance": [20, 20, 20],
                    "shape": {
                        "type": "rectangle",
                        "center": [-0.3, 0.25, 0.45],
                        "normal": [0, 0, 1],
                        "size": [0.15, 0.15],
                    },
                },  # fmt: skip
                {
                    "type": "area",
                    "radiance": [4, 4, 4],
                    "shape": {
                        "type": "rectangle",
                        "center": [2.0, 0, 1.7],
                        "normal": [-0.707, 0, -0.707],
                        "size": [0.6, 0.6],
                    },
                },  # fmt: skip
            ],
        }
    )


@pytest.mark.slow  # slow: ~66 s on 2 cores under load ~15 (two integrators, 32 keys)
def test_refraction_and_roulette_equal_path_tracer_in_expectation():
    """:func:`_glass_scene` at depth 5 with Russian roulette from depth 2 in both integrators
    (the light tracer's survival ``min(max(beta) eta^2, 0.95)`` and ``beta / q`` keep the
    expectation); 32 keys x 8 spp, Welch z from the per-key standard errors."""
    scene = _glass_scene()
    z_ch, z_blk, _, _ = _pt_vs_path(scene, keys=jax.random.split(jax.random.key(9), 32),
                                    spp=8, max_depth=5, rr_depth=2)  # fmt: skip
    assert np.max(np.abs(z_ch)) < 5.0, z_ch
    assert np.max(np.abs(z_blk)) < 5.0, z_blk


# -- distant emitters: a disk over the scene's bounding sphere --------------------------------


def _pixel_rays(cam, sub=16):
    n_x, n_y = cam.width, cam.height
    g = (np.arange(sub) + 0.5) / sub
    xs = (np.arange(n_x)[:, None] + g[None, :]).reshape(-1)
    ys = (np.arange(n_y)[:, None] + g[None, :]).reshape(-1)
    px = np.stack(np.meshgrid(xs, ys), -1)
    return (np.asarray(a, np.float64) for a in cam.generate_ray(jnp.asarray(px)))


@pytest.mark.slow  # slow: ~9 s on 2 cores under load ~15 (one compile, 16 keys)
def test_directional_light_over_diffuse_plane_closed_form():
    """``rho / pi * E cos`` on the whole plane (the particles start on a disk of the bounding
    sphere's radius: a wrong disk area or offset changes the level)."""
    d = np.array([-0.3, -0.2, -1.0])
    d = d / np.linalg.norm(d)
    scene = _plane_scene(n=8, type="directional", direction=d.tolist(), irradiance=3.0)
    imgs = _renders(scene, jax.random.split(jax.random.key(10), 16), 16,
                    ParticleTracer(max_depth=2))[..., 0]  # fmt: skip
    ref = RHO / math.pi * 3.0 * -d[2]
    z_mean = _z(imgs.mean(axis=(1, 2)), ref)
    z_blk = _z(_blocks(imgs[..., None], 2)[..., 0], ref)
    print(f"directional: mean {imgs.mean()} reference {ref} z {z_mean:.2f} "
          f"block |z| max {np.abs(z_blk).max():.2f}")  # fmt: skip
    assert abs(z_mean) < 5.0 and np.max(np.abs(z_blk)) < 5.0, (z_mean, z_blk)


@pytest.mark.slow  # slow: ~18 s on 2 cores under load ~15 (three compiles, 16 keys)
def test_constant_environment_plane_and_visible_sky_closed_form():
    """A diffuse plane (10 x 10) under a constant sky seen at a grazing angle: a pixel is
    ``L`` where its rays miss the plane (the directly visible environment, sampled from the
    camera) and ``rho L`` where they hit it (nothing else occludes the sky)."""
    le = 2.0
    scene = load_scene(
        {
            "camera": camera([0, -4, 1.0], [0, 0, 0.6], up=[0, 0, 1], fov=60, width=8),
            "shapes": [rectangle([0, 0, 0], [0, 0, 1], [10, 10], material="w")],
            "materials": {"w": {"type": "diffuse", "reflectance": RHO}},
            "emitters": [{"type": "constant", "radiance": le}],
        }
    )
    o, d = _pixel_rays(scene.camera)
    t = -o[..., 2] / np.where(d[..., 2] < 0, d[..., 2], -1e-30)
    x = o + t[..., None] * d
    on = (d[..., 2] < 0) & (np.abs(x[..., 0]) < 5) & (np.abs(x[..., 1]) < 5)
    ref = np.where(on, RHO * le, le).reshape(8, 16, 8, 16).mean(axis=(1, 3))
    assert ref.min() < 0.6 * le and ref.max() == le  # both sky and floor in view
    imgs = _renders(scene, jax.random.split(jax.random.key(11), 16), 16,
                    ParticleTracer(max_depth=2))[..., 0]  # fmt: skip
    z = _z(_blocks(imgs[..., None], 2)[..., 0], _blocks(ref[..., None], 2)[..., 0])
    # max_depth 1: the directly visible sky only (none on pixels that see only the floor);
    # hide_emitters drops it
    key = jax.random.key(0)
    sky = np.asarray(render(scene, key, spp=4, integrator=ParticleTracer(max_depth=1)))[..., 0]
    assert np.all(sky[ref == RHO * le] == 0) and sky[ref == le].sum() > 0
    hidden = render(scene, key, spp=4, integrator=ParticleTracer(max_depth=1, hide_emitters=True))
    assert np.all(np.asarray(hidden) == 0)
    print(f"constant: mean {imgs.mean()} reference {ref.mean()} block |z| max "
          f"{np.abs(z).max():.2f}")  # fmt: skip
    assert np.max(np.abs(z)) < 5.0, z


@pytest.mark.slow  # slow: ~37 s on 2 cores under load ~15 (two integrators, 32 keys)
def test_envmap_equals_path_tracer_in_expectation():
    """A small inline environment map with a bright patch (importance sampled by its texels),
    a floor and a diffuse sphere, the sky partly in view, depth 3."""
    img = np.full((8, 16, 3), 0.3)
    img[1:3, 3:6] = [8.0, 6.0, 4.0]  # a "sun" patch above the horizon
    scene = load_scene(
        {
            "camera": camera([0, 1.0, 4], [0, 0.6, 0], up=[0, 1, 0], fov=60, width=8),
            "shapes": [
                rectangle([0, 0, 0], [0, 1, 0], [6, 6], material="floor"),
                {"type": "sphere", "center": [0.2, 0.5, 0], "radius": 0.5, "material": "w"},
            ],
            "materials": {
                "floor": {"type": "diffuse", "reflectance": [0.7, 0.5, 0.3]},
                "w": {"type": "diffuse", "reflectance": 0.6},
            },  # fmt: skip
            "emitters": [{"type": "envmap", "image": img.tolist()}],
        }
    )
    z_ch, z_blk, _, _ = _pt_vs_path(scene, keys=jax.random.split(jax.random.key(12), 32),
                                    spp=8, max_depth=3)  # fmt: skip
    assert np.max(np.abs(z_ch)) < 5.0, z_ch
    assert np.max(np.abs(z_blk)) < 5.0, z_blk


@pytest.mark.slow  # slow: ~8-15 s on 2 cores under load ~15 (one compile, 16 keys)
def test_shading_normals_closed_form():
    """A point light over a square whose shading normals are all tilted by ~25 degrees from
    its geometric normal, seen obliquely: the radiance is ``rho / pi * I cos(wl, ns) / r^2``
    (the shading normal's cosine towards the light, as a camera path computes it). The light
    tracer gets there only through Veach's adjoint factor ``|cos(wo, ns) cos(wc, ng)| /
    |cos(wc, ns) cos(wo, ng)|`` (without it: ``cos(wc, ns) cos(wl, ng) / cos(wc, ng)``)."""
    ns = np.array([-0.45, 0.2, 1.0])
    ns = ns / np.linalg.norm(ns)
    light = np.array([0.3, 0.2, 1.2])
    scene = load_scene(
        {
            "camera": camera([-2.5, 0, 2.5], [0, 0, 0], up=[0, 0, 1], fov=40, width=8),
            "shapes": [_tilted_quad(3.0, ns.tolist(), material="w")],
            "materials": {"w": {"type": "diffuse", "reflectance": RHO}},
            "emitters": [{"type": "point", "position": light.tolist(), "intensity": INTENSITY}],
        }
    )
    o, d = _pixel_rays(scene.camera)
    x = o + (-o[..., 2] / d[..., 2])[..., None] * d
    v = light - x
    r2 = np.sum(v * v, -1)
    wl = v / np.sqrt(r2)[..., None]
    cos_s = wl @ ns
    assert np.all(cos_s > 0) and np.all(-d @ ns > 0)  # no light-leak case in view
    ref = (RHO / math.pi * INTENSITY * cos_s / r2).reshape(8, 16, 8, 16).mean(axis=(1, 3))
    wrong = RHO / math.pi * INTENSITY * (-d @ ns) * wl[..., 2] / (-d[..., 2]) / r2
    wrong = wrong.reshape(8, 16, 8, 16).mean(axis=(1, 3))
    imgs = _renders(scene, jax.random.split(jax.random.key(13), 16), 16,
                    ParticleTracer(max_depth=2))[..., 0]  # fmt: skip
    z = _z(_blocks(imgs[..., None], 2)[..., 0], _blocks(ref[..., None], 2)[..., 0])
    z_wrong = _z(imgs.mean(axis=(1, 2)), wrong.mean())
    print(f"shading normals: mean {imgs.mean()} reference {ref.mean()} (uncorrected "
          f"{wrong.mean()}, z {z_wrong:.1f}); block |z| max {np.abs(z).max():.2f}")  # fmt: skip
    assert np.max(np.abs(z)) < 5.0, z
    assert abs(z_wrong) > 10  # the uncorrected light tracer would be rejected by far


def _grazing_loss(x, scene):
    s = scene.replace("emitters.directional.0.irradiance", x[:3]).replace(
        "emitters.environment.radiance", x[3:]
    )
    return jnp.sum(render(s, jax.random.key(0), spp=2, integrator=ParticleTracer(max_depth=3)))


@pytest.mark.slow  # slow: ~25 s on 2 cores under load ~15 (value + gradient compile)
def test_grazing_directional_and_black_sky_finite_values_and_gradients():
    """Hard cases of the distant emitters: a directional light exactly parallel to the plane
    (its particles never hit it) and a black constant sky: the image is 0 and the gradient
    finite (the irradiance's is 0, the sky radiance's is positive: its visible part)."""
    desc_env = {"type": "constant", "radiance": 0.0}
    scene = load_scene(
        {
            "camera": camera([0, -3, 1], [0, 0, 0.5], up=[0, 0, 1], fov=60, width=4),
            "shapes": [
                {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 0, 1], "size": [4, 4]}
            ],  # fmt: skip
            "emitters": [
                {"type": "directional", "direction": [1, 0, 0], "irradiance": 1.0},
                desc_env,
            ],  # fmt: skip
        }
    )
    x = jnp.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    val, g = jax.jit(jax.value_and_grad(_grazing_loss))(x, scene)
    assert float(val) == 0.0
    g = np.asarray(g)
    assert np.all(np.isfinite(g)) and np.all(g[:3] == 0) and np.all(g[3:] > 0), g
