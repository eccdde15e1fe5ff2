"""Mutation check: every curated mutant of a core function must be caught by its tests.

Usage (from the repository root; ``make mutate`` runs the first form):

    python tools/mutate.py                      # all mutants, fail if any survives
    python tools/mutate.py --only delta_e       # mutants whose name contains a substring
    python tools/mutate.py --list               # print the list and exit
    python tools/mutate.py --check              # only check that every patch still applies
    python tools/mutate.py --json out/mutate.json

Each mutant in ``tools/mutants.py`` is an explicit patch (file, exact old text, new text) and
the pytest node ids that must catch it. The working tree is never touched: the tracked and
untracked-but-not-ignored files are copied once to a temporary directory, each mutant is
applied there, its tests run with ``-x -q`` under a timeout, and the file is restored.

A mutant counts as *killed* only when pytest reports a failing test (exit status 1). A
mutant whose old text is missing or ambiguous (the code moved: update the list), a collection
error, a timeout or a passing run all fail the check. Before the mutants, a baseline run of
the union of their tests on the unmutated copy must pass (else every mutant would look
killed).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))

from mutants import MUTANTS  # noqa: E402

_NOT_COPIED = (".git", ".venv", "out", ".pytest_cache", "__pycache__", ".ruff_cache")


def _copy_tree(dst: Path) -> None:
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT,
            check=True,
            capture_output=True,
        ).stdout.decode()
    except (OSError, subprocess.CalledProcessError):  # not a git checkout (e.g. a tarball)
        shutil.copytree(ROOT, dst, dirs_exist_ok=True, ignore=shutil.ignore_patterns(*_NOT_COPIED))
        return
    for rel in filter(None, out.split("\0")):
        src = ROOT / rel
        if not src.is_file():  # deleted in the working tree
            continue
        (dst / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, dst / rel)


def _pytest(tree: Path, node_ids, timeout: float):
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    env.setdefault("JAX_PLATFORMS", "cpu")
    # the named tests run whatever their markers (pyproject's addopts deselect `slow`; the
    # last -m wins)
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider"]
    cmd += ["-m", "slow or not slow", *node_ids]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return "timeout", time.perf_counter() - t0, ""
    lines = (p.stdout + p.stderr).strip().splitlines()
    # the failing assertion (how far the mutant landed outside the tolerance), else the tail
    evidence = [ln[1:].strip() for ln in lines if ln.startswith("E ") and ln[1:].strip()]
    tail = "\n".join(evidence[:8] if p.returncode == 1 and evidence else lines[-3:])
    return p.returncode, time.perf_counter() - t0, tail


def _check_list(mutants) -> list[str]:
    errors = []
    names = set()
    for m in mutants:
        name = m["name"]
        if name in names:
            errors.append(f"{name}: duplicate name")
        names.add(name)
        if not (ROOT / m["file"]).is_file():
            errors.append(f"{name}: no file {m['file']}")
            continue
        text = (ROOT / m["file"]).read_text()
        n = text.count(m["old"])
        if n != 1:
            errors.append(f"{name}: old text found {n} times in {m['file']} (expected once)")
        if m["old"] == m["new"]:
            errors.append(f"{name}: new text equals old text")
        for t in m["tests"]:
            if not (ROOT / t.split("::")[0]).is_file():
                errors.append(f"{name}: no test file {t.split('::')[0]}")
    return errors


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="run mutants whose name contains this")
    ap.add_argument("--list", action="store_true", help="print the mutants and exit")
    ap.add_argument(
        "--check", action="store_true", help="only check that every patch applies, then exit"
    )
    ap.add_argument("--timeout", type=float, default=300.0, help="seconds per pytest run")
    ap.add_argument("--json", default=None, help="also write the summary to this file")
    ap.add_argument("--no-baseline", action="store_true", help="skip the unmutated run")
    ap.add_argument("-v", "--verbose", action="store_true", help="print each failed assertion")
    args = ap.parse_args(argv)

    mutants = [m for m in MUTANTS if args.only in m["name"]]
    if args.list:
        for m in mutants:
            print(f"{m['name']:45s} {m['file']}  ->  {' '.join(m['tests'])}")
        return 0
    errors = _check_list(mutants)
    if errors:
        print("mutant list is stale:\n  " + "\n  ".join(errors), file=sys.stderr)
        return 2
    if args.check:
        print(f"{len(mutants)} mutants apply cleanly")
        return 0

    t_start = time.perf_counter()
    results = []
    with tempfile.TemporaryDirectory(prefix="jaxgfx-mutate-") as tmp:
        tree = Path(tmp)
        _copy_tree(tree)
        where = subprocess.run(
            [sys.executable, "-c", "import jaxgfx; print(jaxgfx.__file__)"],
            cwd=tree,
            env={**os.environ, "PYTHONPATH": str(tree)},
            capture_output=True,
            text=True,
        ).stdout.strip()
        if not where.startswith(str(tree)):
            print(f"the copy's jaxgfx is not the one imported ({where!r})", file=sys.stderr)
            return 2
        if not args.no_baseline:
            union = list(dict.fromkeys(t for m in mutants for t in m["tests"]))
            rc, dt, tail = _pytest(tree, union, 3 * args.timeout)
            print(f"baseline ({len(union)} selections): rc={rc} in {dt:.1f} s", flush=True)
            if rc != 0:
                print(f"baseline failed: the unmutated tests must pass\n{tail}", file=sys.stderr)
                return 2
        for m in mutants:
            path = tree / m["file"]
            orig = path.read_text()
            path.write_text(orig.replace(m["old"], m["new"], 1))
            try:
                rc, dt, tail = _pytest(tree, m["tests"], args.timeout)
            finally:
                path.write_text(orig)
            status = "killed" if rc == 1 else ("survived" if rc == 0 else f"error({rc})")
            results.append(
                {
                    "name": m["name"],
                    "file": m["file"],
                    "status": status,
                    "seconds": round(dt, 1),
                    "tests": m["tests"],
                    "why": m["why"],
                    "evidence": tail,
                }
            )
            print(f"{status:10s} {dt:6.1f} s  {m['name']}", flush=True)
            if status != "killed" or args.verbose:
                print("    " + tail.replace("\n", "\n    "), flush=True)
    total = time.perf_counter() - t_start
    bad = [r for r in results if r["status"] != "killed"]
    summary = {
        "mutants": len(results),
        "killed": len(results) - len(bad),
        "not_killed": [r["name"] for r in bad],
        "seconds": round(total, 1),
        "results": results,
    }
    print(json.dumps({k: v for k, v in summary.items() if k != "results"}))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(summary, indent=1))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
