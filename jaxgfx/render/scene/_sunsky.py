"""Scene-description reader of the ``sunsky`` environment emitter (Mitsuba 3's plugin of that
name; shared by :func:`load_scene` and the Mitsuba export, so both accept and refuse the same
descriptions)."""

from __future__ import annotations

import numbers

import numpy as np

from jaxgfx.render.emitters import EnvironmentMap
from jaxgfx.render.scene.schema import expect_keys, num, rgb, vec
from jaxgfx.render.sunsky import SUNSKY_DEFAULTS, TIME_KEYS, SunSky, sun_direction_at

__all__ = ["SUNSKY_KEYS", "sunsky_from_desc", "check_time"]

SUNSKY_KEYS = (("type",), ("sun_direction", *TIME_KEYS, "turbidity", "albedo", "sun_scale",
                           "sky_scale", "sun_aperture", "complex_sun", "to_world",
                           "id"))  # fmt: skip
"""(required, optional) keys of a ``sunsky`` description. Without ``sun_direction`` the sun
is placed by the location / time keys (Mitsuba's defaults for the missing ones: Tokyo,
2010-07-10 15:00, timezone 9); giving both is refused, as Mitsuba refuses it."""

_INT_KEYS = ("year", "month", "day")


def check_time(values: dict, err) -> dict:
    """The location / time ``values`` (a subset of :data:`TIME_KEYS`) checked: ``year``,
    ``month`` (1..12), ``day`` (1..31) integers, ``latitude`` in [-90, 90], the others finite
    numbers; ``err(key, message)`` builds the exception naming a bad one."""
    out = {}
    for k, v in values.items():
        if k in _INT_KEYS:
            if isinstance(v, bool) or not isinstance(v, numbers.Integral):
                raise err(k, f"expected an integer, got {v!r}")
            v = int(v)
            lo, hi = {"year": (-4712, 1_000_000), "month": (1, 12), "day": (1, 31)}[k]
            if not lo <= v <= hi:
                raise err(k, f"expected an integer in [{lo}, {hi}], got {v}")
        else:
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not np.isfinite(v):
                raise err(k, f"expected a finite number, got {v!r}")
            v = float(v)
            if k == "latitude" and not -90.0 <= v <= 90.0:
                raise err(k, f"expected degrees in [-90, 90], got {v}")
        out[k] = v
    return out


def sunsky_from_desc(ed, where) -> SunSky:
    """A :class:`~jaxgfx.render.sunsky.SunSky` of a ``sunsky`` description ``{type: sunsky,
    sun_direction? | latitude?, longitude?, timezone?, year?, month?, day?, hour?, minute?,
    second?, turbidity?, albedo?, sun_scale?, sky_scale?, sun_aperture?, complex_sun?,
    to_world?}`` (Mitsuba's names and defaults). Bad values raise one ``ValueError`` naming
    ``where.KEY``."""
    expect_keys(ed, where, *SUNSKY_KEYS)
    rot = None
    if "to_world" in ed:
        rot = EnvironmentMap.check_to_world(ed["to_world"], f"{where}.to_world")
    when = [k for k in TIME_KEYS if k in ed]
    if "sun_direction" in ed:
        if when:
            raise ValueError(f"{where}: give either sun_direction or the location / time keys "
                             f"(got both: {when}), as Mitsuba refuses both")  # fmt: skip
        sd = vec(ed["sun_direction"], f"{where}.sun_direction")
    else:
        t = check_time({k: ed[k] for k in when},
                       lambda k, m: ValueError(f"{where}.{k}: {m}"))  # fmt: skip
        sd = sun_direction_at(rot, **t)
    d = SUNSKY_DEFAULTS
    alb = ed.get("albedo", d["albedo"])
    alb = num(alb, f"{where}.albedo") if np.ndim(alb) == 0 else rgb(alb, f"{where}.albedo")
    if not bool(np.all((np.asarray(alb) >= 0) & (np.asarray(alb) <= 1))):
        raise ValueError(f"{where}.albedo: expected values in [0, 1], got {np.asarray(alb)}")
    turb = num(ed.get("turbidity", d["turbidity"]), f"{where}.turbidity")
    if not 1.0 <= float(turb) <= 10.0:
        raise ValueError(f"{where}.turbidity: expected a number in [1, 10], got {float(turb)}")
    scales = {}
    for k in ("sun_scale", "sky_scale"):
        scales[k] = num(ed.get(k, d[k]), f"{where}.{k}")
        if not float(scales[k]) >= 0:
            raise ValueError(f"{where}.{k}: expected a non-negative number, got "
                             f"{float(scales[k])}")  # fmt: skip
    ap = ed.get("sun_aperture", d["sun_aperture"])
    num(ap, f"{where}.sun_aperture")
    ap = float(np.asarray(ap, np.float64))  # a Python float (static): not rounded to float32
    if not 0.0 < ap < 180.0:
        raise ValueError(f"{where}.sun_aperture: expected degrees in (0, 180), got {ap}")
    cs = ed.get("complex_sun", d["complex_sun"])
    if not isinstance(cs, (bool, np.bool_)):
        raise ValueError(f"{where}.complex_sun: expected true or false, got {cs!r}")
    try:
        return SunSky.create(sd, turbidity=turb, albedo=alb, sun_aperture=ap, complex_sun=bool(cs),
                             to_world=rot, **scales)  # fmt: skip
    except (ValueError, TypeError) as e:
        msg = str(e)
        raise type(e)(msg if msg.startswith(where) else f"{where}.{msg}") from None
