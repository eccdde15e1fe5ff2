"""Shared, cached synthetic stacks for the hdr tests (small images; built once per session)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx import hdr

TIMES5 = (1.0, 4.0, 16.0, 64.0, 256.0)


@functools.cache
def radiance(size=64, dynamic_range=1e4):
    return hdr.synthetic_radiance(jax.random.key(1), size, size, dynamic_range=dynamic_range)


@functools.cache
def stack(
    name="gamma2.2",
    *,
    size=64,
    times=TIMES5,
    bits=8,
    gain=1e-4,
    read_sigma=1e-3,
    dynamic_range=1e4,
    seed=2,
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
