"""Multi-device rendering: :func:`render_sharded` splits a render over a ``jax.sharding.Mesh``.

Two ways to split the work, chosen by ``shard``:

* ``"rows"`` (default): device ``d`` of ``n`` renders the image rows ``d, d + n, d + 2n, ...``
  (interleaved, so cheap sky rows and expensive floor rows spread evenly) with every sample of
  those pixels. Each pixel's camera samples and per-bounce uniform numbers are the ones
  :func:`jaxgfx.render.render` draws for that pixel (the counter of the hash-based sampler is
  offset by the pixel's global index), so every pixel is computed by the same operations: the
  image equals the single-device one up to the rounding of differently compiled programs. The
  height need not divide by ``n``: the last rows are padded (rendered beyond the image and
  dropped), at most ``n - 1`` idle rows.
* ``"samples"``: device ``d`` renders sample passes ``d, d + n, ...`` of the whole image; the
  passes use the same random numbers as the single-device render (pass ``s`` of
  :func:`~jaxgfx.render.render` folds ``s`` into the key), and the partial sums are added with
  a ``psum``. The image equals the single-device one up to the summation order of the ``spp``
  passes. ``spp`` need not divide by ``n`` (padded passes have weight 0, so some devices idle
  for one pass). Use it when the image is small and ``spp`` large.

Both modes call :func:`jaxgfx.render.estimator.render_partial` (the unnormalised sum over some rows
and passes that :func:`~jaxgfx.render.render` itself runs over all of them) with the options
resolved by :func:`jaxgfx.render.estimator.resolve_integrator`, so the sample layout and the
option handling are defined once.

The work runs in ``jax.shard_map`` over all axes of ``mesh`` (default: every device of
``jax.devices()`` on one axis); the result is replicated on every device (an ``all_gather`` of
the rows, or the ``psum``). ``jax.grad`` / ``jax.jvp`` go through ``shard_map``, so gradients are
sharded the same way: the backward pass of each device re-traces its own rows or passes, and the
cotangents of the (replicated) scene are summed across devices.

The same code runs on one CPU (a mesh of one device), several GPUs of one host, or several
hosts: call ``jax.distributed.initialize()`` on every process first, build the same scene and
key on each (same file, same seed), and pass ``mesh=jax.make_mesh((jax.device_count(),),
("render",))``; every process then holds the whole image. Multi-host runs are not tested here.
See docs/render.md ("Multi-device").
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P

from jaxgfx._checks import check_choice, check_positive_int
from jaxgfx.render.estimator import render_partial, resolve_integrator
from jaxgfx.render.integrators import Integrator

__all__ = ["render_sharded", "SHARDS", "default_mesh"]

SHARDS = ("rows", "samples")
"""Ways :func:`render_sharded` splits the work: image rows or sample passes."""


def default_mesh(axis_name: str = "render") -> Mesh:
    """A one-axis ``Mesh`` of every device of ``jax.devices()`` (all processes' devices)."""
    return Mesh(np.asarray(jax.devices()), (axis_name,))


def render_sharded(
    scene,
    key,
    *,
    spp: int = 64,
    integrator: str | Integrator = "path",
    mesh: Mesh | None = None,
    shard: str = "rows",
    max_depth: int | None = None,
    rr_depth: int | None = None,
    strategy: str | None = None,
    sampling: str | None = None,
):
    """:func:`jaxgfx.render.render` split over the devices of ``mesh``: an ``(H, W, C)`` image.

    ``scene``, ``key``, ``spp``, ``integrator`` and its options (``max_depth``, ``rr_depth``,
    ``strategy``, ``sampling``) are those of :func:`~jaxgfx.render.render`, and the result is
    the same image (same key, same samples) up to float32 rounding: ``shard="rows"`` computes
    every pixel with the same operations; ``shard="samples"`` adds the ``spp`` passes in another
    order. ``mesh``: a ``jax.sharding.Mesh`` (default :func:`default_mesh`: all devices); the
    work is split over all of its axes. Differentiable and jittable like ``render`` (``spp``,
    the integrator, ``mesh`` and ``shard`` are static).

    Example (4 CPU devices: ``XLA_FLAGS=--xla_force_host_platform_device_count=4`` set before
    importing jax)::

        img = render_sharded(scene, jax.random.key(0), spp=16)            # rows over 4 devices
        g = jax.grad(lambda a: render_sharded(
            scene.replace("materials.metal.alpha", a), key, spp=16).mean())(0.2)
    """
    check_positive_int(spp, "spp")
    check_choice(shard, "shard", SHARDS)
    if mesh is None:
        mesh = default_mesh()
    elif not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected a jax.sharding.Mesh, got {type(mesh).__name__}")
    integ = resolve_integrator(
        integrator,
        max_depth=max_depth,
        rr_depth=rr_depth,
        strategy=strategy,
        sampling=sampling,
        caller="render_sharded",
    )
    if getattr(integ, "traces_from_lights", False):
        raise ValueError(
            "integrator: the 'ptracer' integrator splats light paths over the whole image and "
            "is not split over devices; use jaxgfx.render.render"
        )
    return _render_sharded(scene, key, spp, integ, mesh, shard)


@eqx.filter_jit
def _render_sharded(scene, key, spp, integrator, mesh, shard):
    axes = tuple(mesh.axis_names)
    n = int(mesh.devices.size)
    h = scene.height
    # shard_map takes arrays only: the scene's other leaves are closed over (static).
    dyn, static = eqx.partition(scene, eqx.is_array)

    if shard == "rows":
        r = -(-h // n)  # rows per device (the last device may render padding rows >= h)

        def local(dyn, key):
            scene = eqx.combine(dyn, static)
            d = jax.lax.axis_index(axes)
            rows = d + n * jnp.arange(r, dtype=jnp.int32)
            acc = render_partial(scene, key, integrator, spp=spp, rows=rows)
            return jax.lax.all_gather(acc, axes)  # (n, r, W, C): tiles[d][i] = row d + n i

        tiles = jax.shard_map(
            local, mesh=mesh, in_specs=(P(), P()), out_specs=P(), check_vma=False
        )(dyn, key)
        img = jnp.swapaxes(tiles, 0, 1).reshape(n * r, *tiles.shape[2:])[:h]
        return img / spp

    q = -(-spp // n)  # passes per device; padded passes (index >= spp) have weight 0

    def local(dyn, key):
        scene = eqx.combine(dyn, static)
        d = jax.lax.axis_index(axes)
        s = d + n * jnp.arange(q, dtype=jnp.int32)
        weights = (s < spp).astype(jnp.float32)
        s = jnp.minimum(s, spp - 1)
        acc = render_partial(scene, key, integrator, spp=spp, passes=s, weights=weights)
        return jax.lax.psum(acc, axes)

    acc = jax.shard_map(local, mesh=mesh, in_specs=(P(), P()), out_specs=P(), check_vma=False)(
        dyn, key
    )
    return acc / spp  # the weights of the passes sum to spp
