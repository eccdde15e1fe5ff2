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

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh
from jax.sharding import PartitionSpec as P

from jaxgfx._checks import check_choice
from jaxgfx._math import fusion_barrier
from jaxgfx.render.film import BoxFilter
from jaxgfx.render.integrators import INTEGRATORS, Integrator, make_integrator
from jaxgfx.render.integrators._common import SAMPLING
from jaxgfx.render.integrators.path import STRATEGIES
from jaxgfx.render.sampler import pcg_hash

__all__ = ["render_sharded", "SHARDS", "default_mesh"]

SHARDS = ("rows", "samples")
"""Ways :func:`render_sharded` splits the work: image rows or sample passes."""


def default_mesh(axis_name: str = "render") -> Mesh:
    """A one-axis ``Mesh`` of every device of ``jax.devices()`` (all processes' devices)."""
    return Mesh(np.asarray(jax.devices()), (axis_name,))


def _resolve_integrator(integrator, max_depth, rr_depth, strategy, sampling) -> Integrator:
    # Mirrors the option handling of jaxgfx.render.render (same defaults, same errors).
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
                f"({type(integrator).__name__}), not passed to render_sharded()"
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
        v = options[name]
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise ValueError(f"{name}: expected a positive integer, got {v!r}")
    return make_integrator(integrator, **options)


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
    if isinstance(spp, bool) or not isinstance(spp, int) or spp < 1:
        raise ValueError(f"spp: expected a positive integer, got {spp!r}")
    check_choice(shard, "shard", SHARDS)
    if mesh is None:
        mesh = default_mesh()
    elif not isinstance(mesh, Mesh):
        raise TypeError(f"mesh: expected a jax.sharding.Mesh, got {type(mesh).__name__}")
    integ = _resolve_integrator(integrator, max_depth, rr_depth, strategy, sampling)
    return _render_sharded(scene, key, spp, integ, mesh, shard)


def _uniform_rows(key, rows, width: int, tail: tuple[int, ...], dtype):
    """``sampler.uniform(key, (H, width, *tail))[rows]`` without drawing the other rows.

    ``sampler.uniform`` hashes the flat index of each number; the flat index of entry
    ``(r, j, *t)`` is ``(r * width + j) * prod(tail) + flat(t)``, so the rows' numbers are
    computed from their global row indices ``rows (R,)`` (int32, may be traced).
    """
    k = math.prod(tail)
    seed = pcg_hash(jax.random.bits(key, (), jnp.uint32))
    local = jax.lax.iota(jnp.uint32, width * k).reshape(1, width * k)
    base = rows.astype(jnp.uint32)[:, None] * jnp.uint32(width * k)
    bits = pcg_hash(base + local + seed).reshape(rows.shape[0], width, *tail)
    if jnp.dtype(dtype) == jnp.float64:
        return bits.astype(jnp.float64) * (2.0**-32)
    return (bits >> 8).astype(dtype) * jnp.asarray(2.0**-24, dtype)


def _pixel_samples_rows(key, rows, width: int, spp: int, rfilter):
    """``film.pixel_samples(key, width, H, spp, rfilter)[rows]`` for global row indices."""
    rfilter = rfilter or BoxFilter()
    n = int(round(spp**0.5))
    u = _uniform_rows(key, rows, width, (spp, 2), jnp.float32)
    if n * n == spp and spp > 1:
        iy, ix = jnp.divmod(jnp.arange(spp), n)
        u = (jnp.stack([ix, iy], -1) + u) / n
    off = rfilter.sample(u)
    jj, ii = jnp.meshgrid(jnp.arange(width), rows)
    centre = jnp.stack([jj, ii], -1).astype(u.dtype) + 0.5
    return centre[:, :, None, :] + off


def _partial_sum(scene, key, integrator, spp: int, rows, passes, weights):
    """Sum over ``passes`` (weighted by ``weights``) of the radiance of the pixels in ``rows``.

    Mirrors ``jaxgfx.render.render._render`` restricted to rows and passes: the same key split,
    the same camera samples, the same per-pass uniform numbers, the same checkpointed pass.
    """
    w = scene.width
    kp, ku = jax.random.split(key)
    px = _pixel_samples_rows(kp, rows, w, spp, scene.rfilter)  # (R, W, spp, 2)
    dtype = px.dtype
    shape_u = integrator.random_shape

    def one_pass(s):
        o, d = scene.camera.generate_ray(px[:, :, s, :])
        o, d = o.astype(dtype), d.astype(dtype)
        o, d = fusion_barrier((o, d))
        u = None
        if shape_u is not None:
            u = _uniform_rows(jax.random.fold_in(ku, s), rows, w, tuple(shape_u), dtype)
        return integrator(scene, o, d, u)

    one_pass = jax.checkpoint(one_pass, prevent_cse=False)

    def body(acc, sw):
        s, wt = sw
        return acc + wt.astype(dtype) * one_pass(s), None

    acc0 = jnp.zeros((rows.shape[0], w, integrator.n_channels), dtype)
    acc, _ = jax.lax.scan(body, acc0, (passes, weights))
    return acc


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
            passes = jnp.arange(spp, dtype=jnp.int32)
            acc = _partial_sum(scene, key, integrator, spp, rows, passes, jnp.ones(spp))
            tiles = jax.lax.all_gather(acc, axes)  # (n, r, W, C): tiles[d][i] = row d + n i
            return tiles

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
        rows = jnp.arange(h, dtype=jnp.int32)
        acc = _partial_sum(scene, key, integrator, spp, rows, s, weights)
        return jax.lax.psum(acc, axes)

    acc = jax.shard_map(local, mesh=mesh, in_specs=(P(), P()), out_specs=P(), check_vma=False)(
        dyn, key
    )
    return acc / spp
