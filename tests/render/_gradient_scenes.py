"""Small lit scenes and a shared AD-vs-finite-difference driver for the gradient tests.

Each scene has area lights and an environment (the boundaries that bias gradients through
sampled directions) and a list of continuous parameters. A parameter is a pair
``(path, base)``: the scene is evaluated at ``replace(path, base * x)`` and the derivative is
taken w.r.t. the scalar ``x`` at 1 (a directional derivative along ``base``, so RGB and texture
parameters are covered by one scalar each).

:func:`ad_fd` compiles ONE program per scene structure that returns, per key, the AD gradient
(reverse mode) of the image mean and the central finite differences of the same renderer with
the same key (common random numbers), so the paired difference ``AD - FD`` has a standard error
estimated from the keys.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene
from jaxgfx.testing import ad_fd_per_key

ENV = {"type": "constant", "radiance": 0.3}  # copied into each scene: tests edit their descriptions


def _camera(w=8, origin=(0, 1.0, 4.0), target=(0, 0.6, 0), fov=40):
    return {"origin": list(origin), "target": list(target), "fov": fov, "width": w, "height": w}


def _floor(material="floor"):
    return {
        "type": "rectangle",
        "center": [0, 0, 0],
        "normal": [0, 1, 0],
        "size": [6, 6],
        "material": material,
    }


def _light(radiance=8.0, center=(0, 3.0, 1.0), normal=(0, -1, -0.3), size=(1.2, 1.2)):
    return {
        "type": "area",
        "shape": {
            "type": "rectangle",
            "center": list(center),
            "normal": list(normal),
            "size": list(size),
        },
        "radiance": radiance,
    }


def glossy_scene(alpha=0.15, w=8):
    """The scene of issue 10: GGX rough-conductor sphere, textured diffuse floor, area light,
    constant environment."""
    texels = [[[0.7, 0.5, 0.3], [0.2, 0.4, 0.6]], [[0.5, 0.5, 0.5], [0.8, 0.3, 0.2]]]
    return {
        "camera": _camera(w),
        "shapes": [
            {"type": "sphere", "center": [0, 0.8, 0], "radius": 0.8, "material": "metal"},
            _floor(),
        ],
        "materials": {
            "metal": {"type": "roughconductor", "alpha": alpha, "reflectance": [0.9, 0.8, 0.7]},
            "floor": {
                "type": "diffuse",
                "reflectance": {"type": "bitmap", "image": texels, "filter": "nearest"},
            },
        },
        "emitters": [_light(), dict(ENV)],
    }


GLOSSY_PARAMS = [
    ("materials.metal.alpha", 0.15),
    ("materials.metal.reflectance", np.array([0.9, 0.8, 0.7])),
    ("materials.floor.reflectance.image", None),  # base = the texture itself
    ("emitters.area.0.radiance", np.array([8.0, 8.0, 8.0])),
    ("emitters.environment.radiance", np.array([0.3, 0.3, 0.3])),
]


def materials_scene(w=8):
    """Direct lighting of every non-delta BSDF: rough plastic and (modified) Phong spheres on an
    anisotropic rough-conductor floor with a complex IOR, lit by an area light, a point light
    and a constant environment."""
    return {
        "camera": _camera(w, origin=(0, 1.6, 4.0), target=(0, 0.5, 0), fov=50),
        "shapes": [
            {"type": "sphere", "center": [-0.7, 0.6, 0], "radius": 0.6, "material": "plastic"},
            {"type": "sphere", "center": [0.7, 0.6, 0], "radius": 0.6, "material": "phong"},
            _floor("metal"),
        ],
        "materials": {
            "plastic": {
                "type": "roughplastic",
                "alpha": 0.2,
                "diffuse_reflectance": [0.6, 0.3, 0.2],
                "specular_reflectance": 0.8,
                "eta": 1.5,
            },
            "phong": {"type": "phong", "kd": [0.3, 0.5, 0.4], "ks": 0.4, "exponent": 20.0},
            "metal": {
                "type": "roughconductor",
                "alpha": 0.15,
                "alpha_v": 0.35,
                "eta": [0.2, 0.9, 1.1],
                "k": [3.9, 2.4, 2.2],
            },
        },
        "emitters": [
            _light(radiance=6.0, center=(0.5, 2.8, 1.5), normal=(0, -1, -0.4)),
            {"type": "point", "position": [-1.5, 2.0, 1.5], "intensity": 4.0},
            dict(ENV),
        ],
    }


MATERIALS_PARAMS = [
    ("materials.plastic.alpha", 0.2),
    ("materials.plastic.diffuse_reflectance", np.array([0.6, 0.3, 0.2])),
    ("materials.plastic.specular_reflectance", np.array([0.8, 0.8, 0.8])),
    ("materials.plastic.eta", 1.5),
    ("materials.phong.kd", np.array([0.3, 0.5, 0.4])),
    ("materials.phong.ks", np.array([0.4, 0.4, 0.4])),
    ("materials.phong.exponent", 20.0),
    ("materials.metal.alpha_u", 0.15),
    ("materials.metal.alpha_v", 0.35),
    ("materials.metal.eta", np.array([0.2, 0.9, 1.1])),
    ("materials.metal.k", np.array([3.9, 2.4, 2.2])),
    ("emitters.point.intensities", None),
    ("emitters.area.0.radiance", np.array([6.0, 6.0, 6.0])),
]


def glass_scene(w=8):
    """Delta BSDFs: a glass sphere and a coloured mirror (complex-IOR conductor) over a diffuse
    floor, area light and constant environment."""
    return {
        "camera": _camera(w, origin=(0, 1.4, 4.0), target=(0, 0.5, 0), fov=50),
        "shapes": [
            {"type": "sphere", "center": [-0.65, 0.6, 0.3], "radius": 0.6, "material": "glass"},
            {"type": "sphere", "center": [0.75, 0.6, -0.3], "radius": 0.6, "material": "mirror"},
            _floor(),
        ],
        "materials": {
            "glass": {"type": "dielectric", "eta": 1.5},
            "mirror": {"type": "conductor", "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.2]},
            "floor": {"type": "diffuse", "reflectance": [0.6, 0.5, 0.4]},
        },
        "emitters": [_light(radiance=6.0), dict(ENV)],
    }


GLASS_PARAMS = [
    ("materials.glass.eta", 1.5),
    ("materials.mirror.eta", np.array([0.2, 0.9, 1.1])),
    ("materials.mirror.k", np.array([3.9, 2.4, 2.2])),
    ("materials.floor.reflectance", np.array([0.6, 0.5, 0.4])),
    ("emitters.area.0.radiance", np.array([6.0, 6.0, 6.0])),
    ("emitters.environment.radiance", np.array([0.3, 0.3, 0.3])),
]


def envmap_scene(w=8):
    """An importance-sampled environment map (its texels set the light-sampling density) over
    a rough-conductor sphere and a diffuse floor, plus an area light."""
    rng = np.random.default_rng(5)
    env = (0.2 + rng.random((4, 8, 3)) * np.array([1.0, 0.8, 0.6])).tolist()
    return {
        "camera": _camera(w),
        "shapes": [
            {"type": "sphere", "center": [0, 0.8, 0], "radius": 0.8, "material": "metal"},
            _floor(),
        ],
        "materials": {
            "metal": {"type": "roughconductor", "alpha": 0.3, "reflectance": 0.9},
            "floor": {"type": "diffuse", "reflectance": 0.5},
        },
        "emitters": [_light(radiance=4.0), {"type": "envmap", "image": env}],
    }


ENVMAP_PARAMS = [
    ("emitters.environment.image", None),
    ("materials.metal.alpha", 0.3),
    ("materials.floor.reflectance", np.array([0.5, 0.5, 0.5])),
]


def make_scene(desc):
    return load_scene(desc)


def resolve(scene, params):
    """``[(path, base array)]`` with ``None`` bases filled from the scene."""
    out = []
    for path, base in params:
        b = scene.get(path) if base is None else jnp.asarray(base, scene.get(path).dtype)
        out.append((path, b))
    return out


def apply(scene, params, x):
    for i, (path, base) in enumerate(params):
        scene = scene.replace(path, base * x[i])
    return scene


def _loss(x, key, scene, bases, opts):
    return jnp.mean(render(apply(scene, bases, x), key, **dict(opts)))


def ad_fd(
    scene, bases, keys, h, *, spp, integrator, max_depth, strategy="mis", sampling="detached"
):
    """Per key: image mean, AD gradient (reverse mode) and central FD w.r.t. each scale.

    Returns ``(values (K,), ad (K, P), fd (K, P))``. ``bases``: list of ``(path, base)``.
    :func:`jaxgfx.testing.ad_fd_per_key` at ``x = 1``: two compiled programs per scene
    structure (value and gradient vmapped over the keys; the ``2P`` perturbed forward renders).
    The keys are vmapped: one program over all keys' rays (8² images are too small to fill a
    kernel alone). It is as fast per key as one key at a time since ``fusion_barrier`` stays a
    barrier under ``vmap`` (before, the batched program was 7-31x slower per key; the glossy
    fixture of test_gradients_fd.py: 57 s before, 33 s now on a quiet machine;
    docs/performance.md "Batches of keys").
    """
    opts = (
        ("spp", spp),
        ("integrator", integrator),
        ("max_depth", max_depth),
        ("strategy", strategy),
        ("sampling", sampling),
    )
    x0 = jnp.ones((len(bases),), jnp.float32)
    return ad_fd_per_key(_loss, x0, keys, h, args=(scene, bases, opts))


@eqx.filter_jit
def _fd_values(xs, keys, scene, bases, opts):
    """``_loss`` at each row of ``xs`` for each key, ``(N, K)``: forward renders only."""
    per_key = jax.vmap(lambda x, k: _loss(x, k, scene, bases, opts), in_axes=(None, 0))
    return jax.lax.map(lambda x: per_key(x, keys), xs)


def fd_only(desc, params, *, spp, keys, integrator, max_depth=3, seed=0):
    """Per key, the same-key central differences of :func:`run` (step ``H``, the step taken in
    float32) WITHOUT the gradient: ``(K, P)``. :func:`jaxgfx.testing.ad_fd_per_key` always
    pays for the reverse-mode gradient too (3 of the 5 forward-render units of a one-parameter
    call, measured); this is for extra FD-only samples of a reference (a program of its own,
    forward only)."""
    scene = make_scene(desc)
    bases = resolve(scene, params)
    ks = jax.random.split(jax.random.key(seed), keys)
    opts = (
        ("spp", spp),
        ("integrator", integrator),
        ("max_depth", max_depth),
        ("strategy", "mis"),
        ("sampling", "detached"),
    )
    n = len(bases)
    e = np.float32(H) * np.eye(n, dtype=np.float32)
    xs = np.concatenate([1 + e, 1 - e]).astype(np.float32)  # +h rows, then -h rows
    step = np.diagonal(xs[:n] - xs[n:]).astype(np.float64)
    v = np.asarray(_fd_values(jnp.asarray(xs), ks, scene, bases, opts), np.float64)
    return ((v[:n] - v[n:]) / step[:, None]).T


def summary(vals, ad, fd):
    ad, fd = np.asarray(ad, np.float64), np.asarray(fd, np.float64)
    k = ad.shape[0]
    d = ad - fd
    return dict(
        value=float(np.mean(vals)),
        ad=ad.mean(0),
        ad_se=ad.std(0, ddof=1) / np.sqrt(k),
        fd=fd.mean(0),
        fd_se=fd.std(0, ddof=1) / np.sqrt(k),
        diff=d.mean(0),
        diff_se=d.std(0, ddof=1) / np.sqrt(k),
    )


# ------------------------------------------------------------------ the check shared by
# test_gradients_fd.py (default) and test_gradients_fd_high_spp.py (slow)

H = 0.1  # relative FD step (0.015 on α = 0.15: FD agrees with Mitsuba's prb there)

# parameters that shape sampled directions or lobe choices: statistical tolerance only
SAMPLING_DEPENDENT = ("alpha", "exponent", "materials.plastic.", "materials.phong.", "glass.eta")


def is_smooth(path):
    return not any(k in path for k in SAMPLING_DEPENDENT)


def ad_fd_raw(desc, params, *, spp, keys, integrator, max_depth=3, sampling="detached", seed=0):
    """Per key ``(values (K,), ad (K, P), fd (K, P))`` of :func:`ad_fd` at step ``H``."""
    scene = make_scene(desc)
    bases = resolve(scene, params)
    ks = jax.random.split(jax.random.key(seed), keys)
    return ad_fd(
        scene,
        bases,
        ks,
        H,
        spp=spp,
        integrator=integrator,
        max_depth=max_depth,
        sampling=sampling,
    )


def run(desc, params, *, spp, keys, integrator, max_depth=3, sampling="detached", seed=0):
    """:func:`summary` of :func:`ad_fd_raw`."""
    out = ad_fd_raw(
        desc,
        params,
        spp=spp,
        keys=keys,
        integrator=integrator,
        max_depth=max_depth,
        sampling=sampling,
        seed=seed,
    )
    return summary(*out)


def check(params, s, *, z=4.0):
    bad = []
    for i, (path, _) in enumerate(params):
        ad, fd, diff, se = s["ad"][i], s["fd"][i], s["diff"][i], s["diff_se"][i]
        assert np.isfinite(ad) and np.isfinite(fd), path
        atol = 0.01 * abs(fd) + 1e-7 if is_smooth(path) else 1e-7
        if not abs(diff) <= z * se + atol:
            bad.append(f"{path}: AD {ad:.5g} FD {fd:.5g} diff {diff:.3g} se {se:.3g}")
    assert not bad, "\n".join(bad)
