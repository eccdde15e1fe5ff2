"""Wall-clock timing shared by the benchmarks (``python -m benchmarks.NAME``).

Every call's result is waited for with ``jax.block_until_ready`` (a no-op on NumPy arrays and
other non-JAX results), so asynchronous dispatch is not mistaken for speed. Steady-state times
are medians over repeats, after a first call that compiles. The machine may be shared: compare
ratios measured in one run, not absolute times.
"""

from __future__ import annotations

import time

import jax
import numpy as np

__all__ = ["median_time", "first_and_median", "interleaved_times", "time_jax", "time_np"]


def median_time(fn, repeats: int) -> float:
    """Median wall seconds of ``repeats`` calls ``fn()``."""
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts))


def first_and_median(fn, repeats: int) -> tuple[float, float]:
    """``(first_s, median_s)``: the first call ``fn()`` (compilation, caches) and the median of
    ``repeats`` calls after it."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    first = time.perf_counter() - t0
    return first, median_time(fn, repeats)


def interleaved_times(fns: dict, repeats: int) -> dict:
    """``{name: (first_s, median_s)}`` for zero-argument callables ``fns``: one first call each,
    then ``repeats`` rounds that call every function once in turn, so a change of the machine's
    load during the run affects all of them alike (use it for ratios on a shared machine)."""
    first, ts = {}, {name: [] for name in fns}
    for name, fn in fns.items():
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        first[name] = time.perf_counter() - t0
    for _ in range(repeats):
        for name, fn in fns.items():
            t0 = time.perf_counter()
            jax.block_until_ready(fn())
            ts[name].append(time.perf_counter() - t0)
    return {name: (first[name], float(np.median(ts[name]))) for name in fns}


def time_jax(f, *args, repeats: int = 5) -> tuple[float, float]:
    """``(compile_s, run_s)`` of ``jax.jit(f)(*args)``: lower + compile time, then the median
    steady-state time of the compiled program (after one warm-up call)."""
    t0 = time.perf_counter()
    compiled = jax.jit(f).lower(*args).compile()
    compile_s = time.perf_counter() - t0
    jax.block_until_ready(compiled(*args))  # warm-up
    return compile_s, median_time(lambda: compiled(*args), repeats)


def time_np(f, repeats: int = 5, max_repeats_s: float = 20.0) -> float:
    """Median seconds of a host (NumPy / OpenCV / scikit-image) call ``f()``; a single call's
    time when ``repeats`` of them would take longer than ``max_repeats_s``."""
    t0 = time.perf_counter()
    jax.block_until_ready(f())
    first = time.perf_counter() - t0
    if first * repeats > max_repeats_s:
        return first
    return median_time(f, repeats)
