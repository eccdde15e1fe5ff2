"""Calibrate a camera from a bracketed stack and merge an HDR radiance map.

    python -m experiments.calibrate --config configs/calibrate.yaml [INPUTS ...] --out out/calibrate

With no inputs it runs on the embedded synthetic stack (known radiance, response and noise)
and reports the curve and radiance errors against the ground truth. The options are those of
``jaxgfx calibrate`` (one definition, in ``jaxgfx.cli``); the job is
``jaxgfx.pipelines.calibrate.run_calibrate``.
"""

from __future__ import annotations

import argparse
import sys

from jaxgfx.cli import add_command_arguments, run_command


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    add_command_arguments(p, "calibrate")
    p.set_defaults(config="configs/calibrate.yaml")
    return run_command(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
