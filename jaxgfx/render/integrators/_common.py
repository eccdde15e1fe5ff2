"""Shared integrator machinery: scene intersection, material dispatch, shading frames,
emission lookup, light sampling and the densities needed for multiple importance sampling."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgfx._checks import check_choice
from jaxgfx._math import eps_for, safe_div, safe_sqrt, sum_last, take_rows
from jaxgfx.render.geometry import area, intersect_scene, occluded_scene, sample_area
from jaxgfx.render.geometry.area import has_uv_map, point_at_uv
from jaxgfx.render.geometry.frame import frame_from_normal, to_local, to_world
from jaxgfx.render.geometry.ray import spawn_ray
from jaxgfx.render.integrators._wavefront import run_if

__all__ = [
    "intersect",
    "occluded",
    "hit_material",
    "dispatch",
    "shading_frame",
    "tangent_space",
    "emitted",
    "area_emission",
    "sample_light",
    "sample_area_light",
    "light_pdf_hit",
    "env_pdf",
    "mis_power",
    "area_to_solid_angle",
    "spawn_ray",
    "to_local",
    "to_world",
    "SAMPLING",
    "check_sampling",
    "replace_grad",
    "detach_bsdf_sample",
]

SAMPLING = ("detached", "attached")
"""How sampled quantities enter derivatives (docs/render_gradients.md): ``"detached"``
(default; Zeltner et al. 2021, Mitsuba 3 ``prb``) or ``"attached"`` (plain AD through the
samplers; biased where a sampled ray crosses a discontinuity)."""


def check_sampling(sampling) -> None:
    check_choice(sampling, "sampling", SAMPLING)


@jax.custom_jvp
def replace_grad(x, y):
    """Value of ``x`` with the derivative of ``y`` (Dr.Jit's ``replace_grad``).

    A ``custom_jvp`` rather than ``x + (y - stop_gradient(y))``: without a derivative the
    primal never computes ``y`` (XLA removes it), so detached sampling costs nothing in a
    forward render; the tangent rule is linear, so reverse mode works too.
    """
    return x


@replace_grad.defjvp
def _replace_grad_jvp(primals, tangents):
    x, y = primals
    _, ty = tangents
    return x, jnp.broadcast_to(ty, jnp.shape(x)).astype(jnp.result_type(x))


def detach_bsdf_sample(scene, mat, wo, s, uv, frame, *, lazy=False, tangents=None):
    """Detached BSDF sample ``(wi, weight)`` for the next path segment.

    Non-delta lobes: the direction carries no derivative and the weight has the value of the
    sampler's ``s.weight`` but the derivative of ``f(wo, wi; θ) |cos θ_i| / stop_gradient(pdf)``
    (the sampling density is frozen at the current parameters, so the estimator's expectation is
    differentiated: Zeltner et al. 2021, "Monte Carlo Estimators for Differential Light
    Transport", §4). Delta lobes keep their direction (a deterministic function of ``wo`` and the
    parameters, e.g. refraction through ``eta``) and weight; a discrete lobe choice is made
    unbiased inside the BSDF (``SmoothDielectric``: ``R / stop_gradient(R)``).

    ``frame`` (the shading frame): the direction is detached in *world* space, as Mitsuba 3
    ``prb`` does, and returned in world coordinates. Detaching the local direction instead would
    leave ``to_world(frame, wi)`` rotating with the frame, i.e. with shape parameters: the
    sampled rays would sweep across emitter outlines and silhouettes as the surface normal
    turns, a boundary term no estimator adds (docs/render_gradients.md, "Visibility"). Values
    are the same either way; derivatives w.r.t. material parameters differ by rounding only.
    """
    sg = jax.lax.stop_gradient
    wi_w = to_world(frame, s.wi)
    wi_d = sg(wi_w)
    wi_eval = to_local(frame, wi_d)
    f = dispatch(scene, mat, lambda m: m.eval(wo, wi_eval), uv=uv, lazy=lazy, tangents=tangents)
    y = safe_div(f, sg(s.pdf)[..., None])
    delta = s.is_delta[..., None]
    wi = jnp.where(delta, wi_w, wi_d)
    weight = jnp.where(delta, s.weight, replace_grad(s.weight, y))
    return wi, weight


def intersect(scene, o, d, *, tmax=jnp.inf):
    """Closest hit of the rays ``o + t d`` with the scene's shapes, ``0 < t < tmax``."""
    return intersect_scene(scene.shapes, o, d, tmin=0.0, tmax=tmax)


def occluded(scene, o, d, tmax):
    """True where something lies on the segment ``o + t d``, ``0 < t < tmax``."""
    return occluded_scene(scene.shapes, o, d, tmax)


def hit_material(scene, hit):
    """Material index per hit (0 where nothing was hit)."""
    mat = jnp.zeros(hit.t.shape, jnp.int32)
    for s, mats in enumerate(scene.shape_materials):
        pid = jnp.clip(hit.prim_id, 0, mats.shape[0] - 1)
        mat = jnp.where(hit.shape_id == s, take_rows(mats, pid), mat)
    return mat


def dispatch(scene, mat_id, fn, *, uv=None, lazy=False, tangents=None):
    """Evaluate ``fn(bsdf)`` for every material of the scene and select per ray by ``mat_id``.

    Only the materials the scene defines are evaluated (a one-material scene pays for one).
    Textured materials (``jaxgfx.render.bsdf.textured.Textured``) are resolved at the hit ``uv``;
    normal- and bump-mapped ones (class flag ``needs_tangents``) at ``uv`` and ``tangents``
    (:func:`tangent_space`).
    ``lazy``: a material no ray of the batch uses is skipped at run time (a ``lax.cond``; its
    rays would get zeros): for the material-sorted chunks of
    :func:`~jaxgfx.render.integrators._wavefront.shade_sorted`, where most chunks hold one.
    """

    def call(m):
        # textures: only materials with an ``at`` method pay for a lookup
        if getattr(m, "needs_tangents", False):
            return fn(m.at(uv, tangents))
        return fn(m.at(uv) if hasattr(m, "at") else m)

    mats = scene.materials
    if len(mats) == 1:
        return call(mats[0])
    if lazy:
        outs = [run_if(jnp.any(mat_id == k), lambda m=m: call(m)) for k, m in enumerate(mats)]
    else:
        outs = [call(m) for m in mats]

    def select(*xs):
        r = xs[0]
        for k in range(1, len(xs)):
            x = xs[k]
            m = (mat_id == k).reshape(mat_id.shape + (1,) * (x.ndim - mat_id.ndim))
            r = jnp.where(m, x, r)
        return r

    return jax.tree_util.tree_map(select, *outs)


def select_candidate(cands, idx):
    """Per element, the pytree ``cands[idx]`` of a list of same-structure candidate pytrees
    (``idx`` integer, the batch shape of the leaves' leading axes): a chain of ``where``."""
    out = cands[0]
    for k in range(1, len(cands)):
        sel = idx == k
        out = jax.tree_util.tree_map(
            lambda a, b, sel=sel: jnp.where(
                sel.reshape(sel.shape + (1,) * (a.ndim - sel.ndim)), b, a
            ),
            out,
            cands[k],
        )
    return out


def material_flag(scene, mat_id, attr):
    flags = [bool(getattr(m, attr)) for m in scene.materials]
    if all(flags):
        return jnp.ones(mat_id.shape, bool)
    if not any(flags):
        return jnp.zeros(mat_id.shape, bool)
    return jnp.asarray(flags)[mat_id]


def shading_frame(scene, hit, d, mat_id):
    """Shading frame and local ``wo``.

    For reflection-only materials the normals are flipped to the side of the incoming ray
    (two-sided shading); transmissive materials keep the geometric orientation so that
    ``wo.z < 0`` means "inside", and so do one-sided materials (:attr:`Scene.one_sided
    <jaxgfx.render.scene.Scene.one_sided>`): seen from behind, ``wo.z < 0`` and their
    reflection lobes return 0 (Mitsuba 3's ``diffuse`` etc. without ``twosided``). A scene
    without one-sided materials computes exactly what it did before the flag existed.
    """
    trans = material_flag(scene, mat_id, "is_transmissive")
    one_sided = any(getattr(scene, "one_sided", ()))  # static
    if one_sided:  # nothing more in scenes without one-sided materials
        sided = jnp.asarray(scene.one_sided)[mat_id]
        trans = trans | sided
    facing = sum_last(hit.ng * d) < 0
    flip = jnp.where(trans | facing, 1.0, -1.0)[..., None]
    ng = hit.ng * flip
    ns = hit.ns * flip
    # keep the shading normal on the geometric side of the ray
    ns = jnp.where((sum_last(ns * ng) > 0)[..., None], ns, ng)
    if one_sided:  # Mitsuba's one-sided BSDFs test the side in the shading frame as it is
        ns = jnp.where(sided[..., None], hit.ns, ns)
    frame = frame_from_normal(ns)
    wo = to_local(frame, -d)
    return frame, ng, wo


def tangent_space(scene, hit, frame):
    """The tangent space (:class:`~jaxgfx.render.bsdf.TangentSpace`) at the hits,
    in the local coordinates of the shading ``frame``, or ``None`` when no material of the
    scene needs it (no normal or bump map: nothing is computed).

    ``s`` = ``dp/du`` projected onto the shading plane (``(1, 0, 0)`` where that vanishes),
    ``t = n_front x s`` with ``n_front`` the unflipped side's normal (so a two-sided material's
    back side sees the front's tangents mirrored, as Mitsuba 3 ``twosided`` does).
    """
    if not any(getattr(m, "needs_tangents", False) for m in scene.materials):
        return None
    from jaxgfx.render.bsdf import TangentSpace  # noqa: PLC0415
    from jaxgfx.render.geometry.tangent import surface_tangents  # noqa: PLC0415

    dpdu, dpdv = surface_tangents(scene.shapes, hit)
    du_l, dv_l = to_local(frame, dpdu), to_local(frame, dpdv)
    sigma = jnp.where(sum_last(frame.n * hit.ng) < 0, -1.0, 1.0).astype(du_l.dtype)
    sx, sy = du_l[..., 0], du_l[..., 1]
    r2 = sx * sx + sy * sy
    ok = r2 > 1e-12 * jnp.maximum(sum_last(du_l * du_l), 1e-30)
    inv = jnp.where(ok, jax.lax.rsqrt(jnp.where(ok, r2, 1.0)), 0.0)
    sx, sy = jnp.where(ok, sx * inv, 1.0), jnp.where(ok, sy * inv, 0.0)
    z0 = jnp.zeros_like(sx)
    s = jnp.stack([sx, sy, z0], axis=-1)
    t = jnp.stack([-sigma * sy, sigma * sx, z0], axis=-1)
    du = jnp.stack([sum_last(du_l * s), sum_last(du_l * t)], axis=-1)
    dv = jnp.stack([sum_last(dv_l * s), sum_last(dv_l * t)], axis=-1)
    return TangentSpace(s=s, t=t, du=du, dv=dv)


def emission_table(scene, dtype):
    """Per-shape constant radiance ``(S, 3)`` (0 for textured lights and non-emitters) and
    inverse emitter area ``(S,)``."""
    n = len(scene.shapes)
    table = jnp.zeros((n, 3), dtype)
    inv_area = jnp.zeros((n,), dtype)
    for al, sh in zip(scene.area_lights, scene.emitter_shapes, strict=True):
        if not al.textured:  # textured lights: area_emission looks them up at the uv
            table = table.at[al.shape_index].set(al.radiance.astype(dtype))
        inv_area = inv_area.at[al.shape_index].set(1.0 / area(sh).astype(dtype))
    return table, inv_area


def _lookup_emission(scene, table, sid, uv, dtype):
    out = take_rows(table, sid)
    for al in scene.area_lights:  # textured lights only: nothing more for constant ones
        if al.textured:
            on = (sid == al.shape_index)[..., None]
            out = jnp.where(on, al.radiance_at(uv[..., :2].astype(dtype)), out)
    return out


def area_emission(scene, shape_id, uv, dtype=None):
    """Radiance ``(..., 3)`` of the area light on shape ``shape_id (...)`` at surface
    coordinates ``uv (..., 2)`` (0 on shapes that do not emit; no front-side test): the emission
    lookup by shape index and ``uv`` that camera / BSDF rays hitting an emitter use
    (:func:`emitted`), for light tracers too. A textured light's texture is evaluated only in
    scenes that have one (a scene of constant lights runs the table lookup alone)."""
    dtype = uv.dtype if dtype is None else dtype
    table, _ = emission_table(scene, dtype)
    sid = jnp.clip(shape_id, 0, len(scene.shapes) - 1)
    return _lookup_emission(scene, table, sid, uv, dtype)


def emitted(scene, hit, d):
    """Radiance emitted towards ``-d`` at hits on area lights (front side only)."""
    if not scene.area_lights:
        return jnp.zeros(d.shape, d.dtype)
    table, _ = emission_table(scene, d.dtype)
    sid = jnp.clip(hit.shape_id, 0, len(scene.shapes) - 1)
    front = (sum_last(hit.ng * d) < 0) & hit.valid
    return jnp.where(front[..., None], _lookup_emission(scene, table, sid, hit.uv, d.dtype), 0.0)


def mis_power(a, b):
    """Power heuristic (beta = 2) weight ``a² / (a² + b²)`` of a strategy with density ``a``
    against ``b`` (0 where both are 0).

    Computed from the ratio of the smaller density to the larger, ``1 / (1 + (b/a)²)`` or
    ``(a/b)² / (1 + (a/b)²)``, so that a density whose square overflows (a float32 density
    above 1.8e19, e.g. an emitter seen edge-on) or an infinite one gives a weight in [0, 1]
    and finite derivatives, not ``inf / inf`` = NaN; both infinite gives 1/2.
    """
    a, b = jnp.broadcast_arrays(a, b)
    a_big = a >= b
    lo = jnp.where(a_big, b, a)
    hi = jnp.where(a_big, a, b)
    both_inf = jnp.isinf(lo)  # lo <= hi: lo infinite means both are
    ok = (hi > 0) & ~both_inf
    r = jnp.where(jnp.isinf(hi), 0.0, safe_div(lo, jnp.where(ok, hi, 1.0)))  # lo/hi in [0, 1]
    r2 = r * r
    w = jnp.where(a_big, 1.0, r2) / (1.0 + r2)
    return jnp.where(ok, w, jnp.where(both_inf, 0.5, 0.0))


def area_to_solid_angle(pdf_area, dist2, cos_l):
    """Solid-angle density ``pdf_area * dist2 / |cos_l|`` of a point on an emitter seen at
    squared distance ``dist2`` under the cosine ``cos_l`` (at the emitter, to the direction).

    0 where ``|cos_l|`` is below the dtype's epsilon, i.e. zero to working precision: the
    direction lies in the emitter's tangent plane, as from a shading point on the emitter's own
    surface (for a planar light, every light sample then lies in that plane). Such a point
    subtends no solid angle, so it contributes nothing (pbrt-v4 likewise drops a light sample
    whose solid-angle density is infinite); without the cut, a rounding-level cosine (3.7e-20:
    a rectangle rotated by 90 degrees has a normal component of cos(pi/2) = 6.1e-17) gave a
    float32 density of 2e19, whose square in :func:`mis_power` overflowed to ``inf / inf``.
    The samples dropped have a contribution proportional to ``|cos_l| < eps`` (bias below the
    dtype's rounding). Light sampling and :func:`light_pdf_hit` use this same function, so
    the MIS weights of both strategies still sum to 1. Finite value and derivatives (double
    ``where``: the ratio is formed only where the cosine is kept).
    """
    c = jnp.abs(cos_l)
    ok = c > eps_for(c)
    return jnp.where(ok, pdf_area * dist2 / jnp.where(ok, c, 1.0), 0.0)


def _selection_prob(scene, dtype):
    return jnp.asarray(1.0 / max(scene.n_lights, 1), dtype)


def light_pdf_hit(scene, p_prev, hit, d):
    """Solid-angle density with which light sampling from ``p_prev`` picks this hit."""
    if not scene.area_lights:
        return jnp.zeros(hit.t.shape, d.dtype)
    _, inv_area = emission_table(scene, d.dtype)
    sid = jnp.clip(hit.shape_id, 0, len(scene.shapes) - 1)
    cos_l = sum_last(hit.ng * d)
    dist2 = sum_last((hit.p - p_prev) ** 2)
    pdf = area_to_solid_angle(_area_pdf(scene, inv_area, sid, hit.uv, d.dtype), dist2, cos_l)
    return jnp.where(hit.valid, pdf * _selection_prob(scene, d.dtype), 0.0)


def _uv_sampled(al, sh) -> bool:
    """Whether the light's samples follow its texture (static): a bitmap radiance on one
    rectangle or sphere (the shapes whose uv maps back to a point); else uniform by area."""
    return al.samples_texture and has_uv_map(sh)


def _area_pdf(scene, inv_area, sid, uv, dtype):
    """Area density of light sampling at hits on shapes ``sid`` with surface coordinates ``uv``."""
    pdf = take_rows(inv_area, sid)
    for al, sh in zip(scene.area_lights, scene.emitter_shapes, strict=True):
        if _uv_sampled(al, sh):  # texture-sampled lights only: nothing more for the others
            _, _, jac = point_at_uv(sh, uv[..., :2].astype(dtype))
            pdf_uv = al.uv_distribution(dtype).pdf(uv[..., :2].astype(dtype))
            pdf = jnp.where(sid == al.shape_index, _per_area(pdf_uv, jac), pdf)
    return pdf


def _per_area(pdf_uv, jac):
    """``pdf_uv / jac`` (density per unit area), 0 where the map degenerates (sphere poles)."""
    ok = jac > 0
    return jnp.where(ok, pdf_uv / jnp.where(ok, jac, 1.0), 0.0)


def sample_area_light(al, sh, u2, dtype):
    """A point on area light ``al`` (shape ``sh``) from uniform numbers ``u2 (..., 2)``:
    ``(p, n, pdf_area, radiance)``, the radiance the light emits there (front side).

    As Mitsuba 3's ``area`` emitter: a constant radiance is sampled uniformly by area; a bitmap
    radiance on a rectangle or sphere by the texture (:meth:`AreaLight.uv_distribution`, the
    sampled ``uv`` mapped onto the shape, density ``pdf_uv / |dp/du x dp/dv|``, frozen w.r.t.
    the texels); other textured lights (meshes, checkerboards) uniformly by area with the
    texture looked up at the sampled point's ``uv``. For light tracers as for next-event
    estimation."""
    if _uv_sampled(al, sh):
        uvl, pdf_uv = al.uv_distribution(dtype).sample(u2)
        uvl = jax.lax.stop_gradient(uvl)
        pl, nl, jac = point_at_uv(sh, uvl)
        return pl, nl, _per_area(jax.lax.stop_gradient(pdf_uv), jac), al.radiance_at(uvl)
    if al.textured:  # the radiance at the sampled point's uv
        pl, nl, pdf_a, uvl = sample_area(sh, u2, with_uv=True)
        return pl, nl, pdf_a, al.radiance_at(uvl.astype(dtype))
    pl, nl, pdf_a = sample_area(sh, u2)
    return pl, nl, pdf_a, al.radiance.astype(dtype)


def env_pdf(scene, d):
    if scene.environment is None:
        return jnp.zeros(d.shape[:-1], d.dtype)
    return scene.environment.pdf(d) * _selection_prob(scene, d.dtype)


def sample_light(scene, p, u_sel, u2, *, detached=False):
    """Pick a light uniformly and sample it from points ``p``.

    ``detached``: the environment sample's direction and density carry no derivative and its
    radiance is re-evaluated at the detached direction (an environment map is importance
    sampled by its own texels). Area-light samples stay attached: the point moves with the
    emitter shape and the density is the area measure's (the correct derivative w.r.t. the
    emitter's geometry, as Mitsuba 3 ``prb`` re-attaches its emitter sample).
    Returns ``(wi, dist, Li, pdf, is_delta)``: world direction towards the light, distance
    (inf for the environment), unoccluded incident radiance, solid-angle density including the
    selection probability (1 x selection for point lights), and whether it is a delta light.
    Light order: area lights, point lights, environment, directional and spot lights.
    """
    dtype = p.dtype
    n = scene.n_lights
    idx = jnp.minimum((u_sel * n).astype(jnp.int32), n - 1)
    cands = []
    for al, sh in zip(scene.area_lights, scene.emitter_shapes, strict=True):
        pl, nl, pdf_a, rad = sample_area_light(al, sh, u2, dtype)
        v = pl - p
        d2 = sum_last(v * v)
        dist = safe_sqrt(d2)
        wi = safe_div(v, dist[..., None])
        cos_l = -sum_last(nl * wi)
        pdf = area_to_solid_angle(pdf_a, d2, cos_l)  # 0 for a point seen edge-on
        li = jnp.where(((cos_l > 0) & (pdf > 0))[..., None], rad, 0.0)
        cands.append((wi, dist, li, pdf, jnp.zeros(p.shape[:-1], bool)))
    na = len(scene.area_lights)
    if scene.point_lights is not None:
        j = jnp.clip(idx - na, 0, scene.point_lights.count - 1)
        wi, dist, li = scene.point_lights.sample(j, p)
        ones = jnp.ones(p.shape[:-1], dtype)
        cands.append((wi, dist, li, ones, jnp.ones(p.shape[:-1], bool)))
    if scene.environment is not None:
        wi, pdf, li = scene.environment.sample(u2)
        if detached:
            wi, pdf = jax.lax.stop_gradient((wi, pdf))
            li = scene.environment.eval(wi)
        dist = jnp.full(p.shape[:-1], jnp.inf, dtype)
        cands.append((wi, dist, li, pdf, jnp.zeros(p.shape[:-1], bool)))
    # map light index -> candidate index
    n_point = scene.point_lights.count if scene.point_lights is not None else 0
    cand_idx = jnp.where(idx < na, idx, jnp.where(idx < na + n_point, na, na + (n_point > 0)))
    if scene.delta_lights:  # directional / spot lights, after the environment (delta lights)
        n_before = na + n_point + (scene.environment is not None)
        c_before = len(cands)
        for light in scene.delta_lights:
            wi, dist, li = light.sample(p)
            ones = jnp.ones(p.shape[:-1], dtype)
            cands.append((wi, dist, li, ones, jnp.ones(p.shape[:-1], bool)))
        cand_idx = jnp.where(idx < n_before, cand_idx, c_before + idx - n_before)
    wi, dist, li, pdf, is_delta = select_candidate(cands, cand_idx)
    return wi, dist, li, pdf * _selection_prob(scene, dtype), is_delta
