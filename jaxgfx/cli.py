"""Command-line entry point: ``jaxgfx <subcommand> ...``.

Subcommands (the :data:`COMMANDS` registry; each is a thin argument → job layer over a
function in :mod:`jaxgfx.pipelines`)
-----------
``jaxgfx filter IN OUT --op gaussian --sigma 2``
    Apply one image operation (see ``jaxgfx filter --list``) to a PNG/JPEG/TIFF/EXR/HDR file.
``jaxgfx calibrate [INPUTS ...] --config configs/calibrate.yaml --out out/calibrate``
    The main job: fit a camera response from a bracketed stack and merge a radiance map.
``jaxgfx render SCENE.yaml OUT.exr --spp 64 --integrator path``
    Render a scene description with the Monte Carlo renderer.
``jaxgfx fit CONFIG --out out/fit``
    Inverse rendering: fit scene (and camera) parameters to a target (docs/inverse.md).
``jaxgfx tonemap IN.exr OUT.png --op drago --bias 0.85``
    Tone map an HDR image for display (see ``jaxgfx tonemap --list``).
``jaxgfx fuse bracket/ OUT.png``
    Exposure fusion of an LDR bracket (files or a directory) into one display image.

Every subcommand takes ``--overwrite`` (replace existing results; without it an output that
already exists is refused before any work) and ``--debug`` (show the traceback of an error).
Errors print one line ``jaxgfx CMD: error: ...`` naming the argument or path, exit status 1
(2 for usage errors). Outputs appear only when the whole job succeeded (see README.md).

Heavy modules are imported inside the subcommands so that ``jaxgfx --help`` is instant.
To add a subcommand: ``COMMANDS["name"] = Command(help, description, add_arguments, run)``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from collections.abc import Callable

__all__ = ["main", "build_parser", "COMMANDS", "Command", "run_command", "format_error"]


@dataclasses.dataclass(frozen=True)
class Command:
    """A subcommand: ``add_arguments(parser)`` declares its options, ``run(args) -> int``
    turns them into a job object, calls the pipeline and prints a summary."""

    help: str
    description: str
    add_arguments: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]


# ----------------------------------------------------------------------------- filter


def _filter_arguments(p):
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


_FILTER_PARAMS = (
    "sigma radius size sigma_spatial sigma_range amount low high gamma cutoff pattern padding"
).split()


def _filter_run(args) -> int:
    from jaxgfx.pipelines.filter_ops import FILTER_OPS, FilterJob, run_filter

    if args.list:
        for name, op in sorted(FILTER_OPS.items()):
            print(f"{name:14s} {op.doc}  params: {', '.join(op.params) or '-'}")
        return 0
    if not args.input or not args.output:
        raise _UsageError("INPUT and OUTPUT are required")
    params = {k: getattr(args, k) for k in _FILTER_PARAMS if getattr(args, k) is not None}
    job = FilterJob(args.input, args.output, args.op, params, overwrite=args.overwrite)
    print(f"wrote {run_filter(job)}")
    return 0


# ----------------------------------------------------------------------------- calibrate


def _calibrate_arguments(p):
    p.add_argument("inputs", nargs="*", help="image files or one directory")
    p.add_argument("--config", default=None, help="YAML config (see configs/calibrate.yaml)")
    p.add_argument("--out", default="out/calibrate", help="output directory")
    p.add_argument("--times", default=None, help="comma-separated exposure times (seconds)")
    p.add_argument("--method", default=None, help="response method (overrides the config)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--tonemap",
        default=None,
        help="comma-separated tone-mapping operators; writes tonemap_<op>.png per operator",
    )
    p.add_argument(
        "--colorspace",
        default=None,
        help="RAW output space: rec709 (default) | srgb | xyz | aces2065-1 | acescg | prophoto "
        "| rec2020 | camera (no white balance, no matrix)",
    )
    p.add_argument(
        "--white-balance",
        default=None,
        help="RAW white balance: as_shot (default) | grey_world | white_patch",
    )
    p.add_argument(
        "--deghost",
        action="store_true",
        help="ghost-free merge of a bracket with moving objects (hdr.merge_deghosted): frames "
        "that disagree with a per-region reference under the noise model are left out",
    )
    p.add_argument(
        "--align",
        action="store_true",
        help="align the frames by a global translation first (align.enabled; LDR: "
        "hdr.align_stack, RAW: hdr.align_raw_stack on the mosaics); shifts in report.json",
    )
    p.add_argument(
        "--flat-field",
        default=None,
        help="RAW flat-field frame (same camera and size): fits the lens vignetting and "
        "divides it out before the colour step (vignetting.png, camera.json)",
    )
    p.add_argument(
        "--chart",
        default=None,
        metavar="X0,Y0,X1,Y1,X2,Y2,X3,Y3",
        help="RAW: a ColorChecker 24 in view; the pixel corners of its patch grid in the merged "
        "image, top-left (dark skin), top-right, bottom-right (black), bottom-left. Fits the "
        "camera matrix and white balance on CIEDE2000 and uses it for the output (report.json "
        "'chart': per-patch ΔE before/after; chart.png; camera.json)",
    )
    p.add_argument(
        "--chart-model",
        default=None,
        help="chart fit: matrix (default, 3x3) | root-polynomial (Finlayson et al. 2015)",
    )


def calibrate_job(args):
    """``argparse`` namespace of ``jaxgfx calibrate`` → :class:`CalibrateJob` (checked)."""
    from jaxgfx.config import load_config
    from jaxgfx.io import parse_exposure_time
    from jaxgfx.pipelines.calibrate import CalibrateConfig, CalibrateJob

    overrides: dict = {}
    if args.times is not None:
        parts = args.times.split(",")
        overrides["exposure_times"] = [
            parse_exposure_time(t, f"--times [{i}]") for i, t in enumerate(parts)
        ]
    if args.method is not None:
        from jaxgfx.config import read_yaml

        base = read_yaml(args.config) if args.config else {}
        section = base.get("response", {})
        if isinstance(section, dict):  # else load_config reports the malformed section
            overrides["response"] = {**section, "method": args.method}
    if getattr(args, "tonemap", None):
        overrides["tonemap"] = [t.strip() for t in args.tonemap.split(",") if t.strip()]
    for flag, key, field in (("deghost", "merge", "deghost"), ("align", "align", "enabled")):
        if getattr(args, flag, False):
            from jaxgfx.config import read_yaml

            base = read_yaml(args.config) if args.config else {}
            section = base.get(key, {})
            if isinstance(section, dict):  # else load_config reports the malformed section
                overrides[key] = {**section, field: True}
    for key in ("colorspace", "white_balance", "flat_field", "chart_model"):
        if getattr(args, key, None) is not None:
            overrides[key] = getattr(args, key)
    if getattr(args, "chart", None) is not None:
        try:
            overrides["chart"] = [float(v) for v in args.chart.split(",")]
        except ValueError:
            raise ValueError(
                f"--chart: expected 8 comma-separated numbers x0,y0,...,x3,y3, got {args.chart!r}"
            ) from None
    cfg = load_config(CalibrateConfig, args.config, **overrides)
    return CalibrateJob(
        config=cfg,
        inputs=tuple(args.inputs),
        out=args.out,
        overwrite=args.overwrite,
        progress=not args.quiet,
    )


def _calibrate_run(args) -> int:
    from jaxgfx.pipelines.calibrate import run_calibrate

    job = calibrate_job(args)
    report = run_calibrate(job)  # "replaced ..." is printed by run_command
    print(f"outputs in {os.path.abspath(job.out)}:")
    for name, p in report["outputs"].items():
        print(f"  {name:14s} {p}")
    if "errors_vs_ground_truth" in report:
        e = report["errors_vs_ground_truth"][job.config.response.method]
        print(
            f"curve error {e['curve_rmse_ln']:.4f} (RMSE ln-exposure), radiance error "
            f"{e['radiance_median_abs_ln']:.4f} (median |ln E - ln E_true|)"
        )
    return 0


# ----------------------------------------------------------------------------- render


def _render_arguments(p):
    p.add_argument("scene", help="scene YAML file")
    p.add_argument(
        "output",
        help="output image: .exr/.hdr/.tif hold linear radiance (a .png preview is written "
        "beside it), .png/.jpg the sRGB display image",
    )
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--integrator", default="path", help="path | direct | whitted | aov | ptracer")
    p.add_argument(
        "--max-depth",
        type=int,
        default=None,
        help="path length, Mitsuba's convention (path, whitted: default 3; direct: 2)",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--preview", default=None, help="preview .png path, or 'none' (default: OUT's stem.png)"
    )
    p.add_argument("--accel", default="auto", help="mesh traversal: auto | embree | warp | jax")


def _render_run(args) -> int:
    from jaxgfx.pipelines.render import RenderJob, run_render

    job = RenderJob(
        scene=args.scene,
        output=args.output,
        spp=args.spp,
        integrator=args.integrator,
        max_depth=args.max_depth,
        seed=args.seed,
        preview=args.preview,
        overwrite=args.overwrite,
        accel=args.accel,
    )
    try:
        res = run_render(job)
    except ValueError as e:  # the library names its argument `spp`; the user typed `--spp`
        if str(e).startswith("spp:"):
            raise ValueError(f"--{e}") from None
        raise
    print(
        f"wrote {' and '.join(res['outputs'].values())} (render {res['seconds']:.3g} s, "
        f"{_rate(res['samples_per_second'])} samples/s; compile {res['compile_seconds']:.3g} s)"
    )
    return 0


def _rate(per_second: float) -> str:
    """``1.23 M`` / ``45.6 k`` / ``789``: three significant digits at any speed."""
    for scale, unit in ((1e9, " G"), (1e6, " M"), (1e3, " k")):
        if per_second >= scale:
            return f"{per_second / scale:.3g}{unit}"
    return f"{per_second:.3g}"


# ----------------------------------------------------------------------------- tonemap


# every name in jaxgfx.tonemap.TONEMAP_PARAMETERS (kept here so --help needs no jax import;
# tests/tonemap/test_pipeline_tonemap.py checks the two agree)
TONEMAP_CLI_PARAMS = (
    "alpha beta bias color_adapt contrast epsilon exposure gamma intensity k key ld_max "
    "light_adapt phi saturation shoulder sigma sigma_range strength white"
).split()


def _tonemap_arguments(p):
    p.add_argument("input", nargs="?", help="linear HDR image (.exr or .hdr)")
    p.add_argument(
        "output", nargs="?", help="display image, sRGB: .png/.jpg 8-bit, .tif 16-bit integer"
    )
    p.add_argument("--op", default="drago", help="operator name (see --list)")
    p.add_argument("--list", action="store_true", help="list operators and their parameters")
    for name in TONEMAP_CLI_PARAMS:
        p.add_argument(f"--{name.replace('_', '-')}", type=float, default=None, dest=name)


def _tonemap_run(args) -> int:
    from jaxgfx.pipelines.tonemap import TonemapJob, operator_help, run_tonemap

    if args.list:
        print("\n".join(operator_help()))
        return 0
    if not args.input or not args.output:
        raise _UsageError("INPUT and OUTPUT are required")
    params = {k: getattr(args, k) for k in TONEMAP_CLI_PARAMS if getattr(args, k) is not None}
    job = TonemapJob(args.input, args.output, args.op, params, overwrite=args.overwrite)
    res = run_tonemap(job)
    neg = res["negative_clamped"]
    note = f"; clamped {neg} negative values to 0" if neg else ""
    print(
        f"wrote {res['outputs']['output']} ({args.op}, {res['seconds']:.2f} s incl. compile{note})"
    )
    return 0


# ----------------------------------------------------------------------------- fuse

# jaxgfx.pipelines.fuse.FUSE_PARAMETERS (kept here so --help needs no jax import;
# tests/tonemap/test_pipeline_fuse.py checks the two agree)
FUSE_CLI_PARAMS = ("contrast_weight", "saturation_weight", "exposedness_weight", "sigma")


def _fuse_arguments(p):
    p.add_argument(
        "paths",
        nargs="+",
        metavar="PATH",
        help="LDR frames of a bracket (PNG/JPEG/TIFF files or a directory), then OUTPUT "
        "(.png/.jpg 8-bit, .tif 16-bit)",
    )
    for name in FUSE_CLI_PARAMS:
        p.add_argument(f"--{name.replace('_', '-')}", type=float, default=None, dest=name)


def _fuse_run(args) -> int:
    from jaxgfx.pipelines.fuse import FuseJob, run_fuse

    if len(args.paths) < 2:
        raise _UsageError("expected input frames (or a directory) followed by OUTPUT")
    params = {k: getattr(args, k) for k in FUSE_CLI_PARAMS if getattr(args, k) is not None}
    job = FuseJob(tuple(args.paths[:-1]), args.paths[-1], params, overwrite=args.overwrite)
    res = run_fuse(job)
    print(
        f"wrote {res['outputs']['output']} (exposure fusion of {len(res['inputs'])} frames, "
        f"{res['seconds']:.2f} s incl. compile)"
    )
    return 0


# ----------------------------------------------------------------------------- fit
def _fit_arguments(p):
    p.add_argument("config", help="YAML config (configs/inverse_material.yaml, docs/inverse.md)")
    p.add_argument("--out", default="out/fit", help="output directory")
    p.add_argument("--steps", type=int, default=None, help="override optimizer.steps")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def fit_job(args):
    """``argparse`` namespace of ``jaxgfx fit`` → :class:`~jaxgfx.pipelines.fit.FitJob`."""
    from jaxgfx.config import load_config, read_yaml
    from jaxgfx.pipelines.fit import FitConfig, FitJob

    data = read_yaml(args.config)
    if args.steps is not None:
        data["optimizer"] = {**(data.get("optimizer") or {}), "steps": args.steps}
    if args.quiet:
        data["progress"] = False
    return FitJob(
        config=load_config(FitConfig, data),
        out=args.out,
        overwrite=args.overwrite,
        base_dir=os.path.dirname(os.path.abspath(args.config)),
    )


def _fit_run(args) -> int:
    from jaxgfx.pipelines.fit import enable_compilation_cache, run_fit

    job = fit_job(args)
    enable_compilation_cache()
    out = run_fit(job)
    for k, v in out["params"].items():
        err = out.get("errors", {}).get(k)
        extra = f"  (truth {out['truth'][k]}, max error {err:.4g})" if err is not None else ""
        print(f"{k} = {v}{extra}")
    if out["camera"]:
        print(f"camera = {out['camera']}")
    print(
        f"loss {out['loss'][0]:.4g} -> {out['loss'][-1]:.4g} in {out['n_steps']} steps, "
        f"{out['seconds']:.1f} s (+{out['compile_seconds']:.1f} s compile); "
        f"outputs in {os.path.abspath(job.out)}"
    )
    return 0


COMMANDS: dict[str, Command] = {
    "filter": Command(
        "apply an image operation to a file",
        "Apply one jaxgfx image operation to an image file. Display-referred files "
        "(PNG/JPEG/TIFF) are processed as floats in [0, 1]; EXR/HDR as linear radiance.",
        _filter_arguments,
        _filter_run,
    ),
    "calibrate": Command(
        "fit a camera response from bracketed exposures and merge an HDR radiance map",
        "Calibrate a camera from a bracketed stack (RAW or JPEG/PNG/TIFF files, or "
        "a directory of them); with no inputs, runs on the embedded synthetic stack.",
        _calibrate_arguments,
        _calibrate_run,
    ),
    "render": Command(
        "render a scene description (YAML) to EXR + PNG",
        "Render a scene (see docs/render.md) with the Monte Carlo renderer.",
        _render_arguments,
        _render_run,
    ),
    "tonemap": Command(
        "tone map an HDR image (EXR/HDR) to a display PNG",
        "Tone map linear radiance for display with a jaxgfx.tonemap operator "
        "(docs/tonemap.md); every continuous parameter is an option.",
        _tonemap_arguments,
        _tonemap_run,
    ),
    "fuse": Command(
        "fuse an LDR exposure bracket into one display image (Mertens et al. 2007)",
        "Exposure fusion of an LDR bracket with jaxgfx.hdr.exposure_fusion "
        "(docs/tonemap.md): no exposure times, response curve or tone mapping needed.",
        _fuse_arguments,
        _fuse_run,
    ),
    "fit": Command(
        "fit scene (and camera) parameters to a target image (inverse rendering)",
        "Fit material / light / texture parameters of a scene, and for 8-bit targets the "
        "camera response and exposure, to a target image (see docs/inverse.md).",
        _fit_arguments,
        _fit_run,
    ),
}


# ----------------------------------------------------------------------------- driver


class _UsageError(Exception):
    """A usage error found after parsing (exit status 2)."""


class _LineEndTracker:
    """``sys.stderr`` during a command: remembers whether the last character written ended a
    line (progress bars end theirs with ``\\r``), so the final message starts a line of its
    own. Everything else is delegated to the real stream."""

    def __init__(self, stream):
        self._stream = stream
        self.at_line_start = True

    def write(self, text):
        if text:
            self.at_line_start = text.endswith("\n")
        return self._stream.write(text)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _common_options() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--overwrite",
        action="store_true",
        help="replace existing results at the output path(s) (default: refuse)",
    )
    common.add_argument("--debug", action="store_true", help="show the full traceback of an error")
    return common


def add_command_arguments(parser: argparse.ArgumentParser, name: str) -> None:
    """Declare subcommand ``name``'s options (and ``--overwrite``/``--debug``) on ``parser``
    (used by ``experiments/*.py`` to offer the same options)."""
    COMMANDS[name].add_arguments(parser)
    for action in _common_options()._actions:
        parser._add_action(action)
    parser.set_defaults(func=COMMANDS[name].run, command=name)


def build_parser() -> argparse.ArgumentParser:
    from jaxgfx import __version__

    parser = argparse.ArgumentParser(
        prog="jaxgfx", description="Differentiable image processing, HDR and rendering in JAX."
    )
    parser.add_argument("--version", action="version", version=f"jaxgfx {__version__}")
    parser.add_argument(
        "--debug", dest="debug_all", action="store_true", help="show tracebacks of errors"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    common = _common_options()
    for name, cmd in COMMANDS.items():
        p = sub.add_parser(name, help=cmd.help, description=cmd.description, parents=[common])
        cmd.add_arguments(p)
        p.set_defaults(func=cmd.run)
    return parser


def format_error(e: BaseException) -> str:
    """One line for an exception: OS errors as ``'path': reason``, others as their message
    (exceptions that are not user errors are prefixed with their type)."""
    if isinstance(e, OSError) and e.filename is not None:
        msg = e.strerror or str(e)
        return f"{msg}: '{os.fspath(e.filename)}'"
    if isinstance(e, (ValueError, TypeError, OSError, _UsageError)):
        text = str(e)
    elif type(e).__name__ in ("JaxRuntimeError", "XlaRuntimeError", "EquinoxRuntimeError"):
        text = _runtime_message(str(e))
    else:
        text = f"{type(e).__name__}: {e}"
    text = " ".join(text.split()) or type(e).__name__
    return text


def _runtime_message(text: str) -> str:
    """The message of an ``eqx.error_if`` check inside a compiled program (the last line of
    the callback traceback that names it), else the first line."""
    for line in text.splitlines():
        if "EquinoxRuntimeError:" in line:
            return line.split("EquinoxRuntimeError:", 1)[1].strip()
    return text.strip().splitlines()[0] if text.strip() else "runtime error"


def run_command(args: argparse.Namespace) -> int:
    """Run a parsed command; every failure becomes one line on stderr and a nonzero status
    (1; 2 for usage errors; 130 for Ctrl-C; 128 + N for SIGTERM / SIGHUP, which remove the
    staging like any failure). With ``--debug`` the traceback is shown. Outputs replaced under
    ``--overwrite`` are named on stdout (one line per stage, by :mod:`jaxgfx.pipelines._output`)."""
    from jaxgfx.pipelines._output import Terminated, cleanup_on_signals, report_replacements

    real_stderr = sys.stderr
    err = sys.stderr = _LineEndTracker(real_stderr)

    def say(message):
        if not err.at_line_start:  # a progress bar's last line: end it first
            print(file=err)
        print(f"jaxgfx {args.command}: {message}", file=err)

    try:
        with cleanup_on_signals(), report_replacements(print):
            return int(args.func(args) or 0)
    except KeyboardInterrupt:
        say("interrupted")
        return 130
    except Terminated as e:
        say(f"terminated ({e})")
        return 128 + e.signum
    except Exception as e:  # noqa: BLE001 - the CLI boundary: one line per failure
        debug = getattr(args, "debug", False) or getattr(args, "debug_all", False)
        if debug:
            import traceback

            if not err.at_line_start:
                print(file=err)
            traceback.print_exc(file=err)
        status = 2 if isinstance(e, _UsageError) else 1
        expected = isinstance(e, (ValueError, TypeError, OSError, _UsageError))
        hint = "" if debug or expected else " (rerun with --debug for the traceback)"
        say(f"error: {format_error(e)}{hint}")
        return status
    finally:
        if sys.stderr is err:
            sys.stderr = real_stderr


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from jaxgfx._jaxcache import enable_compilation_cache  # persistent compile cache (calib)

    enable_compilation_cache()
    return run_command(args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
