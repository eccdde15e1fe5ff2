"""Calibrate a camera from a bracketed stack and merge an HDR radiance map.

    python -m experiments.calibrate --config configs/calibrate.yaml [INPUTS ...] --out out/calibrate

With no inputs it runs on the embedded synthetic stack (known radiance, response and noise)
and reports the curve and radiance errors against the ground truth.
"""

from __future__ import annotations

import argparse
import sys

from jaxgfx.pipelines.calibrate import run_calibrate_cli


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("inputs", nargs="*")
    p.add_argument("--config", default="configs/calibrate.yaml")
    p.add_argument("--out", default="out/calibrate")
    p.add_argument("--times", default=None)
    p.add_argument("--method", default=None)
    p.add_argument("--quiet", action="store_true")
    return run_calibrate_cli(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
