"""What the Mitsuba 3 comparison tests share: the ``mi`` fixture, local-frame BSDF queries,
same-run replicate renders by each renderer, and the agreement checks of two replicate stacks
(``replicate_block_z`` of tests/render/_scenes.py is the block z the others build on)."""

from __future__ import annotations

import jax
import numpy as np
import pytest


def mitsuba_fixture(variant="scalar_rgb"):
    """A module-scoped fixture named ``mi``: the ``mitsuba`` module with ``variant`` set (the
    test skips without Mitsuba). Use as ``mi = mitsuba_fixture()`` at module level."""

    @pytest.fixture(scope="module", name="mi")
    def fixture():
        mitsuba = pytest.importorskip("mitsuba")
        mitsuba.set_variant(variant)
        return mitsuba

    return fixture


def unit_dirs(n, seed, *, upper=False):
    """``n`` directions (n, 3), normal-distributed and normalised (uniform on the sphere; on
    the upper hemisphere ``z >= 0`` with ``upper``), from ``np.random.default_rng(seed)``."""
    v = np.random.default_rng(seed).normal(size=(n, 3))
    if upper:
        v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def local_si(mi, wo):
    """A Mitsuba ``SurfaceInteraction3f`` with local ``wi = wo`` and shading normal ``+z``."""
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(wo)
    si.sh_frame = mi.Frame3f(mi.Normal3f(0, 0, 1))
    return si


def mitsuba_eval_pdf_sample(mi, bsdf, wo, wi, u1, u2):
    """Mitsuba's ``eval``, ``pdf`` and ``sample`` of the loaded ``bsdf`` at each local pair
    ``wo[i]``, ``wi[i]`` (shading point at the origin, normal ``+z``) and uniforms ``u1[i]``,
    ``u2[i]``: float64 arrays ``(eval, pdf, sampled wo, sample pdf, sample weight)``."""
    ctx = mi.BSDFContext()
    f, pdf, sw, sp, sv = [], [], [], [], []
    for a, c, v1, v2 in zip(wo, wi, u1, u2, strict=True):
        si = mi.SurfaceInteraction3f()
        si.p, si.n = [0, 0, 0], [0, 0, 1]
        si.sh_frame = mi.Frame3f(si.n)
        si.wi = mi.Vector3f(*a)
        f.append(np.array(bsdf.eval(ctx, si, mi.Vector3f(*c))))
        pdf.append(bsdf.pdf(ctx, si, mi.Vector3f(*c)))
        bs, w = bsdf.sample(ctx, si, float(v1), mi.Point2f(*v2))
        sw.append(np.array(bs.wo))
        sp.append(bs.pdf)
        sv.append(np.array(w))
    return [np.asarray(x, np.float64) for x in (f, pdf, sw, sp, sv)]


def mitsuba_replicates(mi, scene, k, spp, *, seed0=0):
    """``k`` Mitsuba renders of the loaded ``scene`` at ``spp``, seeds ``seed0 .. seed0+k-1``,
    as one float64 stack ``(k, H, W, 3)`` (RGB of each film)."""
    return np.stack([np.array(mi.render(scene, spp=spp, seed=seed0 + s))[..., :3]
                     for s in range(k)]).astype(np.float64)  # fmt: skip


def jaxgfx_replicates(scene, seed, k, *, jit=False, **render_kw):
    """``k`` jaxgfx renders of ``scene`` with the keys ``jax.random.split(key(seed), k)``
    (``jax.vmap`` of ``render(scene, key, **render_kw)``, under ``jax.jit`` with ``jit``), as
    one float64 stack ``(k, H, W, 3)``."""
    from jaxgfx.render.render import render

    f = jax.vmap(lambda key: render(scene, key, **render_kw))
    if jit:
        f = jax.jit(f)
    return np.asarray(f(jax.random.split(jax.random.key(seed), k)), np.float64)


def mitsuba_scene_from_desc(mi, desc, integrator=None):
    """Mitsuba's scene of the jaxgfx description ``desc`` (``to_mitsuba_dict`` then
    ``load_dict``), with the ``integrator`` dict when given."""
    from jaxgfx.render.scene.mitsuba import to_mitsuba_dict

    d = to_mitsuba_dict(desc, mi=mi)
    if integrator is not None:
        d["integrator"] = integrator
    return mi.load_dict(d)


def assert_channels_and_pixels_agree(a, b):
    """Replicate stacks ``a`` (jaxgfx) and ``b`` (Mitsuba), K x H x W x 3, agree: channel means
    within 5 standard errors of the replicate spread (Welch-type z; P(|z| > 5) ~ 1e-3 with 6
    dof), and pixels (mean of the K replicates each) ``|z| < 4`` for >= 95 % (few dof per pixel:
    heavy tails). Returns ``(channel means a, channel means b, fraction of pixels |z| < 4)``."""
    k = a.shape[0]
    ma, mb = a.mean((0, 1, 2)), b.mean((0, 1, 2))
    se = np.sqrt(a.mean((1, 2)).var(0, ddof=1) / k + b.mean((1, 2)).var(0, ddof=1) / k)
    assert np.all(np.abs(ma - mb) < 5 * se + 1e-6), (ma, mb, se)
    var = a.var(0, ddof=1) / k + b.var(0, ddof=1) / k + (1e-4 * (a.mean(0) + b.mean(0))) ** 2
    z = np.abs(a.mean(0) - b.mean(0)) / np.sqrt(var + 1e-12)
    assert np.mean(z < 4) >= 0.95, np.mean(z < 4)
    return ma, mb, float(np.mean(z < 4))


def assert_channels_and_blocks_agree(a, b, block=8):
    """Replicate stacks ``a`` (jaxgfx) and ``b`` (Mitsuba), K x H x W x 3: channel means within
    5 standard errors of the replicate spread, and ``block`` x ``block`` block means with
    |z| < 4 in >= 90 % of the blocks (few replicates: heavy tails). Returns the channel z and
    the block z."""
    k = a.shape[0]
    ma, mb = a.mean((0, 1, 2)), b.mean((0, 1, 2))
    se = np.sqrt(a.mean((1, 2)).var(0, ddof=1) / k + b.mean((1, 2)).var(0, ddof=1) / k)
    assert np.all(np.abs(ma - mb) < 5 * se + 1e-6), (ma, mb, se)
    h, w = a.shape[1] // block, a.shape[2] // block

    def blocks(x):
        return x[:, : h * block, : w * block].reshape(k, h, block, w, block, 3).mean((2, 4))

    ba, bb = blocks(a), blocks(b)
    se_b = np.sqrt(ba.var(0, ddof=1) / k + bb.var(0, ddof=1) / k) + 1e-9
    z = (ba.mean(0) - bb.mean(0)) / se_b
    assert np.mean(np.abs(z) < 4) >= 0.9, z
    return (ma - mb) / se, z
