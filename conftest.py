"""Root pytest configuration, shared by the tests and the doctests of ``jaxgfx/``.

Doctests (``--doctest-modules``, see pyproject.toml) see ``np``, ``jnp`` and ``jax`` without
importing them and run on the CPU in float32 (as the library defaults) with NumPy's current
array printing (whatever a test-only import such as colour-science set); a module whose
optional dependency is missing is skipped (``--doctest-ignore-import-errors``) rather than
failing the collection.
"""

import os
import shutil
import tempfile

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

_CACHE_ENV = "JAXGFX_TEST_COMPILATION_CACHE"


def pytest_configure(config):
    """One JAX persistent compilation cache per test run, shared by the xdist workers.

    Many tests jit a fresh lambda around the same computation (and the two workers compile
    the same filters, scenes and solvers): identical programs then load from the cache
    instead of compiling again. The directory is new for every run (made by the controller
    before the workers start, which inherit the environment, and removed at its end), so a
    run never sees programs from another version of the code. ``JAXGFX_TEST_COMPILATION_CACHE=off``
    turns it off; a path keeps the cache there (not removed).
    """
    env = os.environ.get(_CACHE_ENV)
    if env is None and not hasattr(config, "workerinput"):
        env = tempfile.mkdtemp(prefix="jaxgfx-test-jaxcache-")
        os.environ[_CACHE_ENV] = env
        config._jaxgfx_cache_to_remove = env
    if env and env.lower() not in ("off", "0", "none", "false"):
        jax.config.update("jax_compilation_cache_dir", env)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.05)
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def pytest_unconfigure(config):
    d = getattr(config, "_jaxgfx_cache_to_remove", None)
    if d is not None:
        shutil.rmtree(d, ignore_errors=True)


@pytest.fixture(autouse=True)
def _doctest_namespace(doctest_namespace):
    doctest_namespace.update(np=np, jnp=jnp, jax=jax)
    # colour-science switches NumPy to legacy="1.13" printing on import; examples show arrays
    # as current NumPy prints them
    with np.printoptions(legacy=False):
        yield
