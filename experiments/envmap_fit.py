"""Environment-map recovery: a 16×32 lat-long environment fitted from 8-bit photos of a known
glossy + diffuse object (issue 25).

    python -m experiments.envmap_fit --mitsuba --config configs/envmap_fit.yaml --out out/envmap_fit

The scene (configs/scenes/envmap_fit.yaml) is a rough gold-ish metal sphere (GGX α 0.15) and a
diffuse sphere on a grey floor, lit only by the environment map
:func:`sky`: a blue gradient sky, a warm horizon, a dark ground and a soft sun, given to the
fit as the synthetic target's value; the scene file holds a constant grey map
(configs/scenes/envmap_grey.exr), so the importance-sampling distribution, which the scene
builds from the file's map, knows nothing of the truth). The targets are 8-bit photos of the
config's views (six) through an sRGB camera at a known exposure, rendered by **Mitsuba 3**
with ``--mitsuba`` (:func:`mitsuba_photos`, written as PNG files and fitted as a list of
``{file, view}`` photos), else by jaxgfx at 256 spp with another seed. The fit starts from a
constant grey map and runs ``jaxgfx fit`` with a Laplacian prior and its own learning rate
on the map, for several step budgets and prior weights (``--priors``; one compiled program).
With ``--mitsuba`` a seventh view (:data:`HELD_OUT`), which no fit sees, scores each fit
(:func:`held_out_error`): what a user without the true map would choose the prior weight and
the budget by. ``--views N``: the config's first N views.

Reported against seconds: the relative error of the map per texel (RMS over texels weighted
by solid angle, over the RMS of the truth) and of its low-frequency content, the order-2
spherical-harmonic projection (9 coefficients per channel: what a diffuse object constrains,
the irradiance), ``‖SH_fit − SH_true‖ / ‖SH_true‖``; also the lower hemisphere, which the floor
hides from every view. Writes ``summary.json`` and ``envmap_error.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

from jaxgfx.config import read_yaml
from jaxgfx.testing.problems import ENVMAP_H as H
from jaxgfx.testing.problems import ENVMAP_W as W
from jaxgfx.testing.problems import envmap_errors as errors
from jaxgfx.testing.problems import envmap_sky as sky


def plot(path, rows):
    """Relative errors against fitting seconds, one line per prior weight (solid: the SH
    order <= 2 content, dashed: per texel, dotted: the held-out view when measured)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    start = rows[0]
    fig, ax = plt.subplots(figsize=(6.4, 3.6))
    weights = sorted({r["prior_laplacian"] for r in rows[1:]})
    for n, w in enumerate(weights):
        rs = [start] + sorted(
            (r for r in rows[1:] if r["prior_laplacian"] == w), key=lambda r: r["steps"]
        )
        s = [r["seconds"] for r in rs]
        col = f"C{n}"
        ax.plot(s, [r["sh2_rel"] for r in rs], "o-", color=col, label=f"SH<=2, prior {w:g}")
        ax.plot(s, [r["texel_rel"] for r in rs], "s--", color=col, label=f"texel, prior {w:g}")
        if all("held_out_rel" in r for r in rs):
            ax.plot(
                s,
                [r["held_out_rel"] for r in rs],
                "^:",
                color=col,
                label=f"held-out view, prior {w:g}",
            )
    ax.set_xlabel("seconds of fitting (compilation excluded)")
    ax.set_ylabel("relative error")
    ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6, ncol=2)
    src = "Mitsuba 3" if "held_out_rel" in start else "jaxgfx"
    ax.set_title(f"environment map from 8-bit views ({src} targets)", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def mitsuba_photos(config: dict, base_dir: str, truth: np.ndarray, out: str) -> list:
    """The views of ``config["target"]`` rendered by **Mitsuba 3** (``scalar_rgb``, its
    ``path`` integrator at ``max_depth`` 2 = direct light, ``target.spp``, ``target.seed``) of
    the scene with the true map, through ``target.camera`` (8-bit, no noise), written as PNG
    files under ``out``: the fit's target list ``[{file, view}]``."""
    import jax

    from jaxgfx.config import read_yaml
    from jaxgfx.io import write_png
    from jaxgfx.pipelines.fit.job import _target_camera
    from jaxgfx.render.scene.mitsuba import render_mitsuba

    desc = read_yaml(os.path.join(base_dir, config["scene"]))
    desc["emitters"] = [
        {"type": "envmap", "image": truth.tolist()} if e.get("type") == "envmap" else e
        for e in desc["emitters"]
    ]
    t = config["target"]
    cam = _target_camera(t["camera"], float(t["camera"].get("exposure", 1.0)), 3)
    os.makedirs(out, exist_ok=True)
    photos = []
    for v, view in enumerate(t["views"]):
        d = dict(desc, camera={**desc["camera"], **view})
        img = render_mitsuba(
            d,
            spp=int(t.get("spp", 256)),
            integrator="direct",
            seed=int(t.get("seed", 7)) + v,
            base_dir=os.path.join(base_dir, os.path.dirname(config["scene"])),
        )
        codes = np.asarray(cam.capture(img, jax.random.key(0)), np.uint8)
        path = os.path.abspath(os.path.join(out, f"view{v}.png"))
        write_png(path, codes)
        photos.append({"file": path, "view": dict(view)})
    return photos


HELD_OUT = {"origin": [0.4, 2.6, -3.2]}
"""A fourth view that no fit sees (from behind and above): the map's prior weight and step
budget are chosen on it, as a user without the true map would."""


def held_out_error(config: dict, base_dir: str, fit: np.ndarray, photo: str) -> float:
    """Relative RMS difference (linear, unclipped pixels) between a 64-spp jaxgfx render of
    the scene with the fitted map from :data:`HELD_OUT` and that view's photo (``photo``: a
    PNG through ``target.camera``, linearised)."""
    import equinox as eqx
    import jax
    from PIL import Image

    from jaxgfx.config import load_config
    from jaxgfx.pipelines.fit import FitConfig, prepare_fit
    from jaxgfx.pipelines.fit.job import _target_camera
    from jaxgfx.pipelines.fit.targets import build_scene, build_view
    from jaxgfx.render import render

    cfg = dict(config)
    cfg["target"] = dict(cfg["target"], synthetic={"emitters.environment.image": fit.tolist()})
    fc = load_config(FitConfig, cfg)
    prep = prepare_fit(fc, base_dir=base_dir)
    path = "emitters.environment.image"
    scene = build_scene(prep.scene, [path], {path: np.asarray(fit, np.float32)})
    scene = eqx.tree_at(lambda s: s.camera, scene, build_view(scene, HELD_OUT, "held_out"))
    img = np.asarray(render(scene, jax.random.key(11), spp=64, integrator="direct", max_depth=2))
    codes = np.asarray(Image.open(photo)).astype(np.float32)
    t = config["target"]["camera"]
    lin = np.asarray(_target_camera(t, float(t.get("exposure", 1.0)), 3).linearize(codes))
    ok = (codes < 255) & (codes > 0)
    return float(np.sqrt(np.mean(((img - lin) ** 2)[ok]) / np.mean((lin**2)[ok])))


def run(
    config: dict, base_dir: str, truth: np.ndarray, steps: int, out: str | None, photos=None
) -> dict:
    """One fit of ``steps``; ``photos`` (a target list of files, e.g. :func:`mitsuba_photos`)
    replaces the synthetic (jaxgfx-rendered) target."""
    from jaxgfx.pipelines.fit import FitJob, run_fit

    cfg = dict(config)
    cfg["optimizer"] = {**cfg["optimizer"], "steps": steps}
    cfg["target"] = dict(cfg["target"])
    cfg["target"]["synthetic"] = {"emitters.environment.image": truth.tolist()}
    if photos is not None:
        cfg["target"] = photos
    res = run_fit(FitJob.load(cfg, out, base_dir=base_dir, overwrite=True))
    fit = np.asarray(res["params"]["emitters.environment.image"], np.float64)
    return {
        "steps": steps,
        "seconds": res["seconds"],
        "compile_seconds": res["compile_seconds"],
        **errors(fit, truth.astype(np.float64)),
        "fit": fit,
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default="configs/envmap_fit.yaml")
    p.add_argument("--out", default="out/envmap_fit")
    p.add_argument("--budgets", default="100,300,1000")
    p.add_argument(
        "--priors",
        default=None,
        help="Laplacian prior weights to sweep, e.g. 0.001,0.01,0.1 (one program)",
    )
    p.add_argument("--map-lr", type=float, default=None, help="the map's own learning rate")
    p.add_argument("--views", type=int, default=None, help="fit the config's first N views")
    p.add_argument(
        "--mitsuba", action="store_true", help="targets rendered by Mitsuba 3 (written as PNG)"
    )
    p.add_argument("--write-start", action="store_true", help="(re)write the scene's grey map")
    a = p.parse_args(argv)
    base_dir = os.path.dirname(os.path.abspath(a.config))
    if a.write_start:
        from jaxgfx.io import write_exr

        write_exr(
            os.path.join(base_dir, "scenes", "envmap_grey.exr"), np.full((H, W, 3), 0.5, np.float32)
        )
    from jaxgfx.pipelines.fit import enable_compilation_cache

    enable_compilation_cache()
    config = read_yaml(a.config)
    config["progress"] = False
    if a.map_lr is not None:
        config["params"]["emitters.environment.image"]["lr"] = a.map_lr
    if a.views is not None:
        views = list(config["target"]["views"])[: a.views]
        config["target"] = dict(config["target"], views=views)
    truth = sky()
    start = np.broadcast_to(
        np.float64(config["params"]["emitters.environment.image"]["init"]), truth.shape
    )
    rows = [{"steps": 0, "seconds": 0.0, **errors(start, truth.astype(np.float64))}]
    os.makedirs(a.out, exist_ok=True)
    photos = held = None
    if a.mitsuba:
        photos = mitsuba_photos(config, base_dir, truth, os.path.join(a.out, "photos"))
        cfg_h = dict(config, target=dict(config["target"], views=[HELD_OUT]))
        held = mitsuba_photos(cfg_h, base_dir, truth, os.path.join(a.out, "held_out"))[0]["file"]
        rows[0]["held_out_rel"] = held_out_error(config, base_dir, np.array(start), held)
    pspec = config["params"]["emitters.environment.image"]
    weights = (
        [float(w) for w in a.priors.split(",")]
        if a.priors
        else [float(pspec["prior"]["laplacian"])]
    )
    for w in weights:
        pspec["prior"] = {"laplacian": w}
        for n in [int(b) for b in a.budgets.split(",")]:
            tag = f"steps{n}" if a.priors is None else f"prior{w:g}_steps{n}"
            r = run(config, base_dir, truth, n, os.path.join(a.out, tag), photos)
            fit = r.pop("fit")
            np.save(os.path.join(a.out, f"envmap_{tag}.npy"), fit)
            if held is not None:
                r["held_out_rel"] = held_out_error(config, base_dir, fit, held)
            r["prior_laplacian"] = w
            rows.append(r)
            print(json.dumps(r), flush=True)
    with open(os.path.join(a.out, "summary.json"), "w", encoding="utf-8") as f:
        json.dump({"rows": rows, "load_average": os.getloadavg()}, f, indent=1)
    plot(os.path.join(a.out, "envmap_error.png"), rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
