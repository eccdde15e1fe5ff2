"""Inverse rendering: parameter error against wall time, jaxgfx vs Mitsuba 3 (prb + Adam).

    python -m benchmarks.inverse [--steps N] [--out FILE] [--plot DIR] [--no-mitsuba]
        [--lm-polish 128:4096 | --lm-polish ''] [--seeds 1,2,3]

The problem is the shipped example (configs/inverse_material.yaml): recover the GGX roughness
of the metal sphere (alpha 0.15, start 0.5) and the clay sphere's albedo ((0.7, 0.3, 0.15),
start 0.5 grey) in configs/scenes/inverse.yaml at 32x32, direct lighting (max_depth 2), 8 spp
per step, Adam with the learning rate decaying from 0.05 to 0.005 over the config's steps
(``--steps`` overrides), each system fitting a target rendered by itself at the config's
``target.spp`` (256; its own noise puts alpha's optimum ~2 % low: ``experiments.fit_settle``,
docs/inverse.md section 4).

* jaxgfx: :func:`jaxgfx.pipelines.fit.run_fit` (jitted step; bounded parameters through a
  sigmoid; primal and adjoint from two independent 4-spp images).
* Mitsuba 3 (``llvm_ad_rgb``, else the benchmark reports why it could not run): its own loop,
  ``prb`` integrator (max_depth 2), ``mi.ad.Adam`` (same schedule), 8 spp per step, a fresh seed per
  step, on the same latent variables (alpha = 0.01 + 0.99 sigmoid(u), albedo = sigmoid(u)),
  so the two optimisers take the same steps for the same gradients. (Adam directly on alpha with
  lr 0.05 and clamping, the usual tutorial loop, oscillates by +-0.1 around 0.15 here.)

Reported per system: seconds per step (median), compile / first-step seconds, the time to
reach alpha within 2 % of the truth (``time_to_2pct_alpha``: from when on the mean of the last
5 iterates stays within 2 % until the end, null if it does not settle;
``time_to_first_2pct_alpha``: the first iterate within 2 %, which a noisy Adam iterate passes
through), and the final errors (mean of the last 10 iterates). ``result_alpha``: the fit's
reported result — the last iterate, or with the config's ``optimizer.average`` the mean of
the tail's iterates in ``u`` (Mitsuba's loop gets the same tail mean); ``time_to_2pct_result``:
from when on that estimate (``estimates``) stays within 2 %. ``--seeds 1,2,3``: after the
timed runs, both systems fit again with those seeds (jaxgfx: the config's ``seed``; Mitsuba:
its step seeds), and ``jaxgfx_seeds`` / ``mitsuba_seeds`` give each seed's result, the mean,
its standard error and how many seeds end / settle within 2 % — one seed's error is mostly
chance (docs/inverse.md section 4). ``jaxgfx_lm``: jaxgfx's route
to 2 % on a fixed key (``jaxgfx.testing.problems.lm_polish``: Levenberg-Marquardt at 128 spp, then 3
Gauss-Newton steps at 4096 spp from its solution, key 0; ``time_to_2pct_alpha`` = compile +
solve seconds of both stages when the result is within 2 %); Mitsuba 3 has no least-squares
solver, so this row has no peer. Also the relative RMSE between the two
targets (conventions check). Prints JSON; ``--plot DIR`` writes ``inverse_speed.png``
(alpha error vs seconds, both systems). The machine may be shared: compare the two systems
within one run.
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import time

import numpy as np

from benchmarks._report import emit, machine
from jaxgfx.config import read_yaml
from jaxgfx.pipelines.fit import FitJob, OptimizerConfig, enable_compilation_cache, run_fit
from jaxgfx.testing import problems

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIG = os.path.join(ROOT, "configs", "inverse_material.yaml")
CONFIG_DIR = os.path.dirname(CONFIG)  # the config's relative paths (its scene) start here
LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"
ALPHA = "materials.metal.alpha"
ALBEDO = "materials.clay.reflectance"


def _log(*a):
    print(*a, file=sys.stderr, flush=True)


def time_to_within(alpha_hist, seconds_cum, truth, rel=0.02, window=5):
    """Seconds after which the running mean of ``window`` iterates of alpha stays within
    ``rel`` of the truth until the last step (None when it does not settle there)."""
    k = problems.settle_step(alpha_hist, truth, rel=rel, window=window)
    return None if k is None else float(seconds_cum[k])


def time_to_first(alpha_hist, seconds_cum, truth, rel=0.02):
    """Seconds until the first iterate of alpha within ``rel`` of the truth (None: never)."""
    a = np.asarray(alpha_hist, np.float64)
    hit = np.nonzero(np.abs(a - truth) <= rel * truth)[0]
    return float(seconds_cum[hit[0]]) if hit.size else None


def tail_start(cfg: dict, steps: int) -> int | None:
    """The step from which the config's ``optimizer.average`` averages the iterates (None:
    off), as the fit computes it (``OptimizerConfig.average_from``)."""
    average = float(cfg["optimizer"].get("average", 0.0))
    return OptimizerConfig(steps=steps, average=average).average_from()


def estimates(alpha_hist, k0, lo, hi):
    """The fit's estimate of alpha after each step: the iterate, and from step ``k0 + 1`` on
    the running mean of the iterates ``k0 + 1 .. k`` in the optimiser's variable ``u``
    (``alpha = lo + (hi - lo) sigmoid(u)``), as ``jaxgfx.optim.fit(average_from=k0)`` reports
    it when stopped at ``k`` (``k0`` None: the iterates)."""
    a = np.asarray(alpha_hist, np.float64)
    if k0 is None:
        return a
    t = np.clip((a - lo) / (hi - lo), 1e-12, 1 - 1e-12)
    u = np.log(t) - np.log1p(-t)
    run = np.cumsum(u[k0 + 1 :]) / np.arange(1, a.size - k0)
    out = a.copy()
    out[k0 + 1 :] = lo + (hi - lo) / (1 + np.exp(-run))
    return out


def problem_config(steps: int | None = None) -> dict:
    """The config dict this benchmark fits: the shipped ``configs/inverse_material.yaml``,
    ``steps`` overriding its step count, no progress bar."""
    cfg = copy.deepcopy(read_yaml(CONFIG))
    if steps is not None:
        cfg["optimizer"] = {**cfg["optimizer"], "steps": int(steps)}
    cfg["progress"] = False
    return cfg


def run_jaxgfx(cfg: dict) -> dict:
    t0 = time.perf_counter()
    out = run_fit(FitJob.load(cfg, None, base_dir=CONFIG_DIR))
    wall = time.perf_counter() - t0
    truth_a = out["truth"][ALPHA]
    alpha = np.asarray(out["history"][ALPHA], np.float64)  # (steps + 1,)
    albedo = np.asarray(out["history"][ALBEDO], np.float64)
    secs = np.concatenate([[0.0], np.cumsum(out["seconds_history"])])
    lo, hi = cfg["params"][ALPHA]["min"], cfg["params"][ALPHA]["max"]
    est = estimates(alpha, tail_start(cfg, len(alpha) - 1), lo, hi)
    result = float(out["params"][ALPHA])
    return {
        "seconds_per_step": out["seconds_per_step"],
        "compile_seconds": out["compile_seconds"],
        "target_seconds": out["target_seconds"],
        "wall_seconds": wall,
        "time_to_2pct_alpha": time_to_within(alpha, secs, truth_a),
        "time_to_first_2pct_alpha": time_to_first(alpha, secs, truth_a),
        "time_to_2pct_result": time_to_within(est, secs, truth_a, window=1),
        "final_alpha": float(alpha[-10:].mean()),
        "alpha_error": float(abs(alpha[-10:].mean() - truth_a)),
        "result_alpha": result,
        "result_alpha_error": abs(result - truth_a),
        "average": out.get("average"),
        "albedo_error": float(np.max(np.abs(albedo[-10:].mean(0) - out["truth"][ALBEDO]))),
        "curve": {"seconds": secs.tolist(), "alpha": alpha.tolist(), "estimate": est.tolist()},
    }


def run_jaxgfx_lm(coarse: int, fine: int, seed: int = 0) -> dict:
    """jaxgfx's route to 2 %: LM at ``coarse`` spp, then at ``fine`` spp from its solution
    (jaxgfx.testing.problems, the same problem and target as the example's fit)."""
    from jaxgfx.testing.problems import TRUE_ALBEDO, TRUE_ALPHA, inverse_example, lm_polish

    with_params, target = inverse_example(
        read_yaml(os.path.join(ROOT, "configs", "scenes", "inverse.yaml"))
    )
    r = lm_polish(with_params, target, coarse, fine, [seed])[0]
    total = r["route_seconds"] + r["compile_seconds"] + r["coarse"]["compile_seconds"]
    return {
        "route": f"LM {coarse} spp, then 3 Gauss-Newton steps at {fine} spp",
        "final_alpha": r["alpha"],
        "alpha_error": abs(r["alpha"] - TRUE_ALPHA),
        "albedo_error": float(np.max(np.abs(np.asarray(r["albedo"]) - np.asarray(TRUE_ALBEDO)))),
        "iterations": [r["coarse"]["iterations"], r["iterations"]],
        "solve_seconds": r["route_seconds"],
        "compile_seconds": r["compile_seconds"] + r["coarse"]["compile_seconds"],
        "time_to_2pct_alpha": total if r["rel_error"] <= 0.02 else None,
    }


def run_mitsuba(cfg: dict, steps: int, spp: int, lr: float, seed: int = 0) -> dict:
    """Mitsuba 3's own loop (module doc); ``seed``: the fit's seeds are ``seed * steps + k``
    (0: ``k``, the seeds of the earlier runs); the target's seed is 12345 whatever ``seed``."""
    t_start = time.perf_counter()
    if os.path.exists(LLVM19):
        os.environ.setdefault("DRJIT_LIBLLVM_PATH", LLVM19)
    from jaxgfx.render.scene.mitsuba import import_mitsuba, to_mitsuba_dict

    variant = "llvm_ad_rgb"
    mi = import_mitsuba(variant)
    import drjit as dr

    scene_path = os.path.join(CONFIG_DIR, cfg["scene"])
    desc = read_yaml(scene_path)
    r = cfg["render"]
    desc["camera"]["width"], desc["camera"]["height"] = r["width"], r["height"]
    md = to_mitsuba_dict(desc, base_dir=os.path.dirname(scene_path), mi=mi)
    md["integrator"] = {"type": "prb", "max_depth": int(r.get("max_depth", 2))}
    scene = mi.load_dict(md)
    params = mi.traverse(scene)
    ka = [k for k in params.keys() if k.endswith("alpha.value")][0]
    kr = "shape_1.bsdf.brdf_0.reflectance.value"  # the clay sphere (second shape)
    truth = cfg["target"]["synthetic"]
    params[ka] = mi.Float(truth[ALPHA])
    params[kr] = mi.Color3f(*truth[ALBEDO])
    params.update()
    t = time.perf_counter()
    ref = mi.render(scene, params, spp=int(cfg["target"].get("spp", 256)), seed=12345)
    dr.eval(ref)
    # the copy to NumPy waits for the kernel: dr.eval returns first (a 16384-spp target:
    # 0.02 s to dr.eval, 5.2 s to the array at load 7.5; the runs before 2026-12-06 timed
    # only dr.eval)
    ref_np = np.array(ref, np.float32)[..., :3]
    target_seconds = time.perf_counter() - t

    # the same parametrisation as jaxgfx: Adam on u with alpha = lo + (hi - lo) sigmoid(u)
    init = cfg["params"]
    lo_a, hi_a = init[ALPHA]["min"], init[ALPHA]["max"]

    def logit(t):
        return float(np.log(t / (1 - t)))

    def sigmoid(u):
        return 1.0 / (1.0 + dr.exp(-u))

    opt = mi.ad.Adam(lr=lr)
    opt["u_alpha"] = mi.Float(logit((init[ALPHA]["init"] - lo_a) / (hi_a - lo_a)))
    opt["u_albedo"] = mi.Color3f(*[logit(v) for v in init[ALBEDO]["init"]])

    def apply():
        params[ka] = lo_a + (hi_a - lo_a) * sigmoid(opt["u_alpha"])
        params[kr] = sigmoid(opt["u_albedo"])
        params.update()

    apply()
    alphas = [float(init[ALPHA]["init"])]
    albedos = [list(init[ALBEDO]["init"])]
    secs = []
    lr_final = cfg["optimizer"].get("lr_final")
    for it in range(steps):
        t = time.perf_counter()
        if lr_final is not None:  # the same exponential decay as jaxgfx's config
            opt.set_learning_rate(lr * (lr_final / lr) ** (it / max(steps - 1, 1)))
        img = mi.render(scene, params, spp=spp, seed=seed * steps + it)
        loss = dr.mean(dr.square(img - ref), axis=None)
        dr.backward(loss)
        opt.step()
        apply()
        a = float(np.array(params[ka]).ravel()[0])
        c = np.array(params[kr]).ravel()[:3].tolist()
        secs.append(time.perf_counter() - t)
        alphas.append(a)
        albedos.append(c)
    alpha = np.asarray(alphas)
    albedo = np.asarray(albedos)
    cum = np.concatenate([[0.0], np.cumsum(secs)])
    # the same Polyak-Ruppert tail as jaxgfx's optimizer.average (in u; off: the last iterate)
    est = estimates(alpha, tail_start(cfg, steps), lo_a, hi_a)
    return {
        "variant": variant,
        "seed": seed,
        "seconds_per_step": float(np.median(secs[1:])),
        "first_step_seconds": float(secs[0]),
        "target_seconds": target_seconds,
        "wall_seconds": time.perf_counter() - t_start,  # import, load, target and loop
        "time_to_2pct_alpha": time_to_within(alpha, cum, truth[ALPHA]),
        "time_to_first_2pct_alpha": time_to_first(alpha, cum, truth[ALPHA]),
        "time_to_2pct_result": time_to_within(est, cum, truth[ALPHA], window=1),
        "final_alpha": float(alpha[-10:].mean()),
        "alpha_error": float(abs(alpha[-10:].mean() - truth[ALPHA])),
        "result_alpha": float(est[-1]),
        "result_alpha_error": float(abs(est[-1] - truth[ALPHA])),
        "albedo_error": float(np.max(np.abs(albedo[-10:].mean(0) - np.asarray(truth[ALBEDO])))),
        "curve": {"seconds": cum.tolist(), "alpha": alpha.tolist(), "estimate": est.tolist()},
        "target": ref_np,
    }


def spread(runs, truth) -> dict:
    """Several fits of one system: each seed's result, the mean, its standard error, and how
    many results are within 2 % of ``truth`` / settle there (``time_to_2pct_alpha``)."""
    r = np.asarray([x["result_alpha"] for x in runs], np.float64)
    return {
        "seeds": [x["seed"] for x in runs],
        "result_alpha": r.tolist(),
        "mean": float(r.mean()),
        "se": float(r.std(ddof=1) / np.sqrt(r.size)) if r.size > 1 else None,
        "sd": float(r.std(ddof=1)) if r.size > 1 else None,
        "within_2pct": int(np.sum(np.abs(r - truth) <= 0.02 * truth)),
        "settled_2pct": sum(x["time_to_2pct_alpha"] is not None for x in runs),
        "time_to_2pct_alpha": [x["time_to_2pct_alpha"] for x in runs],
    }


def plot(path, res, truth):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6))
    for name, r in res.items():
        if not isinstance(r, dict) or "curve" not in r:
            continue
        s = np.asarray(r["curve"]["seconds"])
        a = np.asarray(r["curve"]["alpha"])
        err = np.maximum(np.abs(a - truth) / truth, 1e-4)
        axes[0].loglog(s[1:], err[1:], label=f"{name}, Adam")
        axes[1].plot(np.arange(len(a)), a, label=name)
    lm = res.get("jaxgfx_lm")
    if isinstance(lm, dict) and "solve_seconds" in lm:
        axes[0].scatter(
            [lm["solve_seconds"]],
            [max(lm["alpha_error"] / truth, 1e-4)],
            marker="*",
            s=90,
            color="tab:red",
            zorder=3,
            label="jaxgfx, " + lm["route"].replace("Gauss-Newton", "GN"),
        )
    axes[0].axhline(0.02, color="k", ls=":", lw=0.8)
    axes[0].set_xlabel("seconds (after compilation)")
    axes[0].set_ylabel("|alpha - truth| / truth")
    axes[1].axhline(truth, color="k", ls="--", lw=0.8)
    axes[1].set_xlabel("step")
    axes[1].set_ylabel("alpha")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(
        "GGX roughness + albedo fit, 32x32, 8 spp/step, Adam (lr 0.05 -> 0.005)", fontsize=10
    )
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--steps", type=int, default=None, help="default: the config's")
    p.add_argument("--out", default=None, help="also write the JSON here")
    p.add_argument("--plot", default=None, help="directory for inverse_speed.png")
    p.add_argument("--no-mitsuba", action="store_true")
    p.add_argument("--lm-polish", default="128:4096", help="COARSE:FINE spp ('' to skip)")
    p.add_argument("--seeds", default="",
                   help="more fits of both systems with these seeds (e.g. 1,2,3), after the "
                        "timed ones: the spread of their results")
    a = p.parse_args(argv)
    t_run = time.perf_counter()
    enable_compilation_cache()
    cfg = problem_config(a.steps)
    a.steps = int(cfg["optimizer"]["steps"])
    spp, lr = int(cfg["render"]["spp"]), float(cfg["optimizer"]["lr"])
    res: dict = {
        "benchmark": "inverse",
        "machine": machine(),
        "problem": {
            "config": "configs/inverse_material.yaml",
            "steps": a.steps,
            "spp": spp,
            "lr": lr,
            "truth": cfg["target"]["synthetic"],
        },
    }
    _log("jaxgfx ...")
    res["jaxgfx"] = run_jaxgfx(cfg)
    res["jaxgfx"]["seed"] = int(cfg.get("seed", 0))
    seeds = [int(x) for x in a.seeds.split(",") if x]
    if a.lm_polish:
        _log("jaxgfx LM ...")
        coarse, fine = (int(x) for x in a.lm_polish.split(":"))
        res["jaxgfx_lm"] = run_jaxgfx_lm(coarse, fine)
    if not a.no_mitsuba:
        _log("mitsuba ...")
        try:
            m = run_mitsuba(cfg, a.steps, spp, lr)
            res["machine"]["mitsuba"] = sys.modules["mitsuba"].__version__
            tgt = m.pop("target")
            res["mitsuba"] = m
            # conventions check: the jaxgfx target at the same values and spp
            import jax

            from jaxgfx.config import load_config
            from jaxgfx.pipelines.fit import FitConfig, build_scene, prepare_fit
            from jaxgfx.render import render

            prep = prepare_fit(load_config(FitConfig, cfg), base_dir=CONFIG_DIR)
            s = build_scene(prep.scene, list(prep.truth), prep.truth)
            t_spp = int(cfg["target"].get("spp", 256))
            ours = np.asarray(render(s, jax.random.key(7), spp=t_spp, integrator="direct"))
            res["target_relative_rmse_jaxgfx_vs_mitsuba"] = float(
                np.sqrt(np.mean((ours - tgt) ** 2)) / np.sqrt(np.mean(tgt**2))
            )
        except Exception as e:  # noqa: BLE001 - report why the peer could not run
            res["mitsuba"] = {"error": f"{type(e).__name__}: {e}"}
    res["wall_seconds"] = time.perf_counter() - t_run  # the timed runs (not --seeds')
    if seeds:
        _log(f"jaxgfx seeds {seeds} ...")
        runs = [res["jaxgfx"]]
        for sd in seeds:
            runs.append({**run_jaxgfx({**cfg, "seed": sd}), "seed": sd})
        res["jaxgfx_seeds"] = spread(runs, cfg["target"]["synthetic"][ALPHA])
        if "error" not in res.get("mitsuba", {"error": None}):
            _log(f"mitsuba seeds {seeds} ...")
            runs = [res["mitsuba"]] + [
                run_mitsuba(cfg, a.steps, spp, lr, seed=sd) for sd in seeds
            ]
            res["mitsuba_seeds"] = spread(runs, cfg["target"]["synthetic"][ALPHA])
    if a.plot:
        os.makedirs(a.plot, exist_ok=True)
        plot(os.path.join(a.plot, "inverse_speed.png"), res, cfg["target"]["synthetic"][ALPHA])
    short = {
        k: ({kk: vv for kk, vv in v.items() if kk != "curve"} if isinstance(v, dict) else v)
        for k, v in res.items()
    }
    emit(res, a.out, printed=short)
    return 0


if __name__ == "__main__":
    sys.exit(main())
