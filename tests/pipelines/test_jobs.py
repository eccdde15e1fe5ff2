"""Jobs live in jaxgfx/pipelines (issue 9, part 3): cli.py and experiments/*.py are thin
argument -> job layers; one exposure-time parser and one place that orders a bracket."""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import pkgutil

import numpy as np

import jaxgfx.pipelines.calibrate as calibrate_mod
import jaxgfx.pipelines.render as render_mod
from jaxgfx import io
from jaxgfx.cli import COMMANDS, add_command_arguments, build_parser


def _read(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


def _imports(path):
    tree = ast.parse(_read(path))
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
    return names


def test_demo_does_not_call_the_cli():
    assert "jaxgfx.cli" not in _imports("experiments/demo.py")
    assert {"jaxgfx.pipelines.render", "jaxgfx.pipelines.calibrate"} <= _imports(
        "experiments/demo.py"
    )


def _options(parser):
    return {s for a in parser._actions for s in a.option_strings} - {"-h", "--help"}


def test_experiment_offers_exactly_the_cli_options():
    cli = build_parser()._subparsers._group_actions[0].choices["calibrate"]
    p = argparse.ArgumentParser()
    add_command_arguments(p, "calibrate")
    assert _options(p) == _options(cli) and "--overwrite" in _options(p)
    assert "add_argument" not in _read("experiments/calibrate.py")


def test_pipelines_hold_no_parser_or_sort_of_their_own():
    calibrate_modules = [
        importlib.import_module(f"{calibrate_mod.__name__}.{m.name}")
        for m in pkgutil.iter_modules(calibrate_mod.__path__)
    ]
    for mod in (calibrate_mod, *calibrate_modules, render_mod):
        src = inspect.getsource(mod)
        assert "argparse" not in src and "Namespace" not in src
        assert "argsort" not in src and "Fraction" not in src and "eval_fraction" not in src
    assert set(COMMANDS) >= {"filter", "calibrate", "render"}


def test_the_one_parser_and_sorter():
    assert [io.parse_exposure_time(t) for t in ("1/250", "0.5", 2)] == [0.004, 0.5, 2.0]
    t = np.array([4.0, 1.0, 4.0, 0.5])
    order = io.exposure_order(t)
    np.testing.assert_array_equal(order, [3, 1, 0, 2])  # stable for equal times
    np.testing.assert_array_equal(t[order], np.sort(t))


def test_filter_defaults_are_the_library_functions_defaults():
    """One source of truth (issue 21: the CLI's Canny sigma was 1.5 where the function's is
    1.0): every default a library function defines is the CLI's default, checked through the
    output (the CLI's canny equals image.canny with no arguments) and for every op."""
    import inspect

    import numpy as np

    from jaxgfx import color, image
    from jaxgfx.pipelines.filter_ops import FILTER_OPS, apply_filter

    rng = np.random.default_rng(0)
    img = np.zeros((24, 24, 3), np.float32)
    img[:, 12:] = 1.0
    img += 0.05 * rng.standard_normal(img.shape).astype(np.float32)
    np.testing.assert_array_equal(
        np.asarray(apply_filter(img, "canny")), np.asarray(image.canny(img), np.float32)
    )
    checked = 0
    for name, op in FILTER_OPS.items():
        if op.source is None:
            continue
        mod, fn = op.source.split(".")
        sig = inspect.signature(getattr(image if mod == "image" else color, fn))
        for k in op.params:
            if k not in sig.parameters:
                continue
            d = sig.parameters[k].default
            if d is not inspect.Parameter.empty and d is not None:
                assert op.defaults[k] == d, (name, k)
                checked += 1
    assert checked >= 3


def test_every_run_takes_one_job():
    """Every ``jaxgfx.pipelines`` entry point ``run_*`` takes one argument, a ``*Job``
    dataclass (issue 21: ``run_image_demo(out_dir, *, size)`` was the exception)."""
    import dataclasses
    import typing

    import jaxgfx.pipelines as P

    runs = {}
    for m in pkgutil.walk_packages(P.__path__, P.__name__ + "."):
        mod = importlib.import_module(m.name)
        for name, fn in vars(mod).items():
            if name.startswith("run_") and inspect.isfunction(fn) and fn.__module__ == m.name:
                runs[name] = fn
    assert {"run_calibrate", "run_fit", "run_render", "run_image_demo"} <= set(runs)
    for name, fn in runs.items():
        assert list(inspect.signature(fn).parameters) == ["job"], name
        job = typing.get_type_hints(fn)["job"]
        assert dataclasses.is_dataclass(job) and job.__name__.endswith("Job"), name


def test_image_demo_job(tmp_path):
    import pytest

    from jaxgfx.pipelines.image_demo import ImageDemoJob, run_image_demo

    with pytest.raises(TypeError, match="job: expected an ImageDemoJob"):
        run_image_demo(str(tmp_path))
    with pytest.raises(ValueError, match="size: expected a positive integer"):
        run_image_demo(ImageDemoJob(str(tmp_path), size=0))
