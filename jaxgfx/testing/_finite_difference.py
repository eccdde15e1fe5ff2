"""Central finite differences vs automatic differentiation (common random numbers)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["check_grads_fd", "check_grads_jit"]


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


def check_grads_jit(f, args, order=1, *, eps=1e-6, rtol=1e-6, seed=0):
    """Float64 reverse-mode gradient vs central finite differences along a random direction
    (what ``jax.test_util.check_grads(f, args, order, modes=["rev"])`` checks, with every
    evaluation jitted: the eager version costs seconds of tracing per call on CPU)."""
    args = tuple(jnp.asarray(a, jnp.float64) for a in args)
    rng = np.random.default_rng(seed)
    u = jnp.asarray(rng.standard_normal(jnp.shape(f(*args))))
    dirs = [jnp.asarray(rng.standard_normal(a.shape)) for a in args]
    scalar = jax.jit(lambda *a: jnp.vdot(u, f(*a)))
    grads = jax.jit(jax.grad(scalar, argnums=tuple(range(len(args)))))(*args)
    plus = scalar(*(a + eps * d for a, d in zip(args, dirs, strict=True)))
    minus = scalar(*(a - eps * d for a, d in zip(args, dirs, strict=True)))
    fd = (plus - minus) / (2 * eps)
    ad = sum(jnp.vdot(g, d) for g, d in zip(grads, dirs, strict=True))
    np.testing.assert_allclose(float(ad), float(fd), rtol=rtol, atol=rtol)
    if order == 2:
        w = jnp.asarray(rng.standard_normal(len(args)))
        grad_fn = jax.grad(scalar, argnums=tuple(range(len(args))))
        check_grads_jit(
            lambda *a: (
                jnp.stack([jnp.vdot(g, d) for g, d in zip(grad_fn(*a), dirs, strict=True)]) * w
            ),
            args,
            1,
            eps=eps,
            rtol=rtol,
            seed=seed + 1,
        )
