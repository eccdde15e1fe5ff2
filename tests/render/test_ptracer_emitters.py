"""The particle tracer's emission sampling of textured area lights, textured spot lights and
projectors: the projector against its closed form (irradiance ``pi scale E / z^2`` on a plane
facing it), all three against the path tracer in expectation.

Monte Carlo tolerances: ``K`` independent keys per integrator, z-scores of the difference of
the means from the per-key standard errors (Welch), bound 5."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import load_scene, render
from jaxgfx.render.integrators import ParticleTracer, make_integrator
from tests.render._scenes import camera, rectangle


@pytest.fixture(autouse=True)
def _float64(x64):
    """float64 in every test of this module, restored after it (tests/conftest.py ``x64``)."""
    yield

RHO = 0.5
Z_MAX = 5.0
# 2 x 2 texels (row 0 at the top), nearest lookup: the orientation of each mapping matters
TEX = [[[1.0, 0.2, 0.1], [0.1, 0.9, 0.3]], [[0.2, 0.3, 1.2], [0.8, 0.8, 0.1]]]
BITMAP = {"type": "bitmap", "image": TEX, "filter": "nearest", "wrap": "clamp"}


def _scene(emitters, n=16, shapes=()):
    """The diffuse plane z = 0 seen straight down from (0, 0, 3)."""
    return load_scene(
        {
            "camera": camera([0, 0, 3], [0, 0, 0], fov=40, width=n, up=[0, 1, 0]),
            "shapes": [rectangle((0, 0, 0), (0, 0, 1), (10, 10), "w"), *shapes],
            "materials": {"w": {"type": "diffuse", "reflectance": RHO}},
            "emitters": list(emitters),
        }
    )


def _renders(scene, keys, spp, integrator):
    return np.asarray(
        jax.jit(jax.vmap(lambda k: render(scene, k, spp=spp, integrator=integrator)))(keys)
    )


def _z(samples, ref):
    se = samples.std(0, ddof=1) / math.sqrt(samples.shape[0])
    return (samples.mean(0) - ref) / np.where(se > 0, se, np.inf)


def _z_pair(a, b):
    s = np.sqrt(a.var(0, ddof=1) / a.shape[0] + b.var(0, ddof=1) / b.shape[0])
    return (a.mean(0) - b.mean(0)) / np.where(s > 0, s, np.inf)


def _blocks(img, b):
    h, w = img.shape[-3:-1]
    return img.reshape(*img.shape[:-3], h // b, b, w // b, b, img.shape[-1]).mean(axis=(-4, -2))


# -- the projector: closed form ---------------------------------------------------------------

PH, PT = 2.0, 0.3  # projector height, tan(fov / 2): the frustum meets z = 0 in |x|, |y| < 0.6


def _coverage(scene, half):
    """Per pixel the fraction of its footprint on z = 0 inside ``|x|, |y| < half`` (the camera
    looks straight down: the footprint is an axis-aligned square, mapped linearly)."""
    cam = scene.camera
    n = cam.width
    edges = np.stack([np.arange(n + 1), np.full(n + 1, n / 2)], -1).astype(np.float64)
    o, d = (np.asarray(a, np.float64) for a in cam.generate_ray(jnp.asarray(edges)))
    x = (o + (-o[..., 2] / d[..., 2])[..., None] * d)[:, 0]
    lo, hi = np.minimum(x[:-1], x[1:]), np.maximum(x[:-1], x[1:])
    f = np.clip(np.minimum(hi, half) - np.maximum(lo, -half), 0, None) / (hi - lo)
    return f[None, :] * f[:, None]  # symmetric: rows and columns alike


@pytest.mark.slow  # slow: ~6 s on 2 cores under load (one compile, 16 keys)
def test_projector_over_diffuse_plane_closed_form():
    e, scale = np.array([1.0, 2.0, 3.0]), 0.5
    fov = math.degrees(2 * math.atan(PT))
    proj = {"type": "projector", "position": [0, 0, PH], "direction": [0, 0, -1],
            "up": [0, 1, 0], "fov": fov, "irradiance": e.tolist(), "scale": scale}  # fmt: skip
    scene = _scene([proj])
    # radiance rho / pi * (pi scale E / z^2) inside the frustum, 0 outside
    cov = _coverage(scene, PH * PT)
    ref = cov[..., None] * (RHO * scale * e / PH**2)
    imgs = _renders(scene, jax.random.split(jax.random.key(3), 16), 16, ParticleTracer(max_depth=2))
    inside, out = cov > 0, cov == 0
    assert inside.sum() >= 16 and out.sum() >= 16 and ((cov > 0) & (cov < 1)).sum() >= 8
    z = _z(imgs, ref)
    zb = _z(_blocks(imgs, 2), _blocks(ref, 2))
    print(f"projector: mean {imgs.mean((0, 1, 2))} ref {ref.mean((0, 1))}; |z| max "
          f"{np.abs(z[inside]).max():.2f}, blocks {np.abs(zb).max():.2f}")  # fmt: skip
    assert np.max(np.abs(z[inside])) < Z_MAX
    assert np.max(np.abs(zb)) < Z_MAX
    assert np.all(imgs[:, out] == 0)  # nothing outside the frustum, exactly
    # a wrong constant (the image-plane area, pi) fails by far
    assert abs(imgs.mean() / ref.mean() - 1) < 0.03


# -- textured emitters: the light tracer against the path tracer ------------------------------


def _textured_scene():
    """A textured projector, a textured spot and a textured rectangular area light tilted so
    that the camera sees its front (directly visible) while it lights the plane."""
    proj = {"type": "projector", "position": [-0.3, 0.35, 1.5], "direction": [0, 0, -1],
            "up": [0, 1, 0], "fov": 40.0, "irradiance": BITMAP, "scale": 0.5}  # fmt: skip
    spot = {"type": "spot", "position": [0.45, 0.3, 1.2], "direction": [0, 0, -1],
            "intensity": 1.5, "cutoff_angle": 30.0, "beam_width": 15.0, "up": [0, 1, 0],
            "texture": BITMAP}  # fmt: skip
    area = {"type": "area", "radiance": BITMAP,
            "shape": rectangle((-0.5, -0.45, 0.3), (1, 0, 0.6), (0.5, 0.4))}  # fmt: skip
    return _scene([proj, spot, area])


@pytest.mark.slow  # slow: ~40 s on 2 cores under load (two integrators, 16 keys)
def test_textured_emitters_equal_path_tracer_in_expectation():
    scene = _textured_scene()
    keys = jax.random.split(jax.random.key(11), 16)
    pt = _renders(scene, keys, 16, ParticleTracer(max_depth=3))
    pa = _renders(scene, keys, 16, make_integrator("path", max_depth=3))
    z_ch = _z_pair(pt.mean(axis=(1, 2)), pa.mean(axis=(1, 2)))
    z_blk = _z_pair(_blocks(pt, 2), _blocks(pa, 2))
    print(f"means ptracer {pt.mean(axis=(0, 1, 2))} path {pa.mean(axis=(0, 1, 2))}; "
          f"z channels {np.round(z_ch, 2)}; block |z| max {np.abs(z_blk).max():.2f} "
          f"over {z_blk.size}")  # fmt: skip
    assert np.all(np.abs(z_ch) < Z_MAX), z_ch
    assert np.max(np.abs(z_blk)) < Z_MAX
    # every emitter contributes: the lit regions are not black in either renderer
    assert pa.mean() > 0 and np.mean(pt > 0) > 0.3


# -- the emission weights under jit: closed forms and derivatives -----------------------------


def test_projector_and_textured_spot_emission_weights_and_gradients():
    """``sample_emission`` under jit: the projector's weight is ``n_lights pi scale E(uv) A``
    (``A = 4 tan²(fov / 2) / aspect``) and its direction points through the image-plane point
    of ``uv``; AD of the weights w.r.t. scale, fov and the spot's intensity equals central
    differences (float64)."""
    from jaxgfx.render.integrators.ptracer import sample_emission

    e = [0.3, 0.6, 0.9]
    proj = {"type": "projector", "position": [0, 0, 2], "direction": [0, 0, -1],
            "up": [0, 1, 0], "fov": 50.0, "irradiance": e, "scale": 0.7}  # fmt: skip
    spot = {"type": "spot", "position": [0.4, 0.3, 1.2], "direction": [0, 0, -1],
            "intensity": 1.5, "cutoff_angle": 30.0, "beam_width": 15.0, "up": [0, 1, 0],
            "texture": BITMAP}  # fmt: skip
    scene = load_scene(
        {"camera": camera([0, 0, 3], [0, 0, 0], fov=40, width=2, up=[0, 1, 0]),
         "shapes": [{"type": "sphere", "center": [0, 0, -3], "radius": 1.0}],
         "emitters": [proj, spot]}, dtype=jnp.float64)  # fmt: skip
    u = jax.random.uniform(jax.random.key(0), (64, 5), jnp.float64)
    u_proj = u.at[:, 0].set(0.25)  # the first delta light (the projector)
    o, d, w = jax.jit(sample_emission)(scene, u_proj)
    t = math.tan(math.radians(25.0))
    np.testing.assert_allclose(w, np.tile(2 * math.pi * 0.7 * np.array(e) * 4 * t * t, (64, 1)),
                               rtol=1e-12)  # fmt: skip
    # the direction crosses the image plane at the sampled uv (the projector's own mapping)
    light = scene.delta_lights[0]
    uv, inside = light.uv(light.local(o + d))
    assert np.all(inside)
    np.testing.assert_allclose(uv, u[:, 3:5], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(o, np.tile([0.0, 0.0, 2.0], (64, 1)))

    @jax.jit
    def total(x, uu):
        s = scene.replace("emitters.projector.0.scale", x[0])
        s = s.replace("emitters.projector.0.fov", x[1]).replace("emitters.spot.0.intensity", x[2:])
        return jnp.sum(sample_emission(s, uu)[2])

    x0 = jnp.asarray([0.7, 50.0, 1.5, 1.5, 1.5], jnp.float64)
    u_spot = u.at[:, 0].set(0.75)
    grad = jax.jit(jax.grad(total))
    h = 1e-5
    steps = h * np.eye(5)
    for uu in (u_proj, u_spot):
        g = grad(x0, uu)
        fd = [(total(x0 + steps[i], uu) - total(x0 - steps[i], uu)) / (2 * h) for i in range(5)]
        np.testing.assert_allclose(g, fd, rtol=1e-6, atol=1e-9)
        assert float(jnp.abs(g).sum()) > 0
