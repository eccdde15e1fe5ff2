"""Problems and scenes that experiments, benchmarks and tests share (so that none of them
imports another): the example inverse-rendering fit with its Levenberg–Marquardt route
(``experiments.alpha_precision``, ``benchmarks.inverse``), and the visibility-gradient scene
with its AD-vs-finite-difference measurement (``experiments.visibility_bias``,
``tests/render/test_visibility_gradients.py``), and the environment-map recovery problem
(``experiments.envmap_fit``, ``tests/pipelines/test_fit_envmap.py``). Not imported by
``jaxgfx.testing`` itself (it renders): ``from jaxgfx.testing import problems``."""

from __future__ import annotations

import copy
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx.render import Spheres, load_scene, render

__all__ = [
    "TRUE_ALPHA",
    "TRUE_ALBEDO",
    "settle_step",
    "inverse_example",
    "lm_start",
    "lm_solve",
    "lm_polish",
    "VISIBILITY_CENTER",
    "visibility_scene_desc",
    "measure_visibility_bias",
    "ENVMAP_H",
    "ENVMAP_W",
    "envmap_directions",
    "envmap_sky",
    "sh9",
    "envmap_errors",
]

TRUE_ALPHA = 0.15
"""The example fit's true GGX roughness of the metal sphere."""
TRUE_ALBEDO = (0.7, 0.3, 0.15)
"""The example fit's true albedo of the clay sphere."""


def settle_step(values, truth, *, rel: float = 0.02, window: int = 5) -> int | None:
    """The index of the first iterate from which the mean of the last ``window`` values stays
    within ``rel`` of ``truth`` up to the last one, or ``None`` when it does not end there (the
    settling criterion of ``benchmarks.inverse`` and ``experiments.fit_settle``)."""
    a = np.asarray(values, np.float64)
    ok = [abs(a[k - window : k].mean() - truth) <= rel * truth for k in range(window, len(a) + 1)]
    if not ok or not ok[-1]:
        return None
    first = len(ok) - 1
    while first > 0 and ok[first - 1]:
        first -= 1
    return first + window - 1


def inverse_example(scene_desc: dict, *, size: int = 32):
    """The example fit's problem (configs/inverse_material.yaml): ``scene_desc`` (the
    description of configs/scenes/inverse.yaml, read by the caller) at ``size``², and the
    target rendered at :data:`TRUE_ALPHA` / :data:`TRUE_ALBEDO` (seed 7, 256 spp, direct).
    Returns ``(with_params, target)``: ``with_params({"alpha": a, "albedo": rgb})`` is the
    scene at those values."""
    import jax
    import jax.numpy as jnp

    from jaxgfx.render import load_scene, render

    d = copy.deepcopy(dict(scene_desc))
    d["camera"] = dict(d["camera"], width=size, height=size)
    scene = load_scene(d)

    def with_params(p):
        s = scene.replace("materials.metal.alpha", p["alpha"])
        return s.replace("materials.clay.reflectance", p["albedo"])

    truth = {"alpha": jnp.float32(TRUE_ALPHA), "albedo": jnp.asarray(TRUE_ALBEDO, jnp.float32)}
    # the example's target: seed 7, 256 spp (configs/inverse_material.yaml)
    target = render(with_params(truth), jax.random.key(7), spp=256, integrator="direct")
    return with_params, target


_RESIDUALS = {}


def _residuals(with_params, spp):
    # one function object per (problem, spp), so fit_least_squares compiles one solve per spp
    if (with_params, spp) not in _RESIDUALS:
        from jaxgfx.optim import decorrelated_residuals
        from jaxgfx.render import render

        def residuals(p, args):
            tgt, key = args
            s = with_params(p)
            return decorrelated_residuals(
                lambda k: render(s, k, spp=spp, integrator="direct"), tgt, key
            ).ravel()

        _RESIDUALS[with_params, spp] = residuals
    return _RESIDUALS[with_params, spp]


def lm_solve(with_params, target, spp, seed, start, *, solver="lm", max_steps=40):
    """:func:`jaxgfx.optim.fit_least_squares` of the example at ``spp`` on one key (decorrelated
    residuals); returns ``(params, record)``."""
    import jax

    from jaxgfx.optim import fit_least_squares

    res = fit_least_squares(
        _residuals(with_params, spp),
        start,
        solver=solver,
        args=(target, jax.random.key(seed)),
        bounds={"alpha": (0.01, 1.0), "albedo": (0.0, 1.0)},
        max_steps=max_steps,
    )
    a = float(res.params["alpha"])
    rec = {
        "spp": spp,
        "seed": seed,
        "solver": solver,
        "alpha": a,
        "rel_error": abs(a - TRUE_ALPHA) / TRUE_ALPHA,
        "albedo": np.asarray(res.params["albedo"]).tolist(),
        "iterations": res.n_steps,
        "stop_reason": res.stop_reason,
        "compile_seconds": res.compile_seconds,
        "solve_seconds": float(np.sum(res.seconds)),
    }
    return res.params, rec


def lm_start():
    """The example fit's initial guess: α 0.5, albedo 0.5 grey."""
    import jax.numpy as jnp

    return {"alpha": jnp.float32(0.5), "albedo": jnp.full(3, 0.5, jnp.float32)}


def lm_polish(
    with_params, target, coarse, fine, seeds, *, solver="gauss_newton", steps=3, log=None
):
    """LM at ``coarse`` spp from the start, then ``steps`` iterations of ``solver`` at ``fine``
    spp from its solution (another key): the solution's noise is that of the fine image, the
    iterations from far away are coarse. Measured (docs/inverse.md §4): LM run to convergence
    at 4096 spp from the 128-spp solution took 15 iterations (748 s on the loaded machine);
    the fine stage only has to move a few per cent, which Gauss-Newton does in 2-3 steps."""
    out = []
    for seed in seeds:
        p, rec0 = lm_solve(with_params, target, coarse, seed, lm_start())
        if log is not None:
            log("lm polish, coarse stage", rec0)
        rec = lm_solve(with_params, target, fine, 1000 + seed, p, solver=solver, max_steps=steps)[1]
        rec["coarse"] = rec0
        # the route's cost: both solves (compilation reported separately: once per spp)
        rec["route_seconds"] = rec0["solve_seconds"] + rec["solve_seconds"]
        if log is not None:
            log("lm polish", rec)
        out.append(rec)
    return out


VISIBILITY_CENTER = [0.2, 0.6, 0.0]


def visibility_scene_desc(size: int, occluder: str = "sphere") -> dict:
    """A sphere (or a 20-triangle icosahedron) in front of a rectangular area light over a lit
    floor, ``size``²: silhouettes over the light and the floor, a soft shadow edge."""
    if occluder == "sphere":
        occ = {"type": "sphere", "center": VISIBILITY_CENTER, "radius": 0.4, "material": "white"}
    else:  # an icosahedron mesh (20 triangles; below the BVH threshold of load_scene)
        gen = {"name": "icosphere", "level": 0, "radius": 0.4, "center": VISIBILITY_CENTER}
        occ = {"type": "mesh", "generator": gen, "material": "white"}
    return {
        "camera": {
            "origin": [0, 1.2, 4.0],
            "target": [0, 0.5, 0],
            "fov": 40,
            "width": size,
            "height": size,
        },
        "shapes": [
            occ,
            {
                "type": "rectangle",
                "center": [0, 0, 0],
                "normal": [0, 1, 0],
                "size": [6, 6],
                "material": "floor",
            },
        ],
        "materials": {
            "white": {"type": "diffuse", "reflectance": 0.6},
            "floor": {"type": "diffuse", "reflectance": 0.5},
        },
        "emitters": [
            {
                "type": "area",
                "shape": {
                    "type": "rectangle",
                    "center": [0, 1.3, -1.5],
                    "normal": [0, -0.6, 1],
                    "size": [1.4, 0.9],
                },
                "radiance": 5.0,
            },
            {"type": "constant", "radiance": 0.2},
        ],
    }


def measure_visibility_bias(
    size, keys, spp, h, integrator, max_depth=3, strategy="mis", occluder="sphere"
):
    """d(weighted image sum)/d(occluder x) over ``keys`` keys: plain AD, AD with edge sampling
    and same-key central differences (step ``h``), with paired standard errors and seconds
    per call (``experiments.visibility_bias``, ``tests/render/test_visibility_gradients.py``)."""
    from jaxgfx.render.visibility import project

    scene = load_scene(visibility_scene_desc(size, occluder))
    if occluder == "sphere":
        si = next(i for i, s in enumerate(scene.shapes) if isinstance(s, Spheres))
        path = f"shapes.{si}.centers"
    else:
        si = next(i for i, s in enumerate(scene.shapes) if hasattr(s, "vertices"))
        path = f"shapes.{si}.vertices"
    c0 = scene.get(path)
    e = jnp.asarray([1.0, 0.0, 0.0], c0.dtype)
    col = float(project(scene.camera, jnp.asarray(VISIBILITY_CENTER, c0.dtype))[0][0])
    wts = jnp.asarray(np.arange(size)[None, :] + 0.5 >= col, c0.dtype) * jnp.ones((size, 1))

    def loss(x, key, vis):
        sc = scene.replace(path, c0 + e * x)
        img = render(
            sc,
            key,
            spp=spp,
            integrator=integrator,
            max_depth=max_depth,
            strategy=strategy,
            visibility=vis,
        )
        return jnp.sum(img.mean(-1) * wts) / (size * size)

    g_plain = jax.jit(jax.grad(lambda x, k: loss(x, k, None)))
    g_edge = jax.jit(jax.grad(lambda x, k: loss(x, k, "edge")))
    val = jax.jit(lambda x, k: loss(x, k, None))
    ks = jax.random.split(jax.random.key(2026), keys)
    x0 = jnp.zeros((), c0.dtype)
    rows = []
    secs = np.zeros(3)
    for i, k in enumerate(ks):
        row, ts = [], []
        for fn, x in ((g_plain, x0), (g_edge, x0), (val, x0 + h)):
            t = time.perf_counter()
            row.append(float(fn(x, k)))
            ts.append(time.perf_counter() - t)
        if i > 0:  # the first key's calls include compilation
            secs += ts
        fd = (row[2] - float(val(x0 - h, k))) / (2 * h)
        rows.append((row[0], row[1], fd))
    secs /= max(keys - 1, 1)
    a = np.asarray(rows, np.float64)
    n = a.shape[0]

    def ms(v):
        return {"mean": float(v.mean()), "stderr": float(v.std(ddof=1) / np.sqrt(n))}

    return {
        "size": size,
        "keys": keys,
        "spp": spp,
        "h": h,
        "integrator": integrator,
        "strategy": strategy,
        "occluder": occluder,
        "max_depth": max_depth if integrator == "path" else 2,
        "ad_plain": ms(a[:, 0]),
        "ad_edge": ms(a[:, 1]),
        "fd": ms(a[:, 2]),
        "plain_minus_fd": ms(a[:, 0] - a[:, 2]),
        "edge_minus_fd": ms(a[:, 1] - a[:, 2]),
        "seconds_per_call": {"grad_plain": secs[0], "grad_edge": secs[1], "forward": secs[2]},
    }


# ------------------------------------------------------------------------------------------
# environment-map recovery (experiments/envmap_fit.py, tests/pipelines/test_fit_envmap.py)

ENVMAP_H, ENVMAP_W = 16, 32


def envmap_directions(h: int = ENVMAP_H, w: int = ENVMAP_W):
    """Texel-centre directions (y up, θ from +y) and solid angles of a lat-long map."""
    th = np.pi * (np.arange(h) + 0.5) / h
    ph = 2 * np.pi * (np.arange(w) + 0.5) / w
    T, P = np.meshgrid(th, ph, indexing="ij")
    d = np.stack([np.sin(T) * np.cos(P), np.cos(T), np.sin(T) * np.sin(P)], -1)
    return d, np.sin(T) * (np.pi / h) * (2 * np.pi / w)


def envmap_sky(h: int = ENVMAP_H, w: int = ENVMAP_W) -> np.ndarray:
    """The true environment: sky gradient, warm horizon, dark ground, soft sun."""
    d, _ = envmap_directions(h, w)
    y = d[..., 1]
    up = np.clip(y, 0, 1)[..., None]
    img = (0.25 + 0.6 * up) * np.asarray([0.45, 0.6, 1.0]) * (y >= 0)[..., None]
    img = img + np.exp(-((y / 0.15) ** 2))[..., None] * np.asarray([0.6, 0.4, 0.2])
    img = img + (y < 0)[..., None] * np.asarray([0.12, 0.1, 0.08])
    sun = np.asarray([0.5, 0.55, 0.67])
    sun = sun / np.linalg.norm(sun)
    img = img + 4.0 * np.exp((d @ sun - 1) / 0.02)[..., None] * np.asarray([1.0, 0.9, 0.7])
    return img.astype(np.float32)


def sh9(d):
    """Real spherical harmonics of order <= 2 at unit directions ``d`` (..., 9)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([
        0.282095 * np.ones_like(x), 0.488603 * y, 0.488603 * z, 0.488603 * x,
        1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1), 1.092548 * x * z,
        0.546274 * (x * x - y * y)], -1)  # fmt: skip


def envmap_errors(fit: np.ndarray, truth: np.ndarray) -> dict:
    """Relative errors of a fitted lat-long map against the truth: per texel (solid-angle
    weighted RMS; and over the upper hemisphere), of its order <= 2 spherical-harmonic
    content and of its DC term (experiments/envmap_fit.py, docs/inverse.md section 2d)."""
    d, dw = envmap_directions(*truth.shape[:2])
    wgt = dw[..., None]
    rms = lambda a: float(np.sqrt(np.sum(wgt * a * a) / np.sum(wgt * np.ones_like(a))))  # noqa
    basis = sh9(d)
    c_fit = np.einsum("hwk,hwc,hw->kc", basis, fit, dw)
    c_true = np.einsum("hwk,hwc,hw->kc", basis, truth, dw)
    upper = d[..., 1] >= 0
    return {
        "texel_rel": rms(fit - truth) / rms(truth),
        "texel_rel_upper": float(
            np.sqrt(np.sum((wgt * (fit - truth) ** 2)[upper]) / np.sum((wgt * truth**2)[upper]))
        ),
        "sh2_rel": float(np.linalg.norm(c_fit - c_true) / np.linalg.norm(c_true)),
        "sh_dc_rel": float(np.linalg.norm(c_fit[0] - c_true[0]) / np.linalg.norm(c_true[0])),
    }
