"""Smooth bijections between constrained parameters and unconstrained optimisation variables.

A bounded parameter ``x`` is optimised through an unconstrained variable ``u`` with
``x = forward(u)``:

* ``(lo, hi)``: ``x = lo + (hi - lo) · sigmoid(u)``, ``u = logit((x - lo) / (hi - lo))``;
* ``(lo, None)``: ``x = lo + softplus(u)``, ``u = x - lo + log(-expm1(-(x - lo)))``;
* ``(None, hi)``: ``x = hi - softplus(u)``;
* ``(None, None)`` / ``None``: identity.

The image of ``forward`` is the *open* interval, so a roughness ``α`` never reaches 0 or leaves
``(0, 1]`` however large the step, and ``dx/du`` is finite everywhere (it tends to 0 at the
bounds). An initial value *on* a bound (``α = lo``) has no finite preimage; :func:`Interval.inverse`
moves it inside by ``margin`` (a fraction of the width for two-sided bounds, an absolute offset for
one-sided ones; default ``1e-3``) so that the optimiser starts with a usable gradient
(``sigmoid'(logit(1e-3)) ≈ 1e-3``). Values outside the bounds raise ``ValueError`` at the
Python boundary (see :func:`check_bounds`).

``bounds`` given to :func:`to_unconstrained` / :func:`from_unconstrained` is a pytree *prefix*
of ``params`` whose leaves are ``None``, a 2-tuple ``(lo, hi)`` of numbers / arrays / ``None``,
or an :class:`Interval`; each applies to every array leaf below it (``{"alpha": (1e-3, 1.0),
"albedo": (0.0, 1.0)}``). ``bounds=None`` leaves every parameter free.

References: the softplus / sigmoid constraints of Stan (Carpenter et al. 2017, "Stan: a
probabilistic programming language", J. Stat. Softw.) and TensorFlow Probability bijectors.

Example: ``Interval(0.0, 2.0).forward(0.0)`` → ``1.0``; ``Interval(0.0, None).inverse(
jnp.log(2.0))`` → ``0.0`` (``softplus(0) = ln 2``).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "Interval",
    "as_interval",
    "check_bounds",
    "to_unconstrained",
    "from_unconstrained",
]


def _is_number_like(x) -> bool:
    return x is None or isinstance(x, (int, float, np.ndarray, jax.Array, np.number))


def _is_bound_leaf(x) -> bool:
    if x is None or isinstance(x, Interval):
        return True
    return (
        isinstance(x, tuple)
        and len(x) == 2
        and all(_is_number_like(v) and not isinstance(v, bool) for v in x)
    )


def _nested_tuple(a: np.ndarray):
    """A hashable nested tuple of floats (per-element bounds are static fields)."""
    return tuple(_nested_tuple(r) for r in a) if a.ndim > 1 else tuple(float(v) for v in a)


def _softplus_inv(y):
    """Inverse of softplus for ``y > 0``: ``y + log(-expm1(-y))`` (stable for small and large
    ``y``)."""
    return y + jnp.log(-jnp.expm1(-y))


class Interval(eqx.Module):
    """The constraint ``lo < x < hi`` (either side may be ``None``) as a smooth bijection.

    ``forward(u)`` maps the real line onto the open interval; ``inverse(x)`` maps back (values
    on a bound are moved inside by ``margin``). ``lo``/``hi`` are static Python floats or
    ``None`` (per-element bounds: pass arrays; they are stored as nested tuples).

    Example: ``Interval(1e-3, 1.0).forward(Interval(1e-3, 1.0).inverse(0.3))`` → ``0.3``.
    """

    lo: object = eqx.field(static=True, default=None)
    hi: object = eqx.field(static=True, default=None)
    margin: float = eqx.field(static=True, default=1e-3)

    def __check_init__(self):
        for name in ("lo", "hi"):
            v = getattr(self, name)
            if v is not None and not np.all(np.isfinite(np.asarray(v, np.float64))):
                raise ValueError(f"bounds: {name} must be finite or None, got {v!r}")
        if self.lo is not None and self.hi is not None:
            if not np.all(np.asarray(self.hi, np.float64) > np.asarray(self.lo, np.float64)):
                raise ValueError(f"bounds: expected lo < hi, got ({self.lo!r}, {self.hi!r})")
        if not 0.0 < self.margin < 0.5:
            raise ValueError(f"margin: expected a number in (0, 0.5), got {self.margin!r}")

    @property
    def kind(self) -> str:
        if self.lo is None and self.hi is None:
            return "free"
        if self.lo is None:
            return "upper"
        if self.hi is None:
            return "lower"
        return "interval"

    def _lo_hi(self, x):
        dt = jnp.result_type(x, 1.0)
        lo = None if self.lo is None else jnp.asarray(self.lo, dt)
        hi = None if self.hi is None else jnp.asarray(self.hi, dt)
        return lo, hi

    def forward(self, u):
        """Unconstrained ``u`` → constrained ``x`` (elementwise; smooth, strictly monotone)."""
        u = jnp.asarray(u)
        lo, hi = self._lo_hi(u)
        k = self.kind
        if k == "free":
            return u
        if k == "lower":
            return lo + jax.nn.softplus(u)
        if k == "upper":
            return hi - jax.nn.softplus(u)
        return lo + (hi - lo) * jax.nn.sigmoid(u)

    def inverse(self, x):
        """Constrained ``x`` → unconstrained ``u``; values on (or within ``margin`` of) a bound
        are first moved inside by ``margin``."""
        x = jnp.asarray(x)
        if not jnp.issubdtype(x.dtype, jnp.floating):
            x = x.astype(jnp.result_type(float))
        lo, hi = self._lo_hi(x)
        k = self.kind
        m = self.margin
        if k == "free":
            return x
        if k == "lower":
            return _softplus_inv(jnp.maximum(x - lo, m))
        if k == "upper":
            return _softplus_inv(jnp.maximum(hi - x, m))
        t = jnp.clip((x - lo) / (hi - lo), m, 1.0 - m)
        return jnp.log(t) - jnp.log1p(-t)

    def contains(self, x) -> bool:
        """True when every element of the concrete ``x`` satisfies ``lo <= x <= hi``."""
        x = np.asarray(x, np.float64)
        ok = np.isfinite(x)
        if self.lo is not None:
            ok &= x >= np.asarray(self.lo, np.float64)
        if self.hi is not None:
            ok &= x <= np.asarray(self.hi, np.float64)
        return bool(np.all(ok))


def as_interval(bound) -> Interval:
    """``None`` / ``(lo, hi)`` / :class:`Interval` → :class:`Interval`."""
    if isinstance(bound, Interval):
        return bound
    if bound is None:
        return Interval()
    if _is_bound_leaf(bound):
        lo, hi = bound

        def conv(v):
            if v is None:
                return None
            a = np.asarray(v, np.float64)
            return float(a) if a.ndim == 0 else _nested_tuple(a)

        return Interval(conv(lo), conv(hi))
    raise TypeError(f"bounds: expected None, (lo, hi) or an Interval, got {bound!r}")


def _map(fn, params, bounds):
    """Apply ``fn(interval, leaf)`` to every array leaf of ``params`` under the bound prefix."""
    if bounds is None:
        return jax.tree.map(lambda p: fn(Interval(), p), params)
    try:
        return jax.tree.map(
            lambda b, sub: jax.tree.map(lambda p: fn(as_interval(b), p), sub),
            bounds,
            params,
            is_leaf=_is_bound_leaf,
        )
    except ValueError as e:
        raise ValueError(
            "bounds: expected a prefix of the params pytree (same dict keys / nesting) with "
            f"leaves None, (lo, hi) or Interval ({e})"
        ) from None


def check_bounds(params, bounds) -> None:
    """Raise ``ValueError`` naming the parameter when a concrete value lies outside its bounds
    (or is not finite). Values *on* a bound are accepted (they are moved inside by the
    bijection's margin)."""
    leaves_with_path = jax.tree_util.tree_flatten_with_path(params)[0]
    pairs = []
    _map(lambda b, p: pairs.append((b, p)), params, bounds)
    for (path, _), (b, p) in zip(leaves_with_path, pairs, strict=True):
        if isinstance(p, jax.core.Tracer):
            continue
        if not b.contains(p):
            name = jax.tree_util.keystr(path) or "params"
            raise ValueError(
                f"params{name}: value {np.asarray(p).tolist()} is outside its bounds "
                f"({b.lo}, {b.hi}) or not finite"
            )


def to_unconstrained(params, bounds=None):
    """Map constrained ``params`` to the unconstrained variables (same pytree)."""
    return _map(lambda b, p: b.inverse(p), params, bounds)


def from_unconstrained(u, bounds=None):
    """Map unconstrained variables back to constrained parameters (same pytree)."""
    return _map(lambda b, p: b.forward(p), u, bounds)
