"""Central finite differences vs automatic differentiation (common random numbers)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["check_grads_fd"]


def check_grads_fd(f, x, *, eps: float = 1e-3, rtol: float = 1e-2, atol: float = 1e-6):
    """Compare ``jax.grad(f)(x)`` with central differences ``(f(x + ε e_k) - f(x - ε e_k)) / 2ε``.

    ``f`` maps an array ``x`` to a scalar; for a Monte Carlo estimator, fix its key inside ``f``
    (common random numbers) so both differences see the same samples. ``x`` should be small
    (one difference pair per element). Returns ``(passed, grad_ad, grad_fd)`` with
    ``passed = allclose(grad_ad, grad_fd, rtol, atol)`` (NumPy arrays, shape of ``x``).

    Example: ``check_grads_fd(lambda x: jnp.sum(x**2), jnp.array([1., 2.]))[0]`` is True.
    """
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        raise TypeError(f"x: expected a floating array, got {x.dtype}")
    if eps <= 0:
        raise ValueError(f"eps: expected > 0, got {eps}")
    g_ad = np.asarray(jax.grad(f)(x), dtype=np.float64)
    flat = x.reshape(-1)
    g_fd = np.zeros(flat.shape, np.float64)
    for i in range(flat.size):
        e = jnp.zeros_like(flat).at[i].set(eps).reshape(x.shape)
        g_fd[i] = (float(f(x + e)) - float(f(x - e))) / (2.0 * eps)
    g_fd = g_fd.reshape(x.shape)
    ok = bool(np.all(np.isfinite(g_ad))) and bool(np.allclose(g_ad, g_fd, rtol=rtol, atol=atol))
    return ok, g_ad, g_fd
