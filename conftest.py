"""Root pytest configuration, shared by the tests and the doctests of ``jaxgfx/``.

Doctests (``--doctest-modules``, see pyproject.toml) see ``np``, ``jnp`` and ``jax`` without
importing them and run on the CPU in float32 (as the library defaults) with NumPy's current
array printing (whatever a test-only import such as colour-science set); a module whose
optional dependency is missing is skipped (``--doctest-ignore-import-errors``) rather than
failing the collection.
"""

import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture(autouse=True)
def _doctest_namespace(doctest_namespace):
    doctest_namespace.update(np=np, jnp=jnp, jax=jax)
    # colour-science switches NumPy to legacy="1.13" printing on import; examples show arrays
    # as current NumPy prints them
    with np.printoptions(legacy=False):
        yield
