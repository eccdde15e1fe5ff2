"""Leave-one-out re-exposure error: a self-check of a response + merge without ground truth.

For each frame ``k`` of a bracket, the other frames are merged into a radiance map, which is
re-exposed at frame ``k``'s time through the response (``z = f(E t_k)``) and compared with the
real frame ``k``. A good response and merge predict every held-out frame to within its noise
and JPEG error; a wrong toe, shoulder or exposure time shows up as a biased band.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_choice
from ._model import CameraResponse
from ._stack import prepare_stack
from .merge import (
    MERGE_WEIGHTINGS,
    SLOPE_NOISE_RATIO,
    _frame_terms,
    _noise_arrays,
    check_noise_ratio,
    resolve_time_power,
)

__all__ = ["leave_one_out", "LeaveOneOut", "LOO_BANDS"]

LOO_BANDS = (10.0, 50.0, 100.0, 150.0, 200.0, 245.0)
"""Default band edges of the held frame's level, on the 0–255 scale."""


class LeaveOneOut(NamedTuple):
    """Result of :func:`leave_one_out`; errors on the 0–255 level scale (8-bit code values
    for uint8 input; ``z / code_max · 255`` for uint16 and float input).

    ``mean_abs_error``: scalar, mean ``|predicted − actual|`` over every held frame's pixels
    whose actual level lies in ``[band_edges[0], band_edges[-1]]``; ``per_frame`` ``(N,)`` the
    same per held frame (frames sorted by exposure time; NaN where no pixel is in range);
    ``per_frame_bias`` ``(N,)`` the mean signed error; ``per_band`` / ``per_band_bias`` /
    ``per_band_count`` ``(B,)`` by the held frame's level band ``[band_edges[b],
    band_edges[b+1])`` over all frames; ``band_edges`` ``(B+1,)``; ``exposure_times``
    ``(N,)`` sorted.
    """

    mean_abs_error: jax.Array
    per_frame: jax.Array
    per_frame_bias: jax.Array
    per_band: jax.Array
    per_band_bias: jax.Array
    per_band_count: jax.Array
    band_edges: jax.Array
    exposure_times: jax.Array

    def to_dict(self) -> dict:
        """JSON-ready dict (NaN → ``None``)."""

        def j(v):
            a = np.asarray(v, dtype=float)
            if a.ndim == 0:
                return float(a) if np.isfinite(a) else None
            return [float(x) if np.isfinite(x) else None for x in a]

        return {
            "mean_abs_error": j(self.mean_abs_error),
            "per_frame": j(self.per_frame),
            "per_frame_bias": j(self.per_frame_bias),
            "per_band": j(self.per_band),
            "per_band_bias": j(self.per_band_bias),
            "per_band_count": [int(c) for c in np.asarray(self.per_band_count)],
            "band_edges": j(self.band_edges),
            "exposure_times": j(self.exposure_times),
            "units": "levels on a 0-255 scale",
            "definition": (
                "for each frame: merge the others, re-expose at its time through the response, "
                "mean |predicted - actual| over its pixels with levels in the band range"
            ),
        }


def leave_one_out(
    images,
    exposure_times,
    response: CameraResponse,
    *,
    weighting: str = "slope",
    noise=None,
    bands=LOO_BANDS,
    merge=None,
    time_power: float = 2.0,
    noise_ratio=SLOPE_NOISE_RATIO,
) -> LeaveOneOut:
    """Leave-one-out re-exposure error of ``response`` (and the merge) on a bracket.

    For every frame ``k``: ``E = merge(other frames)``, predicted level
    ``ẑ = response.from_linear(E · t_k)``, error ``ẑ − z_k`` on the 0–255 scale, kept where
    the actual level ``z_k`` lies in ``[bands[0], bands[-1]]`` (default 10…245, away from
    black and clipping, where a level says little). A self-check that needs no ground truth:
    on real photographs it replaces the errors against a known radiance.

    Args:
      images, exposure_times: the stack as for :func:`merge_radiance` (N ≥ 2; any order).
      response: the :class:`CameraResponse` to check (usually recovered from all N frames).
      weighting, noise, time_power, noise_ratio: merge options (:func:`merge_radiance`).
      bands: increasing band edges on the 0–255 scale (at least 2).
      merge: optional callable ``merge(images, times) -> E`` (``(H, W, C)``, in units of
        ``response.to_linear`` per second) replacing :func:`merge_radiance`, e.g. a peer's
        merge for a comparison; then the check runs eagerly (not jittable).

    Returns a :class:`LeaveOneOut`. Jittable in the default path (options static).

    Example: a noise-free float stack with its true response has ``mean_abs_error ≈ 0``
    (see ``tests/hdr/test_selfcheck.py``).
    """
    check_choice(weighting, "weighting", MERGE_WEIGHTINGS)
    time_power = resolve_time_power(weighting, time_power)
    check_noise_ratio(noise_ratio)
    if not isinstance(response, CameraResponse):
        raise TypeError(f"response: expected a CameraResponse, got {type(response).__name__}")
    edges = tuple(float(b) for b in bands)
    if len(edges) < 2 or any(b2 <= b1 for b1, b2 in zip(edges, edges[1:], strict=False)):
        raise ValueError(f"bands: expected at least 2 increasing edges, got {bands!r}")
    if weighting == "noise" and noise is None and merge is None:
        raise ValueError('noise: weighting="noise" needs a noise model (.gain, .read_variance)')
    z, t, code_max, _ = prepare_stack(images, exposure_times, min_frames=2, raw=True)
    n, c = z.shape[0], z.shape[-1]
    if response.channels not in (1, c):
        raise ValueError(f"response: has {response.channels} channels but the images have {c}")
    fdt = jnp.result_type(jnp.float32, response.params.dtype, t.dtype)
    t = t.astype(fdt)
    if jnp.issubdtype(z.dtype, jnp.floating):
        z = z.astype(fdt)
    if merge is None:
        noise_arr = None if noise is None else _noise_arrays(noise, c, fdt)
        return _loo_jit(
            z,
            t,
            response,
            noise_arr,
            jnp.asarray(noise_ratio, fdt),
            weighting=weighting,
            code_max=code_max,
            edges=edges,
            time_power=time_power,
        )
    order = np.argsort(np.asarray(t))
    zs, ts = z[order], t[order]
    preds = []
    for k in range(n):
        keep = [j for j in range(n) if j != k]
        e = jnp.asarray(merge(zs[jnp.asarray(keep)], ts[jnp.asarray(keep)]), fdt)
        if e.ndim == 2:
            e = e[..., None]
        preds.append(response.from_linear_normalized(e * ts[k]))
    return _score(jnp.stack(preds), _norm(zs, code_max, fdt), ts, edges)


def _norm(z, code_max, dt):
    return z.astype(dt) if jnp.issubdtype(z.dtype, jnp.floating) else z.astype(dt) / code_max


@functools.partial(jax.jit, static_argnames=("weighting", "code_max", "edges", "time_power"))
def _loo_jit(z, t, response, noise, noise_ratio, *, weighting, code_max, edges, time_power):
    """Per-frame terms once (one lookup), then for each held frame ``k`` the weighted mean
    over the others (the same as :func:`merge_radiance` on the other frames, fallback
    included)."""
    order = jnp.argsort(t)
    z, t = z[order], t[order]
    n = z.shape[0]
    x, w, _, bright = _frame_terms(
        z,
        t,
        response,
        noise,
        weighting=weighting,
        code_max=code_max,
        need_var=False,
        time_power=time_power,
        noise_ratio=noise_ratio,
    )
    e_j = x / t[:, None, None, None]
    we = w * e_j

    def held(k):
        keep = (jnp.arange(n) != k)[:, None, None, None]
        sk = jnp.sum(jnp.where(keep, we, 0.0), axis=0)
        wk = jnp.sum(jnp.where(keep, w, 0.0), axis=0)
        ok = wk > 0
        shortest = jnp.where(k == 0, 1, 0)
        longest = jnp.where(k == n - 1, n - 2, n - 1)
        fb = jnp.where(bright[shortest], e_j[shortest], e_j[longest])
        e = jnp.where(ok, sk / jnp.where(ok, wk, 1.0), fb)
        return response.from_linear_normalized(e * t[k])

    preds = jax.lax.map(held, jnp.arange(n))
    return _score(preds, _norm(z, code_max, t.dtype), t, edges)


def _score(pred, actual, t, edges):
    """``pred``/``actual``: ``(N, H, W, C)`` normalised levels."""
    dt = actual.dtype
    p = jnp.clip(pred, 0.0, 1.0) * 255.0
    a = actual * 255.0
    d = p - a
    ed = jnp.asarray(edges, dt)
    eps = 1e-3  # levels are k / code_max * 255 in float: make the edges inclusive robustly
    inr = (a >= ed[0] - eps) & (a <= ed[-1] + eps)
    ax = tuple(range(1, d.ndim))

    def mean(v, m, axis=None):
        cnt = jnp.sum(m, axis=axis)
        s = jnp.sum(jnp.where(m, v, 0.0), axis=axis)
        return jnp.where(cnt > 0, s / jnp.maximum(cnt, 1), jnp.nan), cnt

    total, _ = mean(jnp.abs(d), inr)
    pf, _ = mean(jnp.abs(d), inr, ax)
    pfb, _ = mean(d, inr, ax)
    nb = len(edges) - 1
    band = jnp.clip(jnp.searchsorted(ed, a + eps, side="right") - 1, 0, nb - 1)
    pb, pbb, pbc = [], [], []
    for b in range(nb):
        m = inr & (band == b)
        v, cnt = mean(jnp.abs(d), m)
        vb, _ = mean(d, m)
        pb.append(v)
        pbb.append(vb)
        pbc.append(cnt)
    return LeaveOneOut(total, pf, pfb, jnp.stack(pb), jnp.stack(pbb), jnp.stack(pbc), ed, t)
