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
import inspect

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_choice, is_concrete
from ._debevec import DEBEVEC_MAX_CANDIDATES, recover_debevec
from ._model import CameraResponse, resolve_anchor
from ._parametric import recover_gamma, recover_polynomial, recover_spline
from ._robertson import recover_robertson
from ._sampling import _stride_for
from ._stack import normalize_stack, prepare_stack
from ._subspace import recover_subspace

__all__ = [
    "CameraResponse",
    "recover_response",
    "RESPONSE_METHODS",
    "check_response_options",
    "MIN_USABLE_PIXELS",
]

MIN_USABLE_PIXELS = 16
"""Response recovery needs at least this many *usable* pixels per channel: pixels whose level
is strictly between 0 and the clipping level (``code_max``) in at least 2 frames of the
stack. A bracket where every pixel is clipped or black holds no information about the curve;
:func:`recover_response` raises ``ValueError`` for it instead of returning a flat fit."""

MIN_SAMPLES = 32
"""Smallest ``n_samples`` option: pixels are sampled in 32 intensity bins, the same number
from each (``n_samples`` is rounded down to a multiple of 32)."""

RESPONSE_METHODS = {
    "debevec": recover_debevec,
    "robertson": recover_robertson,
    "gamma": recover_gamma,
    "polynomial": recover_polynomial,
    "spline": recover_spline,
    "subspace": recover_subspace,
}
"""Response-recovery methods by name; each ``fn(z, t, code_max, **options) -> CameraResponse``
with normalised levels ``z`` ``(N, H, W, C)`` and ascending times ``t`` ``(N,)``."""


def check_response_options(method: str, options, *, name: str = "options") -> dict:
    """Check method-specific ``options`` of :func:`recover_response` before any work.

    Names must be keyword options of the method (``key`` and ``anchor`` are common to all);
    ``n_samples`` must be an integer >= :data:`MIN_SAMPLES`. Raises ``ValueError`` naming
    ``name`` and listing the accepted options. Returns ``options`` as a dict.

    >>> check_response_options("debevec", {"lam": 50.0})
    {'lam': 50.0}
    """
    check_choice(method, "method", tuple(RESPONSE_METHODS.keys()))
    if not isinstance(options, dict):
        raise TypeError(f"{name}: expected a mapping of option names to values, got {options!r}")
    params = inspect.signature(RESPONSE_METHODS[method]).parameters
    accepted = sorted(k for k, p in params.items() if p.kind is inspect.Parameter.KEYWORD_ONLY)
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise ValueError(
            f"{name}: method {method!r} has no option {', '.join(map(repr, unknown))}; "
            f"accepted: {', '.join(accepted)}"
        )
    if "n_samples" in options:
        n = options["n_samples"]
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < MIN_SAMPLES:
            raise ValueError(
                f"{name}: n_samples: expected an integer >= {MIN_SAMPLES} (pixels per "
                f"channel, drawn from 32 intensity bins), got {n!r}"
            )
    return dict(options)


def _check_usable(raw, code_max) -> None:
    """``ValueError`` when fewer than :data:`MIN_USABLE_PIXELS` pixels per channel are usable
    (concrete stacks); under tracing an ``eqx.error_if`` check in the jitted core does it."""
    if not is_concrete(raw):
        return
    a = np.asarray(raw)
    inside = (a > 0) & (a < code_max)
    usable = np.count_nonzero(np.count_nonzero(inside, axis=0) >= 2, axis=(0, 1))
    if np.min(usable) < MIN_USABLE_PIXELS:
        raise ValueError(
            f"images: too few usable pixels for a response fit: {int(np.min(usable))} per "
            f"channel (at least {MIN_USABLE_PIXELS} needed) are neither black (0) nor clipped "
            f"({code_max:g}) in at least 2 frames; the bracket is all saturated or all black "
            "— add shorter / longer exposures"
        )


def _usable_error_if(z, t):
    inside = (z > 0) & (z < 1)
    usable = jnp.sum(jnp.sum(inside, axis=0) >= 2, axis=(0, 1))
    return eqx.error_if(
        t,
        jnp.min(usable) < MIN_USABLE_PIXELS,
        f"images: too few usable pixels for a response fit (< {MIN_USABLE_PIXELS} per channel "
        "neither black nor clipped in at least 2 frames)",
    )


def recover_response(images, exposure_times, *, method: str = "debevec", **options):
    """Recover the camera response from a bracketed stack of one static scene.

    ``images``: ``(N, H, W, C)`` or ``(N, H, W)`` (or a sequence of N frames), uint8, uint16
    or floats in ``[0, 1]``; ``exposure_times``: ``(N,)`` seconds (any order; frames are
    sorted with them; duplicates are fine as long as 2 distinct times exist). N ≥ 2.
    ``method``: a key of :data:`RESPONSE_METHODS`. Common options: ``key`` (JAX key for the
    pixel sample selection, default ``jax.random.key(0)``), ``n_samples``, ``anchor``.
    Method options are documented on each method (``jaxgfx.hdr._debevec.recover_debevec``…).

    Returns a :class:`CameraResponse` with one curve per channel. Jittable (options static).
    Raises ``ValueError`` for unknown options (:func:`check_response_options`) and for a
    stack with fewer than :data:`MIN_USABLE_PIXELS` usable pixels per channel (all clipped
    or all black). Under ``jax.jit`` / ``jax.grad`` these value checks (and those on the
    exposure times) run inside the program with ``eqx.error_if``: a bad stack raises an
    error at run time instead of returning a meaningless curve.

    References: Debevec & Malik, SIGGRAPH 1997; Robertson, Borman & Stevenson, JEI 2003;
    Mitsunaga & Nayar, CVPR 1999; Grossberg & Nayar, PAMI 2004 (``"subspace"``: a
    low-dimensional curve space, here an analytic one).

    Example: a noise-free float stack of ``x = z^2.2`` data gives back ``gamma ≈ 2.2`` with
    ``method="gamma"``.
    """
    check_choice(method, "method", tuple(RESPONSE_METHODS.keys()))
    check_response_options(method, options)
    raw, t, code_max, _ = prepare_stack(images, exposure_times, min_frames=2, raw=True)
    _check_usable(raw, code_max)
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
    if method in ("debevec", "subspace"):
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
    if not is_concrete(raw):  # the boundary check could not see the values
        t = _usable_error_if(z, t)
    return RESPONSE_METHODS[method](z, t, code_max, key=key, **dict(opts))
