"""Particle (light) tracing: paths start on the emitters and every vertex is connected to the
camera, its contribution splatted into the film (Veach 1997 §10.2; Mitsuba 3's ``ptracer``).

It estimates the same image as the path tracer, by the adjoint of its estimator: a light path
``y0 y1 ... yk`` carries the power-like weight ``Le / p(y0, ω0) · Π f* |cos| / p`` and each
vertex ``yi`` adds ``weight · We(yi -> camera) · f*(yi) · V / dist²`` to the pixel it projects
to. It sees what a camera path cannot complete: the caustic of a point or spot light through
a smooth mirror or dielectric onto a diffuse surface (a camera path reaches the delta BSDF
and then needs to hit a delta light).

Conventions (Mitsuba 3 ``ptracer``):

- Depth: ``max_depth = 1`` only the directly visible emitters (a point sampled on an area
  light by area and connected to the camera; delta lights are never visible), ``2`` adds
  direct light (the first vertex of the light path), ``3`` one more bounce, ...
- Emission: an emitter is picked uniformly (the order of
  :func:`~jaxgfx.render.integrators._common.sample_light`); point lights emit uniformly over
  the sphere (weight ``4π I``), spot lights uniformly in their cutoff cone (weight
  ``I falloff 2π (1 - cos cutoff)``, times the projected texture at the direction's ``uv``
  for a textured spot), projectors through a point uniform on their image rectangle at unit
  distance (weight ``π scale E(uv) A``, ``A`` the rectangle's area: the density of the
  direction ``r³ / A`` against the intensity ``π scale E / cos³θ``), area lights from a
  point drawn as the path tracer's light sampling draws it
  (:func:`~jaxgfx.render.integrators._common.sample_area_light`: by area, or by the texels
  of a bitmap radiance) and a cosine-weighted direction on their front side (weight
  ``π L(uv) / pdf_area``, ``L(uv)`` the radiance there, textured or constant),
  ``directionalarea`` lights from a point uniform by area along the normal there (weight
  ``L A``, Mitsuba's ``sample_ray``; never directly visible); each divided by the selection
  probability.
- Sensor: the pinhole's importance ``We = 1 / (A cos³θ)`` (``A`` the area of the image
  rectangle at unit distance) divided by the squared distance; the film holds the sum of the
  splats of ``W H spp`` light paths divided by ``spp``.
- Russian roulette after ``rr_depth`` bounces with survival ``min(max(β) η², 0.95)``, ``β``
  the path weight including the emitter's (so a bright light rarely stops).
- Adjoint BSDF: jaxgfx's ``eval(wo, wi)`` / ``sample(wo, ...)`` are called with ``wo`` the
  direction towards the previous vertex of the light path (the light's side). For reciprocal
  BSDFs (every reflection model) that is the adjoint BSDF times the cosine at the new
  direction. Refraction in radiance mode carries ``1 / η²``, which importance transport does
  not: sampled refractions are multiplied by the sample's ``η²`` and evaluated transmission
  pairs of a material with an ``eta`` by ``η_it²`` of the ``wo`` side. Shading normals get
  Veach's correction ``|cos(wo, ns) cos(wi, ng)| / |cos(wi, ns) cos(wo, ng)|`` and
  light-leak checks (both as Mitsuba 3).
- Splatting: Mitsuba's ``ImageBlock`` with normalisation: the filter is evaluated at the
  centres of the pixels within its radius of the splat position and the weights divided by
  their sum (box: the one pixel the position lies in). Note that jaxgfx's camera-ray
  integrators use filter importance sampling instead: with the box filter both estimate the
  same pixel integral; with ``gaussian`` / ``tent`` the two reconstructions differ slightly.

- Distant emitters (Mitsuba 3's ``sample_ray`` of ``directional``, ``constant``, ``envmap``):
  the direction is the light's (directional) or sampled by the environment's own sampler
  (``constant``: uniform sphere, ``envmap``: its texel distribution; detached, the radiance
  re-evaluated there); the origin is uniform on the disk of radius ``R`` perpendicular to it,
  centred ``R`` upstream of the centre of the scene's bounding sphere (the bounding box's, the
  camera not included); weight ``irradiance π R²`` or ``L / pdf π R²``. A directly visible
  environment: a direction sampled from the camera's position, ``L We / pdf`` where
  unoccluded (Mitsuba samples it from the sensor's position too).

Not supported (one ``ValueError`` naming it, before tracing): other emitter types, distant
emitters in a scene with a shape that has no bounds here (SDFs), cameras other than the pinhole
:class:`~jaxgfx.render.camera.PerspectiveCamera`.

Derivatives: reverse mode through the splat (``.at[].add``): emitter intensities / radiances
and material parameters. BSDF samples are detached as in the path tracer (the direction
carries no derivative, the weight the derivative of ``f / stop_gradient(pdf)``); the emission
sample is attached (point, direction: a moving emitter moves its particles).
"""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from jaxgfx._math import max_last, safe_div, safe_sqrt, sum_last, take_rows
from jaxgfx.render.bsdf.texture import lookup
from jaxgfx.render.camera import PerspectiveCamera, look_at_basis
from jaxgfx.render.emitters import (
    AreaLight,
    DirectionalAreaLight,
    DirectionalLight,
    ProjectorLight,
    SpotLight,
)
from jaxgfx.render.film import BoxFilter, GaussianFilter, TentFilter
from jaxgfx.render.geometry import sample_area
from jaxgfx.render.geometry.frame import frame_from_normal, to_world
from jaxgfx.render.geometry.instance import Instances
from jaxgfx.render.geometry.mesh import TriangleMesh
from jaxgfx.render.geometry.rectangle import Rectangles
from jaxgfx.render.geometry.sphere import Spheres
from jaxgfx.render.integrators import _common as C
from jaxgfx.render.integrators.base import Integrator, check_depth
from jaxgfx.render.sampler import uniform
from jaxgfx.render.sampling import (
    square_to_cosine_hemisphere,
    square_to_uniform_cone,
    square_to_uniform_disk_concentric,
    square_to_uniform_sphere,
)

__all__ = ["ParticleTracer", "light_trace", "check_light_tracing"]

N_EMIT = 8  # uniform numbers per light path at its start: visible emitter (3), emission (5)
N_BOUNCE = 4  # per bounce: BSDF lobe, BSDF direction (2), Russian roulette


def check_light_tracing(scene) -> None:
    """``ValueError`` naming what the particle tracer cannot trace in ``scene`` (host-side,
    before tracing): a camera other than the pinhole, an emitter type it does not know, an
    environment or directional light in a scene with a shape it cannot bound (an SDF)."""
    cam = scene.camera
    if type(cam) is not PerspectiveCamera:
        raise ValueError(
            f"camera: the 'ptracer' integrator connects paths to a pinhole camera "
            f"(PerspectiveCamera), got {type(cam).__name__}"
        )
    for k, light in enumerate(scene.delta_lights):
        name = type(light).__name__
        if type(light) not in (SpotLight, DirectionalLight, ProjectorLight, DirectionalAreaLight):
            raise ValueError(
                f"emitters: the 'ptracer' integrator does not trace {name} (delta_lights[{k}]): "
                "point, spot, projector, directional, directionalarea, area and environment "
                "lights only; use 'path'"
            )
    for k, al in enumerate(scene.area_lights):
        if type(al) is not AreaLight or (not al.textured and jnp.shape(al.radiance) != (3,)):
            raise ValueError(
                f"emitters: the 'ptracer' integrator traces area lights of RGB or textured "
                f"radiance, got {type(al).__name__} (area_lights[{k}])"
            )
    distant = scene.environment is not None or any(
        type(x) is DirectionalLight for x in scene.delta_lights
    )
    if distant:
        _bounds_parts(scene)  # raises for a shape it cannot bound


# -- the scene's bounding sphere (environment and directional emission) -------------------


def _bounds_parts(scene):
    """Per shape ``(lo (M, 3), hi (M, 3))`` point bounds; ``ValueError`` naming a shape the
    particle tracer cannot bound (needed only with an environment or a directional light)."""
    parts = []
    for k, sh in enumerate(scene.shapes):
        m = getattr(sh, "mesh", sh)  # acceleration structures hold their mesh
        if isinstance(m, Spheres):
            c, r = m.centers.reshape(-1, 3), m.radii.reshape(-1, 1)
            parts.append((c - r, c + r))
        elif isinstance(m, Rectangles):
            c = m.centers.reshape(-1, 3)
            h = 0.5 * (jnp.abs(m.edge_u.reshape(-1, 3)) + jnp.abs(m.edge_v.reshape(-1, 3)))
            parts.append((c - h, c + h))
        elif isinstance(m, TriangleMesh):
            parts.append((m.vertices, m.vertices))
        elif isinstance(m, Instances) and m.bounds is not None:
            parts.append((m.bounds[:, 0], m.bounds[:, 1]))
        else:
            raise ValueError(
                f"shapes[{k}]: the 'ptracer' integrator emits environment and directional "
                f"light from a disk over the scene's bounding sphere and cannot bound a "
                f"{type(m).__name__}; use 'path'"
            )
    return parts


def _bounding_sphere(scene, dtype):
    """Centre and radius of the sphere around the scene's bounding box (Mitsuba 3: the
    distant emitters' ``m_bsphere``; the camera is not included), slightly enlarged."""
    parts = _bounds_parts(scene)
    lo = jnp.min(jnp.concatenate([a.astype(dtype) for a, _ in parts]), 0)
    hi = jnp.max(jnp.concatenate([b.astype(dtype) for _, b in parts]), 0)
    center = 0.5 * (lo + hi)
    radius = 0.5 * jnp.linalg.norm(hi - lo) * (1 + 1e-4) + 1e-4
    return jax.lax.stop_gradient((center, radius))


def _disk_origin(center, radius, d, u):
    """Ray origins on the disk of ``radius`` perpendicular to the unit directions ``d``,
    centred at ``center - radius d`` (the rays ``o + t d`` cross the whole bounding sphere)."""
    off = square_to_uniform_disk_concentric(u)
    zero = jnp.zeros_like(off[..., :1])
    perp = to_world(frame_from_normal(d), jnp.concatenate([off, zero], -1))
    return center + (perp - d) * radius


# -- the sensor ---------------------------------------------------------------------------


def _sensor_connection(cam: PerspectiveCamera, x):
    """Connect world points ``x (..., 3)`` to the pinhole: ``(pixel (..., 2), dir (..., 3)
    from x to the camera, dist, We / dist², valid)``; ``valid`` where the point projects into
    the image in front of the camera."""
    dt = x.dtype
    o = cam.origin.astype(dt)
    right, up, fwd = look_at_basis(o, cam.target.astype(dt), cam.up.astype(dt))
    t = jnp.tan(jnp.deg2rad(cam.fov.astype(dt)) * 0.5)
    aspect = cam.width / cam.height
    tx, ty = (t, t / aspect) if cam.fov_axis == "x" else (t * aspect, t)
    v = x - o
    z = sum_last(v * fwd)
    front = z > 0
    zs = jnp.where(front, z, 1.0)
    sx = sum_last(v * right) / zs
    sy = sum_last(v * up) / zs
    px = (sx / tx + 1.0) * (0.5 * cam.width)
    py = (1.0 - sy / ty) * (0.5 * cam.height)
    inside = front & (px >= 0) & (px < cam.width) & (py >= 0) & (py < cam.height)
    d2 = sum_last(v * v)
    dist = safe_sqrt(d2)
    to_cam = safe_div(-v, dist[..., None])
    # We / dist² = 1 / (A cos³θ dist²) = dist / (A z³)  (A = 4 tx ty, cos θ = z / dist)
    w = jnp.where(inside, dist / (4.0 * tx * ty * zs * zs * zs), 0.0)
    return jnp.stack([px, py], -1), to_cam, dist, w, inside


def _visible(scene, x, n, to_cam, dist):
    """True where the segment from ``x`` (spawned off the surface of normal ``n``) to the
    camera is free (boolean: no derivative)."""
    so, sd = C.spawn_ray(x, n, to_cam)
    tmax = dist * (1 - 1e-4)
    so, sd, tmax = jax.lax.stop_gradient((so, sd, tmax))
    return ~C.occluded(scene, so, sd, tmax)


# -- emission -----------------------------------------------------------------------------


def _light_index(scene, u_sel):
    """Uniform light choice ``-> (candidate index, point-light row)``: candidates are the area
    lights, the point lights (one candidate), then the spot lights."""
    n = scene.n_lights
    idx = jnp.minimum((u_sel * n).astype(jnp.int32), n - 1)
    na = len(scene.area_lights)
    n_point = scene.point_lights.count if scene.point_lights is not None else 0
    cand = jnp.where(idx < na, idx, jnp.where(idx < na + n_point, na, idx - n_point + 1))
    if n_point == 0:
        cand = idx
    row = jnp.clip(idx - na, 0, max(n_point - 1, 0))
    return cand, row


def _projector_emission(light, u):
    """A ray leaving projector ``light`` from ``u (..., 2)``: a point uniform on the image
    rectangle at unit distance (``uv = u``; ``x = (1 - 2u) t``, ``y = (1 - 2v) t / aspect``,
    ``t = tan(fov / 2)``, area ``A = 4 t² / aspect``). Its solid-angle density is
    ``r³ / A`` (``r = 1 / cos θ`` the distance to the point) and the intensity there
    ``π scale E(uv) / cos³ θ`` (the irradiance ``π scale E / z²`` on a plane facing it), so the
    weight is ``π scale E(uv) A``."""
    dtype = u.dtype
    t = jnp.tan(jnp.deg2rad(light.fov.astype(dtype)) * 0.5)
    x = (1.0 - 2.0 * u[..., 0]) * t
    y = (1.0 - 2.0 * u[..., 1]) * t / light.aspect
    loc = jnp.stack([x, y, jnp.ones_like(x)], -1)
    d = loc @ light.frame.astype(dtype)
    d = d / jnp.linalg.norm(d, axis=-1, keepdims=True)  # |loc| >= 1: no zero norm
    area = 4.0 * t * t / light.aspect
    e = lookup(light.irradiance, u).astype(dtype)
    w = e * (math.pi * light.scale.astype(dtype) * area)
    o = jnp.broadcast_to(light.position.astype(dtype), d.shape)
    return o, d, w


def sample_emission(scene, u):
    """A ray leaving an emitter, from uniform numbers ``u (..., 5)`` (select, position (2),
    direction (2)): ``(o, d, weight)`` with ``weight = Le cos / (p_select p_pos p_dir)``."""
    dtype = u.dtype
    batch = u.shape[:-1]
    u_pos, u_dir = u[..., 1:3], u[..., 3:5]
    cand, row = _light_index(scene, u[..., 0])
    n_sel = jnp.asarray(scene.n_lights, dtype)
    cands = []
    for al, sh in zip(scene.area_lights, scene.emitter_shapes, strict=True):
        p, n, pdf_a, rad = C.sample_area_light(al, sh, u_pos, dtype)  # L(uv) if textured
        local = square_to_cosine_hemisphere(u_dir)
        d = to_world(frame_from_normal(n), local)
        o, _ = C.spawn_ray(p, n, d)
        w = rad * safe_div(math.pi, pdf_a)[..., None]
        cands.append((o, d, w))
    if scene.point_lights is not None:
        pl = scene.point_lights
        o = take_rows(pl.positions.astype(dtype), row)
        d = square_to_uniform_sphere(u_dir)
        w = 4.0 * math.pi * take_rows(pl.intensities.astype(dtype), row)
        cands.append((o, d, w))
    if scene.environment is not None or any(
        type(x) is DirectionalLight for x in scene.delta_lights
    ):
        center, radius = _bounding_sphere(scene, dtype)
        disk = math.pi * radius * radius
    if scene.environment is not None:
        env = scene.environment
        wi, pdf, _ = env.sample(u_dir)  # towards the environment: the light travels along -wi
        wi, pdf = jax.lax.stop_gradient((wi, pdf))
        le = env.eval(wi)  # re-attached radiance at the detached direction (as light sampling)
        d = -wi
        o = _disk_origin(center, radius, d, u_pos)
        w = le * (disk * safe_div(1.0, pdf))[..., None]
        cands.append((o, d, w))
    for light in scene.delta_lights:  # spot, projector, directional (check_light_tracing)
        if type(light) is DirectionalAreaLight:  # along the normal at a point uniform by area
            p, n, pdf_a = sample_area(light.shape, u_pos)
            o, _ = C.spawn_ray(p, n, n)
            w = light.radiance.astype(dtype) * safe_div(1.0, pdf_a)[..., None]
            cands.append((o, n, w))
            continue
        if type(light) is ProjectorLight:
            cands.append(_projector_emission(light, u_dir))
            continue
        if type(light) is DirectionalLight:
            d = light.direction.astype(dtype)
            d = jnp.broadcast_to(d / jnp.linalg.norm(d), batch + (3,))
            o = _disk_origin(center, radius, d, u_pos)
            w = jnp.broadcast_to(light.irradiance.astype(dtype) * disk, batch + (3,))
            cands.append((o, d, w))
            continue
        cos_cut = jnp.cos(jnp.deg2rad(light.cutoff_angle.astype(dtype)))
        local = square_to_uniform_cone(u_dir, cos_cut)
        axis = light.direction.astype(dtype)
        axis = axis / jnp.linalg.norm(axis)
        d = to_world(frame_from_normal(jnp.broadcast_to(axis, batch + (3,))), local)
        fall = light.falloff(local[..., 2])
        w = (light.intensity.astype(dtype) * (2.0 * math.pi) * (1.0 - cos_cut)) * fall[..., None]
        if light.texture is not None:  # the projected texture at the direction's uv
            w = w * light.texture_value(d)
        o = jnp.broadcast_to(light.position.astype(dtype), batch + (3,))
        cands.append((o, d, w))
    o, d, w = C.select_candidate([jax.tree_util.tree_map(lambda a: jnp.broadcast_to(
        a, batch + a.shape[-1:]), c) for c in cands], cand)  # fmt: skip
    return o, d, w * n_sel


def _visible_emitters(scene, u):
    """Directly visible emitters: a point drawn by area on a uniformly chosen area light, or a
    direction sampled on the environment from the camera, connected to the camera ->
    ``(value (..., 3), pixel (..., 2))`` (0 for delta lights)."""
    dtype = u.dtype
    batch = u.shape[:-1]
    val = jnp.zeros(batch + (3,), dtype)
    pix = jnp.zeros(batch + (2,), dtype)
    if not scene.area_lights and scene.environment is None:
        return val, pix
    cand, _ = _light_index(scene, u[..., 0])
    n_sel = jnp.asarray(scene.n_lights, dtype)
    na = len(scene.area_lights)
    if scene.area_lights:
        cands = []
        for al, sh in zip(scene.area_lights, scene.emitter_shapes, strict=True):
            p, n, pdf_a, rad = C.sample_area_light(al, sh, u[..., 1:3], dtype)
            cands.append((p, n, rad * safe_div(1.0, pdf_a)[..., None]))
        p, n, le = C.select_candidate(cands, jnp.clip(cand, 0, na - 1))
        pix, to_cam, dist, we, ok = _sensor_connection(scene.camera, p)
        cos_l = sum_last(n * to_cam)  # the front side only (jaxgfx area lights emit along ng)
        ok = ok & (cand < na) & (cos_l > 0) & _visible(scene, p, n, to_cam, dist)
        v = le * (n_sel * we * jnp.maximum(cos_l, 0.0))[..., None]
        val = jnp.where(ok[..., None], v, 0.0)
    if scene.environment is not None:
        env = scene.environment
        has_point = scene.point_lights is not None
        wi, pdf, _ = env.sample(u[..., 1:3])
        wi, pdf = jax.lax.stop_gradient((wi, pdf))
        le = env.eval(wi)
        o = jnp.broadcast_to(scene.camera.origin.astype(dtype), wi.shape)
        # We of the direction: the connection to the point at unit distance along wi
        pix_e, _, _, we, ok = _sensor_connection(scene.camera, o + wi)
        free = ~C.occluded(scene, o, wi, jnp.full(batch, jnp.inf, dtype))
        ok = ok & (cand == na + int(has_point)) & free & (pdf > 0)
        v = le * (n_sel * we * safe_div(1.0, pdf))[..., None]
        val = jnp.where(ok[..., None], v, val)
        pix = jnp.where(ok[..., None], pix_e, pix)
    return val, pix


# -- the light path -----------------------------------------------------------------------


def _eta2_eval(m, wo, wi):
    """``η_it²`` of the ``wo`` side for a transmission pair of a refracting material, else 1:
    what turns jaxgfx's radiance-mode ``eval`` of refraction into importance transport."""
    eta = getattr(m, "eta", None)
    if not getattr(m, "is_transmissive", False) or eta is None:
        return jnp.ones(wo.shape[:-1], wo.dtype)
    eta = jnp.asarray(eta, wo.dtype)
    e_it = jnp.where(wo[..., 2] > 0, eta, 1.0 / eta)
    return jnp.where(wo[..., 2] * wi[..., 2] < 0, e_it * e_it, 1.0)


def _shading_correction(wo_l, wi_l, ng, wo_w, wi_w):
    """Veach's adjoint shading-normal factor ``|cos(wo, ns) cos(wi, ng)| / |cos(wi, ns)
    cos(wo, ng)|`` and the light-leak test (shading and geometric sides agree for both)."""
    c_o_g = sum_last(ng * wo_w)
    c_i_g = sum_last(ng * wi_w)
    ok = (c_o_g * wo_l[..., 2] > 0) & (c_i_g * wi_l[..., 2] > 0)
    num = jnp.abs(wo_l[..., 2] * c_i_g)
    den = jnp.abs(wi_l[..., 2] * c_o_g)
    return jnp.where(ok, safe_div(num, jnp.where(ok, den, 1.0)), 0.0), ok


def _bounce(scene, carry, ub, depth, rr_depth):
    """One vertex of the light path: connect it to the camera, then sample the next segment.
    ``carry = (o, d, beta, eta, alive)``; returns ``(carry, (value (..., 3), pixel (..., 2)))``."""
    o, d, beta, eta, alive = carry
    hit = C.intersect(scene, o, d)
    alive = alive & hit.valid
    mat = C.hit_material(scene, hit)
    frame, ng, wo = C.shading_frame(scene, hit, d, mat)
    tg = C.tangent_space(scene, hit, frame)
    wo_w = -d
    # connection to the camera
    pix, to_cam, dist, we, in_img = _sensor_connection(scene.camera, hit.p)
    wc_l = C.to_local(frame, to_cam)
    f = C.dispatch(
        scene,
        mat,
        lambda m: m.eval(wo, wc_l) * _eta2_eval(m, wo, wc_l)[..., None],
        uv=hit.uv,
        tangents=tg,
    )
    corr, _ = _shading_correction(wo, wc_l, ng, wo_w, to_cam)
    ok = alive & in_img & _visible(scene, hit.p, ng, to_cam, dist)
    val = jnp.where(ok[..., None], beta * f * (we * corr)[..., None], 0.0)
    # the next segment: BSDF sampling (detached, as the path tracer's)
    s = C.dispatch(
        scene, mat, lambda m: m.sample(wo, ub[..., 0], ub[..., 1:3]), uv=hit.uv, tangents=tg
    )
    wi_w, weight = C.detach_bsdf_sample(scene, mat, wo, s, hit.uv, frame, tangents=tg)
    corr_s, ok_s = _shading_correction(wo, s.wi, ng, wo_w, wi_w)
    beta = beta * weight * (corr_s * s.eta * s.eta)[..., None]
    eta = eta * s.eta
    alive = alive & (s.pdf > 0) & ok_s
    # Russian roulette (Mitsuba ptracer: after the depth passes rr_depth)
    q = jax.lax.stop_gradient(jnp.minimum(max_last(beta) * eta * eta, 0.95))
    rr = depth + 2 > rr_depth
    survive = jnp.where(rr, ub[..., 3] < q, True)
    beta = jnp.where(rr, safe_div(beta, q[..., None]), beta)
    alive = alive & survive
    beta = jnp.where(alive[..., None], beta, 0.0)
    o_next, d_next = C.spawn_ray(hit.p, ng, wi_w)
    o_next = jnp.where(alive[..., None], o_next, o)
    d_next = jnp.where(alive[..., None], d_next, d)
    return (o_next, d_next, beta, eta, alive), (val, pix)


# -- the film -----------------------------------------------------------------------------


def _filter_eval(rfilter, x):
    """Mitsuba 3's filter functions (the weights its ``ImageBlock`` splats with)."""
    if isinstance(rfilter, BoxFilter):
        return jnp.where(jnp.abs(x) <= rfilter.radius, 1.0, 0.0).astype(x.dtype)
    if isinstance(rfilter, TentFilter):
        return jnp.maximum(0.0, 1.0 - jnp.abs(x) / rfilter.radius)
    if isinstance(rfilter, GaussianFilter):
        a = -1.0 / (2.0 * rfilter.stddev**2)
        bias = math.exp(a * rfilter.radius**2)
        return jnp.where(
            jnp.abs(x) <= rfilter.radius, jnp.maximum(0.0, jnp.exp(a * x * x) - bias), 0.0
        )
    raise ValueError(f"film.filter: {type(rfilter).__name__} cannot be splatted")


def _axis_weights(rfilter, pos, n):
    """Footprint of a splat along one axis: first pixel index, normalised weights ``(..., m)``."""
    r = rfilter.radius
    m = int(math.floor(2 * r)) + 1
    c = pos - 0.5  # pixel centres at integer + 0.5
    lo = jnp.ceil(c - r)
    xs = lo[..., None] + jnp.arange(m, dtype=pos.dtype)
    w = _filter_eval(rfilter, xs - c[..., None])
    w = jnp.where((xs >= 0) & (xs < n), w, 0.0)  # inside the image (Mitsuba: no border)
    total = jnp.sum(w, -1, keepdims=True)
    w = safe_div(w, jnp.where(total > 0, total, 1.0))
    return lo.astype(jnp.int32), w


def splat(image, rfilter, pix, val):
    """``image (H, W, C)`` plus the splats ``val (..., C)`` at continuous pixel positions
    ``pix (..., 2)`` (normalised filter weights, as Mitsuba 3's ``ImageBlock``)."""
    h, w = image.shape[:2]
    val = val.reshape(-1, val.shape[-1])
    pix = pix.reshape(-1, 2)
    if isinstance(rfilter, BoxFilter) and rfilter.radius == 0.5:
        ix = jnp.clip(jnp.floor(pix[:, 0]).astype(jnp.int32), 0, w - 1)
        iy = jnp.clip(jnp.floor(pix[:, 1]).astype(jnp.int32), 0, h - 1)
        return image.at[iy, ix].add(val)
    x0, wx = _axis_weights(rfilter, pix[:, 0], w)
    y0, wy = _axis_weights(rfilter, pix[:, 1], h)
    for j in range(wy.shape[-1]):
        for i in range(wx.shape[-1]):
            ix = jnp.clip(x0 + i, 0, w - 1)
            iy = jnp.clip(y0 + j, 0, h - 1)
            image = image.at[iy, ix].add(val * (wx[:, i] * wy[:, j])[:, None])
    return image


def light_trace(scene, key, *, spp: int, max_depth: int = 3, rr_depth: int = 5,
                hide_emitters: bool = False):  # fmt: skip
    """The particle tracer's image ``(H, W, 3)``: ``spp`` passes of ``W H`` light paths each,
    splatted into the film and divided by ``spp`` (Mitsuba 3's normalisation). Jittable
    (``spp``, ``max_depth``, ``rr_depth``, ``hide_emitters`` static); call
    :func:`check_light_tracing` on the scene first (:func:`jaxgfx.render.render` does)."""
    h, w = scene.height, scene.width
    dtype = scene.dtype
    n = h * w
    image0 = jnp.zeros((h, w, 3), dtype)
    if scene.n_lights == 0:
        return image0
    steps = max_depth - 1

    def bounce_body(carry, xs):
        ub, depth = xs
        return _bounce(scene, carry, ub, depth, rr_depth)

    bounce_body = jax.checkpoint(bounce_body)

    def one_pass(image, s):
        ks = jax.random.fold_in(key, s)
        ue = uniform(ks, (n, N_EMIT), dtype)
        if not hide_emitters:
            v, p = _visible_emitters(scene, ue[:, :3])
            image = splat(image, scene.rfilter, p, v)
        if steps > 0:
            o, d, beta = sample_emission(scene, ue[:, 3:8])
            alive = max_last(beta) > 0
            carry = (o, d, beta, jnp.ones((n,), dtype), alive)
            ub = uniform(jax.random.fold_in(ks, 1), (steps, n, N_BOUNCE), dtype)
            _, (vals, pixs) = jax.lax.scan(bounce_body, carry, (ub, jnp.arange(steps)))
            image = splat(image, scene.rfilter, pixs, vals)
        return image, None

    image, _ = jax.lax.scan(jax.checkpoint(one_pass), image0, jnp.arange(spp))
    return image / spp


class ParticleTracer(Integrator):
    """Particle (light) tracing (Mitsuba 3 ``ptracer``; module docstring): ``max_depth`` as
    the path tracer (1: visible emitters only, 2: direct light, ...), Russian roulette after
    ``rr_depth`` bounces, ``hide_emitters`` drops the directly visible emitters. All static.

    It does not trace camera rays: :func:`jaxgfx.render.render` calls :meth:`render_image`
    (``random_shape`` is ``None`` and ``__call__`` raises).

    >>> ParticleTracer(max_depth=4).traces_from_lights
    True
    """

    max_depth: int = eqx.field(static=True, default=3)
    rr_depth: int = eqx.field(static=True, default=5)
    hide_emitters: bool = eqx.field(static=True, default=False)

    traces_from_lights: ClassVar[bool] = True

    def __check_init__(self):
        check_depth("max_depth", self.max_depth)
        check_depth("rr_depth", self.rr_depth)
        if not isinstance(self.hide_emitters, bool):
            raise ValueError(f"hide_emitters: expected a bool, got {self.hide_emitters!r}")

    def __call__(self, scene, o, d, u):
        raise TypeError(
            "the 'ptracer' integrator traces paths from the emitters and splats them into the "
            "film: render it with jaxgfx.render.render(scene, key, integrator='ptracer'), not "
            "along camera rays"
        )

    def check_scene(self, scene) -> None:
        """:func:`check_light_tracing` (host-side, before tracing)."""
        check_light_tracing(scene)

    def render_image(self, scene, key, spp: int):
        """The image ``(H, W, 3)`` (:func:`light_trace`; jittable)."""
        return light_trace(scene, key, spp=spp, max_depth=self.max_depth,
                           rr_depth=self.rr_depth, hide_emitters=self.hide_emitters)  # fmt: skip
