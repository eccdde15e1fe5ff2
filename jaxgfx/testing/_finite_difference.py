"""Automatic differentiation against central finite differences (common random numbers): the
one home of the AD-vs-FD checks. :func:`check_grads_fd` (element by element, a fixed key),
:func:`check_grads_jit` (float64, a random direction, jitted), :func:`ad_fd_per_key` (AD and
same-key central differences for each of a batch of keys, vmapped: the raw pairs) and
:func:`grad_stats` (a Monte Carlo gradient over ``n`` keys: mean, standard error, SNR,
work-normalised variance, and its bias against same-key finite differences;
docs/render_gradients.md)."""

from __future__ import annotations

import time
from typing import Any, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["check_grads_fd", "check_grads_jit", "ad_fd_per_key", "grad_stats", "GradStats"]


def check_grads_fd(
    f, x, *, eps: float = 1e-3, rtol: float = 1e-2, atol: float = 1e-6, jit: bool = False
):
    """Compare ``jax.grad(f)(x)`` with central differences ``(f(x + ε e_k) - f(x - ε e_k)) / 2ε``.

    ``f`` maps an array ``x`` to a scalar; for a Monte Carlo estimator, fix its key inside ``f``
    (common random numbers) so both differences see the same samples. ``x`` should be small
    (one difference pair per element). Returns ``(passed, grad_ad, grad_fd)`` with
    ``passed = allclose(grad_ad, grad_fd, rtol, atol)`` (NumPy arrays, shape of ``x``).
    ``jit``: compile ``f`` and its gradient once (two programs) instead of running them op by
    op (a renderer costs seconds per eager evaluation).

    Example: ``check_grads_fd(lambda x: jnp.sum(x**2), jnp.array([1., 2.]))[0]`` is True.
    """
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        raise TypeError(f"x: expected a floating array, got {x.dtype}")
    if eps <= 0:
        raise ValueError(f"eps: expected > 0, got {eps}")
    grad = jax.jit(jax.grad(f)) if jit else jax.grad(f)
    f = jax.jit(f) if jit else f
    g_ad = np.asarray(grad(x), dtype=np.float64)
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
    # the output shape without running f eagerly (op by op: seconds for a BSDF)
    u = jnp.asarray(rng.standard_normal(jax.eval_shape(f, *args).shape))
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


@eqx.filter_jit
def _values_and_grads(loss, x, keys, args):
    """Per key: ``loss(x, key, *args)`` and its reverse-mode gradient w.r.t. ``x``."""
    vg = jax.value_and_grad(lambda x, k: loss(x, k, *args))
    return jax.vmap(lambda k: vg(x, k))(keys)


@eqx.filter_jit
def _values(loss, xs, keys, args):
    """``loss`` at every row of ``xs`` for every key, ``(N, K)``: forward evaluations only."""
    per_key = jax.vmap(lambda x, k: loss(x, k, *args), in_axes=(None, 0))
    return jax.lax.map(lambda x: per_key(x, keys), xs)


def ad_fd_per_key(loss, x, keys, h: float, *, args=()):
    """For each key: ``loss(x, key, *args)``, its reverse-mode gradient w.r.t. ``x`` and its
    central differences ``(loss(x + h e_i, key) - loss(x - h e_i, key)) / step_i`` with the same
    key (common random numbers; ``step_i`` is the step actually taken in ``x``'s dtype).

    Returns NumPy float64 ``(values (K,), ad (K, *x.shape), fd (K, *x.shape))``; the paired
    ``ad - fd`` over the keys estimates the gradient estimator's bias (see :func:`grad_stats`
    for the statistics). Two compiled programs: value and gradient vmapped over the keys, and
    the ``2 x.size`` perturbed forward evaluations (a ``lax.map`` over the perturbations of a
    vmap over the keys; a forward render costs about a third of a value-and-gradient).
    Compiled once per ``loss`` and structure of ``args`` (``eqx.filter_jit``: arrays in
    ``args`` are traced, everything else is static), so pass the scene in ``args`` and keep
    ``loss`` a module-level function to reuse the programs across calls.

    Example: ``ad_fd_per_key(lambda x, k: jnp.sum(x**2) * jax.random.uniform(k), jnp.ones(2),
    jax.random.split(jax.random.key(0), 4), 1e-3)``.
    """
    x = jnp.asarray(x)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        raise TypeError(f"x: expected a floating array, got {x.dtype}")
    if not float(h) > 0:
        raise ValueError(f"h: expected a positive number, got {h!r}")
    args = tuple(args)
    vals, grads = _values_and_grads(loss, x, keys, args)
    n = x.size
    flat = np.asarray(x).reshape(-1)
    e = np.asarray(h, flat.dtype) * np.eye(n, dtype=flat.dtype)
    xs = np.concatenate([flat + e, flat - e])  # (2n, n): +h rows, then -h rows
    step = np.diagonal(xs[:n] - xs[n:]).astype(np.float64)
    v = np.asarray(_values(loss, jnp.asarray(xs.reshape(2 * n, *x.shape)), keys, args), np.float64)
    fd = ((v[:n] - v[n:]) / step[:, None]).T  # (K, n)
    k = fd.shape[0]
    return (
        np.asarray(vals, np.float64),
        np.asarray(grads, np.float64).reshape(k, *x.shape),
        fd.reshape(k, *x.shape),
    )


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
