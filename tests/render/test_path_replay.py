"""Path replay backpropagation (``PathIntegrator(adjoint="replay")``,
jaxgfx/render/integrators/_replay.py).

The strongest check: with the same key, replay's reverse-mode gradient equals the detached AD
gradient of the same integrator (the value is the same program) up to float rounding, in
float64, on scenes covering every parameter kind replay handles. Then the replay gradient
against same-key central finite differences on a glossy scene with an area light and an
occluder (the paired difference's standard error from the keys), the errors that refuse what
replay does not cover, and the hard cases.

Costs: path-tracer gradient programs take 30-500 s of XLA compilation on the shared 2-core
machine at load ~10, so every test that compiles one is ``slow`` (measured cost in its
comment; ~10 min in all at load ~5, ~20 min at load ~10, far above the ~2 min budget:
trimming them is left to do); the default suite runs the option and refusal checks, which
only trace (< 4 s).
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import load_scene, render
from jaxgfx.render.integrators import DirectIntegrator, PathIntegrator, make_integrator
from jaxgfx.testing import ad_fd_per_key

sys.path.insert(0, str(Path(__file__).parent))
import _gradient_scenes as G  # noqa: E402

KEY = jax.random.key(3)


def _occluder_scene(w=4, reflectance=(0.6, 0.5, 0.4)):
    """Diffuse sphere over a diffuse floor (one material), a small area light above (the sphere
    shadows the floor) and a constant environment."""
    return {
        "camera": {
            "origin": [0, 1.5, 3],
            "target": [0, 0.3, 0],
            "fov": 45,
            "width": w,
            "height": w,
        },
        "shapes": [
            {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5, "material": "m"},
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 1, 0],
                "size": [4, 4],
                "material": "m",
            },
        ],
        "materials": {"m": {"type": "diffuse", "reflectance": list(reflectance)}},
        "emitters": [
            {
                "type": "area",
                "radiance": 5.0,
                "shape": {
                    "type": "rectangle",
                    "center": [0, 2, 0.5],
                    "normal": [0, -1, 0],
                    "size": [1, 1],
                },
            },
            {"type": "constant", "radiance": 0.2},
        ],
    }


def _set(scene, params):
    for k, v in params.items():
        scene = scene.replace(k, v)
    return scene


def _both_grads(scene, paths, integ_kw, *, spp=2, key=KEY):
    """Same-key gradients of a non-linear image loss by AD and by replay, one program."""
    params = {p: jnp.asarray(scene.get(p)) for p in paths}

    def grads(ps):
        out = []
        for adjoint in ("ad", "replay"):
            integ = PathIntegrator(adjoint=adjoint, **integ_kw)

            def loss(ps, integ=integ):
                img = render(_set(scene, ps), key, spp=spp, integrator=integ)
                return jnp.mean(img**2) + jnp.mean(img)

            out.append(jax.grad(loss)(ps))
        return out

    ad, rp = jax.jit(grads)(params)
    return {p: np.asarray(ad[p]) for p in paths}, {p: np.asarray(rp[p]) for p in paths}


def _assert_same(ad, rp, rtol=1e-9):
    for p in ad:
        scale = max(np.max(np.abs(ad[p])), 1e-300)
        assert np.all(np.isfinite(rp[p])), p
        np.testing.assert_allclose(rp[p], ad[p], rtol=0, atol=rtol * scale, err_msg=p)
        assert np.max(np.abs(ad[p])) > 0, p  # a zero gradient would make the check vacuous


# ------------------------------------------------------------------------------------------
# options and refusals (trace only: default suite)


def test_adjoint_option_is_validated():
    with pytest.raises(ValueError, match="adjoint"):
        PathIntegrator(adjoint="prb")
    with pytest.raises(ValueError, match="adjoint.*sampling='detached'"):
        PathIntegrator(adjoint="replay", sampling="attached")
    assert PathIntegrator().adjoint == "ad"
    assert DirectIntegrator(adjoint="replay").adjoint == "replay"
    # the scene-file / config form: {type: path, adjoint: replay}
    integ = make_integrator("path", max_depth=4, adjoint="replay")
    assert integ == PathIntegrator(max_depth=4, adjoint="replay")
    from jaxgfx.render.estimator import resolve_integrator  # noqa: PLC0415

    assert resolve_integrator({"type": "path", "adjoint": "replay"}, max_depth=4) == integ
    with pytest.raises(ValueError, match="adjoint"):
        resolve_integrator({"type": "path", "adjoint": "reverse"})
    with pytest.raises(TypeError, match="adjoint"):
        resolve_integrator({"type": "whitted", "adjoint": "replay"})
    with pytest.raises(ValueError, match="integrator.type"):
        resolve_integrator({"adjoint": "replay"})


@pytest.mark.parametrize(
    "path, match",
    [
        ("shapes.0.centers", r"shapes.*adjoint='ad'"),
        ("camera.origin", r"camera.*adjoint='ad'"),
    ],
)
def test_geometry_and_camera_parameters_are_refused(path, match):
    scene = load_scene(_occluder_scene(w=2))
    integ = PathIntegrator(max_depth=2, adjoint="replay")
    x0 = jnp.asarray(scene.get(path))

    def loss(x):
        return jnp.mean(render(scene.replace(path, x), KEY, spp=1, integrator=integ))

    with pytest.raises(ValueError, match=match):
        jax.grad(loss)(x0)


def test_edge_sampling_of_a_shape_parameter_is_refused():
    """``visibility="edge"`` adds boundary terms for shape parameters, whose interior part
    replay does not compute: the combination is refused, not half-differentiated."""
    scene = load_scene(_occluder_scene(w=2))
    integ = DirectIntegrator(adjoint="replay")
    c0 = scene.get("shapes.0.centers")

    def loss(c):
        s = scene.replace("shapes.0.centers", c)
        return jnp.mean(render(s, KEY, spp=1, integrator=integ, visibility="edge"))

    with pytest.raises(ValueError, match=r"shapes.*visibility='edge'"):
        jax.grad(loss)(c0)


def test_dielectric_eta_is_refused():
    desc = G.glass_scene(2)
    scene = load_scene(desc)
    integ = PathIntegrator(max_depth=2, adjoint="replay")

    def loss(eta):
        return jnp.mean(
            render(scene.replace("materials.glass.eta", eta), KEY, spp=1, integrator=integ)
        )

    with pytest.raises(ValueError, match=r"glass.*SmoothDielectric.*adjoint='ad'"):
        jax.grad(loss)(jnp.asarray(1.5))


# ------------------------------------------------------------------------------------------
# same key: replay == detached AD (float64)


# slow: 69-80 s measured on the shared 2-core machine at load ~10 (one program: AD + replay)
@pytest.mark.slow
def test_same_key_diffuse_area_environment_rr(x64):
    """Depth 4 with Russian roulette from the second bounce: albedo, area-light and
    environment radiance."""
    scene = load_scene(_occluder_scene())
    paths = ["materials.m.reflectance", "emitters.area.0.radiance", "emitters.environment.radiance"]
    ad, rp = _both_grads(scene, paths, dict(max_depth=4, rr_depth=2))
    _assert_same(ad, rp)


# slow: 52 s at load ~5, 317 s at load ~10 (chunk=None, 163 s, passed too at commit 97a2386 and was
# dropped: wavefront chunks are the case replay adds; tests/render/test_wavefront.py covers
# chunked = unchunked)
@pytest.mark.slow
@pytest.mark.parametrize("chunk", [16])
def test_same_key_glossy_textured(x64, chunk):
    """GGX α and reflectance, floor texels, area and environment radiance (the glossy scene of
    issue 10), depth 5, Russian roulette on, wavefront shading (``chunk=16``) inside the
    replay."""
    scene = load_scene(G.glossy_scene(0.15, 4))
    paths = [p for p, _ in G.GLOSSY_PARAMS]
    ad, rp = _both_grads(scene, paths, dict(max_depth=5, rr_depth=3, chunk=chunk))
    _assert_same(ad, rp)


# slow: 144 s at load ~5, 560 s at load ~12 with a benchmark alongside (three materials'
# value-and-gradient programs, AD + replay, compile)
@pytest.mark.slow
def test_same_key_materials_point_light_beckmann(x64):
    """Rough plastic, Phong and an anisotropic complex-IOR conductor, area + point +
    environment light, depth 3; plus a Beckmann sphere's α in the interreflection scene."""
    desc = G.materials_scene(4)
    desc["materials"]["metal"]["distribution"] = "beckmann"
    scene = load_scene(desc)
    paths = [p for p, _ in G.MATERIALS_PARAMS]
    ad, rp = _both_grads(scene, paths, dict(max_depth=3, rr_depth=2))
    _assert_same(ad, rp)


# slow: 39 s at load ~5, 94 s at load ~10
@pytest.mark.slow
def test_same_key_glossy_interreflections_depth6_mirror(x64):
    """Two spheres (GGX metal and diffuse clay, configs/scenes/inverse.yaml) at depth 6 with a
    complex-IOR mirror (delta lobe) floor: light bounces between the spheres and the mirror."""
    from jaxgfx.config import read_yaml  # noqa: PLC0415

    desc = read_yaml("configs/scenes/inverse.yaml")
    desc["camera"]["width"] = desc["camera"]["height"] = 4
    desc["materials"]["floor"] = {"type": "conductor", "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.2]}
    scene = load_scene(desc)
    paths = [
        "materials.metal.alpha",
        "materials.metal.reflectance",
        "materials.clay.reflectance",
        "materials.floor.eta",
        "materials.floor.k",
        "emitters.area.0.radiance",
    ]
    ad, rp = _both_grads(scene, paths, dict(max_depth=6, rr_depth=4), spp=2)
    _assert_same(ad, rp)


# ------------------------------------------------------------------------------------------
# replay against finite differences (float64, same keys)


def _fd_loss(x, k, scene, integ):
    base = jnp.asarray([0.15, 1.0, 1.0])  # α, area radiance scale, floor albedo scale
    a, le, rho = x * base
    s = scene.replace("materials.metal.alpha", a)
    s = s.replace("emitters.area.0.radiance", s.get("emitters.area.0.radiance") * le)
    s = s.replace("materials.floor.reflectance", s.get("materials.floor.reflectance") * rho)
    # squared: the highlight's peak (which falls as α grows) dominates, so that dα is resolved
    return jnp.mean(render(s, k, spp=32, integrator=integ) ** 2)


# slow: 69-132 s measured at load 7-10 (value-and-gradient + 6 perturbed renders)
@pytest.mark.slow
def test_replay_matches_finite_differences_glossy_area_occluder(x64):
    """GGX sphere over a diffuse floor it shadows, area light, environment; depth 3, 8²,
    16 keys × 32 spp. The paired (replay − FD) difference must be within 4 standard errors
    (plus 1 % of |FD| for the parameters no sampling decision depends on, where FD is exact to
    O(h²): the loss is a polynomial of degree ≤ 4 in them); the radiance and albedo
    derivatives must be resolved (|mean| > 4 standard errors, 4 standard errors below half of
    |FD|), else the check could not fail; α is checked but not resolved (see below)."""
    desc = G.glossy_scene(0.15, 8)
    desc["materials"]["floor"] = {"type": "diffuse", "reflectance": [0.6, 0.5, 0.4]}
    scene = load_scene(desc)
    integ = PathIntegrator(max_depth=3, adjoint="replay")
    keys = jax.random.split(jax.random.key(11), 16)
    _, ad, fd = ad_fd_per_key(_fd_loss, jnp.ones(3), keys, 0.1, args=(scene, integ))
    diff = ad - fd
    se = diff.std(0, ddof=1) / np.sqrt(len(keys))
    tol = 4 * se + np.array([0.0, 0.01, 0.01]) * np.abs(fd.mean(0))
    print("replay", ad.mean(0), "FD", fd.mean(0), "paired diff", diff.mean(0), "+-", se)
    assert np.all(np.abs(diff.mean(0)) <= tol), (ad.mean(0), fd.mean(0), se)
    # resolved, so that a 50 % bias would fail: area radiance and floor albedo. α is NOT
    # resolved at this budget (measured: replay −0.0070, FD −0.0024, paired −0.0046 ± 0.0045);
    # replay's α derivative equals AD's per sample (the same-key tests above), and AD's is
    # checked against FD at 64 keys × 512 spp in test_gradients_fd_high_spp.py
    assert np.all(np.abs(ad.mean(0)[1:]) > 4 * ad.std(0, ddof=1)[1:] / np.sqrt(len(keys)))
    assert np.all(4 * se[1:] < 0.5 * np.abs(fd.mean(0)[1:]))


# ------------------------------------------------------------------------------------------
# hard cases


# slow: 163 s measured at load ~10 with a benchmark running alongside
@pytest.mark.slow
def test_tiny_roughness_black_albedo_and_zero_channel(x64):
    """α → 0 (clamped at 1e-4: derivative 0, as FD), a black floor and a sphere albedo with a
    zero channel: exactly-zero BSDF weights, where ``(L − L_≤j) / w_j`` is 0/0 and the light
    after the vertex comes from the forward pass's ``Z``. Same gradient as AD (which keeps such
    paths alive), finite, and positive for the black albedo (brightening it brightens the
    image)."""
    desc = G.glossy_scene(1e-6, 4)
    desc["shapes"].append(
        {"type": "sphere", "center": [1.2, 0.4, 0.5], "radius": 0.4, "material": "clay"}
    )
    desc["materials"]["floor"] = {"type": "diffuse", "reflectance": [0.0, 0.0, 0.0]}
    desc["materials"]["clay"] = {"type": "diffuse", "reflectance": [0.7, 0.0, 0.3]}
    scene = load_scene(desc)
    paths = ["materials.metal.alpha", "materials.floor.reflectance", "materials.clay.reflectance"]
    ad, rp = _both_grads(scene, paths, dict(max_depth=4, rr_depth=3), spp=4)
    assert rp["materials.metal.alpha"] == 0.0 == ad["materials.metal.alpha"]
    del ad["materials.metal.alpha"]
    _assert_same(ad, {k: rp[k] for k in ad})
    assert np.all(rp["materials.floor.reflectance"] > 0)
    assert rp["materials.clay.reflectance"][1] > 0  # the zero channel's derivative


# slow: 31-84 s measured at load ~10
@pytest.mark.slow
def test_same_key_embree_mesh(x64):
    """A triangle mesh traced by Embree (``pure_callback``, which has no derivative rule):
    replay never differentiates through a traversal; same gradient as AD."""
    pytest.importorskip("embreex")
    from jaxgfx.render.geometry.mesh_io import make_uv_sphere  # noqa: PLC0415

    desc = _occluder_scene()
    m = make_uv_sphere(6, radius=0.5, center=(0.0, 0.5, 0.0))
    desc["shapes"][0] = {
        "type": "mesh",
        "vertices": np.asarray(m.vertices).tolist(),
        "faces": np.asarray(m.faces).tolist(),
        "material": "m",
    }
    scene = load_scene(desc, accel="embree")
    assert scene.accel == "embree"
    paths = ["materials.m.reflectance", "emitters.area.0.radiance"]
    ad, rp = _both_grads(scene, paths, dict(max_depth=3))
    _assert_same(ad, rp)
