"""``render(scene, key, ...)``: the renderer's entry point.

It composes three layers, none of which imports back into this module: an integrator object
(strings become objects here, through :func:`~jaxgfx.render.estimator.resolve_integrator`),
the estimator over the image plane (:func:`~jaxgfx.render.estimator.render_partial`, the one
sample layout and pass scan), and an optional boundary term for visibility gradients
(:class:`~jaxgfx.render.visibility.EdgeSampling`). Sharding over devices is the same
composition per device (:func:`jaxgfx.render.render_sharded`)."""

from __future__ import annotations

import equinox as eqx

from jaxgfx._checks import check_positive_int
from jaxgfx.render.estimator import render_partial, resolve_integrator
from jaxgfx.render.integrators import Integrator, replace_grad
from jaxgfx.render.visibility import EdgeSampling, edge_sampling

__all__ = ["render"]


def render(
    scene,
    key,
    *,
    spp: int = 64,
    integrator: str | Integrator = "path",
    max_depth: int | None = None,
    rr_depth: int | None = None,
    strategy: str | None = None,
    sampling: str | None = None,
    accel: str | None = None,
    visibility: str | None = None,
):
    """Render ``scene`` to an ``(H, W, 3)`` float32 linear radiance image.

    ``integrator``: an :class:`~jaxgfx.render.integrators.Integrator` object
    (``PathIntegrator(max_depth=3, rr_depth=5, strategy="mis")``, ``DirectIntegrator()``,
    ``WhittedIntegrator(max_depth)``, ``AOVIntegrator()``, ``ParticleTracer(max_depth)``) or a
    name registered in
    :data:`~jaxgfx.render.integrators.INTEGRATORS`: ``"path"`` (next-event estimation + MIS +
    Russian roulette after ``rr_depth`` bounces), ``"direct"`` (emitted + direct light with MIS;
    path of depth 2), ``"whitted"`` (point/area lights with shadows, recursive mirror reflection
    and refraction) or ``"aov"`` (returns ``(H, W, 7)``: albedo, shading normal, depth; see
    ``AOV_CHANNELS``) or ``"ptracer"`` (particle tracing from the emitters, splatted into the
    film: Mitsuba's ``ptracer``; docs/render.md). With a name, ``max_depth`` (default 3),
    ``rr_depth`` (5) and ``strategy`` (``"mis"``, ``"light"`` or ``"bsdf"``) configure it;
    options the named integrator does not use are ignored. With an object, set them on the
    object (``TypeError`` here).
    ``sampling`` (``path``, ``direct``, ``whitted``): ``"detached"`` (default; unbiased
    derivatives, docs/render_gradients.md) or ``"attached"`` (plain AD through the samplers).
    ``max_depth`` follows Mitsuba 3 (1: emitters only, 2: direct light, 3: one indirect bounce).
    ``key`` is a JAX PRNG key; the same key gives the same image. Differentiable w.r.t. every
    float leaf of ``scene`` (see ``Scene.replace``); jittable (``spp`` and the integrator are
    static). Batches of keys (independent estimates, error bars):
    ``jax.jit(jax.vmap(lambda k: render(scene, k, spp=16)))(keys)`` returns ``(K, H, W, 3)``,
    bit-identical to rendering each key alone and no slower per key (also under ``jax.grad``;
    docs/performance.md, "Batches of keys"); ``lax.map`` over the keys holds one key's
    intermediates at a time.
    ``accel``: traversal backend of the scene's triangle meshes, ``"auto"`` | ``"embree"`` |
    ``"warp"`` | ``"jax"`` (docs/render_backends.md); ``None`` (default) keeps the scene's
    (``load_scene(..., accel="auto")``). A different backend is built on the host (cached per
    mesh), so pass ``accel`` outside ``jax.jit`` or use :meth:`Scene.with_accel` once.
    ``visibility``: ``None`` (default: plain AD, which misses the boundary term of moving
    silhouettes) or ``"edge"``: edge sampling (Li et al. 2018) of sphere silhouettes and the
    edges of rectangles and triangle meshes in the image and, for ``path`` / ``direct``, of the
    same occluders seen from the first shading point (box filter, perspective camera). The
    image is identical; only derivatives change (docs/render_gradients.md, "Visibility").
    """
    if accel is not None:
        scene = scene.with_accel(accel)
    check_positive_int(spp, "spp")
    integ = resolve_integrator(
        integrator,
        max_depth=max_depth,
        rr_depth=rr_depth,
        strategy=strategy,
        sampling=sampling,
        caller="render",
    )
    boundary = edge_sampling(visibility, scene, integ)
    if getattr(integ, "traces_from_lights", False):  # the particle tracer splats light paths
        integ.check_scene(scene)
        return _render_light(scene, key, spp, integ)
    return _render(scene, key, spp, integ, boundary)


@eqx.filter_jit
def _render_light(scene, key, spp, integrator):
    return integrator.render_image(scene, key, spp).astype(scene.dtype)


@eqx.filter_jit
def _render(scene, key, spp, integrator, boundary: EdgeSampling | None = None):
    image = render_partial(scene, key, integrator, spp=spp) / spp
    if boundary is None:
        return image
    b = boundary(scene, key, integrator, spp=spp)
    return replace_grad(image, image + b.astype(image.dtype))
