# ruff: noqa: F722  (jaxtyping shape strings)
"""Sphere tracing (Hart 1996) of signed distance functions: :func:`sphere_trace` for one SDF
and :class:`SDFShape`, which plugs an SDF tree into
:func:`jaxgfx.render.geometry.intersect_scene` (``closest_t`` + ``hit`` protocol).

Scene key: ``{type: sdf, expr: {op: smooth_union, k: 0.2, a: {...}, b: {...}}, material: m,
max_steps: 128, eps: 1e-4}`` (``expr`` as in :func:`jaxgfx.render.geometry.sdf.sdf_from_dict`).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxgfx._checks import check_positive
from jaxgfx._math import safe_div, safe_normalize, sum_last
from jaxgfx.render.geometry.ray import Hit, hit_record, prepare_rays
from jaxgfx.render.geometry.sdf import SDF, sdf_normal

__all__ = ["SDFShape", "sphere_trace"]


def _grad(f, p):
    return jax.grad(lambda q: jnp.sum(f(q)))(p)


class SDFShape(eqx.Module):
    """A surface given by the zero set of ``sdf``, intersected by sphere tracing (Hart 1996).

    ``closest_t(o, d, *, tmin, tmax) -> (t, prim_id)``: non-differentiable search (``t = inf``
    on misses, ``prim_id = 0``). The march uses ``|sdf|`` measured from the side the ray starts
    on, so rays starting inside the solid (a camera inside an SDF sphere) find the surface
    from inside. Rays that start within ``4 eps`` of the surface (secondary rays spawned from
    it) first step off it by ``4 eps`` along the normal towards the side ``d`` points to, so
    they do not re-hit their own origin; the step stops when ``|sdf| < eps max(1, t)``.
    ``hit(prim_id, o, d, valid, t=None) -> Hit``: the record at the search's ``t`` (re-traced
    when ``t`` is not given), with ``t``
    made differentiable by one implicit-function step ``t - (f - sg f) / sg(grad f . d)``, so
    ``dt/dθ = -(∂f/∂θ) / (grad f · d)`` for every SDF parameter θ (radius, centre ...);
    normals ``normalize(grad f)``; ``uv`` is the spherical (φ/2π, θ/π) map of the normal.
    SDFs cannot be area lights (no area / sampling).

    Example: ``SDFShape(SDFSphere([0, 0, 0], 1.0)).closest_t(o=(0, 0, -3), d=(0, 0, 1), tmin=0,
    tmax=inf)`` → ``t ≈ 2``.
    """

    sdf: SDF
    max_steps: int = eqx.field(static=True, default=128)
    eps: float = eqx.field(static=True, default=1e-4)

    def __check_init__(self):
        if isinstance(self.max_steps, bool) or not isinstance(self.max_steps, int):
            raise ValueError(f"max_steps: expected an integer >= 1, got {self.max_steps!r}")
        if self.max_steps < 1:
            raise ValueError(f"max_steps: expected an integer >= 1, got {self.max_steps!r}")
        if not (isinstance(self.eps, (int, float)) and 0 < self.eps < 1):
            raise ValueError(f"eps: expected a number in (0, 1), got {self.eps!r}")

    def _start(self, f, o, d, tmin):
        """Start point (pushed off the surface when starting on it) and the march side."""
        p0 = o + tmin[..., None] * d
        f0 = f(p0)
        g0 = safe_normalize(_grad(f, p0))
        near = jnp.abs(f0) < 4 * self.eps
        side = jnp.where(sum_last(g0 * d) >= 0, 1.0, -1.0).astype(o.dtype)
        push = (side * 4 * self.eps - f0)[..., None] * g0
        o_start = o + jnp.where(near[..., None], push, 0.0)
        sign = jnp.where(near, side, jnp.where(f0 >= 0, 1.0, -1.0))
        return o_start, sign

    def _trace(self, o, d, tmin, tmax):
        sg = jax.lax.stop_gradient
        f = sg(self.sdf)
        o, d = sg(o), sg(d)
        batch = o.shape[:-1]
        tmin = jnp.broadcast_to(jnp.asarray(tmin, o.dtype), batch)
        tmax = jnp.broadcast_to(jnp.asarray(tmax, o.dtype), batch)
        o_start, sign = self._start(f, o, d, tmin)
        eps = self.eps

        def cond(s):
            i, _, _, alive = s
            return (i < self.max_steps) & jnp.any(alive)

        def body(s):
            i, t, hit, alive = s
            dist = sign * f(o_start + t[..., None] * d)
            close = dist < eps * jnp.maximum(1.0, jnp.abs(t))
            hit = hit | (alive & close)
            t_new = jnp.where(alive & ~close, t + dist, t)
            alive = alive & ~close & (t_new < tmax)
            return i + 1, t_new, hit, alive

        init = (jnp.int32(0), tmin, jnp.zeros(batch, bool), jnp.ones(batch, bool))
        _, t, hit, _ = jax.lax.while_loop(cond, body, init)
        hit = hit & (t < tmax) & (t >= tmin)
        return jnp.where(hit, t, jnp.inf), o_start

    def closest_t(self, o, d, *, tmin, tmax):
        t, _ = self._trace(o, d, tmin, tmax)
        return t, jnp.zeros(t.shape, jnp.int32)

    def hit(self, prim_id, o, d, valid, t=None) -> Hit:
        sg = jax.lax.stop_gradient
        if t is None:
            t, o_start = self._trace(o, d, 0.0, jnp.inf)
        else:  # the search already ran (intersect_scene passes its t): only redo the start
            batch = jnp.broadcast_shapes(o.shape, d.shape)[:-1]
            o_start, _ = self._start(sg(self.sdf), sg(o), sg(d), jnp.zeros(batch, o.dtype))
            t = sg(t)
        valid = valid & jnp.isfinite(t)
        t = jnp.where(valid, t, 0.0)
        # differentiable origin: the push off the surface is a constant offset
        o_live = o + sg(o_start - o)
        p0 = sg(o_live) + t[..., None] * sg(d)
        gd = sum_last(sg(_grad(self.sdf, p0)) * sg(d))
        f_live = self.sdf(o_live + t[..., None] * d)
        t = t - safe_div(f_live - sg(f_live), gd)
        p = o_live + t[..., None] * d
        n = safe_normalize(_grad(self.sdf, p))
        theta = jnp.arccos(jnp.clip(n[..., 2], -1.0, 1.0))
        phi = jnp.arctan2(n[..., 1], n[..., 0])
        uv = jnp.stack([(phi / (2 * jnp.pi)) % 1.0, theta / jnp.pi], -1)
        return hit_record(valid, t, p, n, n, sg(uv), prim_id, 0)


def sphere_trace(
    sdf: SDF,
    o: Float[Array, "*b 3"],
    d: Float[Array, "*b 3"],
    *,
    tmin=0.0,
    tmax=100.0,
    max_steps: int = 128,
    eps: float = 1e-4,
) -> Hit:
    """First surface crossing of rays ``o, d (..., 3)`` (``d`` unit) by sphere tracing.

    Steps ``t += sdf(o + t d)`` from ``tmin`` (Hart 1996) for a static ``max_steps``
    (``lax.fori_loop``); a hit is declared when ``|sdf| < eps * max(1, t)`` before ``tmax``.
    The returned ``t`` is made differentiable by one implicit-function Newton step at the
    converged point, ``t - (f - stop_grad(f)) / stop_grad(grad f . d)``, so ``dt/dtheta =
    -(df/dtheta) / (grad f . d)`` for any SDF parameter ``theta`` and for ``o, d``. Normals are
    ``normalize(grad_p sdf)``; ``uv = 0``, ``prim_id = 0`` on hits.
    Example: unit :class:`SDFSphere` at the origin, ray from ``(0, 0, -3)`` along ``+z`` →
    ``t = 2``.
    """
    if not isinstance(max_steps, int) or max_steps < 1:
        raise ValueError(f"max_steps: expected an integer >= 1, got {max_steps!r}")
    check_positive(eps, "eps")
    o, d, tmin, tmax = prepare_rays(o, d, tmin, tmax)
    batch = o.shape[:-1]
    tmin = jnp.broadcast_to(tmin, batch)
    tmax = jnp.broadcast_to(tmax, batch)
    sg = jax.lax.stop_gradient
    f_sg, o_sg, d_sg = sg(sdf), sg(o), sg(d)

    def step(_, s):
        t, hit, alive = s
        dist = f_sg(o_sg + t[..., None] * d_sg)
        close = jnp.abs(dist) < eps * jnp.maximum(1.0, jnp.abs(t))
        hit = hit | (alive & close)
        t_new = jnp.where(alive & ~close, t + dist, t)
        alive = alive & ~close & (t_new < tmax) & (t_new >= tmin - 1e3 * eps)
        return t_new, hit, alive

    init = (tmin, jnp.zeros(batch, bool), jnp.ones(batch, bool))
    t, hit, _ = jax.lax.fori_loop(0, max_steps, step, init)
    hit = hit & (t < tmax) & jnp.isfinite(t)
    t = jnp.where(hit, t, 0.0)
    p0 = o_sg + t[..., None] * d_sg
    g = sg(jax.grad(lambda q: jnp.sum(f_sg(q)))(p0))
    gd = sum_last(g * d_sg)
    f_live = sdf(o + t[..., None] * d)
    t = t - safe_div(f_live - sg(f_live), gd)
    p = o + t[..., None] * d
    n = sdf_normal(sdf, p)
    return hit_record(hit, t, p, n, n, jnp.zeros((*batch, 2), o.dtype), 0, 0)
