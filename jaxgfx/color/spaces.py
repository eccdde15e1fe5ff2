"""Colour spaces: RGB <-> CIE XYZ, CIELAB, xyY, HSV, YIQ, CMYK, luminance.

Conventions: colours are channels-last ``(..., 3)`` float arrays (``(..., 4)`` for CMYK); the
dtype follows the input (float32 by default, float64 when given). RGB <-> XYZ conversions act on
*linear* RGB (decode with :mod:`jaxgfx.color.transfer` first). XYZ is relative, scaled so the
reference white has ``Y = 1``; CIELAB ``L*`` is in [0, 100].

RGB -> XYZ matrices are *derived* at import time from the primaries' and white point's xy
chromaticities (SMPTE RP 177-1993 normalised primary matrix), not copied as decimals.

Each public function validates its inputs eagerly (names, shapes, finiteness) and then calls
one jitted core (``_*``): an eager call runs one compiled program. Names are static arguments
of the cores; white points and matrices are traced arguments.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_choice, is_concrete
from .._math import safe_div
from ._common import as_colour, cast_const, matvec3

__all__ = [
    "WHITEPOINTS",
    "RGB_SPACES",
    "RGBSpace",
    "LUMINANCE_WEIGHTS",
    "YIQ_MATRIX",
    "normalised_primary_matrix",
    "rgb_to_xyz_matrix",
    "whitepoint_xyz",
    "xy_to_xyz",
    "rgb_to_xyz",
    "xyz_to_rgb",
    "xyz_to_lab",
    "lab_to_xyz",
    "xyz_to_xyY",
    "xyY_to_xyz",
    "rgb_to_hsv",
    "hsv_to_rgb",
    "rgb_to_yiq",
    "yiq_to_rgb",
    "rgb_to_cmyk",
    "cmyk_to_rgb",
    "luminance",
]

#: CIE 1931 2-degree chromaticities (x, y) of standard illuminants (CIE 15:2004, Table T.3;
#: D65 and D50 as rounded in IEC 61966-2-1 and ISO 22028-2).
WHITEPOINTS: dict[str, tuple[float, float]] = {
    "A": (0.44758, 0.40745),
    "C": (0.31006, 0.31616),
    "D50": (0.3457, 0.3585),
    "D55": (0.33243, 0.34744),
    "D65": (0.3127, 0.3290),
    "D75": (0.29903, 0.31488),
    "E": (1.0 / 3.0, 1.0 / 3.0),
    # the ACES white (~D60), SMPTE ST 2065-1:2012 / Academy TB-2014-004
    "ACES": (0.32168, 0.33767),
}


class RGBSpace(NamedTuple):
    """An RGB colour space: primaries' xy (3, 2), white point name, transfer-function name."""

    primaries: tuple[tuple[float, float], ...]
    white: str
    transfer: str


#: Named RGB spaces. ``"srgb"`` and ``"rec709"`` share primaries/white (they differ only in the
#: transfer function). ProPhoto is ROMM RGB (ISO 22028-2:2013), D50; ``"aces2065-1"`` (AP0)
#: and ``"acescg"`` (AP1) are the scene-linear ACES spaces with the ACES white.
RGB_SPACES: dict[str, RGBSpace] = {
    "srgb": RGBSpace(((0.64, 0.33), (0.30, 0.60), (0.15, 0.06)), "D65", "srgb"),
    "rec709": RGBSpace(((0.64, 0.33), (0.30, 0.60), (0.15, 0.06)), "D65", "rec709"),
    "rec2020": RGBSpace(((0.708, 0.292), (0.170, 0.797), (0.131, 0.046)), "D65", "linear"),
    "adobe_rgb": RGBSpace(((0.64, 0.33), (0.21, 0.71), (0.15, 0.06)), "D65", "adobe_rgb"),
    "prophoto": RGBSpace(((0.7347, 0.2653), (0.1596, 0.8404), (0.0366, 0.0001)), "D50", "prophoto"),
    # ACES AP0 (SMPTE ST 2065-1:2012) and AP1 (ACEScg, Academy S-2014-004), scene-linear
    "aces2065-1": RGBSpace(((0.7347, 0.2653), (0.0, 1.0), (0.0001, -0.0770)), "ACES", "linear"),
    "acescg": RGBSpace(((0.713, 0.293), (0.165, 0.830), (0.128, 0.044)), "ACES", "linear"),
}

#: Luma weights: Rec. ITU-R BT.709 (= sRGB matrix Y row, rounded) and BT.601 (the seed's YIQ Y).
LUMINANCE_WEIGHTS: dict[str, tuple[float, float, float]] = {
    "rec709": (0.2126, 0.7152, 0.0722),
    "rec601": (0.299, 0.587, 0.114),
}

#: NTSC YIQ matrix as given in the lecture notes (FCC 1953, rounded to 3 decimals).
YIQ_MATRIX = np.array(
    [[0.299, 0.587, 0.114], [0.596, -0.274, -0.322], [0.211, -0.522, 0.311]], dtype=np.float64
)
_YIQ_INV = np.linalg.inv(YIQ_MATRIX)

# CIE 1976 constants as exact rationals (CIE 15:2004 note; Lindbloom).
_EPS = 216.0 / 24389.0
_KAPPA = 24389.0 / 27.0


def _xy_to_xyz(xy, xp):
    x, y = xy[..., 0], xy[..., 1]
    return xp.stack([x / y, xp.ones_like(x), (1.0 - x - y) / y], axis=-1)


def _npm(primaries, white_xy, xp):
    p = _xy_to_xyz(primaries, xp)  # (3 primaries, XYZ) with Y = 1
    P = p.T  # columns are primaries
    S = xp.linalg.solve(P, _xy_to_xyz(white_xy, xp))
    return P * S[None, :]


def normalised_primary_matrix(primaries, white_xy):
    """RGB -> XYZ matrix from primaries' and white point's chromaticities (SMPTE RP 177-1993).

    ``M = P diag(P^-1 W)`` with ``P`` the primaries' XYZ (Y = 1) as columns and ``W`` the white
    point's XYZ (Y = 1), so that RGB ``(1, 1, 1)`` maps to ``W``. Differentiable in both
    arguments.

    Args:
      primaries: ``(3, 2)`` xy of R, G, B.
      white_xy: ``(2,)`` xy of the white point.

    Returns:
      ``(3, 3)`` matrix; ``XYZ = M @ RGB``.

    Example:
      >>> M = normalised_primary_matrix([[.64, .33], [.3, .6], [.15, .06]], [.3127, .329])
      >>> round(float(M[1, 0]), 4)  # sRGB red luminance
      0.2126
    """
    primaries = as_colour(primaries, "primaries", channels=2)
    white_xy = as_colour(white_xy, "white_xy", channels=2)
    if primaries.shape != (3, 2) or white_xy.shape != (2,):
        raise ValueError(
            f"primaries/white_xy: expected shapes (3, 2) and (2,), "
            f"got {primaries.shape} and {white_xy.shape}"
        )
    return _npm_jit(primaries, white_xy)


@jax.jit
def _npm_jit(primaries, white_xy):
    return _npm(primaries, white_xy, jnp)


_RGB_TO_XYZ = {
    k: _npm(np.asarray(s.primaries), np.asarray(WHITEPOINTS[s.white]), np)
    for k, s in RGB_SPACES.items()
}
_XYZ_TO_RGB = {k: np.linalg.inv(m) for k, m in _RGB_TO_XYZ.items()}


def rgb_to_xyz_matrix(space="srgb"):
    """The float64 NumPy ``(3, 3)`` linear-RGB -> XYZ matrix of a named space (a copy)."""
    check_choice(space, "space", RGB_SPACES)
    return _RGB_TO_XYZ[space].copy()


def xy_to_xyz(xy):
    """Chromaticity ``(..., 2)`` -> XYZ ``(..., 3)`` with ``Y = 1``."""
    return _xy_to_xyz_jit(as_colour(xy, "xy", channels=2))


@jax.jit
def _xy_to_xyz_jit(xy):
    return _xy_to_xyz(xy, jnp)


def whitepoint_xyz(white, name="white", *, like=None):
    """Resolve a white point to XYZ (Y = 1 for names and xy).

    ``white`` is a name from :data:`WHITEPOINTS`, an xy pair ``(2,)`` or an XYZ triple ``(3,)``
    (used as given). Returned as a JAX array with ``like``'s dtype (float32 if ``like`` is None).
    """
    dtype = jnp.float32 if like is None else jnp.result_type(like)
    if isinstance(white, str):
        check_choice(white, name, WHITEPOINTS)
        return jnp.asarray(_xy_to_xyz(np.asarray(WHITEPOINTS[white]), np), dtype=dtype)
    w = jnp.asarray(white)
    if w.shape == (2,):
        w = as_colour(w, name, channels=2).astype(dtype)
        # NumPy on the concrete value: inside a jit trace a jnp op on a constant is a tracer
        if is_concrete(w) and not (0 < np.asarray(w)[1] and np.asarray(w)[0] >= 0):
            raise ValueError(f"{name}: expected chromaticity xy with x >= 0, y > 0, got {white!r}")
        return _xy_to_xyz(w, jnp)
    if w.shape == (3,):
        w = as_colour(w, name, channels=3).astype(dtype)
        if is_concrete(w) and not np.all(np.asarray(w) > 0):
            raise ValueError(f"{name}: expected a positive XYZ white point, got {white!r}")
        return w
    raise ValueError(
        f"{name}: expected one of {tuple(WHITEPOINTS)}, an xy pair (2,) or XYZ (3,), got {white!r}"
    )


def _apply(m, x):
    # The NumPy float64 matrix is cast here, outside jit: passed as a NumPy argument, it once
    # reached an executable compiled under the other jax_enable_x64 setting in tests/color
    # ("expected f32[3,3] but got f64[3,3]"; JAX 0.10, not reduced to a small repro).
    return _matvec3(cast_const(m, x), x)


_matvec3 = jax.jit(matvec3)


def rgb_to_xyz(rgb, *, space="srgb"):
    """Linear RGB -> CIE XYZ (relative, white ``Y = 1``) in the space's own white point.

    Args:
      rgb: ``(..., 3)`` *linear* RGB.
      space: one of :data:`RGB_SPACES` (``"srgb"``, ``"rec709"``, ``"rec2020"``,
        ``"adobe_rgb"``, ``"prophoto"``). ProPhoto's XYZ is relative to D50, the others to D65.

    Example:
      >>> [round(float(v), 4) for v in rgb_to_xyz(jnp.ones(3))]  # D65 white
      [0.9505, 1.0, 1.0891]
    """
    check_choice(space, "space", RGB_SPACES)
    rgb = as_colour(rgb, "rgb")
    return _apply(_RGB_TO_XYZ[space], rgb)


def xyz_to_rgb(xyz, *, space="srgb"):
    """CIE XYZ -> linear RGB (inverse of :func:`rgb_to_xyz`; no gamut clipping)."""
    check_choice(space, "space", RGB_SPACES)
    xyz = as_colour(xyz, "xyz")
    return _apply(_XYZ_TO_RGB[space], xyz)


def _lab_f(t):
    big = t > _EPS
    t_safe = jnp.where(big, t, 1.0)
    # t ** (1/3) rather than jnp.cbrt: same result here (t > 0), ~2x faster on XLA:CPU
    return jnp.where(big, t_safe ** (1.0 / 3.0), (_KAPPA * t + 16.0) / 116.0)


def xyz_to_lab(xyz, *, white="D65"):
    """CIE XYZ -> CIE 1976 L*a*b* (CIE 15:2004 §8.2.1).

    ``f(t) = t^(1/3)`` for ``t > 216/24389``, else ``(24389/27 t + 16) / 116`` (exact rational
    constants, so ``f`` is continuous with a continuous slope); ``L* = 116 f(Y/Yn) - 16``,
    ``a* = 500 (f(X/Xn) - f(Y/Yn))``, ``b* = 200 (f(Y/Yn) - f(Z/Zn))``. Gradients are finite
    everywhere (the linear branch covers 0 and negative values).

    Args:
      xyz: ``(..., 3)`` relative XYZ (white ``Y = 1``).
      white: reference white: name in :data:`WHITEPOINTS`, xy ``(2,)`` or XYZ ``(3,)``.

    Example:
      >>> [round(float(v), 4) for v in xyz_to_lab(rgb_to_xyz(jnp.ones(3)))]
      [100.0, 0.0, 0.0]
    """
    xyz = as_colour(xyz, "xyz")
    return _xyz_to_lab(xyz, whitepoint_xyz(white, "white", like=xyz))


@jax.jit
def _xyz_to_lab(xyz, wn):
    f = _lab_f(xyz / wn)
    fx, fy, fz = f[..., 0], f[..., 1], f[..., 2]
    return jnp.stack([116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)], axis=-1)


def lab_to_xyz(lab, *, white="D65"):
    """CIE 1976 L*a*b* -> CIE XYZ, exact inverse of :func:`xyz_to_lab` (CIE 15:2004 §8.2.1)."""
    lab = as_colour(lab, "lab")
    return _lab_to_xyz(lab, whitepoint_xyz(white, "white", like=lab))


@jax.jit
def _lab_to_xyz(lab, wn):
    L, a, b = lab[..., 0], lab[..., 1], lab[..., 2]
    fy = (L + 16.0) / 116.0
    fx = fy + a / 500.0
    fz = fy - b / 200.0

    def finv(f):
        f3 = f * f * f
        return jnp.where(f3 > _EPS, f3, (116.0 * f - 16.0) / _KAPPA)

    yr = jnp.where(L > _KAPPA * _EPS, fy * fy * fy, L / _KAPPA)
    return jnp.stack([finv(fx), yr, finv(fz)], axis=-1) * wn


def xyz_to_xyY(xyz, *, white="D65"):
    """CIE XYZ -> CIE xyY. Black (``X + Y + Z = 0``) maps to the ``white`` chromaticity, Y = 0.

    Example:
      >>> [round(float(v), 4) for v in xyz_to_xyY(rgb_to_xyz(jnp.ones(3)))]
      [0.3127, 0.329, 1.0]
    """
    xyz = as_colour(xyz, "xyz")
    return _xyz_to_xyY(xyz, whitepoint_xyz(white, "white", like=xyz))


@jax.jit
def _xyz_to_xyY(xyz, wn):
    s = jnp.sum(xyz, axis=-1)
    w_xy = wn[:2] / jnp.sum(wn)
    x = safe_div(xyz[..., 0], s, fill=0.0) + jnp.where(s == 0, w_xy[0], 0.0)
    y = safe_div(xyz[..., 1], s, fill=0.0) + jnp.where(s == 0, w_xy[1], 0.0)
    return jnp.stack([x, y, xyz[..., 1]], axis=-1)


def xyY_to_xyz(xyY):
    """CIE xyY -> CIE XYZ; ``y = 0`` maps to black."""
    return _xyY_to_xyz(as_colour(xyY, "xyY"))


@jax.jit
def _xyY_to_xyz(xyY):
    x, y, Y = xyY[..., 0], xyY[..., 1], xyY[..., 2]
    return jnp.stack([safe_div(x * Y, y), Y, safe_div((1.0 - x - y) * Y, y)], axis=-1)


def rgb_to_hsv(rgb):
    """RGB -> HSV (hexcone model, Smith 1978), all three components in [0, 1] for RGB in [0, 1].

    Hue is in [0, 1) (fraction of a turn; red = 0, green = 1/3, blue = 2/3). Grey pixels
    (``max == min``) get hue 0 and black gets saturation 0, with finite (zero) gradients there.

    Example:
      >>> [round(float(v), 4) for v in rgb_to_hsv(jnp.array([0.2, 0.4, 0.8]))]
      [0.6111, 0.75, 0.8]
    """
    return _rgb_to_hsv(as_colour(rgb, "rgb"))


@jax.jit
def _rgb_to_hsv(rgb):
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    v = jnp.max(rgb, axis=-1)
    d = v - jnp.min(rgb, axis=-1)
    s = safe_div(d, v)
    h = jnp.where(
        r == v,
        safe_div(g - b, d),
        jnp.where(g == v, 2.0 + safe_div(b - r, d), 4.0 + safe_div(r - g, d)),
    )
    h = jnp.where(d > 0, h, 0.0)
    h = jnp.mod(h / 6.0, 1.0)
    h = jnp.where(h >= 1.0, h - 1.0, h)  # mod of a tiny negative can round to 1.0
    return jnp.stack([h, s, v], axis=-1)


def hsv_to_rgb(hsv):
    """HSV -> RGB, inverse of :func:`rgb_to_hsv` (hue in turns, wrapped modulo 1).

    Uses the continuous form ``c_n = V - V S clip(min(k, 4 - k), 0, 1)``,
    ``k = (n + 6H) mod 6``, ``n = 5, 3, 1`` for R, G, B: piecewise linear in H, so gradients
    are finite everywhere.

    Example:
      >>> [round(float(v), 4) for v in hsv_to_rgb(jnp.array([0.6111111, 0.75, 0.8]))]
      [0.2, 0.4, 0.8]
    """
    return _hsv_to_rgb(as_colour(hsv, "hsv"))


@jax.jit
def _hsv_to_rgb(hsv):
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    n = cast_const(np.array([5.0, 3.0, 1.0]), hsv)
    k = jnp.mod(n + 6.0 * h[..., None], 6.0)
    w = jnp.clip(jnp.minimum(k, 4.0 - k), 0.0, 1.0)
    return v[..., None] - (v * s)[..., None] * w


def rgb_to_yiq(rgb):
    """RGB -> NTSC YIQ with the lecture's matrix (Y = .299 R + .587 G + .114 B;
    I = .596 R - .274 G - .322 B; Q = .211 R - .522 G + .311 B).

    Example:
      >>> [abs(round(float(v), 6)) for v in rgb_to_yiq(jnp.ones(3))]  # white: no chroma
      [1.0, 0.0, 0.0]
    """
    rgb = as_colour(rgb, "rgb")
    return _apply(YIQ_MATRIX, rgb)


def yiq_to_rgb(yiq):
    """NTSC YIQ -> RGB with the numerical inverse of :data:`YIQ_MATRIX` (float64)."""
    yiq = as_colour(yiq, "yiq")
    return _apply(_YIQ_INV, yiq)


def rgb_to_cmyk(rgb):
    """RGB in [0, 1] -> naive CMYK ``(..., 4)``: ``K = 1 - max(R, G, B)``,
    ``C = (1 - R - K) / (1 - K)`` (likewise M, Y); black gives ``C = M = Y = 0, K = 1``.

    Example:
      >>> [round(float(v), 4) for v in rgb_to_cmyk(jnp.array([0.5, 0.25, 0.0]))]
      [0.0, 0.5, 1.0, 0.5]
    """
    return _rgb_to_cmyk(as_colour(rgb, "rgb"))


@jax.jit
def _rgb_to_cmyk(rgb):
    k = 1.0 - jnp.max(rgb, axis=-1)
    cmy = safe_div(1.0 - rgb - k[..., None], 1.0 - k[..., None])
    return jnp.concatenate([cmy, k[..., None]], axis=-1)


def cmyk_to_rgb(cmyk):
    """Naive CMYK ``(..., 4)`` -> RGB: ``R = (1 - C)(1 - K)`` (likewise G, B)."""
    return _cmyk_to_rgb(as_colour(cmyk, "cmyk", channels=4))


@jax.jit
def _cmyk_to_rgb(cmyk):
    return (1.0 - cmyk[..., :3]) * (1.0 - cmyk[..., 3:])


def luminance(rgb, *, weights="rec709"):
    """Relative luminance / luma ``w . rgb`` with named weights.

    ``"rec709"``: 0.2126, 0.7152, 0.0722 (ITU-R BT.709; the Y row of the linear sRGB -> XYZ
    matrix, so use it on *linear* sRGB). ``"rec601"``: 0.299, 0.587, 0.114 (the lecture's YIQ
    ``Y``; BT.601 luma, traditionally applied to gamma-encoded values).

    Returns:
      ``(...)`` array (the channel axis is removed).

    Example:
      >>> float(luminance(jnp.ones(3)))  # doctest: +ELLIPSIS
      1.0...
    """
    check_choice(weights, "weights", LUMINANCE_WEIGHTS)
    return _luminance(as_colour(rgb, "rgb"), weights=weights)


@functools.partial(jax.jit, static_argnames=("weights",))
def _luminance(rgb, *, weights):
    w = LUMINANCE_WEIGHTS[weights]
    return rgb[..., 0] * w[0] + rgb[..., 1] * w[1] + rgb[..., 2] * w[2]
