"""Camera response recovery: :func:`recover_response` and :data:`RESPONSE_METHODS`.

Conventions
-----------
* Pixel levels ``z`` are given in the units of the input images: integer codes for uint8 /
  uint16 data (0…255, 0…65535), or floats in ``[0, 1]``. Internally they are normalised to
  ``[0, 1]`` by ``code_max`` (255, 65535 or 1).
* ``CameraResponse.to_linear(z)`` returns *relative* linear exposure (irradiance × time,
  arbitrary unit) per channel; the unit is fixed by an explicit anchor: by default
  ``to_linear(0.5 * code_max) = 1`` (``anchor="mid"``, Debevec & Malik's ``g(Z_mid) = 0``).
"""

from __future__ import annotations

import functools

import jax

from .._checks import check_choice
from ._debevec import DEBEVEC_MAX_CANDIDATES, recover_debevec
from ._model import CameraResponse, resolve_anchor
from ._parametric import recover_gamma, recover_polynomial, recover_spline
from ._robertson import recover_robertson
from ._sampling import _stride_for
from ._stack import normalize_stack, prepare_stack

__all__ = ["CameraResponse", "recover_response", "RESPONSE_METHODS"]

RESPONSE_METHODS = {
    "debevec": recover_debevec,
    "robertson": recover_robertson,
    "gamma": recover_gamma,
    "polynomial": recover_polynomial,
    "spline": recover_spline,
}
"""Response-recovery methods by name; each ``fn(z, t, code_max, **options) -> CameraResponse``
with normalised levels ``z`` ``(N, H, W, C)`` and ascending times ``t`` ``(N,)``."""


def recover_response(images, exposure_times, *, method: str = "debevec", **options):
    """Recover the camera response from a bracketed stack of one static scene.

    ``images``: ``(N, H, W, C)`` or ``(N, H, W)`` (or a sequence of N frames), uint8, uint16
    or floats in ``[0, 1]``; ``exposure_times``: ``(N,)`` seconds (any order; frames are
    sorted with them; duplicates are fine as long as 2 distinct times exist). N ≥ 2.
    ``method``: a key of :data:`RESPONSE_METHODS`. Common options: ``key`` (JAX key for the
    pixel sample selection, default ``jax.random.key(0)``), ``n_samples``, ``anchor``.
    Method options are documented on each method (``jaxgfx.hdr._debevec.recover_debevec``…).

    Returns a :class:`CameraResponse` with one curve per channel. Jittable (options static).

    References: Debevec & Malik, SIGGRAPH 1997; Robertson, Borman & Stevenson, JEI 2003;
    Mitsunaga & Nayar, CVPR 1999.

    Example: a noise-free float stack of ``x = z^2.2`` data gives back ``gamma ≈ 2.2`` with
    ``method="gamma"``.
    """
    check_choice(method, "method", tuple(RESPONSE_METHODS.keys()))
    raw, t, code_max, _ = prepare_stack(images, exposure_times, min_frames=2, raw=True)
    if "anchor" in options:
        options["anchor"] = resolve_anchor(options["anchor"])
    key = options.pop("key", None)
    if key is None:
        key = jax.random.key(0)
    try:
        opts = tuple(sorted(options.items()))
        hash(opts)
    except TypeError:
        raise TypeError("options: expected hashable option values (numbers, strings)") from None
    return _recover_jit(raw, t, key, method=method, code_max=code_max, opts=opts)


@functools.partial(jax.jit, static_argnames=("method", "code_max", "opts"))
def _recover_jit(raw, t, key, *, method, code_max, opts):
    if method == "debevec":
        # Debevec only looks at the pixels of select_samples' candidate grid: cut it out with
        # one strided slice of the raw codes before normalising and sorting (at 1 MP the full
        # conversion and the n-d gathers cost 5x the rest); flatness is then measured
        # between neighbouring candidates
        n, h, w, c = raw.shape
        s = _stride_for(h, w, dict(opts).get("max_candidates", DEBEVEC_MAX_CANDIDATES))
        if s > 1:
            oy = (h - 1 - ((h - 1) // s) * s) // 2
            ox = (w - 1 - ((w - 1) // s) * s) // 2
            raw = raw[:, oy::s, ox::s, :]
    z, t = normalize_stack(raw, t, code_max)
    return RESPONSE_METHODS[method](z, t, code_max, key=key, **dict(opts))
