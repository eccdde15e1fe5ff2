"""Path replay backpropagation (Vicini, Speierer, Jakob 2021, "Path Replay Backpropagation:
Differentiating Light Paths using Constant Memory and Linear Time"; Mitsuba 3's ``prb``).

:func:`path_radiance_replay` has the value of
:func:`~jaxgfx.render.integrators.path.path_radiance` (same program, ``sampling="detached"``)
and a custom VJP that does not differentiate the bounce loop. Its forward pass stores nothing
but the radiance ``L`` of each ray (and its inputs); the backward pass, given the cotangent
``δL`` of each ray, replays the path with the same uniform numbers and at each vertex ``j``
takes the VJP, w.r.t. the scene's material / emitter / texture / environment leaves, of only
the vertex's own terms at the detached path state:

    g_j(θ) = contrib_j(θ) + w_j(θ) · sg((L − L_≤j) / w_j)

``contrib_j`` = throughput × (emission with its detached MIS weight + the next-event term),
``w_j`` the detached BSDF sample's weight (value ``f cos / pdf``, derivative of
``f(θ) cos / sg(pdf)``), ``L − L_≤j`` the radiance the path gathers after vertex ``j`` (from
the stored ``L`` and the radiance summed so far in the replay; 0 once the path ended), ``sg``
stop-gradient. The sum over ``j`` of ``∂g_j`` is the derivative of ``L = Σ_k β_k e_k`` with
``β_{k+1} = β_k w_k`` by the product rule, i.e. the detached AD gradient of the same path
(Algorithm 2 of the paper, with the detached-sampling conventions of
docs/render_gradients.md). Where a weight is exactly 0 in a channel (a black albedo or texel, a
zero colour channel), ``L − L_≤j`` is 0 but the derivative is not: the forward pass also sums,
per channel, the light gathered after the path's first zero weight with that factor replaced
by 1 (``Z``), and the replay adds ``w_j(θ) · Z`` at that vertex (Mitsuba 3's ``prb`` drops this
term; detached AD keeps such paths alive and has it). The backward pass is one ``lax.scan``
over bounces whose carry is the path state and the accumulated scene cotangent, and both passes
draw each bounce's uniform numbers from the key inside their loop (``u`` a
:class:`~jaxgfx.render.sampler.UniformBlocks`, as ``render`` passes it): memory does not grow
with depth, and the backward pass costs one forward replay plus the local VJPs.

Not covered (refused with a ``ValueError`` at trace time of ``jax.grad``, never silently
zero): geometry and camera leaves (shapes, emitter shapes, camera, the rays ``o, d``); and
materials whose delta lobe's *direction* moves with a parameter (smooth dielectric ``eta``,
normal / bump maps on delta materials), since hits are detached. Reverse mode only:
``jax.jvp`` of a custom VJP is an error in JAX.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jax.ad_checkpoint import checkpoint_name

from jaxgfx._math import safe_div
from jaxgfx.render.integrators import _bounce as P
from jaxgfx.render.sampler import UniformBlocks

__all__ = ["path_radiance_replay", "replay_refusal"]

_GEOMETRY = ("camera", "shapes", "emitter_shapes")

RADIANCE_NAME = "path_replay_radiance"
"""``jax.ad_checkpoint.checkpoint_name`` of what the forward pass stores for the backward pass
(``L`` and ``Z``, 6 numbers per ray), so that a checkpoint policy may keep them instead of
recomputing the forward."""


def _geometry(tree):
    return tuple(getattr(tree, k) for k in _GEOMETRY)


def _first_true(tree, prefix):
    for path, leaf in jtu.tree_flatten_with_path(tree)[0]:
        if leaf is True:
            return prefix + jtu.keystr(path)
    return None


def replay_refusal(scene, perturbed) -> str | None:
    """Why path replay cannot differentiate w.r.t. the leaves marked ``True`` in ``perturbed =
    (scene mask, o, d)`` (a pytree of bools shaped like ``(scene, o, d)``; ``o``, ``d`` may be
    plain bools), or ``None`` where it can: geometry and camera leaves, the camera rays, and the
    parameters of materials whose delta lobe's direction can move with them. Used by the
    custom VJP (which raises it) and by ``jaxgfx fit``'s ``render.adjoint: auto``."""
    p_scene, p_o, p_d = perturbed
    where = None
    for name in _GEOMETRY:
        where = where or _first_true(getattr(p_scene, name), name)
    if where is None and (p_o is True or p_d is True):
        where = "the camera rays (o, d)"
    if where is not None:
        return (
            f"adjoint='replay': {where} is differentiated, but path replay covers only "
            "material, emitter, texture and environment parameters (hits are detached, as in "
            "Mitsuba 3's prb); use adjoint='ad' (PathIntegrator's default) for geometry and "
            "camera parameters, with visibility='edge' for their boundary terms"
        )
    for k, m in enumerate(scene.materials):
        moves_delta = m.has_delta and (m.is_transmissive or getattr(m, "needs_tangents", False))
        where = _first_true(p_scene.materials[k], f"materials[{k}]")
        if moves_delta and where is not None:
            name = scene.material_names[k]
            return (
                f"adjoint='replay': {where} (material {name!r}, {type(m).__name__}) is "
                "differentiated, but its delta lobe's direction can depend on it and replayed "
                "directions carry no derivative; use adjoint='ad'"
            )
    return None


def _check_perturbed(perturbed, scene):
    """``ValueError`` naming the first differentiated leaf replay does not cover."""
    why = replay_refusal(scene, perturbed)
    if why is not None:
        raise ValueError(why)


def _spec(scene, perturbed_scene):
    """Filter: the differentiated float leaves outside the geometry subtrees."""
    spec = jtu.tree_map(lambda p: bool(p), perturbed_scene)
    geo = _geometry(spec)
    return eqx.tree_at(_geometry, spec, replace=jtu.tree_map(lambda _: False, geo))


def _numbers(u, i):
    """Bounce ``i``'s uniform numbers ``(..., 7)`` (``i`` may be traced): drawn from the key
    where ``u`` is a :class:`~jaxgfx.render.sampler.UniformBlocks` (what
    :func:`~jaxgfx.render.estimator.render_partial` passes: nothing per bounce is stored), else
    read from the array ``u (..., max_depth, 7)``."""
    if isinstance(u, UniformBlocks):
        return u.block(i)
    return jax.lax.dynamic_index_in_dim(u, i, axis=u.ndim - 2, keepdims=False)


def _trace(scene, o, d, u, max_depth, rr_depth, strategy, chunk, zero_weights):
    """``L`` (``zero_weights=False``: the radiance of
    :func:`~jaxgfx.render.integrators._bounce.path_radiance`, ``sampling="detached"``, by the
    same operations) or ``(L, Z)``: also, per channel, the radiance gathered after the path's
    first exactly-zero BSDF weight with that factor replaced by 1 (0 where no weight was 0):
    the derivative of ``L`` w.r.t. that weight, which ``(L − L_≤j) / w_j`` cannot recover (a
    black albedo or texel, a zero colour channel). Each bounce draws its own numbers
    (:func:`_numbers`)."""
    chunk = P._use_chunk(chunk, o)
    bounce = P.make_bounce(rr_depth=rr_depth, strategy=strategy, sampling="detached", chunk=chunk)

    def body(state, depth):
        carry, bt, seen, Z = state
        nxt, _, weight, (unit, inv_q, shaded) = bounce(scene, carry, _numbers(u, depth), depth)
        if not zero_weights:
            return (nxt, bt, seen, Z), None
        Z = Z + jnp.where(seen, bt * unit, 0.0)
        first = (weight == 0) & ~seen & shaded[..., None]
        bt = bt * jnp.where(first, 1.0, weight) * inv_q[..., None]
        bt = jnp.where(nxt[4][..., None], bt, 0.0)
        return (nxt, bt, seen | first, Z), None

    carry = P.initial_carry(o, d)
    bt = jnp.ones_like(carry[2])
    seen = jnp.zeros(bt.shape, bool)
    Z = jnp.zeros_like(bt)
    if max_depth > 1:
        state = (carry, bt, seen, Z)
        (carry, bt, seen, Z), _ = jax.lax.scan(body, state, jnp.arange(max_depth - 1))
    unit = P.last_emission(scene, carry, strategy=strategy, sampling="detached")
    L = carry[3] + carry[2] * unit
    if not zero_weights:
        return L
    return L, Z + jnp.where(seen, bt * unit, 0.0)


@eqx.filter_custom_vjp
def _replay(vjp_arg, u, max_depth, rr_depth, strategy, chunk):
    scene, o, d = vjp_arg
    return _trace(scene, o, d, u, max_depth, rr_depth, strategy, chunk, False)


@_replay.def_fwd
def _replay_fwd(perturbed, vjp_arg, u, max_depth, rr_depth, strategy, chunk):
    scene, o, d = vjp_arg
    _check_perturbed(perturbed, scene)
    L, Z = _trace(scene, o, d, u, max_depth, rr_depth, strategy, chunk, True)
    L, Z = checkpoint_name((L, Z), RADIANCE_NAME)
    return L, (L, Z)


@_replay.def_bwd
def _replay_bwd(res, dL, perturbed, vjp_arg, u, max_depth, rr_depth, strategy, chunk):
    scene, o, d = vjp_arg
    spec = _spec(scene, perturbed[0])
    theta, rest = eqx.partition(scene, spec)
    none = (jtu.tree_map(lambda _: None, theta), None, None)
    if dL is None or not jtu.tree_leaves(theta):
        return none
    sg = jax.lax.stop_gradient
    chunk = P._use_chunk(chunk, o)
    bounce = P.make_bounce(rr_depth=rr_depth, strategy=strategy, sampling="detached", chunk=chunk)
    L, Z = sg(res)
    dL = dL.astype(L.dtype)

    def local(th, carry, seen, ub, depth):
        s = eqx.combine(th, rest)
        nxt, contrib, weight, (_, _, shaded) = bounce(s, carry, ub, depth)
        nxt = sg(nxt)
        alive_next = nxt[4][..., None]
        # radiance still to come after this vertex (0 once the path ended: no rounding noise
        # divided by a small weight); per unit of this vertex's detached weight
        rest_per_w = jnp.where(alive_next, safe_div(L - nxt[3], sg(weight)), 0.0)
        term = contrib + jnp.where(alive_next, weight * sg(rest_per_w), 0.0)
        # the path's first zero weight (per channel): its derivative times the light after it
        first = sg((weight == 0) & ~seen & shaded[..., None])
        term = term + jnp.where(first, weight * Z, 0.0)
        return term, (nxt, seen | first)

    def step(state, depth):
        carry, seen, acc = state
        ub = _numbers(u, depth)
        _, vjp_fn, (nxt, seen) = jax.vjp(
            lambda th: local(th, carry, seen, ub, depth), theta, has_aux=True
        )
        (g,) = vjp_fn(dL)
        return (nxt, seen, jtu.tree_map(jnp.add, acc, g)), None

    carry = P.initial_carry(sg(o), sg(d))
    seen = jnp.zeros(carry[2].shape, bool)
    acc = jtu.tree_map(jnp.zeros_like, theta)
    if max_depth > 1:
        state = (carry, seen, acc)
        (carry, seen, acc), _ = jax.lax.scan(step, state, jnp.arange(max_depth - 1))

    def last(th):
        s = eqx.combine(th, rest)
        return carry[2] * P.last_emission(s, carry, strategy=strategy, sampling="detached")

    _, vjp_fn = jax.vjp(last, theta)
    (g,) = vjp_fn(dL)
    acc = jtu.tree_map(jnp.add, acc, g)
    return (acc, None, None)


def path_radiance_replay(
    scene,
    o,
    d,
    u,
    *,
    max_depth: int,
    rr_depth: int = 5,
    strategy: str = "mis",
    chunk: int | None = None,
):
    """:func:`~jaxgfx.render.integrators.path.path_radiance` with ``sampling="detached"``
    whose reverse-mode derivative is computed by path replay (module docstring). ``u``: the
    array ``(..., max_depth, 7)`` or the same numbers as a
    :class:`~jaxgfx.render.sampler.UniformBlocks` (drawn per bounce in the forward pass and
    again in the replay: nothing of size ``max_depth`` is kept). Same values (the same
    bounces); the gradient w.r.t. material, emitter, texture and environment leaves
    equals the detached AD gradient on the same random numbers up to float rounding.
    """
    P._check_strategy(strategy)
    return _replay((scene, o, d), u, max_depth, rr_depth, strategy, chunk)
