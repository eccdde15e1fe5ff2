"""Gradient tools for Monte Carlo renders: diagnostics and decorrelated primal/adjoint keys.

* :func:`grad_stats`: per-parameter mean, standard error and SNR of a stochastic gradient over
  ``n`` independent keys, its bias against central finite differences of the *same* loss with
  the *same* keys (common random numbers), and a work-normalised variance (variance × seconds
  per gradient) to compare estimators at equal cost.
* :func:`decorrelated`: wraps ``fn(params, key)`` so that its value uses ``key`` and its
  reverse-mode derivative an independent key. For a loss that is non-linear in the image (an L2
  loss) a gradient computed with the primal's own samples is biased: ``E[(I - T) ∂I] ≠
  (E[I] - T) E[∂I]`` when ``I`` and ``∂I`` share samples (Nimier-David et al. 2020 §4,
  Azinović et al. 2019). With independent keys the product of expectations is estimated without
  bias.

See docs/render_gradients.md.
"""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["GradStats", "grad_stats", "decorrelated"]


class GradStats(NamedTuple):
    """Result of :func:`grad_stats`; every field but ``seconds`` is a pytree like ``params``.

    ``mean``, ``stderr`` (standard error of the mean over the keys), ``snr`` (``|mean| /
    std`` of ONE gradient sample), ``variance`` (of one gradient sample), ``seconds`` (wall
    time per gradient, after compilation), ``work_variance`` (``variance × seconds``: lower is a
    better estimator at equal cost), ``fd_mean`` / ``fd_stderr`` (central finite differences of
    the loss with the same keys; ``None`` unless ``fd_step`` is given), ``bias`` / ``bias_stderr``
    (paired ``gradient - FD`` over the keys: its mean and standard error; ``None`` without FD).
    """

    mean: Any
    stderr: Any
    snr: Any
    variance: Any
    seconds: float
    work_variance: Any
    fd_mean: Any = None
    fd_stderr: Any = None
    bias: Any = None
    bias_stderr: Any = None


def _stats(samples):
    s = np.asarray(samples, np.float64)
    n = s.shape[0]
    mean = s.mean(0)
    var = s.var(0, ddof=1) if n > 1 else np.full_like(mean, np.nan)
    return mean, var, np.sqrt(var / n)


def grad_stats(loss, params, key, n: int, *, fd_step=None, mode: str = "reverse") -> GradStats:
    """Statistics of the stochastic gradient of ``loss(params, key) -> scalar`` over ``n`` keys.

    ``params``: pytree of float arrays (the differentiated point); ``key``: a JAX PRNG key, split
    into ``n >= 2`` independent keys; ``mode``: ``"reverse"`` (``jax.grad``) or ``"forward"``
    (``jax.jvp`` per parameter element; for few parameters). ``fd_step``: if given, also central
    differences ``(loss(p + h e_i, k) - loss(p - h e_i, k)) / 2h`` per parameter element with the
    same key ``k`` (common random numbers), and the paired bias ``gradient - FD``. The finite
    differences of a Monte Carlo estimator with common random numbers estimate the derivative
    of its *expectation* without the boundary terms AD can miss, so a bias several standard
    errors from 0 means the gradient estimator is biased (or ``fd_step`` too large).

    Host-side driver (not jittable); ``loss`` is jitted once per mode.

    Example::

        st = grad_stats(lambda a, k: render(scene.replace("materials.metal.alpha", a), k,
                                            spp=16).mean(), jnp.float32(0.2), key, 8,
                        fd_step=0.01)
        st.mean, st.stderr, st.bias, st.bias_stderr
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 2:
        raise ValueError(f"n: expected an integer >= 2, got {n!r}")
    if mode not in ("reverse", "forward"):
        raise ValueError(f"mode: expected 'reverse' or 'forward', got {mode!r}")
    if fd_step is not None and not (float(fd_step) > 0):
        raise ValueError(f"fd_step: expected a positive number, got {fd_step!r}")
    leaves, treedef = jax.tree_util.tree_flatten(params)
    leaves = [jnp.asarray(x) for x in leaves]
    flat0 = jnp.concatenate([x.ravel() for x in leaves]) if leaves else jnp.zeros((0,))
    sizes = [x.size for x in leaves]
    offsets = np.cumsum([0] + sizes)

    def unflatten(flat):
        parts = [
            flat[offsets[i] : offsets[i + 1]].reshape(x.shape).astype(x.dtype)
            for i, x in enumerate(leaves)
        ]
        return jax.tree_util.tree_unflatten(treedef, parts)

    def flat_loss(flat, k):
        return loss(unflatten(flat), k)

    if mode == "reverse":
        gfun = jax.jit(jax.grad(flat_loss))
    else:
        eye = jnp.eye(flat0.size, dtype=flat0.dtype)

        @jax.jit
        def gfun(flat, k):
            return jax.vmap(lambda t: jax.jvp(lambda p: flat_loss(p, k), (flat,), (t,))[1])(eye)

    keys = jax.random.split(key, n)
    jax.block_until_ready(gfun(flat0, keys[0]))  # compile
    t0 = time.perf_counter()
    grads = [np.asarray(jax.block_until_ready(gfun(flat0, k))) for k in keys]
    seconds = (time.perf_counter() - t0) / n
    gmean, gvar, gse = _stats(grads)
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = np.abs(gmean) / np.sqrt(gvar)
    out = dict(
        mean=gmean,
        stderr=gse,
        snr=snr,
        variance=gvar,
        seconds=seconds,
        work_variance=gvar * seconds,
    )
    if fd_step is not None:
        h = jnp.asarray(fd_step, flat0.dtype)
        lj = jax.jit(flat_loss)
        eye = np.eye(flat0.size, dtype=np.asarray(flat0).dtype)
        fds = []
        for k in keys:
            row = [
                (float(lj(flat0 + h * e, k)) - float(lj(flat0 - h * e, k))) / (2 * float(h))
                for e in eye
            ]
            fds.append(row)
        fds = np.asarray(fds)
        fmean, _, fse = _stats(fds)
        bmean, _, bse = _stats(np.asarray(grads, np.float64) - fds)
        out.update(fd_mean=fmean, fd_stderr=fse, bias=bmean, bias_stderr=bse)

    def tree(v):
        if v is None or np.isscalar(v) or np.ndim(v) == 0 and not sizes:
            return v
        v = np.asarray(v)
        return jax.tree_util.tree_unflatten(
            treedef,
            [v[offsets[i] : offsets[i + 1]].reshape(x.shape) for i, x in enumerate(leaves)],
        )

    return GradStats(**{k: (v if k == "seconds" else tree(v)) for k, v in out.items()})


def decorrelated(fn, *, salt: int = 0x5EED):
    """``fn(params, key)`` whose reverse-mode derivative uses an independent key.

    The value is ``fn(params, key)``; the vector-Jacobian product is that of
    ``fn(params, fold_in(key, salt))``. Use it for losses that are non-linear in a Monte Carlo
    estimate (e.g. ``mean((render(...) - target)²)``): the gradient ``2 (I - T) ∂I`` is then an
    unbiased estimate of the gradient of ``(E[I] - T)²``, while correlated samples add the
    covariance ``2 Cov(I, ∂I)``. Cost: the backward pass re-runs the forward pass with the second
    key (one extra forward). Reverse mode only (a ``jax.custom_vjp``).

    Example::

        img = decorrelated(lambda s, k: render(s, k, spp=4))
        jax.grad(lambda s: jnp.mean((img(s, key) - target) ** 2))(scene)
    """

    @jax.custom_vjp
    def wrapped(params, key):
        return fn(params, key)

    def fwd(params, key):
        return fn(params, key), (params, key)

    def bwd(res, ct):
        params, key = res
        _, vjp = jax.vjp(lambda p: fn(p, jax.random.fold_in(key, salt)), params)
        (g,) = vjp(ct)
        return g, None

    wrapped.defvjp(fwd, bwd)
    return wrapped
