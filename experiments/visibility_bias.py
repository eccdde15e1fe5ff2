"""Bias of shape derivatives from moving silhouettes and shadows (issue 10, "Visibility").

    python -m experiments.visibility_bias [--size 16] [--keys 16] [--spp 32] [--h 0.05]
                                         [--integrator direct] [--max-depth 3]
                                         [--strategy mis] [--occluder sphere|mesh]
                                         [--out FILE]

Scene: a diffuse sphere (or, ``--occluder mesh``, a 20-triangle icosahedron) moves sideways
(parameter: its centre's x, or every vertex's x) in front of an area light
that faces the camera and lights a diffuse floor, plus a constant environment; the sphere's
silhouette crosses the light and the lit floor in the image, and its shadow edge moves on the
floor. Loss: the mean of the image columns right of the sphere's projected centre (the image
mean would nearly cancel the left and right edges, which move in opposite directions). Per
key: the reverse-mode gradient without
(``visibility=None``) and with edge sampling (``visibility="edge"``), and central finite
differences of the same renderer with the same key (common random numbers), step ``h`` (world
units). Prints JSON: means, standard errors over the keys, and the paired AD − FD differences.
"""

from __future__ import annotations

import argparse
import sys

from experiments._common import emit_json
from jaxgfx.testing.problems import measure_visibility_bias as measure


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--size", type=int, default=16)
    p.add_argument("--keys", type=int, default=16)
    p.add_argument("--spp", type=int, default=32)
    p.add_argument("--h", type=float, default=0.05)
    p.add_argument("--integrator", default="direct")
    p.add_argument("--max-depth", type=int, default=3)
    p.add_argument("--strategy", default="mis")
    p.add_argument("--occluder", default="sphere", choices=("sphere", "mesh"))
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    res = measure(a.size, a.keys, a.spp, a.h, a.integrator, a.max_depth, a.strategy, a.occluder)
    emit_json(res, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
