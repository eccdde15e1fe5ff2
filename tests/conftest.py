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
