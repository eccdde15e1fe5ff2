"""Inverse rendering: fit material (and camera) parameters of a scene to a target image.

    python -m experiments.inverse_material --config configs/inverse_material.yaml --out out/inverse

Writes result.json, curves.png, before.png, after.png and target.png (docs/inverse.md). The
options are those of ``jaxgfx fit CONFIG`` (one definition, in ``jaxgfx.cli``; here the config
is ``--config``); the job is ``jaxgfx.pipelines.fit.run_fit``.
"""

from __future__ import annotations

import argparse
import sys

from jaxgfx.cli import add_command_arguments, run_command


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_command_arguments(p, "fit")
    # the experiment convention: --config PATH (default the shipped example) -> CONFIG
    if "--config" in argv:
        i = argv.index("--config")
        if i + 1 >= len(argv):
            p.error("--config: expected a path")
        argv = [argv[i + 1], *argv[:i], *argv[i + 2 :]]
    else:
        argv = ["configs/inverse_material.yaml", *argv]
    return run_command(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
