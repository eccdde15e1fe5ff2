"""Shared helpers of the reliability suite: run the CLI in-process, snapshot folders, and the
outcome classes every case asserts (a clear error naming the argument, or a correct result)."""

from __future__ import annotations

import contextlib
import functools
import io
import os
import sys

from jaxgfx.cli import main


def run_cli(argv) -> tuple[int, str, str]:
    """``jaxgfx ARGV`` in this process: ``(status, stdout, stderr)`` (argparse exits too)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([os.fspath(a) for a in argv])
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else 1
    return code, out.getvalue(), err.getvalue()


def snapshot(folder) -> dict:
    """Every path under ``folder`` with its size and content hash (files) — to assert that a
    failed run changed nothing."""
    import hashlib

    snap = {}
    for root, dirs, files in os.walk(folder):
        for d in dirs:
            snap[os.path.relpath(os.path.join(root, d), folder) + "/"] = None
        for f in files:
            p = os.path.join(root, f)
            with open(p, "rb") as fh:
                snap[os.path.relpath(p, folder)] = hashlib.sha1(fh.read()).hexdigest()
    return snap


def assert_one_line_error(code, err, *needles, status=1):
    """The CLI failed with ``status``, printed exactly one line ``jaxgfx CMD: error: ...``
    containing every needle, and no traceback."""
    assert code == status, f"exit status {code}, expected {status}; stderr: {err!r}"
    lines = [ln for ln in err.splitlines() if ln.strip()]
    # argparse usage errors print the usage line(s) first; the error is the last line
    last = lines[-1] if lines else ""
    assert "Traceback" not in err, err
    if status == 1:
        assert len(lines) == 1, f"expected one line on stderr, got {lines}"
        assert last.startswith("jaxgfx ") and ": error: " in last, last
    for n in needles:
        assert n in last, f"{n!r} not in {last!r}"


def no_partial_files(folder) -> bool:
    return not any(".partial" in name for _, _, files in os.walk(folder) for name in files) and (
        not any(".partial" in d for _, dirs, _ in os.walk(folder) for d in dirs)
    )


def python_exe() -> str:
    return sys.executable


@functools.cache
def read_only_sys() -> bool:
    """True when ``/sys`` refuses new files (sysfs; even for root): the read-only target."""
    import tempfile

    try:
        fd, name = tempfile.mkstemp(dir="/sys")
    except OSError:
        return True
    os.close(fd)
    os.unlink(name)
    return False
