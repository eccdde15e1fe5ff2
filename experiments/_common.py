"""Helpers shared by the experiment scripts (not part of the jaxgfx library)."""

from __future__ import annotations

import json
import sys


def log(*a) -> None:
    """Progress and partial results on stderr (stdout carries the JSON result)."""
    print(*a, file=sys.stderr, flush=True)


def emit_json(out, path: str | None = None) -> str:
    """Print ``out`` as indented JSON on stdout and, when ``path`` is given, write it there."""
    text = json.dumps(out, indent=1)
    print(text)
    if path:
        with open(path, "w", encoding="utf-8") as f:
            f.write(text)
    return text
