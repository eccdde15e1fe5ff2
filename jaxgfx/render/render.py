"""``render(scene, key, ...)``: the Monte Carlo estimator over the image plane."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from jaxgfx._checks import check_choice, check_positive_int
from jaxgfx._math import fusion_barrier
from jaxgfx.render.film import _pixel_samples
from jaxgfx.render.integrators import INTEGRATORS, Integrator, make_integrator
from jaxgfx.render.integrators._common import SAMPLING
from jaxgfx.render.integrators.path import STRATEGIES
from jaxgfx.render.sampler import _uniform

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
    ``WhittedIntegrator(max_depth)``, ``AOVIntegrator()``) or a name registered in
    :data:`~jaxgfx.render.integrators.INTEGRATORS`: ``"path"`` (next-event estimation + MIS +
    Russian roulette after ``rr_depth`` bounces), ``"direct"`` (emitted + direct light with MIS;
    path of depth 2), ``"whitted"`` (point/area lights with shadows, recursive mirror reflection
    and refraction) or ``"aov"`` (returns ``(H, W, 7)``: albedo, shading normal, depth; see
    ``AOV_CHANNELS``). With a name, ``max_depth`` (default 3), ``rr_depth`` (5) and ``strategy``
    (``"mis"``, ``"light"`` or ``"bsdf"``) configure it; options the named integrator does not
    use are ignored. With an object, set them on the object (``TypeError`` here).
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
    if visibility is not None:
        from jaxgfx.render.visibility import check_visibility, render_with_edges

        check_visibility(visibility, scene, integ)
        return render_with_edges(scene, key, spp, integ)
    return _render(scene, key, spp, integ)


# Package-internal hooks, shared with jaxgfx.render.distributed.render_sharded (not in __all__):
# the option handling and the sample layout exist only here.


def resolve_integrator(
    integrator: str | Integrator,
    *,
    max_depth: int | None = None,
    rr_depth: int | None = None,
    strategy: str | None = None,
    sampling: str | None = None,
    caller: str = "render",
) -> Integrator:
    """The :class:`Integrator` that ``render(..., integrator=..., max_depth=...)`` runs.

    An object is returned as is (options beside it: ``TypeError`` naming them and ``caller``);
    a name of :data:`INTEGRATORS` is built with the defaults ``max_depth=3``, ``rr_depth=5``,
    ``strategy="mis"``, ``sampling="detached"`` for the options left ``None``. Bad names and
    values raise ``ValueError`` naming the option. Runs on the host, before tracing.
    """
    options = {
        "max_depth": max_depth,
        "rr_depth": rr_depth,
        "strategy": strategy,
        "sampling": sampling,
    }
    if isinstance(integrator, Integrator):
        given = [k for k, v in options.items() if v is not None]
        if given:
            raise TypeError(
                f"{', '.join(given)}: set on the integrator object "
                f"({type(integrator).__name__}), not passed to {caller}()"
            )
        return integrator
    check_choice(integrator, "integrator", tuple(INTEGRATORS))
    options = {
        "max_depth": 3 if max_depth is None else max_depth,
        "rr_depth": 5 if rr_depth is None else rr_depth,
        "strategy": "mis" if strategy is None else strategy,
        "sampling": "detached" if sampling is None else sampling,
    }
    check_choice(options["strategy"], "strategy", STRATEGIES)
    check_choice(options["sampling"], "sampling", SAMPLING)
    for name in ("max_depth", "rr_depth"):
        check_positive_int(options[name], name)
    return make_integrator(integrator, **options)


def render_partial(
    scene, key, integrator: Integrator, *, spp: int, rows=None, passes=None, weights=None
):
    """UNNORMALISED sum ``(R, W, C)`` over sample passes of the radiance of some image rows.

    The single definition of the sample layout of :func:`render`, which returns
    ``render_partial(scene, key, integrator, spp=spp) / spp``:
    ``key`` splits into a camera key (``film.pixel_samples``: stratified when ``spp`` is a
    square, ``(H, W, spp, 2)``) and a key into which pass ``s`` is folded for the integrator's
    uniform numbers of shape ``(H, W, *integrator.random_shape)``; pass ``s`` traces one ray per
    pixel through camera sample ``s``. Each pass is checkpointed, so the memory of ``jax.grad``
    does not grow with the number of passes.

    ``rows``: ``None`` (all ``H`` rows) or global row indices ``(R,)`` (int32, may be traced;
    rows ``>= H`` are padding: rendered beyond the image with their own numbers). A row's
    samples and numbers are those of the whole image's row, so the pixel is computed by the same
    operations. ``passes``: ``None`` (``0 .. spp - 1``) or pass indices ``(P,)`` in
    ``[0, spp)`` (may be traced); ``weights``: ``None`` (1 each) or ``(P,)`` factors per pass
    (0 for padding passes). The estimate is the sum divided by the total weight of the passes
    (``spp`` once every pass is summed, on one device or over several);
    :mod:`jaxgfx.render.distributed` splits the rows or the passes over devices with it.
    Package-internal (not in ``__all__``); jittable, differentiable.
    """
    w, h = scene.width, scene.height
    kp, ku = jax.random.split(key)
    dtype = scene.dtype
    px = _pixel_samples(kp, w, h, spp, scene.rfilter, rows=rows, dtype=dtype)  # (R, W, spp, 2)
    shape_u = integrator.random_shape

    def one_pass(s):
        o, d = scene.camera.generate_ray(px[:, :, s, :])
        o, d = o.astype(dtype), d.astype(dtype)
        o, d = fusion_barrier((o, d))  # measured 635 -> 518 ns/sample (direct, one core)
        u = None
        if shape_u is not None:
            u = _uniform(jax.random.fold_in(ku, s), (h, w, *shape_u), dtype, rows=rows)
        return integrator(scene, o, d, u)

    # Reverse mode: a checkpointed pass is recomputed in the backward sweep, so only the
    # pass index is stored per sample pass and the memory of jax.grad does not grow with spp
    # (a plain loop stores every intermediate of every pass; docs/render_gradients.md).
    one_pass = jax.checkpoint(one_pass, prevent_cse=False)

    if passes is None:
        passes = jnp.arange(spp)
    if weights is None:
        weights = jnp.ones(passes.shape, dtype)  # x * 1 is exact: the sum is unchanged

    def body(acc, sw):
        s, wt = sw
        return acc + wt.astype(dtype) * one_pass(s), None

    acc0 = jnp.zeros((px.shape[0], w, integrator.n_channels), dtype)
    acc, _ = jax.lax.scan(body, acc0, (passes, weights))
    return acc


@eqx.filter_jit
def _render(scene, key, spp, integrator):
    return render_partial(scene, key, integrator, spp=spp) / spp
