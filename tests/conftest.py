"""Test configuration: float32 by default (the library default); tests that need float64
turn it on locally with the ``x64`` fixture, which restores the previous setting."""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")
# the CLI turns on JAX's persistent compilation cache (jaxgfx/_jaxcache.py); not in tests
os.environ.setdefault("JAXGFX_CACHE_DIR", "off")

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture
def x64():
    """Enable float64 for the duration of one test."""
    prev = jax.config.jax_enable_x64
    jax.config.update("jax_enable_x64", True)
    try:
        yield
    finally:
        jax.config.update("jax_enable_x64", prev)


@pytest.fixture
def rng():
    """A fixed NumPy generator for reproducible random test inputs."""
    return np.random.default_rng(0)


@pytest.fixture
def key():
    """A fixed JAX PRNG key."""
    return jax.random.key(0)


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_programs():
    """Drop every compiled program after each test module (``jax.clear_caches``).

    XLA:CPU maps each compiled program's code into the process and keeps it while the jitted
    function lives; a worker that runs the slow suite's ~150 render tests accumulates tens of
    thousands of memory mappings (4.8 k after 47 BSDF / accel tests, measured) and reaches the
    kernel's ``vm.max_map_count`` (65530), after which LLVM's next code allocation fails and the
    worker dies of a segmentation fault inside ``backend_compile_and_load`` (CI 2026-12-01, and
    twice on 2026-12-04, each time after ~150 tests in one worker; every crashing test passes
    alone). Modules do not share programs worth keeping: what a module jits, it recompiles."""
    yield
    jax.clear_caches()
