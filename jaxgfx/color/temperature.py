"""Correlated colour temperature (CCT) <-> chromaticity, by Robertson's (1968) method.

Robertson, "Computation of correlated color temperature and distribution temperature",
JOSA 58 (1968) 1528-1535, with the 31 isotemperature lines of Wyszecki & Stiles, *Color
Science* (2nd ed., 1982), Table 1(3.11): reciprocal temperature ``r`` (MK^-1), the CIE 1960
``(u, v)`` of the Planckian locus and the slope ``t`` of the isotemperature line. The DNG
SDK uses the same table to place a white balance between a camera's two calibration
illuminants (:func:`jaxgfx.hdr.raw.dng_xyz_to_camera`). Both directions are jittable and
differentiable (piecewise linear in ``r``); the test oracle is colour-science
(``colour.temperature.uv_to_CCT_Robertson1968`` / ``CCT_to_uv_Robertson1968``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from ._common import as_colour

__all__ = ["ROBERTSON1968", "xy_to_cct", "cct_to_xy", "xy_to_uv1960", "uv1960_to_xy"]

#: (r [MK^-1], u, v, t) isotemperature lines (Wyszecki & Stiles 1982; as in colour-science).
ROBERTSON1968 = np.array(
    [
        (0, 0.18006, 0.26352, -0.24341),
        (10, 0.18066, 0.26589, -0.25479),
        (20, 0.18133, 0.26846, -0.26876),
        (30, 0.18208, 0.27119, -0.28539),
        (40, 0.18293, 0.27407, -0.30470),
        (50, 0.18388, 0.27709, -0.32675),
        (60, 0.18494, 0.28021, -0.35156),
        (70, 0.18611, 0.28342, -0.37915),
        (80, 0.18740, 0.28668, -0.40955),
        (90, 0.18880, 0.28997, -0.44278),
        (100, 0.19032, 0.29326, -0.47888),
        (125, 0.19462, 0.30141, -0.58204),
        (150, 0.19962, 0.30921, -0.70471),
        (175, 0.20525, 0.31647, -0.84901),
        (200, 0.21142, 0.32312, -1.01820),
        (225, 0.21807, 0.32909, -1.21680),
        (250, 0.22511, 0.33439, -1.45120),
        (275, 0.23247, 0.33904, -1.72980),
        (300, 0.24010, 0.34308, -2.06370),
        (325, 0.24792, 0.34655, -2.46810),
        (350, 0.25591, 0.34951, -2.96410),
        (375, 0.26400, 0.35200, -3.58140),
        (400, 0.27218, 0.35407, -4.36330),
        (425, 0.28039, 0.35577, -5.37620),
        (450, 0.28863, 0.35714, -6.72620),
        (475, 0.29685, 0.35823, -8.59550),
        (500, 0.30505, 0.35907, -11.32400),
        (525, 0.31320, 0.35968, -15.62800),
        (550, 0.32129, 0.36011, -23.32500),
        (575, 0.32931, 0.36038, -40.77000),
        (600, 0.33724, 0.36051, -116.45000),
    ]
)


def xy_to_uv1960(xy):
    """CIE 1931 ``xy`` ``(..., 2)`` -> CIE 1960 UCS ``uv`` ``(..., 2)``."""
    x, y = xy[..., 0], xy[..., 1]
    d = -2.0 * x + 12.0 * y + 3.0
    return jnp.stack([4.0 * x / d, 6.0 * y / d], axis=-1)


def uv1960_to_xy(uv):
    """CIE 1960 UCS ``uv`` ``(..., 2)`` -> CIE 1931 ``xy`` ``(..., 2)``."""
    u, v = uv[..., 0], uv[..., 1]
    d = 2.0 * u - 8.0 * v + 4.0
    return jnp.stack([3.0 * u / d, 2.0 * v / d], axis=-1)


@jax.jit
def _xy_to_cct(xy):
    tab = jnp.asarray(ROBERTSON1968, xy.dtype)
    uv = xy_to_uv1960(xy)
    u, v = uv[..., 0:1], uv[..., 1:2]
    r, ui, vi, ti = tab[:, 0], tab[:, 1], tab[:, 2], tab[:, 3]
    d = ((v - vi) - ti * (u - ui)) / jnp.sqrt(1.0 + ti * ti)  # (..., 31) signed distances
    change = d[..., 1:] * d[..., :-1] <= 0.0  # the white lies between lines i and i + 1
    i = jnp.where(jnp.any(change, axis=-1), jnp.argmax(change, axis=-1), 29)
    d0 = jnp.take_along_axis(d, i[..., None], -1)[..., 0]
    d1 = jnp.take_along_axis(d, i[..., None] + 1, -1)[..., 0]
    f = d0 / jnp.where(d0 - d1 == 0.0, 1.0, d0 - d1)
    rr = r[i] + f * (r[i + 1] - r[i])
    return 1.0e6 / jnp.maximum(rr, 1e-6)


def xy_to_cct(xy):
    """Correlated colour temperature (K) of chromaticities ``xy`` ``(..., 2)`` (Robertson 1968).

    The white's CIE 1960 ``uv`` is placed between the two adjacent isotemperature lines whose
    signed distances change sign and the reciprocal temperature is interpolated linearly in
    those distances. Valid from about 1667 K (r = 600) up (r = 0 is infinite temperature).

    >>> round(float(xy_to_cct(jnp.array([0.3127, 0.3290]))))  # D65
    6504
    """
    return _xy_to_cct(as_colour(xy, "xy", channels=2))


@jax.jit
def _cct_to_xy(cct):
    tab = jnp.asarray(ROBERTSON1968, cct.dtype)
    r = 1.0e6 / cct
    i = jnp.clip(jnp.searchsorted(tab[:, 0], r, side="right") - 1, 0, 29)
    f = (r - tab[i, 0]) / (tab[i + 1, 0] - tab[i, 0])
    u = tab[i, 1] + f * (tab[i + 1, 1] - tab[i, 1])
    v = tab[i, 2] + f * (tab[i + 1, 2] - tab[i, 2])
    return uv1960_to_xy(jnp.stack([u, v], axis=-1))


def cct_to_xy(cct):
    """Chromaticities ``xy`` ``(..., 2)`` of the Planckian locus at ``cct`` K (Robertson's table,
    interpolated linearly in reciprocal temperature; zero tint), for 1667 K <= cct.

    >>> [round(float(v), 4) for v in cct_to_xy(2856.0)]  # CIE illuminant A: (0.4476, 0.4074)
    [0.4475, 0.4074]
    """
    from .._checks import as_float_array, check_positive

    c = as_float_array(cct, "cct")
    check_positive(c, "cct")
    return _cct_to_xy(c)
