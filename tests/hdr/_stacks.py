"""Shared, cached synthetic stacks for the hdr tests (small images; built once per session)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx import hdr

TIMES5 = (1.0, 4.0, 16.0, 64.0, 256.0)


def radiance(size=64, dynamic_range=1e4):
    # cached per precision mode: a radiance built under the x64 fixture differs in the last
    # float32 bits and must not leak into float32 tests (it changed a Monte Carlo test)
    return _radiance(size, dynamic_range, bool(jax.config.jax_enable_x64))


@functools.cache
def _radiance(size, dynamic_range, x64):
    return hdr.synthetic_radiance(jax.random.key(1), size, size, dynamic_range=dynamic_range)


def stack(name="gamma2.2", **kw):
    return _stack(name, x64=bool(jax.config.jax_enable_x64), **kw)


@functools.cache
def _stack(
    name="gamma2.2",
    *,
    size=64,
    times=TIMES5,
    bits=8,
    gain=1e-4,
    read_sigma=1e-3,
    dynamic_range=1e4,
    seed=2,
    x64=False,
):
    rad = radiance(size, dynamic_range)
    return hdr.make_bracketed_stack(
        jax.random.key(seed),
        rad,
        jnp.asarray(times),
        hdr.synthetic_response(name),
        bits=bits,
        gain=gain,
        read_sigma=read_sigma,
    )


def opencv_debevec(images, times):
    """OpenCV CalibrateDebevec + MergeDebevec on an RGB uint8 stack → (response, E)."""
    import cv2

    bgr = [np.ascontiguousarray(np.asarray(im)[..., ::-1]) for im in images]
    tt = np.asarray(times, np.float32)
    crv = cv2.createCalibrateDebevec().process(bgr, tt)
    e = cv2.createMergeDebevec().process(bgr, tt, crv)[..., ::-1]
    return _cv_response(crv), jnp.asarray(e)


def opencv_robertson(images, times):
    import cv2

    bgr = [np.ascontiguousarray(np.asarray(im)[..., ::-1]) for im in images]
    tt = np.asarray(times, np.float32)
    crv = cv2.createCalibrateRobertson().process(bgr, tt)
    e = cv2.createMergeRobertson().process(bgr, tt, crv)[..., ::-1]
    return _cv_response(crv), jnp.asarray(e)


def _cv_response(crv):
    tab = np.log(np.maximum(crv[:, 0, ::-1].astype(np.float64), 1e-30)).astype(np.float32)
    return hdr.CameraResponse(jnp.asarray(tab), "table", "opencv", 255.0, 0.5)


JPEG_TIMES3 = (1.0 / 64, 1.0 / 8, 1.0)
JPEG_TIMES5 = (1.0 / 256, 1.0 / 64, 1.0 / 16, 1.0 / 4, 1.0)


@functools.cache
def jpeg_stack(name="camera", *, times=JPEG_TIMES3, size=96, max_shift=0.0, seed=2):
    """A JPEG-like stack (toe/shoulder response, noise, Pillow q90 4:2:0 round trip)."""
    return hdr.make_jpeg_stack(
        jax.random.key(seed), radiance(size, 1e4), jnp.asarray(times), name, max_shift=max_shift
    )


def opencv_loo(images, times):
    """OpenCV CalibrateDebevec on all frames, then leave-one-out with MergeDebevec on the
    others; re-exposure through OpenCV's curve made monotone by sorting (the inverse of a
    non-monotone curve read as a counting function). Returns (response, LeaveOneOut)."""
    import cv2

    bgr = [np.ascontiguousarray(np.asarray(im)[..., ::-1]) for im in images]
    tt = np.asarray(times, np.float32)
    crv = cv2.createCalibrateDebevec().process(bgr, tt)
    tab = np.log(np.maximum(crv[:, 0, ::-1].astype(np.float64), 1e-30))
    anchor = np.exp(0.5 * (tab[127] + tab[128]))
    tab = np.sort(tab, axis=0) + np.arange(256)[:, None] * 1e-6
    resp = hdr.CameraResponse(jnp.asarray(tab, jnp.float32), "table", "opencv", 255.0, 0.5)
    md = cv2.createMergeDebevec()

    def merge(z, t):
        b = [np.ascontiguousarray(im[..., ::-1]) for im in np.asarray(z)]
        return md.process(b, np.asarray(t, np.float32), crv)[..., ::-1] / anchor

    return resp, hdr.leave_one_out(images, times, resp, merge=merge)
