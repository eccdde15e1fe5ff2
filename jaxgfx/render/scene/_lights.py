"""Scene-description readers of the textured delta lights: the ``projector`` emitter and the
spot light's projected ``texture`` (shared by :func:`load_scene` and the Mitsuba export)."""

from __future__ import annotations

from jaxgfx.render.bsdf.texture import Texture
from jaxgfx.render.bsdf.textured import is_texture_desc, texture_from_dict
from jaxgfx.render.emitters import ProjectorLight
from jaxgfx.render.scene.schema import expect_keys, num, rgb, vec

__all__ = ["PROJECTOR_KEYS", "SPOT_TEXTURE_KEYS", "projector_from_desc", "spot_texture"]

PROJECTOR_KEYS = (("type", "position", "direction", "fov"),
                  ("up", "fov_axis", "irradiance", "scale", "id"))  # fmt: skip
"""(required, optional) keys of a ``projector`` description."""
SPOT_TEXTURE_KEYS = ("texture", "up")
"""Optional keys a ``spot`` description adds for its projected texture."""


def _bitmap(d, where, base_dir) -> Texture:
    tex = texture_from_dict(d, where, base_dir=base_dir)
    if not isinstance(tex, Texture):
        raise ValueError(f"{where}.type: expected a bitmap texture, got {d['type']!r}")
    return tex


def spot_texture(ed, where, base_dir=None):
    """``(texture, up)`` of a ``spot`` description: its projected ``texture`` (a bitmap
    description) and the ``up`` vector orienting it; ``(None, None)`` without a texture."""
    if "texture" not in ed:
        if "up" in ed:
            raise ValueError(f"{where}.up: only a spot light with a texture takes 'up'")
        return None, None
    up = vec(ed["up"], f"{where}.up") if "up" in ed else None
    return _bitmap(ed["texture"], f"{where}.texture", base_dir), up


def projector_from_desc(ed, where, base_dir=None) -> ProjectorLight:
    """A :class:`~jaxgfx.render.emitters.ProjectorLight` of a ``projector`` description
    ``{type: projector, position, direction, fov, up?, fov_axis?, irradiance?, scale?}``:
    ``irradiance`` an RGB value (default 1) or a bitmap texture description."""
    expect_keys(ed, where, *PROJECTOR_KEYS)
    irr = ed.get("irradiance", 1.0)
    if is_texture_desc(irr):
        irr = _bitmap(irr, f"{where}.irradiance", base_dir)
    else:
        irr = rgb(irr, f"{where}.irradiance")
    kwargs = {"fov": num(ed["fov"], f"{where}.fov"),
              "scale": num(ed.get("scale", 1.0), f"{where}.scale"),
              "fov_axis": ed.get("fov_axis", "x")}  # fmt: skip
    if "up" in ed:
        kwargs["up"] = vec(ed["up"], f"{where}.up")
    try:
        return ProjectorLight.create(vec(ed["position"], f"{where}.position"),
                                     vec(ed["direction"], f"{where}.direction"), irr,
                                     **kwargs)  # fmt: skip
    except (ValueError, TypeError) as e:
        msg = str(e)
        raise type(e)(msg if msg.startswith(where) else f"{where}.{msg}") from None
