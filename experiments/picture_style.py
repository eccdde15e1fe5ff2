"""A camera's picture style (colour matrix + tone curve) in the fit: where to compare, what
ignoring it costs, and what the stages cost to compile.

    python -m experiments.picture_style --config configs/picture_style.yaml --out out/picture_style
    python -m experiments.picture_style --timing --out out/picture_style_timing

The target (configs/picture_style.yaml) is a bracket of three 8-bit photos (exposures 0.2,
0.8, 3.2: the darkest measures the whole highlight) through exposure, a colour matrix, an ACES
filmic tone curve and sRGB. The same material fit (GGX roughness + diffuse albedo, exposure
fitted from the auto start, ``clipped: unmeasured``) runs under these cameras:

* ``ignore``: sRGB only (no matrix, no tone curve): the picture style ignored;
* ``profile``: the true matrix and tone curve, fixed (as a calibrated profile gives them);
  the loss compares after the matrix in linear space (the default);
* ``tone_fit``: the true matrix, the tone curve's parameter fitted from the operator default;
* ``code``: as ``profile`` but ``camera.space: code`` (display values, censored L2);
* ``no_style``: the control — photos made *without* the picture style (sRGB only), fitted
  with sRGB: the material fit's own floor on this bracket.

``--bracket 0.8,1.6,3.2`` (the photos' exposures), ``--clipped bound``, ``--seed``, ``--spp``:
the ablations of docs/inverse.md 2c.

``--timing``: compile seconds of one fit step in fresh interpreters without the compilation
cache: today's single-photo gamma fit (configs/inverse_camera.yaml) and this config with the
full camera (matrix and tone curve fitted, three photos), ``--repeats`` runs each.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

from jaxgfx.config import read_yaml

VARIANTS = ("ignore", "profile", "tone_fit", "code", "no_style")


def camera_for(variant: str, truth: dict) -> dict:
    # auto: the exposure starts from the photos / initial render ratio (from a start several
    # times off the fit falls into a rough, dark basin: docs/inverse.md section 2b)
    cam = {
        "response": {"model": "srgb"},
        "exposure": {"init": 1.0, "fit": True, "auto": True},
        "clipped": "unmeasured",
    }
    if variant in ("ignore", "no_style"):
        return cam
    cam["color_matrix"] = truth["color_matrix"]
    cam["tonemap"] = dict(truth["tonemap"])
    if variant == "tone_fit":
        cam["tonemap"] = {"op": truth["tonemap"]["op"], "fit": True}  # from the default
    if variant == "code":
        cam["space"] = "code"
    return cam


def _one_timing(which: str, config: str) -> float:
    """Runs in a fresh interpreter: compile seconds of the fit step (2 steps)."""
    from jaxgfx.pipelines.fit import FitJob, run_fit

    cfg = read_yaml(config)
    cfg["optimizer"] = {**cfg.get("optimizer", {}), "steps": 2}
    cfg["progress"] = False
    if which == "full":
        cfg["camera"]["color_matrix"] = {"init": cfg["camera"]["color_matrix"], "fit": True}
        cfg["camera"]["tonemap"] = {**cfg["camera"]["tonemap"], "fit": True}
    out = run_fit(FitJob.load(cfg, None, base_dir=os.path.dirname(os.path.abspath(config))))
    return out["compile_seconds"]


def timing(a) -> dict:
    rows = {
        "gamma_single_photo": ("plain", "configs/inverse_camera.yaml"),
        "full_camera_three_photos": ("full", a.config),
    }
    env = dict(os.environ, JAXGFX_CACHE_DIR="off")
    res = {}
    for name, (which, config) in rows.items():
        runs = []
        for _ in range(a.repeats):
            code = (
                "import sys; from experiments.picture_style import _one_timing; "
                f"print('COMPILE', _one_timing({which!r}, {config!r}))"
            )
            p = subprocess.run(
                [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
            )
            runs.append(float(p.stdout.split("COMPILE")[-1]))
            print(name, runs[-1], flush=True)
        res[name] = {"runs": runs, "median": float(np.median(runs))}
    res["ratio"] = res["full_camera_three_photos"]["median"] / res["gamma_single_photo"]["median"]
    res["load_average"] = os.getloadavg()
    return res


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default="configs/picture_style.yaml")
    p.add_argument("--out", default="out/picture_style")
    p.add_argument("--steps", type=int, default=None)
    p.add_argument("--variants", default=",".join(VARIANTS))
    p.add_argument("--clipped", default=None, help="camera.clipped of every fit")
    p.add_argument("--clip-code", type=int, default=None, help="camera.clip_code of every fit")
    p.add_argument(
        "--bracket",
        default=None,
        help="the target photos' exposures, e.g. 0.2,0.8,3.2 (target.camera)",
    )
    p.add_argument("--seed", type=int, default=None, help="the fits' seed")
    p.add_argument("--spp", type=int, default=None, help="render.spp of every fit")
    p.add_argument("--timing", action="store_true")
    p.add_argument("--repeats", type=int, default=2)
    a = p.parse_args(argv)
    os.makedirs(a.out, exist_ok=True)
    if a.timing:
        res = timing(a)
        with open(os.path.join(a.out, "timing.json"), "w", encoding="utf-8") as f:
            json.dump(res, f, indent=1)
        print(json.dumps(res))
        return 0
    from jaxgfx.pipelines.fit import FitJob, enable_compilation_cache, run_fit

    enable_compilation_cache()
    base = read_yaml(a.config)
    base_dir = os.path.dirname(os.path.abspath(a.config))
    if a.bracket:
        ex = [float(x) for x in a.bracket.split(",")]
        base["target"] = {
            **base["target"],
            "camera": {
                **base["target"]["camera"],
                "exposure": ex[0],
                "exposures": [x / ex[0] for x in ex],
            },
        }
    if a.seed is not None:
        base["seed"] = a.seed
    if a.spp:
        base["render"] = {**base["render"], "spp": a.spp}
    truth_cam = base["target"]["camera"]
    summary = {"truth_camera": truth_cam, "truth": base["target"]["synthetic"], "variants": {}}
    for v in a.variants.split(","):
        cfg = dict(base)
        cfg["camera"] = camera_for(v, truth_cam)
        if v == "no_style":
            tc = {k: x for k, x in truth_cam.items() if k not in ("color_matrix", "tonemap")}
            cfg["target"] = {**cfg["target"], "camera": tc}
        if a.clipped:
            cfg["camera"]["clipped"] = a.clipped
        if a.clip_code:
            cfg["camera"]["clip_code"] = a.clip_code
        cfg["progress"] = False
        if a.steps is not None:
            cfg["optimizer"] = {**cfg.get("optimizer", {}), "steps": a.steps}
        out = run_fit(FitJob.load(cfg, os.path.join(a.out, v), base_dir=base_dir, overwrite=True))
        alpha = out["params"]["materials.metal.alpha"]
        summary["variants"][v] = {
            "params": out["params"],
            "camera": out["camera"],
            "errors": out["errors"],
            "alpha_rel_error": abs(alpha - 0.15) / 0.15,
            "alpha_every_50_steps": out["history"]["materials.metal.alpha"][::50],
            "loss_every_50_steps": out["loss"][::50],
            "seconds": out["seconds"],
            "compile_seconds": out["compile_seconds"],
        }
        print(v, json.dumps(summary["variants"][v]), flush=True)
    with open(os.path.join(a.out, "summary.json"), "w", encoding="utf-8") as f:
        json.dump(summary, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
