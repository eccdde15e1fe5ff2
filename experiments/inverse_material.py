"""Inverse rendering: fit material (and camera) parameters of a scene to a target image.

    python -m experiments.inverse_material --config configs/inverse_material.yaml --out out/inverse

Writes result.json, curves.png, before.png, after.png and target.png (see
jaxgfx/pipelines/fit.py and docs/inverse.md). Same job as ``jaxgfx fit CONFIG --out DIR``.
"""

from __future__ import annotations

import sys

from jaxgfx.pipelines.fit import run_fit_cli


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--config" in argv:  # --config PATH -> positional CONFIG
        i = argv.index("--config")
        argv = [argv[i + 1], *argv[:i], *argv[i + 2 :]]
    else:
        argv = ["configs/inverse_material.yaml", *argv]
    return run_fit_cli(argv, prog="python -m experiments.inverse_material")


if __name__ == "__main__":
    sys.exit(main())
