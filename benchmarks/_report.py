"""What every benchmark prints: the machine it ran on and one JSON document.

``machine()`` is the same block in every benchmark's output (platform, CPU count, load average,
JAX version, backend and device, plus any peer versions passed in), so runs of different
benchmarks can be compared and a loaded machine is visible in the result itself. Call it before
measuring: its load average is then the other load the run started under, not the run's own.
``emit`` prints the document on stdout and, when ``out`` is given, writes it there too.
"""

from __future__ import annotations

import json
import os
import platform

import jax
import numpy as np

__all__ = ["machine", "emit"]


def machine(**peers) -> dict:
    """The machine block: platform, processor, CPUs, 1/5/15-min load average (None where the OS
    has none), JAX version, backend, device kind and count; ``peers`` adds the versions or
    settings of the libraries compared against (``opencv=cv2.__version__``, ...)."""
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "load_avg": None if load is None else [round(x, 2) for x in load],
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "device": jax.devices()[0].device_kind,
        "device_count": jax.device_count(),
        **peers,
    }


def _plain(obj):
    """JSON fallback for NumPy / JAX scalars and arrays (``json.dumps(default=...)``)."""
    if isinstance(obj, np.generic) or hasattr(obj, "__array__"):
        return np.asarray(obj).tolist()
    raise TypeError(f"{type(obj).__name__} is not JSON serializable")


def _dumps(doc) -> str:
    return json.dumps(doc, indent=1, default=_plain)


def emit(doc, out: str | None = None, *, printed=None) -> str:
    """Print ``printed`` (default ``doc``) as indented JSON and write ``doc`` to ``out`` when
    given (``printed`` lets a benchmark keep long curves out of the terminal but in the file).
    NumPy / JAX scalars and arrays become numbers and lists. Returns the printed text."""
    text = _dumps(doc if printed is None else printed)
    print(text, flush=True)
    if out:
        with open(out, "w", encoding="utf-8") as fh:
            fh.write((text if printed is None else _dumps(doc)) + "\n")
    return text
