"""Command-line entry point: ``jaxgfx <subcommand> ...``.

Subcommands
-----------
``jaxgfx filter IN OUT --op gaussian --sigma 2``
    Apply one image operation (see ``jaxgfx filter --list``) to a PNG/JPEG/TIFF/EXR/HDR file.
``jaxgfx calibrate [INPUTS ...] --config configs/calibrate.yaml --out out/calibrate``
    The main job: fit a camera response from a bracketed stack and merge a radiance map.
``jaxgfx render SCENE.yaml OUT.exr --spp 64 --integrator path``
    Render a scene description with the Monte Carlo renderer.

Heavy modules are imported inside the subcommands so that ``jaxgfx --help`` is instant.
"""

from __future__ import annotations

import argparse
import sys

__all__ = ["main", "build_parser"]


def _add_filter(sub):
    p = sub.add_parser(
        "filter",
        help="apply an image operation to a file",
        description="Apply one jaxgfx image operation to an image file. Display-referred files "
        "(PNG/JPEG/TIFF) are processed as floats in [0, 1]; EXR/HDR as linear radiance.",
    )
    p.add_argument("input", nargs="?", help="input image (.png .jpg .tif .exr .hdr)")
    p.add_argument("output", nargs="?", help="output image; format from the extension")
    p.add_argument("--op", default="gaussian", help="operation name (see --list)")
    p.add_argument("--list", action="store_true", help="list operations and their parameters")
    for name, kind, hlp in [
        ("sigma", float, "Gaussian sigma in pixels"),
        ("radius", int, "box radius in pixels"),
        ("size", int, "median window size (odd)"),
        ("sigma-spatial", float, "bilateral spatial sigma (pixels)"),
        ("sigma-range", float, "bilateral range sigma (value units)"),
        ("amount", float, "unsharp-mask amount"),
        ("low", float, "low threshold / quantile"),
        ("high", float, "high threshold / quantile"),
        ("gamma", float, "gamma exponent"),
        ("cutoff", float, "Fourier cutoff in cycles/pixel"),
        ("pattern", str, "Bayer pattern (RGGB, BGGR, GRBG, GBRG)"),
        ("padding", str, "padding mode (zero, edge, reflect, wrap)"),
    ]:
        p.add_argument(f"--{name}", type=kind, default=None, help=hlp)
    p.set_defaults(func=_cmd_filter)


def _cmd_filter(args) -> int:
    from jaxgfx.pipelines.filter_ops import FILTER_OPS, apply_filter_file

    if args.list:
        for name, op in sorted(FILTER_OPS.items()):
            print(f"{name:14s} {op.doc}  params: {', '.join(op.params) or '-'}")
        return 0
    if not args.input or not args.output:
        print("jaxgfx filter: error: INPUT and OUTPUT are required", file=sys.stderr)
        return 2
    params = {
        k: v
        for k, v in vars(args).items()
        if k not in ("input", "output", "op", "list", "func", "command") and v is not None
    }
    out = apply_filter_file(args.input, args.output, args.op, **params)
    print(f"wrote {out}")
    return 0


def _add_calibrate(sub):
    p = sub.add_parser(
        "calibrate",
        help="fit a camera response from bracketed exposures and merge an HDR radiance map",
        description="Calibrate a camera from a bracketed stack (RAW or JPEG/PNG/TIFF files, or "
        "a directory of them); with no inputs, runs on the embedded synthetic stack.",
    )
    p.add_argument("inputs", nargs="*", help="image files or one directory")
    p.add_argument("--config", default=None, help="YAML config (see configs/calibrate.yaml)")
    p.add_argument("--out", default="out/calibrate", help="output directory")
    p.add_argument("--times", default=None, help="comma-separated exposure times (seconds)")
    p.add_argument("--method", default=None, help="response method (overrides the config)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_calibrate)


def _cmd_calibrate(args) -> int:
    from jaxgfx.pipelines.calibrate import run_calibrate_cli

    return run_calibrate_cli(args)


def _add_render(sub):
    p = sub.add_parser(
        "render",
        help="render a scene description (YAML) to EXR + PNG",
        description="Render a scene (see docs/render.md) with the Monte Carlo renderer.",
    )
    p.add_argument("scene", help="scene YAML file")
    p.add_argument("output", help="output .exr (a tone-mapped .png is written beside it)")
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--integrator", default="path", help="path | direct | whitted | aov")
    p.add_argument("--max-depth", type=int, default=3)
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=_cmd_render)


def _cmd_render(args) -> int:
    import os
    import time

    import jax
    import numpy as np

    from jaxgfx import io
    from jaxgfx.color import linear_to_srgb
    from jaxgfx.render.render import render
    from jaxgfx.render.scene import load_scene

    scene = load_scene(args.scene)
    t0 = time.perf_counter()
    img = render(
        scene,
        jax.random.key(args.seed),
        spp=args.spp,
        integrator=args.integrator,
        max_depth=args.max_depth,
    )
    img = np.asarray(jax.block_until_ready(img))
    dt = time.perf_counter() - t0
    parent = os.path.dirname(os.path.abspath(args.output))
    os.makedirs(parent, exist_ok=True)
    io.write_exr(args.output, np.ascontiguousarray(img, np.float32))
    png = os.path.splitext(args.output)[0] + ".png"
    # AOV images: the PNG shows the albedo channels
    io.write_png(png, np.asarray(linear_to_srgb(np.clip(img[..., :3], 0.0, 1.0))))
    n = img.shape[0] * img.shape[1] * args.spp
    print(
        f"wrote {args.output} and {png} ({dt:.2f} s incl. compile, {n / dt / 1e6:.2f} M samples/s)"
    )
    return 0


def build_parser() -> argparse.ArgumentParser:
    from jaxgfx import __version__

    parser = argparse.ArgumentParser(
        prog="jaxgfx", description="Differentiable image processing, HDR and rendering in JAX."
    )
    parser.add_argument("--version", action="version", version=f"jaxgfx {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    _add_filter(sub)
    _add_calibrate(sub)
    _add_render(sub)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (ValueError, TypeError, FileNotFoundError) as e:
        print(f"jaxgfx {args.command}: error: {e}", file=sys.stderr)
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
