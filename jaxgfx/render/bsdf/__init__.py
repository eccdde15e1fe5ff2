"""jaxgfx.render.bsdf: BSDF models in the local shading frame (normal ``+z``).

Every model implements the :class:`BSDF` interface (``eval``, ``pdf``, ``sample``,
``albedo``, ``has_delta``, ``is_transmissive``) with Mitsuba 3 conventions; see
``docs/render_bsdf.md``. ``make_bsdf({"type": "diffuse", "reflectance": 0.5})`` builds one from
a scene-description dict.
"""

from __future__ import annotations

import inspect

from jaxgfx._checks import check_choice
from jaxgfx.render.bsdf._base import BSDF as BSDF
from jaxgfx.render.bsdf._base import BSDFSample as BSDFSample
from jaxgfx.render.bsdf._base import rgb_param as rgb_param
from jaxgfx.render.bsdf._blend import BlendBSDF as BlendBSDF
from jaxgfx.render.bsdf._conductor import Mirror as Mirror
from jaxgfx.render.bsdf._dielectric import SmoothDielectric as SmoothDielectric
from jaxgfx.render.bsdf._diffuse import Diffuse as Diffuse
from jaxgfx.render.bsdf._hair import Hair as Hair
from jaxgfx.render.bsdf._mask import Mask as Mask
from jaxgfx.render.bsdf._mask import Null as Null
from jaxgfx.render.bsdf._measured import Measured as Measured
from jaxgfx.render.bsdf._measured import read_measured as read_measured
from jaxgfx.render.bsdf._measured import write_measured as write_measured
from jaxgfx.render.bsdf._normalmap import BumpMap as BumpMap
from jaxgfx.render.bsdf._normalmap import NormalMap as NormalMap
from jaxgfx.render.bsdf._normalmap import TangentSpace as TangentSpace
from jaxgfx.render.bsdf._phong import Phong as Phong
from jaxgfx.render.bsdf._plastic import SmoothPlastic as SmoothPlastic
from jaxgfx.render.bsdf._polarizer import CircularPolarizer as CircularPolarizer
from jaxgfx.render.bsdf._polarizer import PassThrough as PassThrough
from jaxgfx.render.bsdf._polarizer import Polarizer as Polarizer
from jaxgfx.render.bsdf._polarizer import Retarder as Retarder
from jaxgfx.render.bsdf._pplastic import PolarizedPlastic as PolarizedPlastic
from jaxgfx.render.bsdf._principled import Principled as Principled
from jaxgfx.render.bsdf._principledthin import PrincipledThin as PrincipledThin
from jaxgfx.render.bsdf._roughconductor import RoughConductor as RoughConductor
from jaxgfx.render.bsdf._roughdielectric import RoughDielectric as RoughDielectric
from jaxgfx.render.bsdf._roughplastic import RoughPlastic as RoughPlastic
from jaxgfx.render.bsdf._thindielectric import ThinDielectric as ThinDielectric

__all__ = [
    "BSDF",
    "BSDFSample",
    "Diffuse",
    "Hair",
    "Measured",
    "Mirror",
    "Phong",
    "Principled",
    "PrincipledThin",
    "RoughConductor",
    "RoughDielectric",
    "SmoothDielectric",
    "SmoothPlastic",
    "RoughPlastic",
    "PolarizedPlastic",
    "ThinDielectric",
    "BlendBSDF",
    "Mask",
    "Null",
    "PassThrough",
    "Polarizer",
    "CircularPolarizer",
    "Retarder",
    "NormalMap",
    "BumpMap",
    "TangentSpace",
    "BSDF_TYPES",
    "make_bsdf",
    "rgb_param",
    "read_measured",
    "write_measured",
]

BSDF_TYPES = {
    "diffuse": Diffuse,
    "mirror": Mirror,
    "conductor": Mirror,
    "roughconductor": RoughConductor,
    "dielectric": SmoothDielectric,
    "roughdielectric": RoughDielectric,
    "plastic": SmoothPlastic,
    "roughplastic": RoughPlastic,
    "phong": Phong,
    "thindielectric": ThinDielectric,
    "blendbsdf": BlendBSDF,
    "mask": Mask,
    "null": Null,
    "principled": Principled,
    "principledthin": PrincipledThin,
    "normalmap": NormalMap,
    "bumpmap": BumpMap,
    "hair": Hair,
    "pplastic": PolarizedPlastic,
    "polarizer": Polarizer,
    "circular": CircularPolarizer,
    "retarder": Retarder,
    "measured": Measured,
}


def make_bsdf(desc: dict) -> BSDF:
    """Build a BSDF from a description dict ``{"type": name, **parameters}``.

    ``type`` is a key of :data:`BSDF_TYPES`; the other keys are the constructor's parameter
    names (e.g. ``{"type": "roughconductor", "alpha": 0.2, "distribution": "beckmann"}``).
    Raises ``ValueError`` naming an unknown type or an unknown parameter key.
    """
    if not isinstance(desc, dict):
        raise TypeError(f"desc: expected a dict, got {type(desc).__name__}")
    if "type" not in desc:
        raise ValueError("desc: missing key 'type'")
    kind = check_choice(desc["type"], "desc['type']", BSDF_TYPES)
    cls = BSDF_TYPES[kind]
    params = {k: v for k, v in desc.items() if k != "type"}
    allowed = [p for p in inspect.signature(cls.__init__).parameters if p != "self"]
    for k in params:
        if k not in allowed:
            raise ValueError(
                f"desc[{k!r}]: unknown parameter for {kind!r}; expected one of {allowed}"
            )
    required = [
        n for n, p in inspect.signature(cls.__init__).parameters.items()
        if n != "self" and p.default is inspect.Parameter.empty
        and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]  # fmt: skip
    missing = [k for k in required if k not in params]
    if missing:
        raise ValueError(f"desc: {kind!r} needs {', '.join(repr(k) for k in missing)}")
    if kind in ("blendbsdf", "mask", "normalmap", "bumpmap"):  # nested descriptions
        for k in ("bsdf0", "bsdf1", "bsdf"):
            if isinstance(params.get(k), dict):
                try:
                    params[k] = make_bsdf(params[k])
                except (ValueError, TypeError) as e:
                    raise type(e)(f"{k}.{e}") from None
    return cls(**params)
