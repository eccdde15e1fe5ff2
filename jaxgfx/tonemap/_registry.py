"""Name -> operator registry, parameter metadata (defaults and constraints) and a dispatcher."""

from __future__ import annotations

from typing import NamedTuple

from .._checks import check_choice
from ._global import (
    tonemap_ACES_Narkowicz2015,
    tonemap_Drago2003,
    tonemap_exposure,
    tonemap_Hable2010,
    tonemap_Reinhard2002,
    tonemap_Reinhard2005,
)
from ._local import (
    tonemap_contrast_inversion,
    tonemap_Durand2002,
    tonemap_Fattal2002,
    tonemap_Reinhard2002_local,
)

__all__ = ["TONEMAP_METHODS", "TONEMAP_PARAMETERS", "ParamSpec", "tonemap"]

TONEMAP_METHODS = {
    "exposure": tonemap_exposure,
    "drago": tonemap_Drago2003,
    "reinhard": tonemap_Reinhard2002,
    "reinhard_devlin": tonemap_Reinhard2005,
    "filmic": tonemap_ACES_Narkowicz2015,
    "hable": tonemap_Hable2010,
    "reinhard_local": tonemap_Reinhard2002_local,
    "contrast_inversion": tonemap_contrast_inversion,
    "durand": tonemap_Durand2002,
    "fattal": tonemap_Fattal2002,
}
"""Tone-mapping operators by short name; each is ``op(hdr, **params)`` with documented
defaults (``op(hdr)`` works). ``"filmic"`` is the ACES fit (Narkowicz 2015)."""

GLOBAL_METHODS = ("exposure", "drago", "reinhard", "filmic", "hable")
"""Operators that are one monotone luminance curve (invertible by :func:`inverse_tonemap`)."""

ADAPTIVE_METHODS = ("drago", "reinhard", "filmic", "hable", "reinhard_local")
"""Operators taking ``adaptation=`` statistics (usable by :func:`smooth_adaptation`)."""


class ParamSpec(NamedTuple):
    """A continuous operator parameter: default and constraint for fitting.

    ``constraint``: ``"real"``, ``"positive"`` (> 0, fitted in log), ``"unit"`` (in (0, 1),
    fitted by logit) or ``"above1"`` (> 1, fitted as log(p - 1)).
    """

    default: float
    constraint: str
    help: str


_SAT = ParamSpec(1.0, "positive", "colour saturation exponent s of (C/L)^s")

TONEMAP_PARAMETERS: dict[str, dict[str, ParamSpec]] = {
    "exposure": {
        "exposure": ParamSpec(0.0, "real", "exposure in stops"),
        "gamma": ParamSpec(1.0, "positive", "display gamma on luminance"),
        "saturation": _SAT,
    },
    "drago": {
        "bias": ParamSpec(0.85, "unit", "bias b of the adaptive logarithm"),
        "ld_max": ParamSpec(100.0, "positive", "display maximum, cd/m^2"),
        "saturation": _SAT,
    },
    "reinhard": {
        "key": ParamSpec(0.18, "positive", "key a (mid-grey level)"),
        "white": ParamSpec(4.0, "positive", "L_white in scaled units (default: image maximum)"),
        "saturation": _SAT,
    },
    "reinhard_devlin": {
        "intensity": ParamSpec(0.0, "real", "intensity f"),
        "light_adapt": ParamSpec(1.0, "unit", "light adaptation c"),
        "color_adapt": ParamSpec(0.0, "unit", "chromatic adaptation a"),
    },
    "filmic": {
        "exposure": ParamSpec(0.0, "real", "exposure in stops (after auto-exposure)"),
        "saturation": _SAT,
    },
    "hable": {
        "exposure": ParamSpec(0.0, "real", "exposure in stops (after auto-exposure)"),
        "shoulder": ParamSpec(0.15, "positive", "shoulder strength A"),
        "white": ParamSpec(11.2, "positive", "linear white point W"),
        "saturation": _SAT,
    },
    "reinhard_local": {
        "key": ParamSpec(0.18, "positive", "key a"),
        "saturation": _SAT,
    },
    "contrast_inversion": {
        "k": ParamSpec(2.0, "positive", "divisor k (flat regions -> 1/k)"),
        "sigma": ParamSpec(8.0, "positive", "blur sigma in pixels"),
        "saturation": _SAT,
    },
    "durand": {
        "contrast": ParamSpec(5.0, "above1", "target contrast of the base layer"),
        "sigma_range": ParamSpec(0.4, "positive", "range sigma, log10 units"),
        "saturation": _SAT,
    },
    "fattal": {
        "alpha": ParamSpec(0.1, "positive", "gradient threshold relative to the mean"),
        "beta": ParamSpec(0.85, "positive", "attenuation exponent"),
        "gamma": ParamSpec(0.8, "positive", "output gamma"),
        "saturation": ParamSpec(0.8, "positive", "colour saturation exponent"),
    },
}
"""Continuous parameters of each operator (fitted by :func:`fit_tonemap`, exposed by the CLI).
Other keyword options (``encode``, ``sigma_spatial``, ``num_scales``...) are static."""


def tonemap(hdr, *, method: str = "drago", **params):
    """Tone map ``hdr`` with the operator ``TONEMAP_METHODS[method]`` and keyword parameters.

    Example:
        >>> tonemap(jnp.ones((2, 2, 3)), method="reinhard", encode="linear").shape
        (2, 2, 3)
    """
    check_choice(method, "method", tuple(TONEMAP_METHODS))
    return TONEMAP_METHODS[method](hdr, **params)
