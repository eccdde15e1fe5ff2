"""The path tracer's bounce loop, shared by reverse-mode AD (:func:`path_radiance`,
:mod:`~jaxgfx.render.integrators.path`) and path replay
(:mod:`~jaxgfx.render.integrators._replay`): one bounce-step function, the first carry and the
last vertex's emission. Its own module so that the integrator classes (``path``) can call the
replay module, which builds on these, without an import cycle.

Depth convention (Mitsuba 3): ``max_depth = 1`` renders only directly visible emitters,
``2`` adds direct illumination, ``3`` one indirect bounce, ... The bounce loop is a
``lax.scan`` with a static trip count, so the estimator is reverse-mode differentiable w.r.t.
every scene parameter (no ``while_loop`` carries radiance or throughput).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgfx._checks import check_choice
from jaxgfx._math import fusion_barrier, max_last, safe_div
from jaxgfx.render.integrators import _common as C
from jaxgfx.render.integrators import _wavefront
from jaxgfx.render.integrators.base import check_depth

__all__ = [
    "path_radiance",
    "make_bounce",
    "initial_carry",
    "last_emission",
    "STRATEGIES",
    "ADJOINTS",
]

STRATEGIES = ("mis", "light", "bsdf")

ADJOINTS = ("ad", "replay")
"""How reverse mode differentiates the path integrator (docs/render_gradients.md): ``"ad"``
(JAX's reverse mode through the checkpointed bounce loop; every parameter) or ``"replay"``
(path replay backpropagation, :mod:`~jaxgfx.render.integrators._replay`: material, emitter,
texture and environment parameters only, memory flat in depth)."""

# A/B switch for benchmarks.render_compile: "on" (checkpoint each bounce of a loop of two or
# more bounces), "always" (a loop of one bounce too: the "checkpointed" variant, as before
# issue 22), "off" (no bounce checkpoint: the pass checkpoint of estimator.pass_scan then keeps
# every bounce's intermediates of one pass), "no_cse" (``prevent_cse=False``, safe inside a scan)
BOUNCE_CHECKPOINT = "on"


def _identity(x):
    return x


def _emission_term(scene, hit, d, p_prev, prev_pdf, prev_delta, strategy, detach=_identity):
    le = C.emitted(scene, hit, d)
    if scene.environment is not None:
        miss = ~hit.valid
        le = le + jnp.where(miss[..., None], scene.environment.eval(d), 0.0)
    if strategy == "bsdf":  # emitters are found only by BSDF sampling: full weight
        return le
    if strategy == "light":  # only camera rays and specular chains see emitters directly
        return jnp.where(prev_delta[..., None], le, 0.0)
    lpdf = C.light_pdf_hit(scene, p_prev, hit, d)
    if scene.environment is not None:
        lpdf = jnp.where(~hit.valid, C.env_pdf(scene, d), lpdf)
    w = jnp.where(prev_delta, 1.0, C.mis_power(detach(prev_pdf), detach(lpdf)))
    return le * w[..., None]


def _use_chunk(chunk, o):
    """``chunk``, or ``None`` where a pass holds fewer than two chunks (sorting is then pure
    overhead)."""
    batch = o.shape[:-1]
    if (
        chunk is not None
        and batch
        and o.size // 3 < 2 * _wavefront.chunk_rows(chunk, batch[-1]) * batch[-1]
    ):
        return None
    return chunk


def initial_carry(o, d):
    """The bounce loop's carry for camera rays ``o, d``: ``(o, d, beta, L, alive, prev_pdf,
    prev_delta, p_prev)``."""
    dtype = o.dtype
    batch = o.shape[:-1]
    return (
        o,
        d,
        jnp.ones(batch + (3,), dtype),
        jnp.zeros(batch + (3,), dtype),
        jnp.ones(batch, bool),
        jnp.ones(batch, dtype),
        jnp.ones(batch, bool),
        o,
    )


def make_bounce(*, rr_depth, strategy, sampling, chunk):
    """``bounce(scene, carry, ub, depth) -> (carry_next, contrib, weight, aux)``: one vertex.

    ``contrib`` is the radiance this vertex adds (emission with its MIS weight and the
    next-event term, both times the throughput ``beta``); ``weight`` the BSDF sample's weight
    (per channel, before Russian roulette), so that ``carry_next``'s throughput is
    ``beta * weight`` (divided by the detached survival probability under Russian roulette;
    0 for dead paths) and its radiance ``L + contrib``; ``aux = (unit, inv_q, shaded)``:
    ``contrib`` per unit of throughput, the Russian-roulette factor (1 or ``1 / q``) and
    whether the vertex was shaded (a live hit). The path integrator scans it
    (:func:`path_radiance`); path replay (:mod:`._replay`) takes the VJP of ``contrib`` and
    ``weight`` w.r.t. the scene at a detached carry. ``chunk``: as :func:`path_radiance`,
    already resolved by :func:`_use_chunk`.
    """
    detached = sampling == "detached"
    detach = jax.lax.stop_gradient if detached else _identity
    lazy = chunk is not None

    def shade(scene, args, mat):
        """Light sampling, shadow ray, BSDF sampling at live hits -> the next segment."""
        hit, d, beta, ub, alive = args
        has_lights = scene.n_lights > 0 and strategy != "bsdf"
        frame, ng, wo = fusion_barrier(C.shading_frame(scene, hit, d, mat))
        tg = C.tangent_space(scene, hit, frame)  # None without normal / bump maps
        dL = jnp.zeros_like(beta)
        if has_lights:
            wi, dist, li, lpdf, l_delta = fusion_barrier(
                C.sample_light(scene, hit.p, ub[..., 0], ub[..., 1:3], detached=detached)
            )
            so, sd = C.spawn_ray(hit.p, ng, wi)
            shadow_tmax = jnp.where(jnp.isfinite(dist), dist * (1 - 1e-4), jnp.inf)
            # materialised: XLA fused the shadow-ray tests into the three channels of the
            # radiance update and ran them three times (9.7 % of a depth-4 path render).
            # The ray is detached: visibility is boolean (no derivative), and a host traversal
            # (Embree's pure_callback) has no JVP rule
            so, sd, shadow_tmax = jax.lax.stop_gradient((so, sd, shadow_tmax))
            vis = fusion_barrier(~C.occluded(scene, so, sd, shadow_tmax))
            wi_local = C.to_local(frame, wi)
            f, bpdf = fusion_barrier(
                C.dispatch(
                    scene,
                    mat,
                    lambda m: (m.eval(wo, wi_local), m.pdf(wo, wi_local)),
                    uv=hit.uv,
                    lazy=lazy,
                    tangents=tg,
                )
            )
            if strategy == "mis":
                w = jnp.where(l_delta, 1.0, C.mis_power(detach(lpdf), detach(bpdf)))
            else:
                w = jnp.ones_like(lpdf)
            contrib = f * li * safe_div(w, lpdf)[..., None]
            ok = alive & vis & (lpdf > 0)
            dL = jnp.where(ok[..., None], contrib, 0.0)  # per unit of throughput

        s = fusion_barrier(
            C.dispatch(
                scene,
                mat,
                lambda m: m.sample(wo, ub[..., 3], ub[..., 4:6]),
                uv=hit.uv,
                lazy=lazy,
                tangents=tg,
            )
        )
        if detached:
            # world-space detached direction (Mitsuba 3 prb): it does not turn with the normal
            wi_world, weight = C.detach_bsdf_sample(
                scene, mat, wo, s, hit.uv, frame=frame, lazy=lazy, tangents=tg
            )
            # a zero weight (e.g. reflectance 0) still has a derivative: keep the path
            alive = alive & (s.pdf > 0)
        else:
            wi_world, weight = C.to_world(frame, s.wi), s.weight
            alive = alive & (s.pdf > 0) & (max_last(s.weight) > 0)
        o_next, d_next = C.spawn_ray(hit.p, ng, wi_world)
        return dL, weight, alive, o_next, d_next, s.pdf, s.is_delta

    def bounce(scene, carry, ub, depth):
        o, d, beta, L, alive, prev_pdf, prev_delta, p_prev = carry
        n_mat = len(scene.materials)
        hit = C.intersect(scene, o, d)
        em = jnp.where(
            alive[..., None],
            _emission_term(scene, hit, d, p_prev, prev_pdf, prev_delta, strategy, detach),
            0,
        )
        alive = alive & hit.valid
        shaded = alive
        mat = C.hit_material(scene, hit)
        args = (hit, d, beta, ub, alive)
        if chunk is None:
            dL, weight, alive, o_next, d_next, pdf, delta = shade(scene, args, mat)
        else:
            key = jnp.where(alive, mat, n_mat)
            outs = _wavefront.shade_sorted(lambda a, m: shade(scene, a, m), args, key, n_mat, chunk)
            # rays that were not shaded: no light, dead, and a finite ray for the next bounce
            dL, weight, alive_s, o_next, d_next, pdf, delta = outs
            dL = jnp.where(alive[..., None], dL, 0.0)
            weight = jnp.where(alive[..., None], weight, 0.0)
            o_next = jnp.where(alive[..., None], o_next, o)
            d_next = jnp.where(alive[..., None], d_next, d)
            pdf = jnp.where(alive, pdf, 1.0)
            delta = jnp.where(alive, delta, True)
            alive = alive & alive_s
        unit = em + dL  # the vertex's radiance per unit of throughput
        em, dL = beta * em, beta * dL
        contrib = em + dL
        L = (L + em) + dL
        beta = beta * weight
        # Russian roulette (Mitsuba: after rr_depth bounces, survival = min(max(beta), 0.95))
        q = detach(jnp.clip(max_last(beta), 0.0, 0.95))
        rr = depth >= rr_depth - 1
        survive = jnp.where(rr, ub[..., 6] < q, True)
        beta = jnp.where(rr, safe_div(beta, q[..., None]), beta)
        inv_q = jnp.where(rr, safe_div(jnp.ones_like(q), q), 1.0)
        alive = alive & survive
        beta = jnp.where(alive[..., None], beta, 0.0)
        carry = (o_next, d_next, beta, L, alive, pdf, delta, hit.p)
        return carry, contrib, weight, (unit, inv_q, shaded)

    return bounce


def last_emission(scene, carry, *, strategy, sampling):
    """What the last vertex adds per unit of throughput: its emission (MIS-weighted), 0 on
    paths that ended; :func:`path_radiance` adds ``beta *`` this."""
    detach = jax.lax.stop_gradient if sampling == "detached" else _identity
    o, d, beta, L, alive, prev_pdf, prev_delta, p_prev = carry
    hit = C.intersect(scene, o, d)
    term = _emission_term(scene, hit, d, p_prev, prev_pdf, prev_delta, strategy, detach)
    return jnp.where(alive[..., None], term, 0.0)


def path_radiance(
    scene,
    o,
    d,
    u,
    *,
    max_depth: int,
    rr_depth: int = 5,
    strategy: str = "mis",
    sampling: str = "detached",
    chunk: int | None = None,
):
    """Radiance along rays ``o, d (..., 3)`` with uniform numbers ``u (..., max_depth, 7)``.

    ``strategy`` selects how direct light is estimated at each vertex: ``"mis"`` (light
    sampling and BSDF sampling combined with the power heuristic, Veach 1997), ``"light"``
    (light sampling only; emitters hit by BSDF-sampled rays count only after specular
    bounces) or ``"bsdf"`` (BSDF sampling only, no shadow rays; point lights are then never
    found). All three are unbiased for area and environment lights; they differ in variance.

    ``sampling="detached"`` (default) makes derivatives unbiased (docs/render_gradients.md):
    BSDF-sampled directions, the environment's light samples, both MIS weights and the
    Russian-roulette survival probability carry no derivative, and the BSDF sample's weight
    has the derivative of ``f(wo, wi; θ) |cos| / stop_gradient(pdf)``
    (:func:`~jaxgfx.render.integrators._common.detach_bsdf_sample`). ``"attached"``
    differentiates through the samplers (pathwise): unbiased only where no sampled ray crosses
    a discontinuity of the integrand as the parameter moves and no sampling decision depends
    on the parameter. The image is identical in both modes.

    ``chunk``: ``None`` (every ray shaded with every material) or the number of rays per chunk
    of wavefront shading (:func:`~jaxgfx.render.integrators._wavefront.shade_sorted`), used
    when a pass holds at least two chunks (whole rows of the batch's last axis).
    """
    check_choice(strategy, "strategy", STRATEGIES)
    C.check_sampling(sampling)
    chunk = _use_chunk(chunk, o)
    bounce = make_bounce(rr_depth=rr_depth, strategy=strategy, sampling=sampling, chunk=chunk)

    def body(carry, xs):
        ub, depth = xs
        return bounce(scene, carry, ub, depth)[0], None

    carry = initial_carry(o, d)
    if max_depth > 1:
        us = jnp.moveaxis(u[..., : max_depth - 1, :], -2, 0)
        # each bounce is checkpointed: reverse mode stores only the carry per bounce (~100
        # bytes per ray) and recomputes the bounce in the backward sweep, instead of every
        # intermediate of it (~1.4 MB per bounce at 32² x 4 spp before; measured in
        # docs/render_gradients.md: same gradient, same time per gradient, faster compile)
        # (one bounce, e.g. direct light: the checkpoint would keep the same intermediates and
        # only add a recomputation to compile; issue 22)
        if BOUNCE_CHECKPOINT != "off" and (max_depth > 2 or BOUNCE_CHECKPOINT == "always"):
            body = jax.checkpoint(body, prevent_cse=BOUNCE_CHECKPOINT != "no_cse")
        carry, _ = jax.lax.scan(body, carry, (us, jnp.arange(max_depth - 1)))
    # last vertex: emission only
    return carry[3] + carry[2] * last_emission(scene, carry, strategy=strategy, sampling=sampling)


def _check_chunk(chunk):
    if chunk is not None:
        check_depth("chunk", chunk)


def _check_strategy(strategy):
    check_choice(strategy, "strategy", STRATEGIES)
