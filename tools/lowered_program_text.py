"""Whether scenes that use no new feature compile to the same program in two checkouts: the
StableHLO text of ``jax.jit(render).lower(scene, key).as_text()`` (no debug locations) of a
few scenes, each checkout in its own interpreter, compared text for text.

Design rule checked ("nothing a scene doesn't use may cost it time"): e.g. a scene without a
projector or a spot texture lowers to the same text before and after they were added. Run from
the repository root::

    JAX_PLATFORMS=cpu python tools/lowered_program_text.py /work/main [.]

prints one line per scene and integrator (``same`` / ``DIFFERENT``, text length, SHA-256) and
exits 1 if any differ. ``--dump DIR`` also writes each text (``DIR/<checkout>_<case>.txt``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import pathlib
import subprocess
import sys

# (name, scene description or YAML path relative to the checkout, integrator, max_depth)
_CAMERA = {"origin": [0, 1.5, 4], "target": [0, 0.5, 0], "fov": 45, "width": 8, "height": 8}
_FLOOR = {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 1, 0], "size": [6, 6],
          "material": "m"}  # fmt: skip
_BALL = {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5, "material": "m"}
_SPOT = {"type": "spot", "position": [0, 3, 0], "direction": [0, -1, 0], "intensity": 5.0,
         "cutoff_angle": 30.0}  # fmt: skip
_DIR = {"type": "directional", "direction": [0.3, -1, 0.2], "irradiance": 1.0}
_POINT = {"type": "point", "position": [1, 2, 1], "intensity": 3.0}
_ENVMAP = {"type": "envmap", "image": [[[0.2, 0.3, 0.5 + 0.1 * i] for i in range(4)],
                                       [[0.1, 0.1, 0.1 * i] for i in range(4)]]}  # fmt: skip


def _desc(*emitters):
    return {"camera": _CAMERA, "shapes": [_FLOOR, _BALL], "emitters": list(emitters),
            "materials": {"m": {"type": "diffuse", "reflectance": 0.5}}}  # fmt: skip


# every delta-only BSDF (Mirror, SmoothDielectric, ThinDielectric, the pass-through polarizers)
_DELTA = {"camera": _CAMERA, "emitters": [_POINT, _DIR],
          "shapes": [{**_FLOOR, "material": "mirror"}, {**_BALL, "material": "glass"},
                     {**_BALL, "center": [1, 0.3, 0], "radius": 0.3, "material": "thin"},
                     {**_BALL, "center": [-1, 0.3, 0], "radius": 0.3, "material": "pol"}],
          "materials": {"mirror": {"type": "conductor", "eta": 0.2, "k": 3.0},
                        "glass": {"type": "dielectric"}, "thin": {"type": "thindielectric"},
                        "pol": {"type": "polarizer", "transmittance": 0.8}}}  # fmt: skip

CASES = [
    ("example.yaml", "configs/scenes/example.yaml", "path", 3),
    ("spot", _desc(_SPOT), "path", 3),
    ("spot+point+directional", _desc(_SPOT, _POINT, _DIR), "path", 3),
    ("spot+directional whitted", _desc(_SPOT, _DIR), "whitted", 3),
    ("spot, tent filter", {**_desc(_SPOT), "film": {"filter": "tent"}}, "path", 3),
    ("envmap", _desc(_ENVMAP), "path", 3),
    ("delta BSDFs", _DELTA, "path", 3),
]


def child(root: str) -> None:
    """Lower every case with the checkout ``root``; print a JSON list of the texts."""
    sys.path.insert(0, root)
    import jax

    from jaxgfx.render import load_scene, render

    assert os.path.dirname(os.path.dirname(sys.modules["jaxgfx"].__file__)) == root
    out = []
    for _, desc, integrator, depth in CASES:
        if isinstance(desc, str):
            scene = load_scene(os.path.join(root, desc))
        else:
            scene = load_scene(desc)
        f = jax.jit(lambda s, k, i=integrator, d=depth: render(s, k, spp=2, integrator=i,
                                                                 max_depth=d))  # fmt: skip
        out.append(f.lower(scene, jax.random.key(0)).as_text())
    print(json.dumps(out))


def texts(root: str) -> list[str]:
    env = dict(os.environ, JAX_PLATFORMS=os.environ.get("JAX_PLATFORMS", "cpu"))
    env.pop("PYTHONPATH", None)
    r = subprocess.run([sys.executable, __file__, "--child", root], capture_output=True,
                       text=True, env=env, cwd=root)  # fmt: skip
    if r.returncode:
        raise RuntimeError(f"{root}: {r.stderr[-2000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("base", help="the checkout to compare with (e.g. /work/main)")
    ap.add_argument("other", nargs="?", default=".", help="this checkout (default .)")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--dump", help="write the texts into this folder")
    a = ap.parse_args(argv)
    if a.child:
        child(os.path.abspath(a.base))
        return 0
    roots = [os.path.abspath(a.base), os.path.abspath(a.other)]
    got = [texts(r) for r in roots]
    bad = 0
    for k, (name, _, integrator, _) in enumerate(CASES):
        x, y = got[0][k], got[1][k]
        same = x == y
        bad += not same
        h = [hashlib.sha256(t.encode()).hexdigest()[:16] for t in (x, y)]
        print(f"{'same' if same else 'DIFFERENT':9s} {name} ({integrator}): {len(x)} / {len(y)} "
              f"chars, sha256 {h[0]} / {h[1]}")  # fmt: skip
        if a.dump:
            pathlib.Path(a.dump).mkdir(parents=True, exist_ok=True)
            for r, t in zip(roots, (x, y), strict=True):
                pathlib.Path(a.dump, f"{pathlib.Path(r).name}_{k}.txt").write_text(t)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
