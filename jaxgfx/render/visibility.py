"""Boundary (visibility) terms of shape derivatives by edge sampling (Li et al. 2018).

Plain AD of ``render`` differentiates the integrand where it is continuous; when a shape
parameter ``θ`` (a sphere's centre or radius, the camera's origin) moves a silhouette, the
radiance jumps across a moving curve and the derivative of the integral gains a boundary term

    d/dθ ∫_D L(x) dx  =  ∫_D ∂L/∂θ dx  +  ∮_{∂Ω(θ)} (L_in − L_out) v_n dℓ

(Reynolds transport theorem; ``Ω`` the region the shape covers, ``v_n`` the outward normal
velocity of its boundary, ``L_in`` / ``L_out`` the integrand just inside / outside). This module
estimates the second integral for the silhouettes of **spheres** (and the straight edges of
**rectangles** and **triangle meshes**, :func:`_segments`) in two domains:

* **primary visibility**: the image plane (pixel units, box filter of one pixel): the
  silhouette of a sphere seen from the pinhole is the projection of the circle of tangent points
  ``T(φ)``; ``L`` is the integrator's radiance along the camera ray through a point just inside /
  outside ``T(φ)``;
* **direct (first-bounce) lighting**: the sphere of directions at the shading point ``p`` of each
  camera ray: the occluder's silhouette seen from ``p`` is again a circle of tangent points
  ``T(ψ)``; the integrand is ``f(wo, ω) |cos| L_i(p, ω)`` with ``L_i`` the incident radiance
  (emitted radiance for the direct integrator, a path of ``max_depth − 1`` for the path tracer).

Both use the same estimator: uniform (stratified) samples of the circle parameter, the jump
``ΔL = L_in − L_out`` evaluated with common random numbers and no derivative, the length element
``|∂x/∂φ|`` and the outward normal ``n`` at the current parameters, and the boundary point
``x(φ; θ)`` itself attached, so that ``b = Σ stop_gradient(ΔL |∂x/∂φ| / pdf · n) · x(φ; θ)`` has
``∂b/∂θ`` equal to the boundary integral. :class:`EdgeSampling` (composed by
:func:`jaxgfx.render.render`) adds ``b`` to the image with
:func:`~jaxgfx.render.integrators.replace_grad` (value of the image, derivative of
``image + b``): images are bit-identical, and a forward render never computes ``b``.
See docs/render_gradients.md ("Visibility") for the derivation, measurements and what remains
biased. Package-internal except through ``render(..., visibility="edge")``.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._math import safe_div, safe_normalize, safe_sqrt, sum_last
from jaxgfx.render.camera import PerspectiveCamera, look_at_basis
from jaxgfx.render.estimator import pass_scan
from jaxgfx.render.film import BoxFilter
from jaxgfx.render.geometry.curves import BSplineCurves, LinearCurves
from jaxgfx.render.geometry.ellipsoids import Ellipsoids
from jaxgfx.render.geometry.frame import to_local
from jaxgfx.render.geometry.mesh import TriangleMesh
from jaxgfx.render.geometry.ray import spawn_ray
from jaxgfx.render.geometry.rectangle import Rectangles
from jaxgfx.render.geometry.sphere import Spheres
from jaxgfx.render.integrators import (
    dispatch,
    hit_material,
    intersect,
    shading_frame,
    tangent_space,
)
from jaxgfx.render.integrators.path import DirectIntegrator, PathIntegrator
from jaxgfx.render.sampler import uniform

__all__ = [
    "VISIBILITY",
    "check_visibility",
    "tangent_circle",
    "project",
    "edge_boundary",
    "edge_multiplicity_weights",
    "EdgeSampling",
    "edge_sampling",
]

VISIBILITY = ("edge",)
"""Boundary-term methods ``render(..., visibility=...)`` accepts (``None``: none)."""

_SALT = 0x5EED_ED6E  # boundary samples use fold_in(key, _SALT): the image's samples are unchanged
_ETA = 1e-3  # relative offset (of the circle radius) of the inside / outside rays


def check_visibility(visibility, scene, integrator) -> None:
    """``ValueError`` / ``TypeError`` at the Python boundary for what edge sampling supports."""
    if visibility is None:
        return
    if not isinstance(visibility, str) or visibility not in VISIBILITY:
        raise ValueError(f"visibility: expected None or one of {VISIBILITY}, got {visibility!r}")
    if not isinstance(integrator, (PathIntegrator, DirectIntegrator)):
        raise ValueError(
            "visibility: edge sampling supports the 'path' and 'direct' integrators, got "
            f"{type(integrator).__name__}"
        )
    if not isinstance(scene.camera, PerspectiveCamera):
        name = type(scene.camera).__name__
        raise TypeError(f"visibility: edge sampling needs a PerspectiveCamera, got {name}")
    if any(isinstance(s, (LinearCurves, BSplineCurves)) for s in scene.shapes):
        raise ValueError(
            "visibility: edge sampling does not cover the silhouettes of curves "
            "(LinearCurves, BSplineCurves): render without visibility='edge' (the gradients of "
            "curve control points then lack the boundary term; material gradients are exact)"
        )
    if any(isinstance(s, Ellipsoids) for s in scene.shapes):
        raise ValueError(
            "visibility: edge sampling does not cover the silhouettes of ellipsoids: render "
            "without visibility='edge' (the gradients of their centres, scales and rotations "
            "then lack the boundary term; material gradients are exact)"
        )
    rf = scene.rfilter
    if rf is not None and not (isinstance(rf, BoxFilter) and rf.radius == 0.5):
        raise ValueError(f"visibility: edge sampling needs the box filter of radius 0.5, got {rf}")


def _spheres(scene, *, occluders=False):
    """All sphere primitives of the scene: centres (K, 3), radii (K,), and per primitive the
    static ``(shape index, primitive index)`` of the hit records; ``None`` if there are none.

    ``occluders``: leave out spheres that are area lights. A moving sphere light's outline seen
    from a shading point is a boundary in the direction measure only, which light sampling (area
    measure, attached) already differentiates; adding it here would count it twice.
    """
    lights = {al.shape_index for al in scene.area_lights}
    cs, rs, sid, pid = [], [], [], []
    for i, s in enumerate(scene.shapes):
        if isinstance(s, Spheres) and not (occluders and i in lights):
            n = s.centers.shape[0]
            cs.append(s.centers)
            rs.append(s.radii)
            sid += [i] * n
            pid += list(range(n))
    if not cs:
        return None
    return (
        jnp.concatenate(cs),
        jnp.concatenate(rs),
        np.asarray(sid, np.int32),
        np.asarray(pid, np.int32),
    )


def edge_multiplicity_weights(faces):
    """``(3F,)`` weight of each half-edge ``(f0, f1), (f1, f2), (f2, f0)`` of ``faces (F, 3)``:
    ``1 / (number of faces sharing the edge)`` for edges shared by at most two faces, so that
    sampling every half-edge counts each edge of a mesh once. Jittable (a lexicographic sort of
    the undirected edges; ``faces`` may be traced)."""
    a = faces.reshape(-1)
    b = jnp.roll(faces, -1, axis=1).reshape(-1)
    lo, hi = jnp.minimum(a, b), jnp.maximum(a, b)
    order = jnp.lexsort((hi, lo))
    slo, shi = lo[order], hi[order]
    same = (slo[1:] == slo[:-1]) & (shi[1:] == shi[:-1])
    pad = jnp.zeros((1,), bool)
    mult = 1 + jnp.concatenate([pad, same]).astype(jnp.int32)
    mult = mult + jnp.concatenate([same, pad]).astype(jnp.int32)
    w_sorted = 1.0 / mult
    return jnp.zeros(a.shape, w_sorted.dtype).at[order].set(w_sorted)


def _segments(scene, *, occluders=False):
    """Straight edges: the four edges of every rectangle and every edge of every triangle mesh.

    Returns endpoints ``(E, 2, 3)`` (differentiable w.r.t. the rectangles' centres and edge
    vectors and the meshes' vertices), a weight per edge ``(E,)`` (1, or 1/2 for a mesh edge
    two faces share: both half-edges are listed), and the static shape and primitive index of
    each (-1 for meshes: a mesh edge next to the shading point lies in its tangent plane, where
    ``f |cos|`` vanishes); ``None`` if there are none. ``occluders``: leave out area lights (as
    :func:`_spheres`).
    """
    lights = {al.shape_index for al in scene.area_lights}
    segs, wts, sid, pid = [], [], [], []
    for i, s in enumerate(scene.shapes):
        if occluders and i in lights:
            continue
        if isinstance(s, Rectangles):
            c, hu, hv = s.centers, 0.5 * s.edge_u, 0.5 * s.edge_v
            corners = [c - hu - hv, c + hu - hv, c + hu + hv, c - hu + hv]
            for a in range(4):
                segs.append(jnp.stack([corners[a], corners[(a + 1) % 4]], axis=1))
                wts.append(jnp.ones((c.shape[0],), c.dtype))
                sid += [i] * c.shape[0]
                pid += list(range(c.shape[0]))
            continue
        mesh = s.mesh if isinstance(getattr(s, "mesh", None), TriangleMesh) else s
        if isinstance(mesh, TriangleMesh):
            v, f = mesh.vertices, mesh.faces
            a = v[f.reshape(-1)]
            b = v[jnp.roll(f, -1, axis=1).reshape(-1)]
            segs.append(jnp.stack([a, b], axis=1))
            wts.append(edge_multiplicity_weights(f).astype(v.dtype))
            sid += [-1] * a.shape[0]
            pid += [-1] * a.shape[0]
    if not segs:
        return None
    return (
        jnp.concatenate(segs),
        jnp.concatenate(wts),
        np.asarray(sid, np.int32),
        np.asarray(pid, np.int32),
    )


def tangent_circle(center, radius, o, phi):
    """Points ``T (..., 3)`` where rays from ``o`` graze the sphere, at angle ``phi (...)``.

    The tangent points form a circle of centre ``c − (r²/D) a`` and radius ``ρ = r √(D² − r²)/D``
    in the plane normal to ``a = (c − o)/D``, ``D = |c − o|``. Returns ``(T, u, rho, ok)``: ``u``
    the unit vector from the circle's centre to ``T`` (outwards: ``T + ε u`` is outside the cone of
    rays from ``o`` that hit the sphere), ``ok`` where ``o`` is outside the sphere. ``T`` is
    differentiable w.r.t. ``center``, ``radius`` and ``o``, and stays on the circle as they move
    (the in-plane basis is built from ``a`` with a frozen helper axis).
    """
    v = center - o
    d2 = sum_last(v * v)
    r2 = radius * radius
    ok = d2 > r2 * (1.0 + 1e-4)
    d = safe_sqrt(jnp.where(ok, d2, 1.0))
    a = v / d[..., None]
    # helper axis: the world axis least aligned with a (frozen: a choice, not a function of θ)
    helper = jax.nn.one_hot(
        jnp.argmin(jnp.abs(jax.lax.stop_gradient(a)), axis=-1), 3, dtype=a.dtype
    )
    e1 = safe_normalize(jnp.cross(a, helper))
    e2 = jnp.cross(a, e1)
    rho = radius * safe_sqrt(jnp.where(ok, d2 - r2, 0.0)) / d
    cphi, sphi = jnp.cos(phi), jnp.sin(phi)
    u = cphi[..., None] * e1 + sphi[..., None] * e2
    t = center - (r2 / d)[..., None] * a + rho[..., None] * u
    return t, u, rho, ok


def project(camera: PerspectiveCamera, x):
    """Continuous pixel position ``(..., 2)`` of world points ``x (..., 3)`` (the inverse of
    ``camera.generate_ray``) and their depth along the viewing direction (``<= 0``: behind)."""
    right, up, fwd = look_at_basis(camera.origin, camera.target, camera.up)
    v = x - camera.origin
    z = sum_last(v * fwd)
    tx, ty = camera._tan_half()
    sx = safe_div(sum_last(v * right), z)
    sy = safe_div(sum_last(v * up), z)
    px = (sx / tx + 1.0) * (0.5 * camera.width)
    py = (1.0 - sy / ty) * (0.5 * camera.height)
    return jnp.stack([px, py], axis=-1), z


def _sub_integrator(integrator):
    """Incident radiance along a ray leaving the first vertex: a path one vertex shorter."""
    depth = integrator.max_depth - 1
    return PathIntegrator(
        max_depth=depth,
        rr_depth=max(integrator.rr_depth - 1, 1),
        strategy=integrator.strategy,
        sampling=integrator.sampling,
    )


def _boundary_term(valid, jump, weight, n, x):
    """Per sample ``sg(jump · weight) · (sg(n) · x(θ))``, 0 where not ``valid``: its value is
    meaningless, its derivative is the boundary integrand (the jump across the edge times the
    normal speed ``n · ∂x/∂θ`` of the attached boundary point ``x``), ``(..., C)``."""
    sg = jax.lax.stop_gradient
    v = valid[..., None]
    wgt = jnp.where(v, jump * weight[..., None], 0.0)
    vn = sum_last(jnp.where(v, sg(n) * x, 0.0))
    return sg(wgt) * vn[..., None]


def _in_image(x0, w, h):
    """Image points ``(M, 2)`` (pixel units) inside the ``w × h`` image."""
    return (x0[:, 0] >= 0) & (x0[:, 0] < w) & (x0[:, 1] >= 0) & (x0[:, 1] < h)


def _splat(x0, contrib, w, h, dtype):
    """Sum the samples' ``contrib (M, C)`` into the ``(H*W, C)`` pixels their points ``x0`` fall
    in (box filter)."""
    ix = jnp.clip(jnp.floor(x0[:, 0]).astype(jnp.int32), 0, w - 1)
    iy = jnp.clip(jnp.floor(x0[:, 1]).astype(jnp.int32), 0, h - 1)
    return jnp.zeros((w * h, contrib.shape[-1]), dtype).at[iy * w + ix].add(contrib)


def _primary_pass(scene, scene_sg, key, integrator, spheres):
    """Boundary image ``(H*W, C)`` of one pass of ``H*W`` silhouette samples (box filter)."""
    centers, radii, _, _ = spheres
    sg = jax.lax.stop_gradient
    cam, cam_sg = scene.camera, scene_sg.camera
    w, h = scene.width, scene.height
    m = w * h
    k = centers.shape[0]
    dtype = centers.dtype
    u = uniform(key, (m, 2), dtype)
    kk = jnp.minimum((u[:, 0] * k).astype(jnp.int32), k - 1)
    phi = (2 * math.pi / m) * (jnp.arange(m, dtype=dtype) + u[:, 1])  # stratified
    c, r = centers[kk], radii[kk]
    c_sg, r_sg = sg(c), sg(r)

    def screen(phi, c, r, cam):
        t = tangent_circle(c, r, cam.origin, phi)[0]
        return project(cam, t)[0]

    # boundary point attached to θ (sphere and camera), and its φ-tangent at the current θ
    x = screen(phi, c, r, cam)
    x0, dx = jax.jvp(lambda p: screen(p, c_sg, r_sg, cam_sg), (phi,), (jnp.ones_like(phi),))
    t0, uo, rho, ok = tangent_circle(c_sg, r_sg, cam_sg.origin, phi)
    _, z = project(cam_sg, t0)
    _, ju = jax.jvp(lambda t: project(cam_sg, t)[0], (t0,), (uo,))  # outward in the image
    length = jnp.sqrt(sum_last(dx * dx))
    n = safe_div(jnp.stack([dx[:, 1], -dx[:, 0]], -1), length[:, None])
    n = jnp.where((sum_last(n * ju) < 0)[:, None], -n, n)
    # radiance just inside and just outside the silhouette, common random numbers
    o = jnp.broadcast_to(cam_sg.origin, (m, 3)).astype(dtype)
    off = (_ETA * rho)[:, None] * uo
    d_in = safe_normalize(t0 - off - o)
    d_out = safe_normalize(t0 + off - o)
    uu = None
    if integrator.random_shape is not None:
        uu = uniform(jax.random.fold_in(key, 1), (m, *integrator.random_shape), dtype)
    both = integrator(
        scene_sg,
        jnp.concatenate([o, o]),
        jnp.concatenate([d_in, d_out]),
        None if uu is None else jnp.concatenate([uu, uu]),
    )
    dl = both[:m] - both[m:]
    valid = ok & (z > 0) & _in_image(x0, w, h) & jnp.all(jnp.isfinite(dl), -1) & (length > 0)
    contrib = _boundary_term(valid, dl, length * (2 * math.pi * k / m), n, x)
    return _splat(x0, contrib, w, h, dtype)


def _primary_segments_pass(scene, scene_sg, key, integrator, segments):
    """As :func:`_primary_pass` for straight edges (rectangles, meshes): ``H*W`` samples dealt
    to the edges in turn from a random offset (:func:`_deal`), stratified along each edge; the
    two sides are 10⁻⁴ pixel away along the edge's image normal ``n``, and the
    jump is ``L(x − εn) − L(x + εn)`` (the formula does not depend on the orientation of ``n``).
    """
    ends, ew = segments[0], segments[1]
    sg = jax.lax.stop_gradient
    cam, cam_sg = scene.camera, scene_sg.camera
    w, h = scene.width, scene.height
    m = w * h
    e = ends.shape[0]
    dtype = ends.dtype
    u = uniform(key, (m, 2), dtype)
    kk, t, per = _deal(m, e, u[0, 0], u[:, 1])
    a, b = ends[kk, 0], ends[kk, 1]

    def screen(t, a, b, cam):
        return project(cam, a + t[:, None] * (b - a))

    x, _ = screen(t, a, b, cam)
    (x0, z), (dx, _) = jax.jvp(lambda q: screen(q, sg(a), sg(b), cam_sg), (t,), (jnp.ones_like(t),))
    length = jnp.sqrt(sum_last(dx * dx))
    n = safe_div(jnp.stack([dx[:, 1], -dx[:, 0]], -1), length[:, None])
    # 1e-4 px: a hidden edge ending on a silhouette straddles it over ~eps/sin(angle) of its
    # length, a rare O(eps) artefact (measured: 1 sample in ~10 passes at 1e-3 px on a cube)
    eps = 1e-4
    o, d = cam_sg.generate_ray(jnp.concatenate([x0 - eps * n, x0 + eps * n]))
    uu = None
    if integrator.random_shape is not None:
        uu = uniform(jax.random.fold_in(key, 1), (m, *integrator.random_shape), dtype)
        uu = jnp.concatenate([uu, uu])
    both = integrator(scene_sg, o.astype(dtype), d.astype(dtype), uu)
    dl = both[:m] - both[m:]
    valid = (z > 0) & _in_image(x0, w, h) & jnp.all(jnp.isfinite(dl), -1) & (length > 0)
    valid = valid & jnp.isfinite(length)
    contrib = _boundary_term(valid, dl, length * ew[kk] * per, n, x)
    return _splat(x0, contrib, w, h, dtype)


def _deal(m: int, e: int, u_off, u_t):
    """Deal ``m`` samples to ``e`` edges: sample ``j`` goes to edge ``(j + off) mod e`` (random
    offset ``off`` from ``u_off``) at ``t`` stratified among that edge's samples (``u_t (m,)``).
    Returns ``(edge (m,), t (m,), weight (m,))``: each edge's estimate of ``∫₀¹ g dt`` is
    ``Σ weight g(t)`` over its samples, unbiased (``1/n_e`` with ``n_e ≥ 1`` samples when
    ``m ≥ e``; ``e/m`` for an edge included with probability ``m/e`` otherwise)."""
    off = jnp.minimum((u_off * e).astype(jnp.int32), e - 1)
    j = jnp.arange(m, dtype=jnp.int32) + off
    edge = j % e
    r = (edge - off) % e  # first sample index of this edge
    n_e = (m - 1 - r) // e + 1  # samples this edge gets (>= 1 for the dealt ones)
    q = (jnp.arange(m, dtype=jnp.int32) - r) // e  # index among this edge's samples
    dtype = u_t.dtype
    if m >= e:
        t = (q.astype(dtype) + u_t) / n_e.astype(dtype)
        weight = 1.0 / n_e.astype(dtype)
    else:
        t = u_t
        weight = jnp.full((m,), e / m, dtype)
    return edge, t, weight


def _first_vertex(scene_sg, key, dtype):
    """One camera ray per pixel (uniform in the pixel) and its first vertex's shading data."""
    w, h = scene_sg.width, scene_sg.height
    u = uniform(key, (h, w, 4), dtype)
    jj, ii = jnp.meshgrid(jnp.arange(w), jnp.arange(h))
    px = jnp.stack([jj, ii], -1).astype(dtype) + u[..., :2]
    o, d = scene_sg.camera.generate_ray(px)
    o, d = o.astype(dtype), d.astype(dtype)
    hit = intersect(scene_sg, o, d)
    mat = hit_material(scene_sg, hit)
    frame, ng, wo = shading_frame(scene_sg, hit, d, mat)
    return u[..., 2:], hit, mat, frame, ng, wo


def _jump(scene_sg, key, integrator, vertex, w_minus, w_plus):
    """``f L_i`` on the two sides (common random numbers): the integrand of the first vertex's
    outgoing radiance along directions ``w_minus``, ``w_plus`` (..., 3)."""
    _, hit, mat, frame, ng, wo = vertex
    h = w_minus.shape[0]
    sub = _sub_integrator(integrator)
    uu = uniform(key, (*w_minus.shape[:-1], *sub.random_shape), w_minus.dtype)
    fs, os_, ds = [], [], []
    tg = tangent_space(scene_sg, hit, frame)  # None without normal / bump maps
    for wi in (w_minus, w_plus):
        fs.append(
            dispatch(
                scene_sg,
                mat,
                lambda mm, wi=wi: mm.eval(wo, to_local(frame, wi)),
                uv=hit.uv,
                tangents=tg,
            )
        )
        so, sd = spawn_ray(hit.p, ng, wi)
        os_.append(so)
        ds.append(sd)
    li = sub(scene_sg, jnp.concatenate(os_), jnp.concatenate(ds), jnp.concatenate([uu, uu]))
    return fs[0] * li[:h] - fs[1] * li[h:]


def _shadow_segments_pass(scene, scene_sg, key, integrator, segments):
    """As :func:`_shadow_pass` for straight edges of occluding rectangles."""
    ends, ew, sids, pids = segments
    sg = jax.lax.stop_gradient
    e = ends.shape[0]
    dtype = ends.dtype
    vertex = _first_vertex(scene_sg, key, dtype)
    u, hit = vertex[0], vertex[1]
    p = hit.p
    kk = jnp.minimum((u[..., 0] * e).astype(jnp.int32), e - 1)
    t = u[..., 1]
    a, b = ends[kk, 0], ends[kk, 1]

    def direction(t, a, b):
        return safe_normalize(a + t[..., None] * (b - a) - p)

    om = direction(t, a, b)
    om0, dom = jax.jvp(lambda q: direction(q, sg(a), sg(b)), (t,), (jnp.ones_like(t),))
    length = jnp.sqrt(sum_last(dom * dom))
    n = safe_div(jnp.cross(om0, dom), length[..., None])
    eps = 1e-4  # radians
    w_minus = safe_normalize(om0 - eps * n)
    w_plus = safe_normalize(om0 + eps * n)
    dh = _jump(scene_sg, jax.random.fold_in(key, 1), integrator, vertex, w_minus, w_plus)
    own = (hit.shape_id == jnp.asarray(sids)[kk]) & (hit.prim_id == jnp.asarray(pids)[kk])
    valid = hit.valid & ~own & jnp.all(jnp.isfinite(dh), -1) & (length > 0)
    return _boundary_term(valid, dh, length * ew[kk] * e, n, om)


def _shadow_pass(scene, scene_sg, key, integrator, spheres):
    """Boundary image ``(H, W, 3)`` of the occluders' silhouettes seen from the first vertex of
    one camera ray per pixel (direction measure, box filter)."""
    centers, radii, sids, pids = spheres
    sg = jax.lax.stop_gradient
    k = centers.shape[0]
    dtype = centers.dtype
    vertex = _first_vertex(scene_sg, key, dtype)
    u, hit = vertex[0], vertex[1]
    p = hit.p
    kk = jnp.minimum((u[..., 0] * k).astype(jnp.int32), k - 1)
    psi = 2 * math.pi * u[..., 1]
    c, r = centers[kk], radii[kk]
    c_sg, r_sg = sg(c), sg(r)

    def direction(psi, c, r):
        t = tangent_circle(c, r, p, psi)[0]
        return safe_normalize(t - p)

    om = direction(psi, c, r)  # attached to the sphere's parameters
    om0, dom = jax.jvp(lambda q: direction(q, c_sg, r_sg), (psi,), (jnp.ones_like(psi),))
    t0, uo, rho, ok = tangent_circle(c_sg, r_sg, p, psi)
    length = jnp.sqrt(sum_last(dom * dom))
    n = safe_div(jnp.cross(om0, dom), length[..., None])
    n = jnp.where((sum_last(n * uo) < 0)[..., None], -n, n)  # outwards
    off = (_ETA * rho)[..., None] * uo
    w_in = safe_normalize(t0 - off - p)
    w_out = safe_normalize(t0 + off - p)
    dh = _jump(scene_sg, jax.random.fold_in(key, 1), integrator, vertex, w_in, w_out)
    own = (hit.shape_id == jnp.asarray(sids)[kk]) & (hit.prim_id == jnp.asarray(pids)[kk])
    valid = hit.valid & ok & ~own & jnp.all(jnp.isfinite(dh), -1) & (length > 0)
    return _boundary_term(valid, dh, length * (2 * math.pi * k), n, om)


def edge_boundary(scene, key, integrator, *, spp: int):
    """Boundary image ``(H, W, C)`` whose derivative w.r.t. the scene is the silhouette term of
    the image's derivative (its value is meaningless). Jittable; ``spp`` passes."""
    spheres, segs = _spheres(scene), _segments(scene)
    w, h = scene.width, scene.height
    nc = integrator.n_channels
    if spheres is None and segs is None:
        return jnp.zeros((h, w, nc), jnp.float32)
    sg = jax.lax.stop_gradient
    scene_sg = sg(scene)
    dtype = (spheres[0] if spheres is not None else segs[0]).dtype
    direct = integrator.max_depth > 1
    occ = _spheres(scene, occluders=True) if direct else None
    occ_segs = _segments(scene, occluders=True) if direct else None

    def one_pass(s):
        ks = jax.random.fold_in(key, s)
        b = jnp.zeros((h, w, nc), dtype)
        if spheres is not None:
            pb = _primary_pass(scene, scene_sg, jax.random.fold_in(ks, 0), integrator, spheres)
            b = b + pb.reshape(h, w, nc)
        if segs is not None:
            k2 = jax.random.fold_in(ks, 2)
            b = b + _primary_segments_pass(scene, scene_sg, k2, integrator, segs).reshape(h, w, nc)
        if occ is not None:
            b = b + _shadow_pass(scene, scene_sg, jax.random.fold_in(ks, 1), integrator, occ)
        if occ_segs is not None:
            k3 = jax.random.fold_in(ks, 3)
            b = b + _shadow_segments_pass(scene, scene_sg, k3, integrator, occ_segs)
        return b

    acc = pass_scan(one_pass, jnp.arange(spp), jnp.zeros((h, w, nc), dtype))
    return acc / spp


class EdgeSampling(eqx.Module):
    """The boundary-term layer of :func:`jaxgfx.render.render` (``visibility="edge"``):
    ``boundary(scene, key, integrator, spp=spp)`` is :func:`edge_boundary` on samples drawn
    from ``fold_in(key, _SALT)`` (the image's own samples are unchanged); the renderer returns
    the image with the derivative of ``image + boundary``."""

    def __call__(self, scene, key, integrator, *, spp: int):
        return edge_boundary(scene, jax.random.fold_in(key, _SALT), integrator, spp=spp)


def edge_sampling(visibility, scene, integrator) -> EdgeSampling | None:
    """The boundary layer for ``render(..., visibility=...)``: ``None`` for ``None``, an
    :class:`EdgeSampling` for ``"edge"`` (after :func:`check_visibility`)."""
    check_visibility(visibility, scene, integrator)
    return None if visibility is None else EdgeSampling()
