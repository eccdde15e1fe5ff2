"""Every fenced ``python`` block of README.md and docs/*.md runs, as written (issue 28).

Each block runs in a fresh namespace with a temporary working directory in which ``configs/``
and ``docs/`` of the repository are visible (so ``configs/scenes/example.yaml`` resolves as it
does from the repository root, and files a block writes stay out of the checkout). A block
in doctest form (``>>>`` prompts) runs through :mod:`doctest`, so its shown output is checked;
a plain block states the results it shows with ``assert``. docs/architecture.md is not checked
(being rewritten by the lead).

The README's command lines (``bash`` blocks) are checked without running them: each
``jaxgfx ...`` line parses with the CLI's own parser, every ``--op`` it names is in that
subcommand's ``--list`` and every other option is a parameter of that op; each
``python -m experiments.X ...`` line's options parse with that script's parser; every
``experiments.X`` / ``benchmarks.X`` module and ``make`` target the README names exists.
"""

from __future__ import annotations

import argparse
import contextlib
import doctest
import importlib
import importlib.util
import io
import re
import shlex
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOC_FILES = [ROOT / "README.md"] + sorted(
    p for p in (ROOT / "docs").glob("*.md") if p.name != "architecture.md"
)
_FENCE = re.compile(r"^([ \t]*)```([\w-]*)\s*$")

# Blocks too slow for the default run (all in `make test-slow`), by (file, a text only that
# block contains), with the cost of the block measured on the shared 2-core machine (load
# average 7-8) from a cold compilation cache; nearly all of it is XLA compiling the renderer
# and its gradient. The default run keeps README.md's library block (8 s; 24 s at that load:
# blur, its gradient, a synthetic stack, Debevec, merge) and docs/tonemap.md's (3 s; 8 s).
# The README block, docs/render.md's first block and docs/render_gradients.md's first block make
# the same calls (example scene, 64-spp path render at depth 3, gradient of the mean w.r.t. the
# metal's alpha at 4 spp), so one worker compiles those programs once (2026-12-05: the three
# blocks 82 s of process CPU in one process, against 141 s when they used 16 / 64 / 16 spp;
# measured side by side at load 7-11).
SLOW = {
    ("README.md", "R.load_scene("): "120 s: path tracer at 64 spp and its gradient",
    ("docs/render.md", "img = render(scene, jax.random.key(0), spp=64"): "54 s: path + grad",
    # the same path program as the block above: 3 s after it in one process
    ("docs/render.md", "PathIntegrator(max_depth=3"): "two 64-spp path renders",
    # 64 / 4 spp since 2026-12-05: 41 s of process CPU against 50 s at 256 / 16 spp (load ~6)
    ("docs/render.md", "render_sharded"): "132 s: sharded render and its gradient",
    # eager scene building: ~40 tiny XLA compilations (rectangle, projector, spot) at load 12
    ("docs/render.md", 'load_scene("projector.yaml")'): "6 s: load_scene + one jitted sample",
    ("docs/render_backends.md", "build_traversal"): "64 s: mesh scene, three backends",
    ("docs/render_gradients.md", "grad_stats"): "104 s: 8 gradient estimates + FD",
    ("docs/render_gradients.md", 'visibility="edge"'): "182 s: edge-sampled gradient",
    ("docs/render_gradients.md", 'adjoint="replay")   #'): "25 s: a 64-spp path gradient by replay",
    ("docs/inverse.md", "fit(loss"): "106 s: 100 Adam steps through the renderer",
    # 128 spp since 2026-12-05: 68 s of process CPU against 111 s at 512 spp (one process,
    # load ~9); was 260 s of wall at load 7-8 and 127 s in the last slow run at 512 spp
    ("docs/inverse.md", "fit_least_squares(residuals"): "68 s CPU: LM through a 128-spp render",
}


def extract_blocks(text: str):
    """``(language, line, code)`` of every fenced block of a markdown text (``line``: 1-based
    line of the opening fence; a fence indented inside a list item is dedented)."""
    lines = text.splitlines()
    out, i = [], 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if not m or not m.group(2):
            i += 1
            continue
        j = i + 1
        while j < len(lines) and not re.match(r"^[ \t]*```\s*$", lines[j]):
            j += 1
        if j == len(lines):
            raise ValueError(f"line {i + 1}: unclosed ``` fence")
        out.append((m.group(2), i + 1, textwrap.dedent("\n".join(lines[i + 1 : j])) + "\n"))
        i = j + 1
    return out


def run_block(code: str, name: str) -> None:
    """Run one python block in a fresh namespace; a doctest-form block must print what it
    shows (AssertionError with doctest's report otherwise)."""
    if re.search(r"^\s*>>> ", code, re.M):
        test = doctest.DocTestParser().get_doctest(
            code, {"__name__": "__docblock__"}, name, name, 0
        )
        runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
        report = io.StringIO()
        runner.run(test, out=report.write)
        if runner.failures:
            raise AssertionError(f"{name}: doctest output differs\n{report.getvalue()}")
    else:
        exec(compile(code, name, "exec"), {"__name__": "__docblock__"})  # noqa: S102


def _python_blocks():
    params = []
    slow_hits = dict.fromkeys(SLOW, 0)
    for path in DOC_FILES:
        rel = path.relative_to(ROOT).as_posix()
        for lang, line, code in extract_blocks(path.read_text()):
            if lang != "python":
                continue
            hits = [k for k in SLOW if k[0] == rel and k[1] in code]
            for k in hits:
                slow_hits[k] += 1
            marks = [pytest.mark.slow] if hits else []
            params.append(pytest.param(rel, line, code, id=f"{rel}:{line}", marks=marks))
    return params, slow_hits


BLOCKS, _SLOW_HITS = _python_blocks()


@pytest.fixture
def docs_cwd(tmp_path, monkeypatch):
    for name in ("configs", "docs"):
        (tmp_path / name).symlink_to(ROOT / name, target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.parametrize(("rel", "line", "code"), BLOCKS)
def test_python_block_runs(rel, line, code, docs_cwd):
    run_block(code, f"{rel}:{line}")


def test_every_slow_entry_names_exactly_one_block():
    assert {k: n for k, n in _SLOW_HITS.items() if n != 1} == {}


def test_the_readme_library_block_is_in_the_default_run():
    fast = [p for p in BLOCKS if p.values[0] == "README.md" and not p.marks]
    assert len(fast) == 1 and "hdr.recover_response(images" in fast[0].values[2]


# ------------------------------------------------------------------ the harness itself


def test_extract_finds_indented_fences_and_languages():
    md = "x\n```python\na = 1\n```\n\n* item\n\n  ```python\n  b = 2\n  ```\n```bash\nls\n```\n"
    assert extract_blocks(md) == [
        ("python", 2, "a = 1\n"),
        ("python", 8, "b = 2\n"),
        ("bash", 11, "ls\n"),
    ]
    with pytest.raises(ValueError, match="line 1: unclosed"):
        extract_blocks("```python\na = 1\n")


def test_run_block_reports_wrong_doctest_output_and_errors():
    run_block(">>> 1 + 1\n2\n", "ok")
    with pytest.raises(AssertionError, match=r"bad: doctest output differs(.|\n)*Expected:\s+3"):
        run_block(">>> 1 + 1\n3\n", "bad")
    with pytest.raises(NameError, match="images"):
        run_block("resp = images.mean()\n", "undefined")
    with pytest.raises(AssertionError):
        run_block("assert 1 + 1 == 3\n", "assert")


def test_blocks_run_in_fresh_namespaces(docs_cwd):
    run_block("leak = 1\n", "first")
    with pytest.raises(NameError, match="leak"):
        run_block("leak\n", "second")
    run_block("with open('out.txt', 'w') as f:\n    f.write('x')\n", "writes")
    assert (docs_cwd / "out.txt").read_text() == "x"
    assert not (ROOT / "out.txt").exists()


# ------------------------------------------------------------------ the README's commands


def _readme_command_lines():
    lines = []
    for lang, _, code in extract_blocks((ROOT / "README.md").read_text()):
        if lang == "bash":
            for ln in code.splitlines():
                argv = shlex.split(ln, comments=True)
                if argv:
                    lines.append(argv)
    return lines


_COMMANDS = _readme_command_lines()


def _list_output(sub: str) -> dict[str, str]:
    """``op -> its parameter text`` from ``jaxgfx SUB --list``."""
    from jaxgfx.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main([sub, "--list"]) == 0
    return {ln.split()[0]: ln for ln in buf.getvalue().splitlines() if ln.strip()}


def test_readme_names_the_commands_it_checks():
    heads = {a[0] if a[0] != "python" else a[2].split(".")[0] for a in _COMMANDS}
    assert heads == {"make", "jaxgfx", "experiments"}
    assert sum(a[0] == "jaxgfx" for a in _COMMANDS) >= 8


def test_readme_make_targets_exist():
    makefile = (ROOT / "Makefile").read_text()
    text = (ROOT / "README.md").read_text()
    targets = {a[1] for a in _COMMANDS if a[0] == "make"} | set(
        re.findall(r"`make ([\w-]+)`", text)
    )
    assert {"demo", "test", "test-slow", "mutate", "test-mitsuba"} <= targets
    missing = [t for t in targets if not re.search(rf"^{re.escape(t)}:", makefile, re.M)]
    assert missing == []


@pytest.mark.parametrize("argv", [a for a in _COMMANDS if a[0] == "jaxgfx"], ids=" ".join)
def test_readme_jaxgfx_line_parses(argv):
    from jaxgfx.cli import build_parser

    args = build_parser().parse_args(argv[1:])  # SystemExit(2) on an unknown option
    assert args.command == argv[1]
    if getattr(args, "op", None) is None or "--op" not in argv:
        return
    ops = _list_output(argv[1])
    assert args.op in ops
    params = ops[args.op].split("params:")[-1] if argv[1] == "filter" else ops[args.op]
    flags = [a[2:].replace("-", "_") for a in argv if a.startswith("--")]
    for f in flags:
        if f not in ("op", "overwrite", "debug", "list"):
            assert re.search(rf"\b{f}\b", params), (args.op, f, params)


def test_readme_tonemap_ops_of_calibrate_exist():
    ops = _list_output("tonemap")
    lists = [a[a.index("--tonemap") + 1] for a in _COMMANDS if "--tonemap" in a]
    assert lists and all(op in ops for x in lists for op in x.split(","))


class _Parsed(Exception):
    pass


@pytest.mark.parametrize("argv", [a for a in _COMMANDS if a[0] == "python"], ids=" ".join)
def test_readme_experiment_line_parses(argv, monkeypatch):
    assert argv[1] == "-m"
    mod = importlib.import_module(argv[2])
    real = argparse.ArgumentParser.parse_args

    def parse_and_stop(self, args=None, namespace=None):
        raise _Parsed(real(self, args, namespace))

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", parse_and_stop)
    with pytest.raises(_Parsed):  # parsed, then stopped before the experiment runs
        mod.main(argv[3:])


def test_readme_named_modules_exist():
    text = (ROOT / "README.md").read_text()
    names = set(re.findall(r"\b((?:benchmarks|experiments)\.[a-z_]+)\b", text))
    assert len([n for n in names if n.startswith("benchmarks.")]) >= 15
    missing = [n for n in sorted(names) if importlib.util.find_spec(n) is None]
    assert missing == []
    subs = set(re.findall(r"`jaxgfx ([a-z]+)", text))
    from jaxgfx.cli import COMMANDS

    assert subs and subs <= set(COMMANDS)
