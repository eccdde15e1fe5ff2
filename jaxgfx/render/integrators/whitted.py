"""Whitted ray tracing: direct light with hard shadows at non-specular surfaces, and recursive
perfect reflection / refraction at specular (delta) surfaces.

Both the reflected and the refracted ray of a dielectric are followed (weighted by Fresnel), as
in Whitted (1980). The recursion is evaluated breadth-first on a batch whose branch axis doubles
per level, so the compiled program grows linearly with depth; scenes without transmissive
specular materials keep a single branch. Area and environment lights are sampled once per
camera sample (light sampling only), point lights exactly.

Derivatives (``sampling="detached"``, default): the environment's light sample carries no
derivative (see :func:`~jaxgfx.render.integrators._common.sample_light`); the specular branches
are deterministic functions of the parameters (a reflected / refracted direction, a Fresnel
weight), so they are differentiated as they are, and a branch's Fresnel factor is taken from
the weight ``R / stop_gradient(R)`` times the frozen lobe probability.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from jaxgfx._math import safe_div
from jaxgfx.render.integrators import _common as C
from jaxgfx.render.integrators.base import N_RANDOM, Integrator, check_depth

__all__ = ["WhittedIntegrator", "whitted_radiance"]


def _direct(scene, hit, frame, ng, wo, mat, alive, u, detached, tg=None):
    L = jnp.zeros(hit.p.shape, hit.p.dtype)
    if scene.n_lights == 0:
        return L

    def one(wi, dist, li, pdf):
        so, sd = C.spawn_ray(hit.p, ng, wi)
        tmax = jnp.where(jnp.isfinite(dist), dist * (1 - 1e-4), jnp.inf)
        vis = ~C.occluded(scene, so, sd, tmax)
        f = C.dispatch(
            scene, mat, lambda m: m.eval(wo, C.to_local(frame, wi)), uv=hit.uv, tangents=tg
        )
        ok = alive & vis & (pdf > 0)
        return jnp.where(ok[..., None], f * li * safe_div(1.0, pdf)[..., None], 0.0)

    if scene.point_lights is not None:
        for j in range(scene.point_lights.count):
            wi, dist, li = scene.point_lights.sample(jnp.full(hit.t.shape, j), hit.p)
            L = L + one(wi, dist, li, jnp.ones(hit.t.shape, hit.p.dtype))
    for light in scene.delta_lights:  # directional / spot: one shadow ray each
        wi, dist, li = light.sample(hit.p)
        L = L + one(wi, dist, li, jnp.ones(hit.t.shape, hit.p.dtype))
    if scene.area_lights or scene.environment is not None:
        # sample the non-delta lights with a uniform choice among them
        sub = _nondelta_scene(scene)
        wi, dist, li, pdf, _ = C.sample_light(sub, hit.p, u[..., 0], u[..., 1:3], detached=detached)
        L = L + one(wi, dist, li, pdf)
    return L


def _nondelta_scene(scene):
    import equinox as eqx

    scene = eqx.tree_at(lambda s: s.point_lights, scene, None, is_leaf=lambda x: x is None)
    return eqx.tree_at(lambda s: s.delta_lights, scene, ()) if scene.delta_lights else scene


def whitted_radiance(scene, o, d, u, *, max_depth: int, sampling: str = "detached"):
    """Radiance along rays ``o, d (..., 3)``; ``u (..., max_depth, 7)`` uniform numbers.

    ``sampling``: ``"detached"`` (default) or ``"attached"``, see the module docstring.
    """
    C.check_sampling(sampling)
    detached = sampling == "detached"
    split = any(m.has_delta and m.is_transmissive for m in scene.materials)
    # branch axis at -2: (..., B, 3)
    o, d = o[..., None, :], d[..., None, :]
    beta = jnp.ones(o.shape, o.dtype)
    L = jnp.zeros(o.shape[:-2] + (3,), o.dtype)
    for level in range(max_depth):
        ub = u[..., level, :][..., None, :]
        hit = C.intersect(scene, o, d)
        le = C.emitted(scene, hit, d)
        if scene.environment is not None:
            le = le + jnp.where((~hit.valid)[..., None], scene.environment.eval(d), 0.0)
        L = L + jnp.sum(beta * le, -2)
        mat = C.hit_material(scene, hit)
        frame, ng, wo = C.shading_frame(scene, hit, d, mat)
        tg = C.tangent_space(scene, hit, frame)  # None without normal / bump maps
        delta = C.material_flag(scene, mat, "has_delta") & hit.valid
        direct = _direct(scene, hit, frame, ng, wo, mat, hit.valid & ~delta, ub, detached, tg)
        L = L + jnp.sum(beta * direct, -2)
        if level == max_depth - 1:
            break
        branches = [(jnp.zeros_like(ub[..., 3]), True)]
        if split:
            branches.append((jnp.full_like(ub[..., 3], 1.0 - 1e-6), False))
        new_o, new_d, new_beta = [], [], []
        for u1, want_reflect in branches:
            s = C.dispatch(
                scene,
                mat,
                lambda m, u1=u1, wo=wo, u2=ub[..., 4:6]: m.sample(wo, u1, u2),
                uv=hit.uv,
                tangents=tg,
            )
            reflected = s.wi[..., 2] * wo[..., 2] > 0
            ok = delta & s.is_delta & (reflected if want_reflect else ~reflected)
            # both branches are followed: weight x lobe probability. The weight carries the
            # lobe choice's derivative (R / stop_gradient(R)), so the probability is frozen
            p_lobe = jax.lax.stop_gradient(s.pdf)
            w = jnp.where(ok[..., None], s.weight * p_lobe[..., None], 0.0)
            oo, dd = C.spawn_ray(hit.p, ng, C.to_world(frame, s.wi))
            new_o.append(oo)
            new_d.append(dd)
            new_beta.append(beta * w)
        o = jnp.concatenate(new_o, -2)
        d = jnp.concatenate(new_d, -2)
        beta = jnp.concatenate(new_beta, -2)
    return L


class WhittedIntegrator(Integrator):
    """Whitted (1980) ray tracing to ``max_depth`` specular levels (:func:`whitted_radiance`).

    >>> WhittedIntegrator(max_depth=2).random_shape
    (2, 7)
    """

    max_depth: int = eqx.field(static=True, default=3)

    sampling: str = eqx.field(static=True, default="detached")

    def __check_init__(self):
        check_depth("max_depth", self.max_depth)
        C.check_sampling(self.sampling)

    @property
    def random_shape(self):
        return (self.max_depth, N_RANDOM)

    def __call__(self, scene, o, d, u):
        return whitted_radiance(scene, o, d, u, max_depth=self.max_depth, sampling=self.sampling)
