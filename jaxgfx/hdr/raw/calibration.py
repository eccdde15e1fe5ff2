"""The RAW calibration of a bracket as a sequence of steps, each a function returning a typed
result: :func:`white_level_step` (:class:`WhiteLevel`), :func:`black_level_step`
(:class:`BlackLevelResult`), :func:`linearity_step` (:class:`LinearityResult`),
:func:`exposure_ratios_step` (:class:`ExposureRatios`), :func:`noise_step`
(:class:`NoiseResult`); :func:`calibrate_raw_stack` runs them in order and gathers a
JSON-reportable :class:`RawCalibration`."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice
from jaxgfx.hdr.noise import NoiseModel, fit_noise_from_bracket, fit_photon_transfer

from ._common import CFA_PATTERNS, _channels, _jsonable, _times, cfa_channel_names, cfa_channels
from .levels import (
    Measurement,
    WhiteLevel,
    _black_from_pairs,
    estimate_black_level,
    estimate_white_level,
)
from .linearity import Linearity, _linearity_window, linearity_check
from .ratios import ExposureRatios, estimate_exposure_ratios

__all__ = [
    "BlackLevelResult",
    "LinearityResult",
    "NoiseResult",
    "RawCalibration",
    "white_level_step",
    "black_level_step",
    "linearity_step",
    "exposure_ratios_step",
    "noise_step",
    "calibrate_raw_stack",
]

_BRACKET_NOISE_KEYS = (
    "gain_se",
    "read_variance_se",
    "chi2_reduced",
    "gain_e_per_dn",
    "gain_e_per_dn_se",
    "read_noise_dn",
    "read_noise_dn_se",
)


class BlackLevelResult(eqx.Module):
    """The black level ``(C,)`` with its standard error and how it was obtained: ``"given"``,
    ``"dark_frames"`` or ``"affine_pairs"`` (from the bracket itself)."""

    level: Measurement
    method: str = eqx.field(static=True)


class LinearityResult(eqx.Module):
    """The linearity check (``None`` when no frames qualify), the frames it ran on (input
    indices) and a note saying which and why (or why it did not run)."""

    check: Linearity | None
    frames: tuple = eqx.field(static=True)
    note: str = eqx.field(static=True)


class NoiseResult(eqx.Module):
    """The noise model in normalised units (``None`` when not estimated), the standard errors
    and diagnostics of its fit, and the method (or why it was not estimated)."""

    model: NoiseModel | None
    se: dict | None
    method: str = eqx.field(static=True)


def white_level_step(x, white=None) -> WhiteLevel:
    """``white`` if given (se 0), else :func:`estimate_white_level` of the stack ``x``
    ``(N, H, W, C)``; a stack that never saturates reports its maximum (``saturated`` False)."""
    c = x.shape[-1]
    if white is None:
        return estimate_white_level(x)
    wv = jnp.broadcast_to(as_float_array(white, "white"), (c,))
    return WhiteLevel(wv, jnp.zeros_like(wv), jnp.ones(c, bool), jnp.zeros_like(wv))


def black_level_step(
    x, t, white: WhiteLevel, *, black=None, dark_frames=None, cfa_pattern=None
) -> BlackLevelResult:
    """``black`` if given; else :func:`estimate_black_level` of ``dark_frames``; else from the
    bracket: adjacent pairs obey ``x_b = r x_a + B (1 - r)``, so an affine fit gives
    ``B = c / (1 - r)`` (pairs combined by inverse variance; linear sensor, static scene)."""
    c = x.shape[-1]
    if black is not None:
        bv = jnp.broadcast_to(as_float_array(black, "black"), (c,))
        return BlackLevelResult(Measurement(bv, jnp.zeros_like(bv)), "given")
    if dark_frames is not None:
        bm = estimate_black_level(dark_frames, per_channel_pattern=cfa_pattern)
        bm = Measurement(jnp.broadcast_to(bm.value, (c,)), jnp.broadcast_to(bm.se, (c,)))
        return BlackLevelResult(bm, "dark_frames")
    return BlackLevelResult(Measurement(*_black_from_pairs(x, t, white.value)), "affine_pairs")


def linearity_step(x, t, black, white) -> LinearityResult:
    """:func:`linearity_check` on the longest run of >= 3 consecutive exposures sharing >= 64
    usable pixels per channel; when there is none, ``note`` says why."""
    frames, note = _linearity_window(x, t, black, white)
    check = None
    if frames:
        idx = np.asarray(frames)
        check = linearity_check(x[idx], t[idx], black=black, white=white)
    return LinearityResult(check, frames, note)


def exposure_ratios_step(x, t, black, white) -> ExposureRatios:
    """:func:`estimate_exposure_ratios` of the bracket against its nominal times."""
    return estimate_exposure_ratios(x, t, black=black, white=white)


def noise_step(
    x,
    ratios: ExposureRatios,
    black,
    white,
    *,
    dark_frames=None,
    noise_pairs=None,
    bracket_noise: bool = True,
    cfa_pattern=None,
) -> NoiseResult:
    """The noise model in normalised units: :func:`fit_photon_transfer` on ``noise_pairs``
    when given; else (``bracket_noise``) :func:`fit_noise_from_bracket` with the measured
    ratios, its read variance replaced by the temporal variance of >= 2 ``dark_frames``."""
    if noise_pairs is not None:
        pairs = as_float_array(noise_pairs, "noise_pairs")
        if pairs.ndim == 3:
            pairs = pairs[None]
        if pairs.ndim != 4 or pairs.shape[1] != 2:
            raise ValueError(
                f"noise_pairs: expected (2, H, W) or (P, 2, H, W) mosaics, got shape {pairs.shape}"
            )
        pairs = cfa_channels(pairs, cfa_pattern) if cfa_pattern is not None else pairs[..., None]
        noise, info = fit_photon_transfer(pairs, black=black, white=white)
        se = {k: info[k] for k in ("gain_se", "read_variance_se", "chi2_reduced")}
        return NoiseResult(noise, se, "flat pairs (photon transfer)")
    if not bracket_noise:
        return NoiseResult(None, None, "")
    rat = np.asarray(ratios.ratios)
    if not (np.all(np.isfinite(rat)) and np.all(rat > 0)):
        return NoiseResult(None, None, "not estimated: an exposure ratio could not be measured")
    try:
        noise, info = fit_noise_from_bracket(x, rat, black=black, white=white)
    except ValueError as e:
        return NoiseResult(None, None, f"not estimated: {e}")
    se = {k: info[k] for k in _BRACKET_NOISE_KEYS}
    method = "bracket: variance of y_b - r y_a of adjacent frames"
    if dark_frames is not None:
        dk = _channels(dark_frames, "dark_frames", cfa_pattern, min_frames=1)
        if dk.shape[0] >= 2:  # temporal variance of the darks: read noise without shot noise
            rv = jnp.mean(jnp.var(dk, axis=0, ddof=1), axis=(0, 1)) / (white - black) ** 2
            noise = NoiseModel(noise.gain, rv, noise.black_level, noise.white_level)
            method += "; read variance from the dark frames"
    return NoiseResult(noise, se, method)


class RawCalibration(eqx.Module):
    """Everything measured from one bracketed RAW stack (see ``calibrate_raw_stack``)."""

    black: Measurement
    white: WhiteLevel
    linearity: Linearity | None
    ratios: ExposureRatios
    noise: NoiseModel | None
    noise_se: dict | None
    exposure_times: jax.Array
    cfa_pattern: str | None = eqx.field(static=True, default=None)
    black_method: str = eqx.field(static=True, default="given")
    linearity_frames: tuple = eqx.field(static=True, default=())
    linearity_note: str = eqx.field(static=True, default="")
    noise_method: str = eqx.field(static=True, default="")

    def to_dict(self) -> dict:
        """JSON-ready nested dict (NaN/Inf written as ``null``)."""
        names = list(cfa_channel_names(self.cfa_pattern)) if self.cfa_pattern is not None else None
        return {
            "cfa_pattern": self.cfa_pattern,
            "channels": names,
            "exposure_times": _jsonable(self.exposure_times),
            "black_level": {**self.black.to_dict(), "method": self.black_method},
            "white_level": self.white.to_dict(),
            "linearity": None
            if self.linearity is None
            else {**self.linearity.to_dict(), "frames": list(self.linearity_frames)},
            "linearity_note": self.linearity_note,
            "exposure_ratios": self.ratios.to_dict(),
            "noise": None
            if self.noise is None
            else {
                **self.noise.to_dict(),
                **{k: _jsonable(v) for k, v in (self.noise_se or {}).items()},
                "method": self.noise_method,
            },
        }


def calibrate_raw_stack(
    mosaics,
    exposure_times,
    *,
    cfa_pattern: str | None = "RGGB",
    black=None,
    white=None,
    dark_frames=None,
    noise_pairs=None,
    bracket_noise: bool = True,
) -> RawCalibration:
    """Calibrate a camera from a bracketed RAW stack of a static scene.

    Steps (each reported with standard errors):
      1. black level: ``black`` if given; else ``estimate_black_level(dark_frames)`` if dark
         frames are given; else from the stack itself: for each adjacent pair the raw values
         obey ``x_b = r x_a + B (1 - r)``, so an affine fit gives ``B = c / (1 - r)`` (pairs
         combined by inverse variance; assumes a linear sensor and a static scene).
      2. white level: ``white`` if given (se 0), else ``estimate_white_level`` of the stack; a
         stack that never saturates uses its maximum (``saturated`` False in the report).
      3. ``linearity_check`` on the longest run of >= 3 consecutive exposures that share
         >= 64 usable pixels per channel (``linearity_frames``); when there is none the
         report's ``linearity_note`` says why instead of a check on zero pixels,
      4. ``estimate_exposure_ratios`` vs the nominal times,
      5. the noise model in normalised units: ``fit_photon_transfer`` on ``noise_pairs`` (two
         identical exposures per level, ``(2, H, W)`` or ``(P, 2, H, W)`` mosaics) when given;
         otherwise (``bracket_noise``) :func:`jaxgfx.hdr.noise.fit_noise_from_bracket` from the
         bracket itself with the measured ratios, its read variance replaced by the temporal
         variance of ``dark_frames`` when >= 2 are given. ``noise_method`` says which.

    Args:
      mosaics: ``(N, H, W)`` raw mosaics (``cfa_pattern`` set) or ``(N, H, W[, C])`` frames
        (``cfa_pattern=None``).
      exposure_times: ``(N,)`` nominal (EXIF) exposure times in seconds.

    Returns:
      ``RawCalibration`` (``.to_dict()`` for a JSON report).
    """
    if cfa_pattern is not None:
        check_choice(cfa_pattern, "cfa_pattern", CFA_PATTERNS)
    x = _channels(mosaics, "mosaics", cfa_pattern, min_frames=2)
    t = _times(exposure_times, "exposure_times", x.shape[0])
    wl = white_level_step(x, white)  # white first: it does not need black
    bl = black_level_step(x, t, wl, black=black, dark_frames=dark_frames, cfa_pattern=cfa_pattern)
    lin = linearity_step(x, t, bl.level.value, wl.value)
    ratios = exposure_ratios_step(x, t, bl.level.value, wl.value)
    noise = noise_step(
        x,
        ratios,
        bl.level.value,
        wl.value,
        dark_frames=dark_frames,
        noise_pairs=noise_pairs,
        bracket_noise=bracket_noise,
        cfa_pattern=cfa_pattern,
    )
    return RawCalibration(
        black=bl.level,
        white=wl,
        linearity=lin.check,
        ratios=ratios,
        noise=noise.model,
        noise_se=noise.se,
        exposure_times=t,
        cfa_pattern=cfa_pattern,
        black_method=bl.method,
        linearity_frames=lin.frames,
        linearity_note=lin.note,
        noise_method=noise.method,
    )
