"""Path tracing with next-event estimation, MIS (power heuristic) and Russian roulette.

Depth convention (Mitsuba 3): ``max_depth = 1`` renders only directly visible emitters,
``2`` adds direct illumination, ``3`` one indirect bounce, ... The bounce loop is a
``lax.scan`` with a static trip count, so the estimator is reverse-mode differentiable w.r.t.
every scene parameter (no ``while_loop`` carries radiance or throughput).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from jaxgfx._checks import check_choice
from jaxgfx._math import fusion_barrier, max_last, safe_div
from jaxgfx.render.integrators import _common as C
from jaxgfx.render.integrators import _wavefront
from jaxgfx.render.integrators.base import N_RANDOM, Integrator, check_depth

__all__ = ["PathIntegrator", "DirectIntegrator", "path_radiance", "N_RANDOM", "STRATEGIES"]

STRATEGIES = ("mis", "light", "bsdf")

CHECKPOINT_ONE_BOUNCE = False  # True: checkpoint a bounce loop of one bounce too (A/B switch)


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
    detached = sampling == "detached"
    detach = jax.lax.stop_gradient if detached else _identity
    dtype = o.dtype
    batch = o.shape[:-1]
    has_lights = scene.n_lights > 0 and strategy != "bsdf"

    n_mat = len(scene.materials)
    # wavefront shading only where a pass has two chunks or more (else it is pure overhead)
    if (
        chunk is not None
        and batch
        and o.size // 3 < 2 * _wavefront.chunk_rows(chunk, batch[-1]) * batch[-1]
    ):
        chunk = None
    lazy = chunk is not None

    def shade(args, mat):
        """Light sampling, shadow ray, BSDF sampling at live hits -> the next segment."""
        hit, d, beta, ub, alive = args
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
            # radiance update and ran them three times (9.7 % of a depth-4 path render)
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
            dL = jnp.where(ok[..., None], beta * contrib, 0.0)

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
        return dL, beta * weight, alive, o_next, d_next, s.pdf, s.is_delta

    def bounce(carry, xs):
        o, d, beta, L, alive, prev_pdf, prev_delta, p_prev = carry
        ub, depth = xs
        hit = C.intersect(scene, o, d)
        L = L + jnp.where(
            alive[..., None],
            beta * _emission_term(scene, hit, d, p_prev, prev_pdf, prev_delta, strategy, detach),
            0,
        )
        alive = alive & hit.valid
        mat = C.hit_material(scene, hit)
        args = (hit, d, beta, ub, alive)
        if chunk is None:
            dL, beta, alive, o_next, d_next, pdf, delta = shade(args, mat)
        else:
            key = jnp.where(alive, mat, n_mat)
            outs = _wavefront.shade_sorted(shade, args, key, n_mat, chunk)
            # rays that were not shaded: no light, dead, and a finite ray for the next bounce
            dL, beta, alive_s, o_next, d_next, pdf, delta = outs
            dL = jnp.where(alive[..., None], dL, 0.0)
            o_next = jnp.where(alive[..., None], o_next, o)
            d_next = jnp.where(alive[..., None], d_next, d)
            pdf = jnp.where(alive, pdf, 1.0)
            delta = jnp.where(alive, delta, True)
            alive = alive & alive_s
        L = L + dL
        # Russian roulette (Mitsuba: after rr_depth bounces, survival = min(max(beta), 0.95))
        q = detach(jnp.clip(max_last(beta), 0.0, 0.95))
        rr = depth >= rr_depth - 1
        survive = jnp.where(rr, ub[..., 6] < q, True)
        beta = jnp.where(rr, safe_div(beta, q[..., None]), beta)
        alive = alive & survive
        beta = jnp.where(alive[..., None], beta, 0.0)
        carry = (o_next, d_next, beta, L, alive, pdf, delta, hit.p)
        return carry, None

    carry = (
        o,
        d,
        jnp.ones(batch + (3,), dtype),
        jnp.zeros(batch + (3,), dtype),
        jnp.ones(batch, bool),
        jnp.ones(batch, dtype),
        jnp.ones(batch, bool),
        o,
    )
    if max_depth > 1:
        us = jnp.moveaxis(u[..., : max_depth - 1, :], -2, 0)
        # each bounce is checkpointed: reverse mode stores only the carry per bounce (~100
        # bytes per ray) and recomputes the bounce in the backward sweep, instead of every
        # intermediate of it (~1.4 MB per bounce at 32² x 4 spp before; measured in
        # docs/render_gradients.md: same gradient, same time per gradient, faster compile)
        # (one bounce, e.g. direct light: the checkpoint would keep the same intermediates and
        # only add a recomputation to compile; issue 22)
        body = bounce if max_depth == 2 and not CHECKPOINT_ONE_BOUNCE else jax.checkpoint(bounce)
        carry, _ = jax.lax.scan(body, carry, (us, jnp.arange(max_depth - 1)))
    # last vertex: emission only
    o, d, beta, L, alive, prev_pdf, prev_delta, p_prev = carry
    hit = C.intersect(scene, o, d)
    term = _emission_term(scene, hit, d, p_prev, prev_pdf, prev_delta, strategy, detach)
    return L + jnp.where(alive[..., None], beta * term, 0.0)


def _check_chunk(chunk):
    if chunk is not None:
        check_depth("chunk", chunk)


def _check_strategy(strategy):
    check_choice(strategy, "strategy", STRATEGIES)


class PathIntegrator(Integrator):
    """Path tracing with next-event estimation, MIS and Russian roulette (:func:`path_radiance`).

    ``max_depth`` follows Mitsuba 3 (1: emitters only, 2: direct light, 3: one indirect
    bounce); Russian roulette starts after ``rr_depth`` bounces; ``strategy``: ``"mis"``,
    ``"light"`` or ``"bsdf"``. ``chunk`` (default 4096): wavefront shading, the rays of a
    pass sorted by material and shaded ``chunk`` at a time, skipping chunks without a live ray
    and materials a chunk does not hold; ``None``: every ray with every material (same values
    to float rounding; docs/render.md). All static.

    >>> PathIntegrator(max_depth=3).random_shape
    (3, 7)
    """

    max_depth: int = eqx.field(static=True, default=3)
    rr_depth: int = eqx.field(static=True, default=5)
    strategy: str = eqx.field(static=True, default="mis")
    sampling: str = eqx.field(static=True, default="detached")
    chunk: int | None = eqx.field(static=True, default=4096)

    def __check_init__(self):
        check_depth("max_depth", self.max_depth)
        check_depth("rr_depth", self.rr_depth)
        _check_chunk(self.chunk)
        _check_strategy(self.strategy)
        C.check_sampling(self.sampling)

    @property
    def random_shape(self):
        return (self.max_depth, N_RANDOM)

    def __call__(self, scene, o, d, u):
        return path_radiance(
            scene,
            o,
            d,
            u,
            max_depth=self.max_depth,
            rr_depth=self.rr_depth,
            strategy=self.strategy,
            sampling=self.sampling,
            chunk=self.chunk,
        )


class DirectIntegrator(Integrator):
    """Emitted plus direct light (a path of depth 2: :class:`PathIntegrator` with
    ``max_depth = 2``); ``strategy`` as there; ``chunk`` as there, default ``None`` (most
    camera rays are live, so sorting them does not pay: measured 5–10 % slower).

    >>> DirectIntegrator().max_depth
    2
    """

    rr_depth: int = eqx.field(static=True, default=5)
    strategy: str = eqx.field(static=True, default="mis")
    sampling: str = eqx.field(static=True, default="detached")
    chunk: int | None = eqx.field(static=True, default=None)

    def __check_init__(self):
        check_depth("rr_depth", self.rr_depth)
        _check_chunk(self.chunk)
        _check_strategy(self.strategy)
        C.check_sampling(self.sampling)

    @property
    def max_depth(self) -> int:
        return 2

    @property
    def random_shape(self):
        return (self.max_depth, N_RANDOM)

    def __call__(self, scene, o, d, u):
        return path_radiance(
            scene,
            o,
            d,
            u,
            max_depth=2,
            rr_depth=self.rr_depth,
            strategy=self.strategy,
            sampling=self.sampling,
            chunk=self.chunk,
        )
