"""Name -> operator registry, parameter metadata (defaults and constraints) and a dispatcher."""

from __future__ import annotations

import inspect
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
from ._mantiuk import tonemap_Mantiuk2006

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
    "mantiuk": tonemap_Mantiuk2006,
}
"""Tone-mapping operators by short name; each is ``op(hdr, **params)`` with documented
defaults (``op(hdr)`` works). ``"filmic"`` is the ACES fit (Narkowicz 2015)."""

GLOBAL_METHODS = ("exposure", "drago", "reinhard", "filmic", "hable")
"""Operators that are one monotone luminance curve (invertible by :func:`inverse_tonemap`)."""

ADAPTIVE_METHODS = ("drago", "reinhard", "filmic", "hable", "reinhard_local")
"""Operators taking ``adaptation=`` statistics (usable by :func:`smooth_adaptation`)."""


class ParamSpec(NamedTuple):
    """A continuous operator parameter: default and constraint for fitting.

    ``default`` is the operator's own keyword default (read from its signature, the one
    source of truth; ``None`` means "from the image", e.g. Reinhard's ``white``);
    ``constraint``: ``"real"``, ``"positive"`` (> 0, fitted in log), ``"unit"`` (in (0, 1),
    fitted by logit) or ``"above1"`` (> 1, fitted as log(p - 1)); ``start``: where
    :func:`fit_tonemap` starts when ``default`` is ``None``.
    """

    default: float | None
    constraint: str
    help: str
    start: float | None = None

    @property
    def initial(self) -> float:
        """The fit's starting value: ``default``, or ``start`` for an image-dependent one."""
        return self.start if self.default is None else self.default


def _defaults(fn, specs: dict[str, tuple]) -> dict[str, ParamSpec]:
    """``ParamSpec``s whose defaults are ``fn``'s keyword defaults (never a second copy)."""
    sig = inspect.signature(fn).parameters
    return {name: ParamSpec(sig[name].default, *rest) for name, rest in specs.items()}


_SAT = ("positive", "colour saturation exponent s of (C/L)^s")

_SPECS = {
    "exposure": {
        "exposure": ("real", "exposure in stops"),
        "gamma": ("positive", "display gamma on luminance"),
        "saturation": _SAT,
    },
    "drago": {
        "bias": ("unit", "bias b of the adaptive logarithm"),
        "ld_max": ("positive", "display maximum, cd/m^2"),
        "saturation": _SAT,
    },
    "reinhard": {
        "key": ("positive", "key a (mid-grey level)"),
        "white": ("positive", "L_white in scaled units (default: the image maximum)", 4.0),
        "saturation": _SAT,
    },
    "reinhard_devlin": {
        "intensity": ("real", "intensity f in [-8, 8]"),
        "light_adapt": ("unit", "light adaptation c in [0, 1]"),
        "color_adapt": ("unit", "chromatic adaptation a in [0, 1]"),
    },
    "filmic": {
        "exposure": ("real", "exposure in stops (after auto-exposure)"),
        "saturation": _SAT,
    },
    "hable": {
        "exposure": ("real", "exposure in stops (after auto-exposure)"),
        "shoulder": ("positive", "shoulder strength A"),
        "white": ("positive", "linear white point W"),
        "saturation": _SAT,
    },
    "reinhard_local": {
        "key": ("positive", "key a"),
        "phi": ("real", "sharpening phi (scale selection; zero gradient a.e.)"),
        "epsilon": ("positive", "activity threshold (scale selection; zero gradient a.e.)"),
        "saturation": _SAT,
    },
    "contrast_inversion": {
        "k": ("positive", "divisor k (the log-average maps to 1 / (1 + k))"),
        "strength": ("unit", "exponent c of the blurred surround, in (0, 1]"),
        "sigma": ("positive", "surround blur sigma in pixels"),
        "saturation": _SAT,
    },
    "durand": {
        "contrast": ("above1", "target contrast of the base layer"),
        "sigma_range": ("positive", "range sigma, log10 units"),
        "saturation": _SAT,
    },
    "fattal": {
        "alpha": ("positive", "gradient threshold relative to the mean"),
        "beta": ("positive", "attenuation exponent"),
        "gamma": ("positive", "output gamma"),
        "saturation": ("positive", "colour saturation exponent"),
    },
    "mantiuk": {
        "contrast": ("unit", "contrast factor l: responses scaled by l, in (0, 1]"),
        "saturation": _SAT,
    },
}

TONEMAP_PARAMETERS: dict[str, dict[str, ParamSpec]] = {
    name: _defaults(TONEMAP_METHODS[name], specs) for name, specs in _SPECS.items()
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
