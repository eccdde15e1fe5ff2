"""Optimisation loops: :func:`fit` (first-order, optax) and :func:`fit_least_squares`
(Levenberg–Marquardt / Gauss–Newton, optimistix).

Both take a pytree of parameters (dict, tuple, ``eqx.Module`` of float arrays), optional
bounds (see :mod:`jaxgfx.optim.transforms`) and return a :class:`FitResult` whose ``params`` has
the same pytree structure as the input.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from .._checks import check_choice
from ._transforms import _map, check_bounds, from_unconstrained, to_unconstrained

__all__ = [
    "fit",
    "fit_least_squares",
    "least_squares_solve",
    "LeastSquaresSolution",
    "FitResult",
    "OPTIMIZERS",
    "LEAST_SQUARES_SOLVERS",
    "FAST_COMPILE_OPTIONS",
    "compile_step",
    "CompiledStep",
]

FAST_COMPILE_OPTIONS: dict[str, bool | int] = {
    "xla_cpu_use_fusion_emitters": False,
    "xla_backend_optimization_level": 1,
    "xla_llvm_disable_expensive_passes": True,
}
"""XLA CPU compile options for :func:`fit`'s ``compiler_options`` (fit config
``optimizer.fast_compile: true``): measured on the ``configs/inverse_material.yaml`` step
(``python -m benchmarks.render_compile``, docs/performance.md "Compile time, second pass"):
1.6-2.2x less XLA compile time (process CPU), the same step time, images equal within
float32 rounding. Not the default: on the textured and mesh fits (``configs/multiview*.yaml``)
the fitted values move by more than float32 rounding (docs/performance.md, "The cold
jaxgfx fit, phase by phase")."""

OPTIMIZERS: dict[str, Callable[..., optax.GradientTransformation]] = {
    "adam": optax.adam,
    "adamw": optax.adamw,
    "sgd": optax.sgd,
    "rmsprop": optax.rmsprop,
    "adabelief": optax.adabelief,
}
"""First-order optimisers by name: ``fn(learning_rate, **options) -> optax transformation``."""


def _lm(rtol, atol):
    return optx.LevenbergMarquardt(rtol=rtol, atol=atol)


def _gn(rtol, atol):
    return optx.GaussNewton(rtol=rtol, atol=atol)


def _dogleg(rtol, atol):
    return optx.Dogleg(rtol=rtol, atol=atol)


LEAST_SQUARES_SOLVERS: dict[str, Callable[[float, float], Any]] = {
    "lm": _lm,
    "gauss_newton": _gn,
    "dogleg": _dogleg,
}
"""Least-squares solvers by name (optimistix): ``fn(rtol, atol) -> optx solver``."""


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Outcome of :func:`fit` / :func:`fit_least_squares`.

    * ``params``: the fitted parameters (same pytree as the input, JAX arrays).
    * ``loss``: ``(n_steps,)`` NumPy array, ``loss[k]`` evaluated at ``history`` entry ``k``
      (for least squares: ``[initial, final]`` of ``0.5 · Σ r²``).
    * ``history``: the parameters per step, each leaf stacked ``(n_steps + 1, ...)`` (entry 0 =
      the initial values, entry ``k + 1`` = after ``k + 1`` updates); ``None`` when
      ``keep_history=False``. Least squares: ``[initial, final]``.
    * ``seconds``: ``(n_steps,)`` wall-clock seconds per step (after compilation).
    * ``compile_seconds``: time to trace and compile the step.
    * ``n_steps``, ``stop_reason`` (``"steps"``, ``"tol"``, ``"callback"``, ``"converged"``,
      ``"max_steps"``).
    * ``n_averaged``: how many iterates ``params`` is the mean of (:func:`fit`'s
      ``average_from``; 0: ``params`` is the last iterate).
    """

    params: Any
    loss: np.ndarray
    history: Any
    seconds: np.ndarray
    compile_seconds: float
    n_steps: int
    stop_reason: str
    n_averaged: int = 0

    @property
    def total_seconds(self) -> float:
        return float(self.compile_seconds + np.sum(self.seconds))


def _as_param_tree(params):
    leaves, treedef = jax.tree_util.tree_flatten(params)
    if not leaves:
        raise ValueError("params: expected a pytree with at least one array leaf")
    out = []
    for path, leaf in jax.tree_util.tree_flatten_with_path(params)[0]:
        name = "params" + jax.tree_util.keystr(path)
        if isinstance(leaf, (str, bytes)) or leaf is None or isinstance(leaf, bool):
            raise TypeError(f"{name}: expected a float array, got {type(leaf).__name__}")
        try:
            a = jnp.asarray(leaf)
        except (TypeError, ValueError) as e:
            raise TypeError(f"{name}: expected a float array ({e})") from None
        if not jnp.issubdtype(a.dtype, jnp.inexact):
            a = a.astype(jnp.result_type(float))
        out.append(a)
    return jax.tree_util.tree_unflatten(treedef, out)


def _check_compiler_options(opts):
    if opts is None:
        return
    if not isinstance(opts, dict):
        raise TypeError(f"compiler_options: expected a dict or None, got {type(opts).__name__}")
    for k, v in opts.items():
        if not isinstance(k, str) or not isinstance(v, (bool, int, float, str)):
            raise TypeError(
                f"compiler_options: expected option names (str) with bool / int / float / str "
                f"values, got {k!r}: {v!r}"
            )


def _check_nonneg_int(v, name, *, minimum=1):
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {v!r}")


def _call(loss, p, key, args):
    a = () if args is None else (args,)
    return loss(p, *a) if key is None else loss(p, key, *a)


@functools.lru_cache(maxsize=64)
def _named_optimizer(name, opts):
    return optax.inject_hyperparams(OPTIMIZERS[name])(learning_rate=1e-2, **dict(opts))


def _bound_spec(params, bounds):
    """Hashable (treedef, per-leaf Interval tuple) for the compiled step."""
    intervals = []
    _map(lambda b, p: intervals.append(b), params, bounds)
    return jax.tree_util.tree_structure(params), tuple(intervals)


def _unconstrained_to_params(u, spec):
    treedef, intervals = spec
    leaves = jax.tree_util.tree_leaves(u)
    return jax.tree_util.tree_unflatten(
        treedef, [b.forward(x) for b, x in zip(intervals, leaves, strict=True)]
    )


def _value(u, k, a, *, loss, tx, spec, use_key):
    del tx
    p = _unconstrained_to_params(u, spec)
    return _call(loss, p, k if use_key else None, a)


@functools.partial(jax.jit, static_argnames=("loss", "tx", "spec", "use_key"))
def _step(u, state, k, i, a, *, loss, tx, spec, use_key):
    ki = jax.random.fold_in(k, i)
    val, g = jax.value_and_grad(_value)(u, ki, a, loss=loss, tx=tx, spec=spec, use_key=use_key)
    gsq = sum(jnp.sum(jnp.abs(x) ** 2) for x in jax.tree_util.tree_leaves(g))
    updates, state = tx.update(g, state, u)
    u_new = optax.apply_updates(u, updates)
    return u_new, state, val, jnp.isfinite(gsq), _unconstrained_to_params(u_new, spec)



@dataclasses.dataclass(frozen=True)
class CompiledStep:
    """A compiled step of :func:`fit` (from :func:`compile_step`): the XLA executable, what
    it was compiled for (the loss, optimiser, bounds and key use, the compiler options, the
    shapes and dtypes of the parameters, optimiser state and ``args``) and ``compile_seconds``
    (trace + lower + XLA compile, wall)."""

    compiled: Any
    static: tuple
    in_types: Any
    compile_seconds: float


class _Setup(NamedTuple):
    params: Any
    u0: Any
    opt_state: Any
    step_key: Any
    schedule: Any
    lr_dtype: Any
    static: dict


def _setup(loss, params, optimizer, learning_rate, key, bounds, optimizer_options):
    """The checked inputs of the step: unconstrained start, optimiser state, static args."""
    if isinstance(optimizer, str):
        check_choice(optimizer, "optimizer", (*OPTIMIZERS, *LEAST_SQUARES_SOLVERS))
        opts = tuple(sorted((optimizer_options or {}).items()))
        try:
            hash(opts)
        except TypeError:
            raise TypeError(
                "optimizer_options: expected hashable values (numbers, strings)"
            ) from None
        tx = _named_optimizer(optimizer, opts)
    elif isinstance(optimizer, optax.GradientTransformation):
        tx = optimizer
    else:
        raise TypeError(
            f"optimizer: expected a name in {sorted(OPTIMIZERS)} or an optax "
            f"GradientTransformation, got {type(optimizer).__name__}"
        )
    params = _as_param_tree(params)
    check_bounds(params, bounds)
    if key is not None and not isinstance(key, jax.Array):
        raise TypeError(f"key: expected a JAX PRNG key, got {type(key).__name__}")

    spec = _bound_spec(params, bounds)
    u0 = to_unconstrained(params, bounds)
    opt_state = tx.init(u0)
    lr_dtype = None
    if isinstance(optimizer, str):
        # the learning rate lives in the optimiser state (optax.inject_hyperparams), so fits that
        # differ only in it share one compiled step
        lr0 = opt_state.hyperparams["learning_rate"]
        lr_dtype = lr0.dtype
        schedule = learning_rate if callable(learning_rate) else None
        opt_state.hyperparams["learning_rate"] = jnp.asarray(
            schedule(0) if schedule else learning_rate, lr_dtype
        )
    elif callable(learning_rate):
        raise TypeError("learning_rate: a schedule needs a named optimizer (optax: build it in)")
    else:
        schedule = None
    step_key = jax.random.key(0) if key is None else key
    static = dict(loss=loss, tx=tx, spec=spec, use_key=key is not None)
    return _Setup(params, u0, opt_state, step_key, schedule, lr_dtype, static)


def _types(tree):
    """Shapes, dtypes and weak types of a pytree's leaves (arrays or ShapeDtypeStructs)."""

    def one(x):
        a = x if isinstance(x, jax.ShapeDtypeStruct) else jax.typeof(x)
        return (tuple(a.shape), str(a.dtype), bool(getattr(a, "weak_type", False)))

    leaves, treedef = jax.tree_util.tree_flatten(tree)
    return treedef, tuple(one(x) for x in leaves)


def _signature(setup, compiler_options):
    st = setup.static
    return (st["loss"], st["tx"], st["spec"], st["use_key"],
            tuple(sorted((compiler_options or {}).items())))


def _compile(setup, args, compiler_options) -> CompiledStep:
    static = setup.static
    inputs = (setup.u0, setup.opt_state, setup.step_key, np.int32(0), args)
    t0 = time.perf_counter()
    try:
        lowered = _step.lower(*inputs, **static)
    except TypeError as e:  # a loss that does not return a scalar fails value_and_grad
        out_shape = jax.eval_shape(functools.partial(_value, **static), setup.u0,
                                   setup.step_key, args)
        if getattr(out_shape, "shape", None) != ():
            raise ValueError(f"loss: expected a scalar, got {out_shape}") from None
        raise TypeError(f"loss: could not be traced with these params ({e})") from e
    val = lowered.out_info[2]
    if val.shape != ():
        raise ValueError(f"loss: expected a scalar, got {val}")
    compiled = lowered.compile(compiler_options=compiler_options or None)
    return CompiledStep(compiled, _signature(setup, compiler_options), _types(inputs),
                        time.perf_counter() - t0)


def _check_step(step, setup, args, compiler_options):
    if not isinstance(step, CompiledStep):
        raise TypeError(f"step: expected a CompiledStep (compile_step), got {type(step).__name__}")
    names = ("loss", "optimizer / optimizer_options", "bounds", "key (None or not)",
             "compiler_options")
    for name, a, b in zip(names, step.static, _signature(setup, compiler_options), strict=True):
        if a is not b and a != b:
            raise ValueError(f"step: compiled for another {name} than this fit's")
    got = _types((setup.u0, setup.opt_state, setup.step_key, np.int32(0), args))
    if got != step.in_types:
        raise ValueError(
            "step: compiled for parameters / args of other shapes or dtypes than this fit's "
            f"({step.in_types[1]} against {got[1]})"
        )


def compile_step(
    loss: Callable,
    params,
    *,
    optimizer="adam",
    key=None,
    args=None,
    bounds=None,
    optimizer_options: dict | None = None,
    compiler_options: dict | None = None,
) -> CompiledStep:
    """Compile :func:`fit`'s step ahead of the fit (same arguments as :func:`fit`; the
    learning rate does not enter the program); pass the result as ``fit(..., step=...)``, e.g.
    to compile one loss under several ``compiler_options`` and time their steps
    (``benchmarks/fit_cold.py --warm-steps``). ``args`` may hold ``jax.ShapeDtypeStruct``
    leaves in place of arrays not made yet: the step is compiled for their shapes and dtypes.
    (Compiling it in a thread while the fit's target renders did not shorten a cold
    ``jaxgfx fit``: XLA's CPU compile holds the GIL, docs/performance.md.)"""
    if isinstance(optimizer, str) and optimizer in LEAST_SQUARES_SOLVERS:
        raise ValueError("optimizer: compile_step is for the first-order optimisers of fit")
    if not callable(loss):
        raise TypeError(f"loss: expected a callable, got {type(loss).__name__}")
    _check_compiler_options(compiler_options)
    setup = _setup(loss, params, optimizer, 1e-2, key, bounds, optimizer_options)
    return _compile(setup, args, compiler_options)


def fit(
    loss: Callable,
    params,
    *,
    optimizer="adam",
    steps: int,
    learning_rate: float | Callable[[int], float] = 1e-2,
    key=None,
    args=None,
    bounds=None,
    callback: Callable | None = None,
    progress: bool = True,
    tol: float | None = None,
    patience: int = 10,
    keep_history: bool = True,
    optimizer_options: dict | None = None,
    compiler_options: dict | None = None,
    average_from: int | None = None,
    step: CompiledStep | None = None,
) -> FitResult:
    """Minimise a scalar ``loss`` over ``params`` with a jitted first-order step.

    ``loss`` is called as ``loss(params)``; with a ``key`` as ``loss(params, key_k)`` where
    ``key_k = jax.random.fold_in(key, k)`` is a fresh key at step ``k`` (Monte Carlo losses);
    with ``args`` (large arrays such as target images, scenes: pass them here rather than closing
    over them, so they are not baked into the compiled program) it gets ``args`` as the last
    argument. It must return a scalar.

    ``optimizer``: a name in :data:`OPTIMIZERS` (built with ``learning_rate`` — a number, or a
    schedule ``step -> rate`` evaluated on the host and written into the optimiser state, so it
    does not recompile — and ``optimizer_options``), an ``optax.GradientTransformation``, or
    ``"lm"`` / ``"gauss_newton"`` / ``"dogleg"``: then ``loss`` is a *residual* function and the
    call is
    forwarded to :func:`fit_least_squares` with ``max_steps=steps``.
    ``bounds``: pytree prefix of ``params`` with ``None`` / ``(lo, hi)`` / ``Interval`` leaves;
    bounded parameters are optimised through smooth bijections (:mod:`.transforms`), so they
    never leave the open interval; values outside the bounds raise ``ValueError`` before any
    tracing, values on a bound start ``margin`` inside it.
    ``tol``: stop when ``|loss_k - loss_{k-patience}| <= tol · max(|loss_k|, |loss_{k-patience}|)``
    (relative change over ``patience`` steps; a loss that stays exactly 0 also stops).
    ``compiler_options``: XLA options for compiling the step (``jax.stages.Lowered.compile``;
    e.g. :data:`FAST_COMPILE_OPTIONS`); names XLA does not know raise its error.
    ``step``: the step compiled beforehand by :func:`compile_step` with the same ``loss``,
    ``optimizer``, ``optimizer_options``, ``key`` (``None`` or not), ``bounds``,
    ``compiler_options`` and parameters and ``args`` of the same shapes and dtypes (else
    ``ValueError``); ``compile_seconds`` is then its compile time.
    ``callback(step, params, loss)`` runs on the host after each step; returning ``True`` stops
    the loop. ``progress`` shows a tqdm bar.
    ``average_from``: Polyak–Ruppert iterate averaging (Polyak & Juditsky 1992; Ruppert 1988):
    the returned ``params`` is the mean of the iterates after updates ``average_from + 1, ...,
    n_steps`` (``history[average_from + 1:]``), taken in the optimiser's unconstrained
    variables and mapped through the bounds (``FitResult.n_averaged`` counts them; a loop that
    stops before step ``average_from`` returns its last iterate, ``n_averaged == 0``). With
    noisy (Monte Carlo) gradients the last iterate wanders in a noise ball around the optimum;
    the mean over a tail of ``m`` steps has ~``√(τ / m)`` of its spread (``τ``: the walk's
    correlation time in steps). ``None`` (default): the last iterate. It changes nothing in the
    compiled step or the history.

    A non-finite loss or gradient raises ``FloatingPointError`` naming the step (the parameters
    of the last finite step are in the message). A parameter that does not influence the loss
    has a zero gradient and stays where it started (Adam's update ``m / (√v + ε)`` is 0).

    Returns a :class:`FitResult`. Example: ``fit(lambda p: (p["x"] - 3.0) ** 2, {"x": 0.0},
    steps=500, learning_rate=0.1).params["x"]`` → ``≈ 3.0``.
    """
    if isinstance(optimizer, str) and optimizer in LEAST_SQUARES_SOLVERS:
        if key is not None:
            raise ValueError("key: least-squares solvers need a deterministic residual function")
        if average_from is not None:
            raise ValueError("average_from: a least-squares solver returns its solution, not "
                             "iterates to average")
        return fit_least_squares(
            loss, params, solver=optimizer, bounds=bounds, args=args, max_steps=steps
        )
    if not callable(loss):
        raise TypeError(f"loss: expected a callable, got {type(loss).__name__}")
    _check_nonneg_int(steps, "steps")
    _check_nonneg_int(patience, "patience")
    if tol is not None and not (isinstance(tol, (int, float)) and tol >= 0):
        raise ValueError(f"tol: expected a non-negative number or None, got {tol!r}")
    setup = _setup(loss, params, optimizer, learning_rate, key, bounds, optimizer_options)
    _check_compiler_options(compiler_options)
    if average_from is not None:
        _check_nonneg_int(average_from, "average_from", minimum=0)
        if average_from >= steps:
            raise ValueError(
                f"average_from: expected a step in 0..{steps - 1} (steps = {steps}), got "
                f"{average_from}"
            )
    u0, opt_state, step_key = setup.u0, setup.opt_state, setup.step_key
    schedule, lr_dtype, params = setup.schedule, setup.lr_dtype, setup.params
    if step is None:
        step = _compile(setup, args, compiler_options)
    else:
        _check_step(step, setup, args, compiler_options)
    compiled, compile_seconds = step.compiled, step.compile_seconds

    from tqdm.auto import tqdm

    bar = tqdm(total=steps, disable=not progress, desc="fit", unit="step", leave=False)
    losses, secs = [], []
    hist = [params] if keep_history else None
    u = u0
    reason = "steps"
    u_sum, n_avg = None, 0
    try:
        for i in range(steps):
            if schedule is not None and i > 0:
                opt_state.hyperparams["learning_rate"] = jnp.asarray(schedule(i), lr_dtype)
            t = time.perf_counter()
            u_new, opt_state, val, gfin, p = compiled(u, opt_state, step_key, np.int32(i), args)
            val = float(val)
            secs.append(time.perf_counter() - t)
            if not (np.isfinite(val) and bool(gfin)):
                last = jax.tree.map(lambda x: np.asarray(x).tolist(), from_unconstrained(u, bounds))
                what = "loss" if not np.isfinite(val) else "gradient"
                raise FloatingPointError(
                    f"fit: the {what} is not finite at step {i} (loss = {val}); "
                    f"parameters at that step: {last}"
                )
            u = u_new
            if average_from is not None and i >= average_from:  # u = history[i + 1]
                u_sum = u if u_sum is None else jax.tree.map(jnp.add, u_sum, u)
                n_avg += 1
            losses.append(val)
            if keep_history:
                hist.append(p)
            bar.update(1)
            if progress:
                bar.set_postfix(loss=f"{val:.4g}")
            if callback is not None and callback(i, p, val):
                reason = "callback"
                break
            if tol is not None and len(losses) > patience:
                ref = losses[-1 - patience]
                if abs(val - ref) <= tol * max(abs(val), abs(ref)):
                    reason = "tol"
                    break
    finally:
        bar.close()
    if n_avg:
        u = jax.tree.map(lambda s: s / n_avg, u_sum)
    final = from_unconstrained(u, bounds)
    history = None
    if keep_history:
        history = jax.tree.map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *hist)
    return FitResult(
        params=final,
        loss=np.asarray(losses, np.float64),
        history=history,
        seconds=np.asarray(secs, np.float64),
        compile_seconds=compile_seconds,
        n_steps=len(losses),
        stop_reason=reason,
        n_averaged=n_avg,
    )


class LeastSquaresSolution(NamedTuple):
    """Result of :func:`least_squares_solve`: the solution ``value`` (pytree like ``y0``),
    ``converged`` (bool array), ``num_steps`` and the solver's ``result`` code."""

    value: Any
    converged: Any
    num_steps: Any
    result: Any


def least_squares_solve(fn, y0, args=None, *, solver="lm", rtol=1e-8, atol=1e-8,
                        max_steps: int = 256) -> LeastSquaresSolution:  # fmt: skip
    """The traceable core of :func:`fit_least_squares`: ``min ½ Σ fn(y, args)²`` from ``y0`` by
    an optimistix least-squares solver (``solver``: a name of :data:`LEAST_SQUARES_SOLVERS` or a
    solver object), never raising on non-convergence (``converged`` says). Callable inside
    ``jit`` / ``vmap`` (the response fits of :mod:`jaxgfx.hdr` solve one curve per channel
    under ``vmap``); no bounds (write the parametrisation into ``fn``).
    """
    if isinstance(solver, str):
        check_choice(solver, "solver", tuple(LEAST_SQUARES_SOLVERS))
        solver = LEAST_SQUARES_SOLVERS[solver](rtol, atol)
    sol = optx.least_squares(fn, solver, y0, args=args, max_steps=max_steps, throw=False)
    return LeastSquaresSolution(
        sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"], sol.result
    )


def _ls_residuals(u, a, residuals, spec, has_args):
    p = _unconstrained_to_params(u, spec)
    return residuals(p, a) if has_args else residuals(p)


def _half_sq(r):
    return 0.5 * sum(jnp.sum(jnp.abs(x) ** 2) for x in jax.tree_util.tree_leaves(r))


@functools.partial(
    jax.jit, static_argnames=("residuals", "solver", "spec", "max_steps", "has_args")
)
def _solve_ls(u0, a, *, residuals, solver, spec, max_steps, has_args):
    def fn(u, a):
        return _ls_residuals(u, a, residuals, spec, has_args)

    sol = least_squares_solve(fn, u0, a, solver=solver, max_steps=max_steps)
    l0, l1 = _half_sq(fn(u0, a)), _half_sq(fn(sol.value, a))
    return sol.value, sol.result, sol.num_steps, l0, l1


def fit_least_squares(
    residuals: Callable,
    params,
    *,
    solver="lm",
    bounds=None,
    args=None,
    rtol: float | None = None,
    atol: float | None = None,
    max_steps: int = 256,
) -> FitResult:
    """Solve ``min ½ Σ r(params)²`` for a deterministic residual function (optimistix).

    ``residuals(params)`` (or ``residuals(params, args)``) returns an array or pytree of
    residuals. ``solver``: ``"lm"`` (Levenberg–Marquardt, default), ``"gauss_newton"``,
    ``"dogleg"`` (see :data:`LEAST_SQUARES_SOLVERS`) or an optimistix least-squares solver
    object. ``rtol``/``atol`` default to ``1e-8`` in float64 and ``1e-5`` in float32.
    Bounded parameters go through the same bijections as in :func:`fit` (the solution is then
    the least-squares optimum over the open box; an optimum on the boundary is approached, not
    reached). ``max_steps`` exceeded → ``stop_reason="max_steps"`` (not an error).
    The whole solve is one jitted program.

    References: Levenberg 1944; Marquardt 1963; Rader, Lyons & Kidger 2024 (optimistix).

    Example: fitting ``y = a·exp(b·t)`` to exact data recovers ``(a, b)`` to ``rtol``.
    """
    if not callable(residuals):
        raise TypeError(f"residuals: expected a callable, got {type(residuals).__name__}")
    _check_nonneg_int(max_steps, "max_steps")
    params = _as_param_tree(params)
    check_bounds(params, bounds)
    dt = jnp.result_type(*jax.tree_util.tree_leaves(params))
    small = jnp.finfo(dt).bits <= 32
    rtol = (1e-5 if small else 1e-8) if rtol is None else rtol
    atol = (1e-5 if small else 1e-8) if atol is None else atol
    if isinstance(solver, str):
        check_choice(solver, "solver", tuple(LEAST_SQUARES_SOLVERS))
        solver_obj = LEAST_SQUARES_SOLVERS[solver](rtol, atol)
    else:
        solver_obj = solver

    static = dict(
        residuals=residuals,
        solver=solver_obj,
        spec=_bound_spec(params, bounds),
        max_steps=max_steps,
        has_args=args is not None,
    )
    u0 = to_unconstrained(params, bounds)
    t0 = time.perf_counter()
    try:
        hash(tuple(static.values()))
    except TypeError:  # an unhashable solver object: compile for this call only
        lowered = jax.jit(functools.partial(_solve_ls.__wrapped__, **static)).lower(u0, args)
    else:
        # one compiled solve per (residuals, solver, bounds, max_steps): later calls with other
        # starts, targets or keys (passed in args) reuse it
        lowered = _solve_ls.lower(u0, args, **static)
    compiled = lowered.compile()
    compile_seconds = time.perf_counter() - t0
    t = time.perf_counter()
    u, result, n, l0, l1 = compiled(u0, args)
    l1 = float(l1)
    seconds = time.perf_counter() - t
    if not np.isfinite(l1):
        raise FloatingPointError(f"fit_least_squares: the residuals are not finite (loss = {l1})")
    if result == optx.RESULTS.successful:
        reason = "converged"
    elif result in (optx.RESULTS.max_steps_reached, optx.RESULTS.nonlinear_max_steps_reached):
        # optimistix's least-squares solvers report the nonlinear variant
        reason = "max_steps"
    else:
        try:
            reason = f"failed: {optx.RESULTS[result]}"
        except (KeyError, TypeError, ValueError):
            reason = "failed"
    final = from_unconstrained(u, bounds)
    history = jax.tree.map(lambda a, b: np.stack([np.asarray(a), np.asarray(b)]), params, final)
    return FitResult(
        params=final,
        loss=np.asarray([float(l0), l1], np.float64),
        history=history,
        seconds=np.asarray([seconds], np.float64),
        compile_seconds=compile_seconds,
        n_steps=int(n),
        stop_reason=reason,
    )
