"""The Monte Carlo estimator over the image plane: the one owner of the sample layout and of
the pass scan.

:func:`render_partial` is the sum over sample passes that :func:`jaxgfx.render.render`,
:func:`jaxgfx.render.render_sharded` (per device: some rows or some passes) and the
edge-sampling boundary term (:mod:`jaxgfx.render.visibility`, through :func:`pass_scan`) are
built from; :func:`resolve_integrator` turns ``render``'s string options into an
:class:`~jaxgfx.render.integrators.Integrator` object at the API edge. Nothing here imports
``render.py``, ``visibility.py`` or ``distributed.py``: they compose this module.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxgfx._checks import check_choice, check_positive_int
from jaxgfx._math import fusion_barrier
from jaxgfx.render.film import pixel_samples
from jaxgfx.render.integrators import INTEGRATORS, Integrator, make_integrator
from jaxgfx.render.integrators._common import SAMPLING
from jaxgfx.render.integrators.path import STRATEGIES
from jaxgfx.render.sampler import uniform

__all__ = ["render_partial", "resolve_integrator", "pass_scan"]


def pass_scan(one_pass, passes, acc0, weights=None):
    """``acc0 + Σ_s weights[s] · one_pass(s)`` over the pass indices ``passes`` ``(P,)``, one
    ``lax.scan`` step per pass, each pass checkpointed: the reverse sweep recomputes a pass from
    its index, so the memory of ``jax.grad`` does not grow with the number of passes (a plain
    loop stores every intermediate of every pass; docs/render_gradients.md). ``weights``:
    ``None`` (1 each; ``x * 1`` is exact, so the sum is that of the unweighted passes)."""
    one_pass = jax.checkpoint(one_pass, prevent_cse=False)
    if weights is None:
        weights = jnp.ones(passes.shape, acc0.dtype)

    def body(acc, sw):
        s, wt = sw
        return acc + wt.astype(acc.dtype) * one_pass(s), None

    acc, _ = jax.lax.scan(body, acc0, (passes, weights))
    return acc


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
    a name of :data:`INTEGRATORS` is built by :func:`make_integrator` from the options given
    (not ``None``); the others keep the class's defaults (``PathIntegrator``: ``max_depth=3``,
    ``rr_depth=5``, ``strategy="mis"``, ``sampling="detached"``). An option the named
    integrator does not have is a ``TypeError`` naming it (``"aov"`` with ``max_depth``; the
    depth of ``"direct"`` is 2). Bad names and values raise ``ValueError`` naming the option.
    Runs on the host, before tracing.
    """
    given = {
        k: v
        for k, v in (
            ("max_depth", max_depth),
            ("rr_depth", rr_depth),
            ("strategy", strategy),
            ("sampling", sampling),
        )
        if v is not None
    }
    if isinstance(integrator, Integrator):
        if given:
            raise TypeError(
                f"{', '.join(given)}: set on the integrator object "
                f"({type(integrator).__name__}), not passed to {caller}()"
            )
        return integrator
    check_choice(integrator, "integrator", tuple(INTEGRATORS))
    if "strategy" in given:
        check_choice(given["strategy"], "strategy", STRATEGIES)
    if "sampling" in given:
        check_choice(given["sampling"], "sampling", SAMPLING)
    for name in ("max_depth", "rr_depth"):
        if name in given:
            check_positive_int(given[name], name)
    return make_integrator(integrator, **given)


def render_partial(
    scene, key, integrator: Integrator, *, spp: int, rows=None, passes=None, weights=None
):
    """UNNORMALISED sum ``(R, W, C)`` over sample passes of the radiance of some image rows.

    The single definition of the sample layout of :func:`jaxgfx.render.render`, which returns
    ``render_partial(scene, key, integrator, spp=spp) / spp``:
    ``key`` splits into a camera key (``film.pixel_samples``: stratified when ``spp`` is a
    square, ``(H, W, spp, 2)``) and a key into which pass ``s`` is folded for the integrator's
    uniform numbers of shape ``(H, W, *integrator.random_shape)``; pass ``s`` traces one ray per
    pixel through camera sample ``s``; the passes run through :func:`pass_scan`.

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
    px = pixel_samples(kp, w, h, spp, scene.rfilter, rows=rows, dtype=dtype)  # (R, W, spp, 2)
    shape_u = integrator.random_shape

    def one_pass(s):
        o, d = scene.camera.generate_ray(px[:, :, s, :])
        o, d = o.astype(dtype), d.astype(dtype)
        o, d = fusion_barrier((o, d))  # measured 635 -> 518 ns/sample (direct, one core)
        u = None
        if shape_u is not None:
            u = uniform(jax.random.fold_in(ku, s), (h, w, *shape_u), dtype, rows=rows)
        return integrator(scene, o, d, u)

    if passes is None:
        passes = jnp.arange(spp)
    acc0 = jnp.zeros((px.shape[0], w, integrator.n_channels), dtype)
    return pass_scan(one_pass, passes, acc0, weights)


