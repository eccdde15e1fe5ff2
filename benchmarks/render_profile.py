"""Where a render's time goes: XLA kernels by profiled time, each with its source lines.

    python -m benchmarks.render_profile [--integrator path] [--max-depth 3] [--res 128]
                                        [--spp 2] [--chunk 4096|none] [--top 15] [--out F]

Renders the example scene (``configs/scenes/example.yaml``) under ``jax.profiler.trace``, sums
the time of every XLA CPU kernel (fusion) over the traced calls and joins each kernel with the
source lines its instructions came from (the HLO's stack frames: innermost ``jaxgfx`` frame
outside ``_math.py``). A per-ray computation that appears in several large kernels is being
recomputed by each of them (XLA's CPU fusion duplicates elementwise producers into every
consumer, and into each of the 3 channels of an ``(..., 3)`` output): materialise it with
:func:`jaxgfx._math.fusion_barrier` (docs/performance.md, "Renderer"). Prints JSON.
"""

from __future__ import annotations

import argparse
import collections
import glob
import gzip
import json
import os
import re
import tempfile

import jax

from benchmarks._report import emit, machine
from jaxgfx.config import read_yaml
from jaxgfx.render.integrators import DirectIntegrator, PathIntegrator
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE = os.path.join(ROOT, "configs", "scenes", "example.yaml")


def _sections(hlo: str):
    """``{frame id: (file, line)}`` of the innermost frame of each HLO stack frame."""
    files, locs, frames = {}, {}, {}
    sec = None
    for line in hlo.split("\n"):
        if line in ("FileNames", "FunctionNames", "FileLocations", "StackFrames"):
            sec = line
            continue
        if line.startswith("%") or line.startswith("ENTRY"):
            break
        if not re.match(r"^\d+ ", line):
            continue
        if sec == "FileNames":
            i, name = line.split(" ", 1)
            files[int(i)] = name.strip('"').split("/")[-1]
        elif sec == "FileLocations":
            m = re.match(r"(\d+) \{file_name_id=(\d+) function_name_id=\d+ line=(\d+)", line)
            locs[int(m[1])] = (files[int(m[2])], int(m[3]))
        elif sec == "StackFrames":
            m = re.match(r"(\d+) \{file_location_id=(\d+) parent_frame_id=(\d+)", line)
            frames[int(m[1])] = (int(m[2]), int(m[3]))

    def source(fid):
        seen = set()
        while fid in frames and fid not in seen:
            seen.add(fid)
            loc, parent = frames[fid]
            f, ln = locs[loc]
            if f != "_math.py" and not f.startswith("_jit"):
                return f"{f}:{ln}"
            fid = parent
        return "?"

    return source


def kernel_table(hlo: str, trace_events, top: int):
    source = _sections(hlo)
    comps, cur = {}, None
    for line in hlo.split("\n"):
        m = re.match(r"^(%\S+|ENTRY \S+) ", line)
        if m and line.rstrip().endswith("{"):
            cur = m.group(1).lstrip("%").replace("ENTRY ", "")
            comps[cur] = []
        elif cur:
            comps[cur].append(line)
    fusions = {}
    for body in comps.values():
        for line in body:
            m = re.match(r"\s*(?:ROOT )?%(\S+) = (\S+) .*fusion\(.*calls=%([\w.\-]+)", line)
            if m:
                fusions[m.group(1)] = (m.group(2), m.group(3))
    us = collections.Counter()
    for e in trace_events:
        if e.get("ph") == "X" and e.get("name") in fusions:
            us[e["name"]] += e["dur"]
    total = sum(us.values())
    rows = []
    for name, t in us.most_common(top):
        shape, callee = fusions[name]
        body = comps.get(callee, [])
        lines = collections.Counter(
            source(int(f)) for ln in body for f in re.findall(r"stack_frame_id=(\d+)", ln)
        )
        rows.append(
            {
                "kernel": name,
                "share": round(t / total, 4),
                "output": re.sub(r"\{[^}]*\}", "", shape),
                "instructions": len(body),
                "sources": dict(lines.most_common(8)),
            }
        )
    return total, rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--integrator", choices=("path", "direct"), default="path")
    ap.add_argument("--max-depth", type=int, default=3)
    ap.add_argument("--res", type=int, default=128)
    ap.add_argument("--spp", type=int, default=2)
    ap.add_argument("--chunk", default="default", help="rays per shading chunk, or none")
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--out", default=None, help="also write the JSON here")
    a = ap.parse_args(argv)
    mach = machine()
    desc = read_yaml(EXAMPLE)
    desc["camera"]["width"] = desc["camera"]["height"] = a.res
    scene = load_scene(desc)
    opts = {} if a.chunk == "default" else {"chunk": None if a.chunk == "none" else int(a.chunk)}
    if a.integrator == "direct":
        integ = DirectIntegrator(**opts)
    else:
        integ = PathIntegrator(max_depth=a.max_depth, **opts)
    f = jax.jit(lambda s, k: render(s, k, spp=a.spp, integrator=integ))
    key = jax.random.key(0)
    hlo = f.lower(scene, key).compile().as_text()
    f(scene, key).block_until_ready()
    with tempfile.TemporaryDirectory() as d:
        with jax.profiler.trace(d):
            for i in range(2):
                f(scene, jax.random.key(i)).block_until_ready()
        path = glob.glob(os.path.join(d, "**", "*.trace.json.gz"), recursive=True)[0]
        with gzip.open(path) as fh:
            events = json.load(fh)["traceEvents"]
    total, rows = kernel_table(hlo, events, a.top)
    doc = {
        "benchmark": "render_profile",
        "machine": mach,
        "integrator": a.integrator,
        "max_depth": a.max_depth if a.integrator == "path" else 2,
        "chunk": integ.chunk,
        "res": a.res,
        "spp": a.spp,
        "kernel_seconds": round(total * 1e-6, 4),
        "top_kernels": rows,
    }
    emit(doc, a.out)


if __name__ == "__main__":
    main()
