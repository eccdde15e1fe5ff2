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
    """JAX's persistent compilation cache in tests: off unless asked for.

    ``JAXGFX_TEST_COMPILATION_CACHE=PATH`` shares one cache directory between the xdist workers
    (kept); ``=new`` makes a fresh one for the run (removed at its end). It is off by default:
    with jax/jaxlib 0.10.2 an xdist worker of the slow suite died of a segmentation fault inside
    ``executable.serialize()`` (the cache write) twice, in CI (2026-12-01) and on a developer
    machine (2026-12-04, ``test_several_passes_per_step_keep_every_sample`` after ~150 other
    tests in that worker; the same test passes alone), and under ``--dist loadfile`` the run then
    hung until CI's limit. The cache saved about 4 % of the default suite's CPU time (within the
    noise, docs/testing.md).
    """
    env = os.environ.get(_CACHE_ENV, "off")
    if env.lower() == "new" and not hasattr(config, "workerinput"):
        env = tempfile.mkdtemp(prefix="jaxgfx-test-jaxcache-")
        os.environ[_CACHE_ENV] = env  # the workers inherit it
        config._jaxgfx_cache_to_remove = env
    if env and env.lower() not in ("off", "0", "none", "false", "new"):
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
