"""Multi-device rendering benchmark: samples/s of ``render`` vs ``render_sharded`` on n devices.

    python -m benchmarks.distributed [--devices 1 2] [--size 64] [--spp 16] [--repeat 3] [--out F]

For each device count n, a subprocess with ``XLA_FLAGS=--xla_force_host_platform_device_count=n``
(the flag must be set before jax is imported) renders ``configs/scenes/example.yaml`` at
``size``² with the ``direct`` integrator: the single-device ``render`` (the peer, in the same
process) and ``render_sharded`` with ``shard="rows"`` and ``"samples"`` over all n devices.
Timing: one warm-up call each (compilation), then the medians of ``repeat`` rounds that call the
three in turn (``benchmarks._timing.interleaved_times``); samples/s =
W·H·spp / median. Host "devices" are threads of one CPU process, so the speed-up is bounded by
the free cores: on a shared machine the numbers depend on the other load (compare the ratios
within one run). Prints one JSON document.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import subprocess
import sys

import jax

from benchmarks._report import emit, machine

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _child(size: int, spp: int, repeat: int) -> dict:
    import numpy as np

    from benchmarks._timing import interleaved_times
    from jaxgfx.config import read_yaml
    from jaxgfx.render import load_scene, render, render_sharded

    desc = read_yaml(ROOT / "configs/scenes/example.yaml")
    desc["camera"].update(width=size, height=size)
    scene = load_scene(desc)
    key = jax.random.key(0)
    runs = {
        "render": lambda: render(scene, key, spp=spp, integrator="direct"),
        "rows": lambda: render_sharded(scene, key, spp=spp, integrator="direct", shard="rows"),
        "samples": lambda: render_sharded(
            scene, key, spp=spp, integrator="direct", shard="samples"
        ),
    }
    out = {"devices": jax.device_count()}
    times = interleaved_times(runs, repeat)
    images = {name: np.asarray(f()) for name, f in runs.items()}
    for name, (first, med) in times.items():
        out[name] = {
            "median_s": med,
            "compile_s": first - med,
            "samples_per_s": size * size * spp / med,
        }
        # equal to the single-device image up to float32 summation order
        out[name]["max_abs_diff_vs_render"] = float(np.abs(images[name] - images["render"]).max())
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--devices", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--size", type=int, default=64)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=None, help="also write the JSON here")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(_child(a.size, a.spp, a.repeat)))
        return
    jax.config.update("jax_platforms", "cpu")  # the backend the children use (JAX_PLATFORMS)
    doc = {
        "benchmark": "distributed",
        "machine": machine(),
        "scene": "configs/scenes/example.yaml",
        "size": a.size,
        "spp": a.spp,
        "integrator": "direct",
        "results": [],
    }
    for n in a.devices:
        env = dict(os.environ)
        env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={n}"
        env["JAX_PLATFORMS"] = "cpu"
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
        cmd = [sys.executable, "-m", "benchmarks.distributed", "--child", "--size", str(a.size)]
        cmd += ["--spp", str(a.spp), "--repeat", str(a.repeat)]
        proc = subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True)
        if proc.returncode != 0:
            sys.exit(f"{n} devices: child failed:\n{proc.stderr[-4000:]}")
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        for name in ("rows", "samples"):
            r[name]["speedup_vs_render"] = r["render"]["median_s"] / r[name]["median_s"]
        doc["results"].append(r)
        print(f"{n} devices done", file=sys.stderr)
    emit(doc, a.out)


if __name__ == "__main__":
    main()
