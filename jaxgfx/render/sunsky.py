"""Mitsuba 3's ``sunsky`` environment emitter in RGB: the Hosek-Wilkie sky (2012) and sun
(2013) models as Mitsuba 3.9.1's ``*_rgb`` variants evaluate them.

Sources: L. Hosek, A. Wilkie, "An Analytic Model for Full Spectral Sky-Dome Radiance", ACM TOG
31(4), 2012 (the sky: nine parameters per channel, Bezier-interpolated in the sun elevation and
linear in turbidity and ground albedo); L. Hosek, A. Wilkie, "Adding a Solar-Radiance Function
to the Hosek-Wilkie Skylight Model", IEEE CG&A 33(3), 2013 (the sun, with limb darkening); the
tables are Mitsuba 3.9.1's (``jaxgfx/render/data/sunsky``, ORIGIN.md there) and the way they
are combined follows Mitsuba's ``include/mitsuba/render/sunsky.h`` (read, not copied):

* local frame: Z up, X to the north; a world direction ``d`` is looked up at
  ``to_world^T d`` (``to_world`` a rotation, ``None`` for the identity). ``sun_direction`` is
  the world direction towards the sun.
* sky, per RGB channel with ``theta`` the view's zenith angle and ``gamma`` its angle to the
  sun: ``(1 + A exp(B / (cos theta + 0.01))) (C + D exp(E gamma) + F cos^2 gamma + G chi(H,
  gamma) + I sqrt(cos theta)) L_M`` with ``chi = (1 + cos^2 gamma) / (1 + H^2 - 2 H cos
  gamma)^1.5`` (the tables store the nine as A..G, I, H); they and ``L_M`` are linear in
  turbidity (levels 1..10) and in the channel's albedo (levels 0, 1), then a quintic Bezier
  in ``x = (2 eta / pi)^(1/3)``, ``eta`` the sun's elevation.
* sun (default, Mitsuba's ``complex_sun`` false): a disc of half-angle ``sun_aperture / 2``
  of constant radiance ``E_sun / (2 pi (1 - cos(aperture / 2)))`` (Mitsuba's float32 value of
  that cosine, see ``_disc``), ``E_sun`` the model's
  solar irradiance (11 wavelengths, linear in turbidity and in the elevation on a 3-degree
  grid from 2 to 89 degrees) converted to linear Rec. 709 RGB with the CIE 1931 functions at
  those wavelengths, times Mitsuba's constant 467.069280386. ``complex_sun``: the 2013
  model's piecewise polynomial in the view's elevation (45 segments) times the limb darkening
  polynomial in ``cos psi`` (baked into Mitsuba's RGB table), scaled by the same area ratio.
* both times ``1 / 106.75025939941406`` (Mitsuba's CIE Y normalisation); 0 below the horizon,
  and everything 0 when the sun is below or exactly on the horizon (Mitsuba warns and renders
  black; exactly on it, its float32 round trip through the zenith angle puts the sun 4e-8
  below).

Importance sampling (jaxgfx's own, not Mitsuba's warps): the sky from a piecewise-constant
density over ``(phi / 2 pi, cos theta)`` tabulated at build time from the sky's luminance (with
``sky_scale`` 1, a floor of 1/1000 of the mean so every upper direction has density), the sun
uniformly in its cone; chosen by the sky's and sun's luminous power. The tabulation and
powers are built from the creation values and carry no derivative (a later
:meth:`~jaxgfx.render.scene.Scene.replace` keeps them: still unbiased, any upper-hemisphere
direction has density). :meth:`SunSky.pdf` is the exact density of :meth:`SunSky.sample`.
"""

from __future__ import annotations

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_finite, is_concrete
from jaxgfx._math import (
    safe_atan2,
    safe_div,
    safe_norm,
    safe_normalize,
    safe_sqrt,
    sincos,
    sum_last,
)
from jaxgfx.color import LUMINANCE_WEIGHTS
from jaxgfx.render._sunsky_data import tables
from jaxgfx.render.geometry.frame import frame_from_normal, rotation_to_local, rotation_to_world
from jaxgfx.render.sampling import Distribution2D

__all__ = ["SunSky", "sun_coordinates", "sun_direction_at", "SUNSKY_DEFAULTS"]

CIE_Y_NORMALIZATION = 1.0 / 106.7502593994140625
"""Mitsuba's ``MI_CIE_Y_NORMALIZATION`` (a unit spectrum integrates to luminance 1)."""
SPEC_TO_RGB_SUN_CONV = 467.069280386
"""Mitsuba's ``SPEC_TO_RGB_SUN_CONV`` (spectral solar luminosity -> RGB)."""
XYZ_TO_REC709 = np.array([[3.240479, -1.537150, -0.498535],
                          [-0.969256, 1.875991, 0.041556],
                          [0.055648, -0.204043, 1.057311]])  # fmt: skip
"""CIE XYZ -> linear Rec. 709 RGB (Mitsuba's ``xyz_to_srgb``)."""
DEFAULT_SUN_APERTURE = 0.5358
"""Mitsuba's default ``sun_aperture`` (degrees; its ``SUN_HALF_APERTURE`` is half of it)."""
SUNSKY_DEFAULTS = {"turbidity": 3.0, "albedo": 0.3, "sun_scale": 1.0, "sky_scale": 1.0,
                   "sun_aperture": DEFAULT_SUN_APERTURE, "complex_sun": False,
                   "latitude": 35.6894, "longitude": 139.6917, "timezone": 9.0, "year": 2010,
                   "month": 7, "day": 10, "hour": 15.0, "minute": 0.0, "second": 0.0}  # fmt: skip
"""Mitsuba 3.9.1's defaults of the ``sunsky`` parameters (Tokyo, 10 July 2010, 15:00)."""
TIME_KEYS = ("latitude", "longitude", "timezone", "year", "month", "day", "hour", "minute",
             "second")  # fmt: skip
"""The location / time parameters (exclusive with ``sun_direction``)."""
SKY_GRID = (64, 128)
"""``(cos theta bins, phi bins)`` of the sky's sampling density."""

_EARTH_MEAN_RADIUS = 6371.01  # km
_ASTRONOMICAL_UNIT = 149597890.0  # km


# -- the sun's position (host code, float64) -------------------------------------------------


def _cdiv(a: int, b: int) -> int:
    """C integer division (truncation towards zero), as Mitsuba's Int32 arithmetic."""
    q = abs(a) // abs(b)
    return q if (a >= 0) == (b > 0) else -q


def sun_coordinates(year, month, day, hour, minute, second, latitude, longitude, timezone):
    """``(theta, phi)``: the sun's zenith angle and azimuth (radians) in the sunsky frame (Z
    up, X north) at a date, local time and place, by Blanco-Muriel et al., "Computing the
    Solar Vector", Solar Energy 70(5), 2001, with the parallax correction, as Mitsuba 3.9.1's
    ``sun_coordinates`` (which returns ``azimuth - pi``). Host code in float64 (Mitsuba
    computes in float32: they agree to ~1e-4 rad)."""
    year, month, day = int(year), int(month), int(day)
    dec_hours = float(hour) - float(timezone) + (float(minute) + float(second) / 60.0) / 60.0
    aux1 = _cdiv(month - 14, 12)
    aux2 = (_cdiv(1461 * (year + 4800 + aux1), 4) + _cdiv(367 * (month - 2 - 12 * aux1), 12)
            - _cdiv(3 * _cdiv(year + 4900 + aux1, 100), 4) + day - 32075)  # fmt: skip
    n = aux2 - 0.5 + dec_hours / 24.0 - 2451545.0  # days since noon 1 January 2000 (UT)
    omega = 2.1429 - 0.0010394594 * n
    mean_longitude = 4.8950630 + 0.017202791698 * n
    anomaly = 6.2400600 + 0.0172019699 * n
    ecl_long = (mean_longitude + 0.03341607 * math.sin(anomaly) + 0.00034894 * math.sin(2 * anomaly)
                - 0.0001134 - 0.0000203 * math.sin(omega))  # fmt: skip
    ecl_obl = 0.4090928 - 6.2140e-9 * n + 0.0000396 * math.cos(omega)
    sl = math.sin(ecl_long)
    ra = math.atan2(math.cos(ecl_obl) * sl, math.cos(ecl_long))
    ra += 2 * math.pi if ra < 0 else 0.0
    decl = math.asin(math.sin(ecl_obl) * sl)
    gmst = 6.6974243242 + 0.0657098283 * n + dec_hours
    lmst = math.radians(gmst * 15.0 + float(longitude))
    lat = math.radians(float(latitude))
    ha = lmst - ra
    cl, sl_, ch = math.cos(lat), math.sin(lat), math.cos(ha)
    zenith = math.acos(cl * ch * math.cos(decl) + math.sin(decl) * sl_)
    azimuth = math.atan2(-math.sin(ha), math.tan(decl) * cl - sl_ * ch)
    azimuth += 2 * math.pi if azimuth < 0 else 0.0
    zenith += _EARTH_MEAN_RADIUS / _ASTRONOMICAL_UNIT * math.sin(zenith)
    return zenith, azimuth - math.pi


def sun_direction_at(to_world=None, **when):
    """The world direction towards the sun (``to_world`` times the local ``(sin theta cos phi,
    sin theta sin phi, cos theta)`` of :func:`sun_coordinates`) for the location / time keys
    ``when`` (:data:`TIME_KEYS`; Mitsuba's defaults for the missing ones)."""
    unknown = sorted(set(when) - set(TIME_KEYS))
    if unknown:
        raise ValueError(f"unknown location / time key(s) {unknown}; expected {list(TIME_KEYS)}")
    args = {k: when.get(k, SUNSKY_DEFAULTS[k]) for k in TIME_KEYS}
    theta, phi = sun_coordinates(**args)
    d = np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi),
                  math.cos(theta)])  # fmt: skip
    return d if to_world is None else np.asarray(to_world, np.float64) @ d


# -- model pieces (jnp, differentiable) ----------------------------------------------------


def _unit_angle(a, b):
    """Angle between unit vectors, accurate near 0 and pi (Mitsuba's ``unit_angle``); finite
    gradients everywhere (0 at ``a = b``)."""
    dot = sum_last(a * b)
    # each branch's argument is <= 1/sqrt(2) where it is selected: the clip only keeps the
    # other branch's derivative finite
    near = 2.0 * jnp.arcsin(jnp.minimum(0.5 * safe_norm(a - b), 0.75))
    far = math.pi - 2.0 * jnp.arcsin(jnp.minimum(0.5 * safe_norm(a + b), 0.75))
    return jnp.where(dot < 0, far, near)


def _elevation(v):
    """Elevation ``atan2(z, |xy|)`` of vectors ``v (..., 3)`` (finite gradient at the poles)."""
    return safe_atan2(v[..., 2], safe_norm(v[..., :2]))


def _cbrt_pos(x):
    """``x^(1/3)`` for ``x >= 0`` (0 below), finite gradient at 0."""
    pos = x > 0
    return jnp.where(pos, jnp.cbrt(jnp.where(pos, x, 1.0)), 0.0)


def _lerp_index(table, pos, n):
    """Mitsuba's ``take_interp`` along axis 0 of ``table`` at fractional ``pos`` (a scalar):
    segment ``clip(floor(pos), 0, n - 2)``, weight ``pos - segment`` (not clipped)."""
    i = jnp.clip(jnp.floor(pos), 0, n - 2)
    w = pos - i
    i = i.astype(jnp.int32)
    return table[i] * (1.0 - w) + table[i + 1] * w


def _bezier_weights(eta):
    """Quintic Bernstein weights ``(6,)`` at ``x = min((2 eta / pi)^(1/3), 1 - 2^-24)``."""
    x = jnp.minimum(_cbrt_pos(2.0 / math.pi * eta), 1.0 - 2.0**-24)
    k = np.arange(6)
    coef = np.array([1.0, 5.0, 10.0, 10.0, 5.0, 1.0])
    return coef * x ** k * (1.0 - x) ** (5 - k)


@functools.lru_cache(maxsize=16)
def _disc(aperture: float):
    """``(omc, half, sin_half)`` of Mitsuba's sun disc for ``sun_aperture`` degrees: Mitsuba
    computes the half-angle ``h = deg_to_rad(aperture / 2)`` and its ``1 - cos h`` in float32
    (cancellation: 0.22 % below the exact value at the default aperture), tests ``dot >=
    cos h`` and gives the disc the radiance ``E / (2 pi (1 - cos h))``. jaxgfx takes that same
    cone: ``omc`` is Mitsuba's float32 ``1 - cos h`` (exact in float64), ``half`` the angle
    whose ``1 - cos`` is ``omc`` (the disc, tested on the accurate angle to the sun), so
    radiance, disc and irradiance ``E`` all agree with Mitsuba's. (The exact ``1 - cos`` where
    float32 rounds it to 0, apertures below ~0.04 degrees.)"""
    h32 = np.float32(np.float32(0.5 * aperture) * np.float32(math.pi / 180.0))
    omc = 1.0 - float(np.cos(h32))
    if not omc > 0:
        omc = 2.0 * math.sin(0.5 * float(h32)) ** 2
    return omc, 2.0 * math.asin(math.sqrt(0.5 * omc)), math.sin(float(h32))


@eqx.filter_jit
def _sampling_tables(sky):
    # one compiled program (eager, its few hundred small ops took ~20 s to dispatch)
    return sky._tabulate()


class SunSky(eqx.Module):
    """Mitsuba 3's ``sunsky`` (RGB): Hosek-Wilkie sky and sun, see the module docstring.

    Differentiable leaves: ``sun_direction (3,)`` (world, towards the sun; normalised where
    used), ``turbidity`` (in [1, 10]), ``albedo (3,)`` (ground albedo per channel, in [0, 1]),
    ``sun_scale``, ``sky_scale`` (>= 0). ``to_world``: ``None`` or a 3x3 rotation (no
    derivative). Static: ``sun_aperture`` (degrees, in (0, 180)) and ``complex_sun``. The
    remaining fields (underscored, not listed as parameters) are the model's tables and the
    sampling density. Build with :meth:`create`.

    Example: ``SunSky.create([0, 0.6, 0.8]).eval(jnp.array([0., 0., 1.]))`` is the zenith's
    RGB radiance with the sun 53 degrees above the horizon (Mitsuba's ``eval`` of the same
    ``sunsky``, tests/render/test_sunsky_mitsuba.py).
    """

    sun_direction: jnp.ndarray
    turbidity: jnp.ndarray
    albedo: jnp.ndarray
    sun_scale: jnp.ndarray
    sky_scale: jnp.ndarray
    _sky_params: jnp.ndarray  # (10 turbidity, 2 albedo, 6 control points, 3 RGB, 9)
    _sky_rad: jnp.ndarray  # (10, 2, 6, 3)
    _sun_irr: jnp.ndarray  # (10 turbidity, 30 elevations, 3 RGB)
    _distribution: Distribution2D | None = None  # sky sampling over (phi / 2 pi, cos theta)
    _power: jnp.ndarray | None = None  # (2,) luminous power of the unscaled sky and sun
    _sun_rad: jnp.ndarray | None = None  # complex sun: (10, 45 segments, 3, 4, 6); else None
    to_world: jnp.ndarray | None = None
    sun_aperture: float = eqx.field(static=True, default=DEFAULT_SUN_APERTURE)
    complex_sun: bool = eqx.field(static=True, default=False)

    def __check_init__(self):  # also runs on Scene.replace (concrete values only)
        for name in ("sun_direction", "turbidity", "albedo", "sun_scale", "sky_scale"):
            check_finite(getattr(self, name), name)
        if not 0.0 < self.sun_aperture < 180.0:
            raise ValueError(f"sun_aperture: expected degrees in (0, 180), got {self.sun_aperture}")
        if not is_concrete(self.sun_direction) or not is_concrete(self.albedo):
            return
        if not np.linalg.norm(np.asarray(self.sun_direction, np.float64)) > 0:
            raise ValueError("sun_direction: expected a nonzero vector")
        a = np.asarray(self.albedo)
        if not np.all((a >= 0) & (a <= 1)):
            raise ValueError(f"albedo: expected values in [0, 1], got {a}")
        for name, lo, hi in (("turbidity", 1.0, 10.0), ("sun_scale", 0.0, math.inf),
                             ("sky_scale", 0.0, math.inf)):  # fmt: skip
            v = getattr(self, name)
            if is_concrete(v) and not lo <= float(v) <= hi:
                what = "a number in [1, 10]" if name == "turbidity" else "a non-negative number"
                raise ValueError(f"{name}: expected {what}, got {float(v)}")

    # -- construction (host) ---------------------------------------------------------------

    @classmethod
    def create(cls, sun_direction, *, turbidity=3.0, albedo=0.3, sun_scale=1.0, sky_scale=1.0,
               sun_aperture=DEFAULT_SUN_APERTURE, complex_sun=False, to_world=None):  # fmt: skip
        """``sun_direction``: world direction towards the sun (3 numbers, nonzero; see
        :func:`sun_direction_at` for a date and place). ``albedo`` a number or RGB triple.
        ``to_world``: ``None`` or a 3x3 / 4x4 affine rotation (translation ignored; a scale or
        shear raises ``ValueError`` naming ``sunsky.to_world``). Bad values raise one
        ``ValueError`` naming the parameter. Host function (checks in NumPy; one compiled
        program per dtype builds the sampling tables)."""
        from jaxgfx.render.emitters import EnvironmentMap

        rot = EnvironmentMap.check_to_world(to_world, "sunsky.to_world")
        # the leaves' dtype: the default float (float64 under x64), or a JAX sun_direction's
        dtype = as_float_array(sun_direction if isinstance(sun_direction, jax.Array) else 0.0,
                               "sun_direction").dtype  # fmt: skip
        vals = {}
        for name, v, shape in (("sun_direction", sun_direction, (3,)),
                               ("turbidity", turbidity, ()), ("albedo", albedo, (3,)),
                               ("sun_scale", sun_scale, ()), ("sky_scale", sky_scale, ()),
                               ("sun_aperture", sun_aperture, ())):  # fmt: skip
            as_float_array(v, name)  # its TypeError for non-numbers
            a = np.asarray(v, np.float64)  # host float64: a Python aperture stays unrounded
            if name == "albedo" and a.shape == ():
                a = np.full(3, float(a))
            if a.shape != shape:
                what = "3 numbers" if shape else "a number"
                if name == "albedo":
                    what = "a number or an RGB triple"
                raise ValueError(f"{name}: expected {what}, got shape {a.shape}")
            check_finite(a, name)
            vals[name] = a
        n = float(np.linalg.norm(vals["sun_direction"]))
        if not n > 0:
            raise ValueError("sun_direction: expected a nonzero vector")
        if not isinstance(complex_sun, (bool, np.bool_)):
            raise TypeError(f"complex_sun: expected a bool, got {type(complex_sun).__name__}")
        t = tables()
        # Mitsuba's spectrum_to_srgb (without its CIE Y factor) of the solar irradiance
        rgb_cmf = t["cie_xyz"] @ XYZ_TO_REC709.T  # (11, 3)
        sun_irr = np.einsum("tel,lc->tec", t["sun_irradiance"], rgb_cmf) / rgb_cmf.shape[0]
        sd = vals["sun_direction"] / n
        arr = lambda x: jnp.asarray(x, dtype)  # noqa: E731
        common = [arr(vals["turbidity"]), arr(vals["albedo"]), arr(vals["sun_scale"]),
                  arr(vals["sky_scale"]), arr(t["sky_params_rgb"]), arr(t["sky_rad_rgb"]),
                  arr(sun_irr)]  # fmt: skip
        # the sampling tables depend on the sky and the sun's irradiance only: built on a
        # canonical view (the local sun direction, no rotation, the default static fields), one
        # compiled program per dtype whatever the aperture, complex_sun and to_world
        local = sd if rot is None else rot.T @ sd
        dist, power = _sampling_tables(cls(arr(local), *common))
        return cls(arr(sd), *common, dist, power,
                   arr(t["sun_rad_rgb"]) if complex_sun else None,
                   None if rot is None else arr(rot), float(vals["sun_aperture"]),
                   bool(complex_sun))  # fmt: skip

    def _tabulate(self):
        """The sky's sampling density (its luminance at 2 x 2 points per cell of
        :data:`SKY_GRID`, plus 1/1000 of the mean) and the luminous powers ``(sky, sun)`` of
        the unscaled sky and sun (0 for a sun below the horizon)."""
        h, w = SKY_GRID
        dt = self.turbidity.dtype
        off = jnp.asarray([0.25, 0.75], dt)
        ct = ((jnp.arange(h, dtype=dt)[:, None] + off) / h).reshape(-1)  # (2h,)
        ph = ((jnp.arange(w, dtype=dt)[:, None] + off) / w).reshape(-1) * (2 * math.pi)
        st = jnp.sqrt(1.0 - ct * ct)
        sp, cp = sincos(ph)
        d = jnp.stack([st[:, None] * cp, st[:, None] * sp, jnp.broadcast_to(ct[:, None],
                      (2 * h, 2 * w))], -1)  # fmt: skip
        s = self._sun_local(dt)
        lum_w = jnp.asarray(LUMINANCE_WEIGHTS["rec709"], dt)
        lum = self._sky(d, s) @ lum_w  # (2h, 2w), unscaled, local directions
        lum = jnp.maximum(lum, 0.0).reshape(h, 2, w, 2).mean((1, 3))
        lum = jnp.where(s[2] > 0, lum, 0.0)
        p_sky = jnp.sum(lum) * (2 * math.pi / (h * w)) * CIE_Y_NORMALIZATION
        # the disc's radiance times its solid angle: its irradiance, whatever the aperture
        p_sun = jnp.where(s[2] > 0, self._sun_disc_rgb(s, dt) @ lum_w, 0.0)
        p_sun = jnp.maximum(p_sun, 0.0) * (2 * math.pi * _disc(self.sun_aperture)[0])
        dist = Distribution2D(lum + 1e-3 * jnp.mean(lum))
        return jax.lax.stop_gradient((dist, jnp.stack([p_sky, p_sun])))

    # -- model -------------------------------------------------------------------------------

    def _local(self, d):
        return rotation_to_local(self.to_world, d)

    def _world(self, d):
        return rotation_to_world(self.to_world, d)

    def _sun_local(self, dtype):
        return self._local(safe_normalize(self.sun_direction.astype(dtype)))

    def _turbidity_index(self, dtype):
        return self.turbidity.astype(dtype) - 1.0

    def _sky_coefficients(self, s, dtype):
        """``(params (3, 9), radiance (3,))`` at the current turbidity, albedo and sun
        elevation (``s``: the local unit sun direction)."""
        t = self._turbidity_index(dtype)
        a = self.albedo.astype(dtype)
        bw = _bezier_weights(jnp.maximum(_elevation(s), 0.0))
        p = _lerp_index(self._sky_params.astype(dtype), t, 10)  # (2, 6, 3, 9)
        p = p[0] * (1.0 - a)[:, None] + p[1] * a[:, None]  # (6, 3, 9)
        r = _lerp_index(self._sky_rad.astype(dtype), t, 10)  # (2, 6, 3)
        r = r[0] * (1.0 - a) + r[1] * a  # (6, 3)
        return jnp.tensordot(bw, p, 1), bw @ r

    def _sky(self, d, s):
        """Unscaled sky radiance ``(..., 3)`` (without Mitsuba's CIE Y factor) toward local
        unit directions ``d`` (clamped to the horizon; masking is the caller's)."""
        dt = d.dtype
        params, rad = self._sky_coefficients(s, dt)
        ct = jnp.maximum(d[..., 2], 0.0)[..., None]
        gamma = _unit_angle(s, d)[..., None]
        cg = jnp.cos(gamma)
        # the tables' order (Hosek and Wilkie's): A, B, C, D, E, F, G, I (zenith), H (Mie g)
        A, B, C, D, E, F, G, I, H = (params[:, k] for k in range(9))  # noqa: N806
        chi = (1.0 + cg * cg) / (1.0 + H * H - 2.0 * H * cg) ** 1.5
        c1 = 1.0 + A * jnp.exp(B / (ct + 0.01))
        c2 = C + D * jnp.exp(E * gamma) + F * cg * cg + G * chi + I * safe_sqrt(ct)
        return c1 * c2 * rad

    def _sun_disc_rgb(self, s, dtype):
        """The simple sun's radiance ``(3,)`` (with Mitsuba's constants, unscaled)."""
        t = self._turbidity_index(dtype)
        e = jnp.clip((jnp.rad2deg(_elevation(s)) - 2.0) / 3.0, 0.0, 29.0)
        irr = _lerp_index(_lerp_index(self._sun_irr.astype(dtype), t, 10), e, 30)
        return irr * (SPEC_TO_RGB_SUN_CONV * CIE_Y_NORMALIZATION
                      / (2.0 * math.pi * _disc(self.sun_aperture)[0]))  # fmt: skip

    def _sun_complex(self, d, gamma, dtype):
        """The complex sun's radiance ``(..., 3)`` toward ``d`` (unscaled, unmasked)."""
        t = self._turbidity_index(dtype)
        table = _lerp_index(self._sun_rad.astype(dtype), t, 10)  # (45, 3, 4, 6)
        elev = jnp.maximum(_elevation(d), 0.0)
        pos = jnp.clip(jnp.floor(_cbrt_pos(2.0 / math.pi * elev) * 45.0), 0, 44)
        x = elev - 0.5 * math.pi * (pos / 45.0) ** 3
        omc, _, sin_half = _disc(self.sun_aperture)
        cos_psi = safe_sqrt(1.0 - (jnp.sin(gamma) / sin_half) ** 2)
        xk = x[..., None] ** np.arange(4)  # (..., 4)
        pj = cos_psi[..., None] ** np.arange(6)  # (..., 6)
        coef = table[pos.astype(jnp.int32)]  # (..., 3, 4, 6)
        val = jnp.einsum("...ckj,...k,...j->...c", coef, xk, pj)
        # Mitsuba's get_area_ratio: its float32 1 - cos of the default half-angle over ours
        h0 = np.float32(math.pi * (0.5 * DEFAULT_SUN_APERTURE) / 180.0)
        ratio = (1.0 - float(np.cos(h0))) / omc
        return val * (ratio * SPEC_TO_RGB_SUN_CONV * CIE_Y_NORMALIZATION)

    def eval(self, d):
        """RGB radiance ``(..., 3)`` arriving from world directions ``d (..., 3)`` (unit)."""
        dt = d.dtype
        dl = self._local(d)
        s = self._sun_local(dt)
        # a sun exactly on the horizon is below it for Mitsuba (its float32 theta = pi / 2 gives
        # z = cos(theta) = -4e-8): black, as there
        active = (dl[..., 2] >= 0) & (s[2] > 0)
        gamma = _unit_angle(s, dl)
        sky = self._sky(dl, s) * (self.sky_scale.astype(dt) * CIE_Y_NORMALIZATION)
        half = _disc(self.sun_aperture)[1]
        if self.complex_sun:
            sun = self._sun_complex(dl, gamma, dt)
        else:
            sun = jnp.broadcast_to(self._sun_disc_rgb(s, dt), sky.shape)
        sun = jnp.where((gamma <= half)[..., None], sun * self.sun_scale.astype(dt), 0.0)
        return jnp.where(active[..., None], sky + sun, 0.0)

    # -- sampling ----------------------------------------------------------------------------

    def _sky_weight(self, dtype):
        """Probability of sampling the sky (else the sun cone), by luminous power."""
        sky = self.sky_scale.astype(dtype) * self._power[0].astype(dtype)
        sun = self.sun_scale.astype(dtype) * self._power[1].astype(dtype)
        return jax.lax.stop_gradient(safe_div(sky, sky + sun, fill=1.0))

    def _pdf_local(self, dl, s):
        dt = dl.dtype
        w = self._sky_weight(dt)
        phi = safe_atan2(dl[..., 1], dl[..., 0]) / (2 * math.pi)
        uv = jnp.stack([phi - jnp.floor(phi), dl[..., 2]], -1)
        dist = jax.lax.stop_gradient(self._distribution)
        p_sky = jnp.where(dl[..., 2] >= 0, dist.pdf(uv) / (2 * math.pi), 0.0)
        omc, half, _ = _disc(self.sun_aperture)
        p_sun = jnp.where(_unit_angle(s, dl) <= half, 1.0 / (2 * math.pi * omc), 0.0)
        return w * p_sky + (1.0 - w) * p_sun

    def pdf(self, d):
        """Solid-angle density of :meth:`sample` at world directions ``d (..., 3)``."""
        s = jax.lax.stop_gradient(self._sun_local(d.dtype))
        return self._pdf_local(self._local(d), s)

    def sample(self, u):
        """Uniform ``u (..., 2)`` -> ``(wi, pdf, Li)``: world direction towards the sky, its
        solid-angle density, the radiance from it."""
        dt = u.dtype
        w = self._sky_weight(dt)
        s = jax.lax.stop_gradient(self._sun_local(dt))
        pick_sky = u[..., 0] < w
        u0 = jnp.where(pick_sky, safe_div(u[..., 0], w), safe_div(u[..., 0] - w, 1.0 - w))
        uu = jnp.stack([jnp.clip(u0, 0.0, 1.0), u[..., 1]], -1)
        # sky: the tabulated density over (phi / 2 pi, cos theta)
        uv, _ = jax.lax.stop_gradient(self._distribution).sample(uu)
        ct = uv[..., 1]
        st = safe_sqrt(1.0 - ct * ct)
        sp, cp = sincos(2 * math.pi * uv[..., 0])
        d_sky = jnp.stack([st * cp, st * sp, ct], -1)
        # sun: uniform in the cone of half-angle sun_aperture / 2 around s
        a = uu[..., 0] * _disc(self.sun_aperture)[0]  # 1 - cos(angle to s), no cancellation
        sg = safe_sqrt(a * (2.0 - a))
        sp2, cp2 = sincos(2 * math.pi * uu[..., 1])
        fr = frame_from_normal(jnp.broadcast_to(s, u.shape[:-1] + (3,)))
        d_sun = ((1.0 - a)[..., None] * fr.n + (sg * cp2)[..., None] * fr.s
                 + (sg * sp2)[..., None] * fr.t)  # fmt: skip
        dl = jnp.where(pick_sky[..., None], d_sky, d_sun)
        wi = self._world(dl)
        return wi, self._pdf_local(dl, s), self.eval(wi)
