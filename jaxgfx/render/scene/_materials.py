"""Materials from descriptions whose parameters may be textures (``material_from_desc``): shared
by the scene loader (:func:`jaxgfx.render.scene.load_scene`) and the Mitsuba writer, which
builds a material to read its texels (its own module so that the writer does not import the
loader, which imports the XML reader, which imports the writer)."""

from __future__ import annotations

import os
from collections.abc import Mapping

from jaxgfx.render.bsdf import BSDF_TYPES, Mask, PassThrough, make_bsdf
from jaxgfx.render.bsdf.textured import (
    Textured,
    is_texture_desc,
    texturable_paths,
    texture_from_dict,
    texture_min,
)
from jaxgfx.render.parameters import get_path

__all__ = ["material_from_desc", "emission_from_desc", "check_one_sided"]


def material_from_desc(desc, *, where="material", base_dir=None):
    """A BSDF from a material description whose parameters may be textures.

    Texture-valued keys are replaced by a neutral constant for :func:`make_bsdf` (which
    validates everything else), then wrapped in :class:`Textured` (the keys resolve to BSDF
    fields through the class's ``PARAMETER_ALIASES``). Without texture keys the plain BSDF is
    returned (no wrapper, no cost). Roughness / exponent / eta textures must be positive,
    colour textures non-negative. A ``one_sided`` key (a scene property, read by
    :func:`~jaxgfx.render.scene.load_scene`) is ignored here.
    """
    desc = dict(desc)
    _resolve_measured(desc, base_dir)
    # one-sidedness is the scene's (Scene.one_sided, read by load_scene), not the BSDF's
    desc.pop("one_sided", None)
    pre = f"{where}." if where else ""
    if isinstance(desc.get("type"), str) and desc["type"] in _MAP_TEXTURE:
        return _map_material(desc, pre, base_dir)
    # nested BSDF descriptions (blendbsdf's bsdf0 / bsdf1) are not textures
    tex_keys = [
        k for k, v in desc.items() if k != "type" and is_texture_desc(v) and not _is_bsdf_desc(v)
    ]
    if not tex_keys:
        return make_bsdf(desc)
    if getattr(BSDF_TYPES.get(desc.get("type")), "needs_tangents", False):  # hair
        raise ValueError(f"{pre}{tex_keys[0]}: {desc['type']!r} parameters cannot be textures")
    plain = dict(desc)
    for k in tex_keys:
        plain[k] = 0.5
    bsdf = make_bsdf(plain)
    textures = {}
    for k in tex_keys:
        try:
            paths = texturable_paths(bsdf, k)
        except ValueError as e:
            raise ValueError(f"{pre}{k}: {e}") from None
        old = get_path(bsdf, paths[0])
        rgb = old.ndim >= 1 and old.shape[-1] == 3
        tex = texture_from_dict(desc[k], f"{pre}{k}", base_dir=base_dir, channels=3 if rgb else 1)
        lo = texture_min(tex)
        positive = k.startswith("alpha") or k in ("exponent", "eta")
        if (positive and not lo > 0) or lo < 0:
            need = "positive" if positive else "non-negative"
            raise ValueError(f"{pre}{k}: texture values must be {need}, got min {lo}")
        textures[k] = tex
    return Textured(bsdf, textures)


def _resolve_measured(desc, base_dir) -> None:
    """A ``measured`` material's relative ``filename`` is relative to ``base_dir``."""
    path = desc.get("filename") if desc.get("type") == "measured" else None
    if isinstance(path, (str, os.PathLike)) and base_dir and not os.path.isabs(path):
        desc["filename"] = os.path.join(base_dir, os.fspath(path))


def check_one_sided(value, material, where) -> bool:
    """A material description's ``one_sided`` flag, checked against the built ``material``:
    a bool (default false: jaxgfx shades reflection-only materials on both sides), true only
    for a reflection-only material (not transmissive, no ``mask``, whose pass-through is seen
    from both sides). ``where``: the key's path for the error."""
    if not isinstance(value, bool):
        raise ValueError(f"{where}: expected true or false, got {value!r}")
    if value and (material.is_transmissive or _has_mask(material)):
        kind = _has_mask(material) or f"{type(material).__name__} (transmissive)"
        raise ValueError(f"{where}: only reflection-only materials can be one-sided; "
                         f"{kind} scatters on both sides")  # fmt: skip
    return value


def _has_mask(m) -> str:
    """``"a mask"`` / ``"a pass-through (Polarizer)"`` when a ``mask`` or a pass-through
    (``polarizer``, ``retarder``) is ``m`` or nested in it (textured, mapped or blended), else
    ``""``."""
    if isinstance(m, Mask):
        return "a mask"
    if isinstance(m, PassThrough):
        return f"a pass-through ({type(m).__name__})"
    kids = (_has_mask(getattr(m, k)) for k in ("bsdf", "bsdf0", "bsdf1") if hasattr(m, k))
    return next((k for k in kids if k), "")


def emission_from_desc(value, where, *, base_dir=None, rgb=None):
    """An area light's ``radiance``: an RGB constant (``rgb(value, where)``, the schema's
    parser) or a texture description (``bitmap`` / ``checkerboard``, as material textures:
    8-bit files sRGB-decoded unless ``raw``), whose values must be non-negative. ``mesh_attribute``
    radiance is refused (the attribute layout is laid out for materials only)."""
    if not is_texture_desc(value):
        return rgb(value, where)
    if value.get("type") == "mesh_attribute":
        raise ValueError(f"{where}: mesh_attribute radiance is not supported "
                         "(bitmap or checkerboard)")  # fmt: skip
    tex = texture_from_dict(value, where, base_dir=base_dir, channels=3)
    lo = texture_min(tex)
    if not lo >= 0:
        raise ValueError(f"{where}: texture values must be non-negative, got min {lo}")
    return tex


_MAP_TEXTURE = {"normalmap": ("normalmap", 3), "bumpmap": ("height", 1)}


def _map_material(desc, pre, base_dir):
    """``normalmap`` / ``bumpmap``: ``{type, bsdf: {...}, normalmap | height: texture,
    scale, flip_invalid_normals, use_shadowing_function}`` (the nested material may itself be
    textured)."""
    kind = desc["type"]
    key, channels = _MAP_TEXTURE[kind]
    flags = ("flip_invalid_normals", "use_shadowing_function")
    allowed = ("type", "bsdf", key) + (("scale",) if kind == "bumpmap" else ()) + flags
    unknown = sorted(set(desc) - set(allowed))
    if unknown:
        raise ValueError(f"{pre}{unknown[0]}: unknown key for {kind!r}; expected {list(allowed)}")
    if not isinstance(desc.get("bsdf"), Mapping):
        raise ValueError(f"{pre}bsdf: {kind!r} needs a nested material description")
    nested = material_from_desc(desc["bsdf"], where=f"{pre}bsdf", base_dir=base_dir)
    if key not in desc:
        raise ValueError(f"{pre}{key}: {kind!r} needs a texture")
    tex = desc[key]
    if is_texture_desc(tex):
        tex = texture_from_dict(tex, f"{pre}{key}", base_dir=base_dir, channels=channels)
    kw = {k: desc[k] for k in ("scale", *flags) if k in desc}
    try:
        return make_bsdf({"type": kind, "bsdf": nested, key: tex, **kw})
    except (ValueError, TypeError) as e:
        raise type(e)(f"{pre}{e}") from None


def _is_bsdf_desc(v):
    return isinstance(v, Mapping) and v.get("type") in BSDF_TYPES
