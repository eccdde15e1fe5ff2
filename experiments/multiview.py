"""Several views of a textured plane (docs/inverse.md, "Several views").

    python -m experiments.multiview --config configs/multiview.yaml --out out/multiview
    python -m experiments.multiview --timing --out out/multiview_timing

The default run fits the 64x64 albedo texture of a plane (configs/scenes/multiview_plane.yaml)
from four views (configs/multiview.yaml), each of which sees about a quarter of it, with a tv
prior, and again from the first view alone; it reports the texture's PSNR over the texels the
views see (a texel is seen when the gradient of the views' summed render w.r.t. it is not
zero), over the texels the first view sees and over those it does not, and writes
``result.json`` and ``textures.png`` (truth | four views | one view, each texel 4x4 pixels).

``--timing`` compares, each in a fresh interpreter (no compilation cache), the compile time
and the median step time of configs/inverse_camera.yaml (one photo, gamma and exposure
fitted) with the same scene seen from three views, a bracket of two photos per view, gamma,
exposure and white balance fitted, its views rendered by ``vmap`` or by a Python ``loop``
(:data:`jaxgfx.pipelines.fit.loss.VIEW_BATCHING`).

``--write-texture`` rewrites configs/scenes/multiview_albedo.png (8x8 blocks of uniform random
colours in [0.1, 0.9], seed 3, stored raw).
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import subprocess
import sys
import time

import numpy as np

from experiments._common import emit_json, log

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIGS = os.path.join(ROOT, "configs")
TEXTURE = "materials.plane.reflectance.image"
THREE_VIEWS = [
    {},
    {"origin": [1.6, 1.2, 3.6]},
    {"origin": [-1.6, 1.2, 3.6]},
]


def albedo_texture(n: int = 64, seed: int = 3) -> np.ndarray:
    """``(n, n, 3)`` uint8: 8x8 blocks of uniform random colours in [0.1, 0.9]."""
    rng = np.random.default_rng(seed)
    blocks = np.round(rng.uniform(0.1, 0.9, (8, 8, 3)) * 255).astype(np.uint8)
    return np.kron(blocks, np.ones((n // 8, n // 8, 1), np.uint8))


def psnr(a, b, mask) -> float:
    """PSNR (peak 1) of ``a`` against ``b`` over the texels where ``mask`` ``(H, W)``."""
    err = (np.asarray(a, np.float64) - np.asarray(b, np.float64))[mask]
    return float(10 * np.log10(1.0 / max(np.mean(err * err), 1e-30)))


def seen_texels(prep, spp: int = 16) -> np.ndarray:
    """``(V, H, W)``: the texels each view sees (a non-zero gradient of its render's sum)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from jaxgfx.render import render

    scene = prep.scene
    cams = prep.views if prep.views is not None else (scene.camera,)

    def total(img, cam):
        s = eqx.tree_at(lambda sc: sc.camera, scene.replace(TEXTURE, img), cam)
        return jnp.sum(render(s, jax.random.key(0), spp=spp, integrator="direct", max_depth=2))

    g = jax.jit(jax.grad(total))
    tex = jnp.asarray(scene.get(TEXTURE))
    return np.stack([np.any(np.asarray(g(tex, c)) != 0, axis=-1) for c in cams])


def run_texture(config: str, out: str | None) -> dict:
    from jaxgfx.config import config_to_dict, load_config
    from jaxgfx.io import write_png
    from jaxgfx.pipelines.fit import FitConfig, FitJob, prepare_fit, run_fit

    base = os.path.dirname(os.path.abspath(config))
    cfg = load_config(FitConfig, config)
    desc = config_to_dict(cfg)
    prep = prepare_fit(cfg, base_dir=base)
    truth = np.asarray(prep.scene.get(TEXTURE), np.float64)
    seen = seen_texels(prep)
    union, first = seen.any(axis=0), seen[0]
    log(
        f"texels seen: {union.mean():.3f} by the {len(seen)} views, "
        f"{[round(float(s.mean()), 3) for s in seen]} by each"
    )
    results, fits = {}, {}
    for name, views in (
        ("views", desc["target"]["views"]),
        ("one_view", desc["target"]["views"][:1]),
    ):
        d = copy.deepcopy(desc)
        d["target"]["views"] = views
        d["progress"] = False
        t = time.perf_counter()
        res = run_fit(
            FitJob.load(
                d, None if out is None else os.path.join(out, name), base_dir=base, overwrite=True
            )
        )
        seconds = time.perf_counter() - t
        fit = np.asarray(res["params"][TEXTURE], np.float64)
        fits[name] = fit
        results[name] = {
            "n_views": len(views),
            "psnr_seen": psnr(fit, truth, union),
            "psnr_first_view_seen": psnr(fit, truth, first),
            "psnr_first_view_hidden": psnr(fit, truth, union & ~first),
            "seconds": seconds,
            "compile_seconds": res["compile_seconds"],
            "seconds_per_step": res["seconds_per_step"],
            "view_loss_after": res["views"]["loss_after"],
        }
        log(name, json.dumps({k: v for k, v in results[name].items() if k != "view_loss_after"}))
    summary = {
        "texture": list(truth.shape),
        "texels_seen": float(union.mean()),
        "texels_seen_by_each_view": [float(s.mean()) for s in seen],
        "init_psnr_seen": psnr(np.asarray(prep.init[TEXTURE]), truth, union),
        **results,
    }
    if out is not None:
        os.makedirs(out, exist_ok=True)
        gap = np.ones((truth.shape[0], 2, 3))
        row = np.concatenate([truth, gap, fits["views"], gap, fits["one_view"]], axis=1)
        big = np.kron(row, np.ones((4, 4, 1)))
        write_png(
            os.path.join(out, "textures.png"), np.round(np.clip(big, 0, 1) * 255).astype(np.uint8)
        )
        emit_json(summary, os.path.join(out, "result.json"))
    else:
        emit_json(summary)
    return summary


def timing_config(variant: str) -> dict:
    """The fit of a ``--timing`` variant: ``single`` (configs/inverse_camera.yaml as shipped,
    20 steps) or ``vmap`` / ``loop`` (three views, two photos each, full camera)."""
    from jaxgfx.config import read_yaml

    d = read_yaml(os.path.join(CONFIGS, "inverse_camera.yaml"))
    d["optimizer"] = dict(d["optimizer"], steps=20)
    d["progress"] = False
    if variant != "single":
        d["target"] = dict(d["target"], views=THREE_VIEWS)
        d["target"]["camera"] = dict(
            d["target"]["camera"], exposures=[0.5, 2.0], white_balance=[1.1, 1.0, 0.9]
        )
        d["camera"] = {
            "response": {"model": "gamma", "fit": True, "init": 2.2},
            "exposure": {"init": 1.0, "fit": True},
            "white_balance": {"fit": True},
        }
    return d


def _time_one(variant: str) -> None:
    from jaxgfx.pipelines.fit import FitJob, loss, run_fit

    if variant in ("vmap", "loop"):
        loss.VIEW_BATCH = variant
    res = run_fit(FitJob.load(timing_config(variant), None, base_dir=CONFIGS))
    print(
        json.dumps(
            {
                "variant": variant,
                "compile_seconds": res["compile_seconds"],
                "seconds_per_step": res["seconds_per_step"],
                "n_targets": res["n_targets"],
            }
        )
    )


def run_timing(out: str | None, repeats: int) -> dict:
    env = dict(os.environ, JAXGFX_CACHE_DIR="off")
    rows = []
    for r in range(repeats):
        for variant in ("single", "vmap", "loop"):
            p = subprocess.run(
                [sys.executable, "-m", "experiments.multiview", "--time-one", variant],
                cwd=ROOT,
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            row = json.loads(p.stdout.strip().splitlines()[-1])
            row["repeat"] = r
            log(json.dumps(row))
            rows.append(row)
    summary = {"rows": rows}
    for v in ("single", "vmap", "loop"):
        c = [x["compile_seconds"] for x in rows if x["variant"] == v]
        s = [x["seconds_per_step"] for x in rows if x["variant"] == v]
        summary[v] = {
            "compile_seconds_median": float(np.median(c)),
            "seconds_per_step_median": float(np.median(s)),
        }
    for v in ("vmap", "loop"):
        summary[v]["compile_ratio_to_single"] = (
            summary[v]["compile_seconds_median"] / summary["single"]["compile_seconds_median"]
        )
    summary["load_average"] = os.getloadavg()
    if out is not None:
        os.makedirs(out, exist_ok=True)
    emit_json(summary, None if out is None else os.path.join(out, "timing.json"))
    return summary


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default=os.path.join(CONFIGS, "multiview.yaml"))
    p.add_argument("--out", default=None, help="output folder (default: print only)")
    p.add_argument("--timing", action="store_true", help="compile / step time, vmap vs loop")
    p.add_argument("--repeats", type=int, default=2, help="--timing: runs of each variant")
    p.add_argument("--write-texture", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--time-one", choices=("single", "vmap", "loop"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.time_one:
        _time_one(a.time_one)
    elif a.write_texture:
        from jaxgfx.io import write_png

        write_png(os.path.join(CONFIGS, "scenes", "multiview_albedo.png"), albedo_texture())
    elif a.timing:
        run_timing(a.out, a.repeats)
    else:
        run_texture(a.config, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
