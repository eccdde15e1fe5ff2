"""Textured materials: per-hit lookups of BSDF parameters from bitmap or procedural textures.

A :class:`Textured` wraps an unchanged BSDF and a mapping ``field -> texture``; ``at(uv)``
returns the BSDF with those fields replaced by the texture values at the hit's ``uv`` (via
``eqx.tree_at``), so every BSDF works with per-ray parameters ``(..., 3)`` / ``(...)``
unchanged. The integrators resolve textures through ``dispatch(..., uv=hit.uv)``;
materials without textures are never wrapped, so untextured scenes compile to the same program.

Scene-description keys (Mitsuba 3 conventions):

* ``{type: bitmap, file: tex.png, wrap: repeat|clamp|mirror, filter: bilinear|nearest,
  raw: false, to_uv: [[a, b, c], [d, e, f]]}`` (``to_uv`` optional: ``uv' = (a u + b v + c,
  d u + e v + f)`` before the lookup, Mitsuba's bitmap ``to_uv``): 8-bit/16-bit LDR files
  are decoded from sRGB to linear unless ``raw: true``;
  EXR / HDR files are linear. ``{type: bitmap, image: [[...]]}`` gives texels inline
  (linear, ``(H, W)`` or ``(H, W, C)``).
* ``{type: checkerboard, color0: 0.4, color1: 0.2, scale: 1}``: Mitsuba's ``checkerboard``
  with ``uv' = scale * uv``: ``color0`` where ``frac(u') > 1/2`` equals ``frac(v') > 1/2``,
  else ``color1``.

A one-channel texture feeding an RGB parameter is broadcast; an RGB texture feeding a scalar
parameter (``alpha``, ``exponent``, ``eta``) gives its luminance (Rec. 709 Y), like Mitsuba's
``eval_1``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxgfx import io
from jaxgfx._checks import as_float_array, check_choice, check_finite
from jaxgfx.color import LUMINANCE_WEIGHTS
from jaxgfx.render.bsdf._base import WrapsBSDF
from jaxgfx.render.bsdf.texture import (
    TEXTURE_FILTERS,
    TEXTURE_WRAP_MODES,
    MeshAttribute,
    Texture,
    check_uv_transform,
    lookup,
)
from jaxgfx.render.parameters import get_path, parameter_paths

__all__ = [
    "Checkerboard",
    "Textured",
    "TEXTURE_TYPES",
    "texture_from_dict",
    "texture_eval",
    "is_texture_desc",
    "texture_min",
    "texturable_paths",
]

TEXTURE_TYPES = ("bitmap", "checkerboard", "mesh_attribute")
_LUMA = LUMINANCE_WEIGHTS["rec709"]


class Checkerboard(eqx.Module):
    """Procedural checkerboard (Mitsuba 3 ``checkerboard``) on ``uv' = scale * uv``.

    ``color0``, ``color1``: (C,) arrays (differentiable leaves); ``scale``: static float.
    Value ``color0`` where ``(frac(u') > 1/2) == (frac(v') > 1/2)``, else ``color1``.
    Example: default colours 0.4 / 0.2: ``uv = (0.25, 0.25)`` → 0.4, ``(0.75, 0.25)`` → 0.2.
    """

    color0: jnp.ndarray
    color1: jnp.ndarray
    scale: float = eqx.field(static=True, default=1.0)


def texture_eval(tex, uv):
    """Texture value at ``uv (..., 2)`` → ``(..., C)`` (bitmap: bilinear / nearest lookup)."""
    if isinstance(tex, Checkerboard):
        q = uv[..., :2] * tex.scale
        m = (q - jnp.floor(q)) > 0.5
        same = (m[..., 0] == m[..., 1])[..., None]
        return jnp.where(same, tex.color0.astype(uv.dtype), tex.color1.astype(uv.dtype))
    if isinstance(tex, MeshAttribute):
        return tex(uv)
    return lookup(tex, uv[..., :2]).astype(uv.dtype)  # mesh attributes may follow (u, v)


def texturable_paths(bsdf, name):
    """Attribute paths of the BSDF that the parameter ``name`` sets (its class's alias table)."""
    try:
        return parameter_paths(bsdf, name)
    except ValueError:
        raise ValueError(f"{name}: not a texturable parameter of {type(bsdf).__name__}") from None


class Textured(WrapsBSDF):
    """A BSDF whose parameters named in ``textures`` (dict ``key -> Bitmap/Checkerboard``) are
    looked up per hit. ``at(uv (..., 2))`` returns the plain BSDF with per-ray fields
    (RGB: ``(..., 3)``, scalar: ``(...)``). Forwards ``has_delta`` / ``is_transmissive``.

    Example: ``Textured(Diffuse(0.5), {"reflectance": Checkerboard(jnp.ones(3),
    jnp.zeros(3))}).at(jnp.array([0.25, 0.25])).reflectance`` → ``[1, 1, 1]``.
    """

    bsdf: eqx.Module
    textures: dict

    def __check_init__(self):
        for k in self.textures:
            texturable_paths(self.bsdf, k)

    def at(self, uv):
        if uv is None:
            raise ValueError("uv: a textured material needs the hit uv (dispatch(..., uv=hit.uv))")
        out = self.bsdf
        # a key setting several fields first (``alpha`` sets alpha_u and alpha_v): the
        # per-axis keys (``alpha_v``) then override it whatever the dict's order
        items = sorted(self.textures.items(),
                       key=lambda kv: -len(texturable_paths(self.bsdf, kv[0])))  # fmt: skip
        for name, tex in items:
            val = texture_eval(tex, uv)
            for path in texturable_paths(self.bsdf, name):
                old = get_path(self.bsdf, path)
                rgb = old.ndim >= 1 and old.shape[-1] == 3
                if rgb:
                    new = jnp.broadcast_to(val, val.shape[:-1] + (3,))
                elif val.shape[-1] == 1:
                    new = val[..., 0]
                else:
                    new = val[..., :3] @ jnp.asarray(_LUMA, val.dtype)
                out = eqx.tree_at(lambda b, p=path: get_path(b, p), out, new)
        return out

    @property
    def albedo(self):
        raise ValueError("albedo of a textured material depends on uv: use .at(uv).albedo")


def is_texture_desc(x) -> bool:
    """True when a material parameter value is a texture description (a mapping with type)."""
    return isinstance(x, Mapping) and "type" in x


def _expect(d, where, allowed):
    unknown = sorted(set(d) - set(allowed))
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; expected {sorted(allowed)}")


def _read_bitmap(path, raw, where):
    try:
        img = np.asarray(io.read_any(path), np.float32)
    except (OSError, ValueError) as e:
        raise ValueError(f"{where}.file: cannot read texture {path!r}: {e}") from None
    if io.kind_of(path) == "ldr" and not raw:
        from jaxgfx.color.transfer import srgb_to_linear

        img = np.asarray(srgb_to_linear(img), np.float32)
    return img


def texture_from_dict(d, where="texture", *, base_dir=None, channels=3):
    """Build a texture (:class:`~jaxgfx.render.bsdf.texture.Texture` or :class:`Checkerboard`) from
    a description (see the module docstring). ``channels``: 3 for RGB parameters, 1 for
    scalar ones (sets the default checkerboard colours' length). Errors name ``where``."""
    if not is_texture_desc(d):
        raise ValueError(f"{where}: expected a mapping with a 'type' key")
    kind = check_choice(d["type"], f"{where}.type", TEXTURE_TYPES)
    if kind == "mesh_attribute":  # {type: mesh_attribute, name: vertex_color, scale: 1}
        _expect(d, where, ("type", "name", "scale"))
        name = d.get("name")
        if not isinstance(name, str) or not name.startswith(("vertex_", "face_")):
            raise ValueError(f"{where}.name: expected 'vertex_...' or 'face_...', got {name!r}")
        scale = as_float_array(d.get("scale", 1.0), f"{where}.scale")
        if scale.ndim != 0:
            raise ValueError(f"{where}.scale: expected a number")
        return MeshAttribute(name, check_finite(scale, f"{where}.scale"))
    if kind == "checkerboard":
        _expect(d, where, ("type", "color0", "color1", "scale"))
        cols = []
        for name, default in (("color0", 0.4), ("color1", 0.2)):
            c = as_float_array(d.get(name, default), f"{where}.{name}")
            check_finite(c, f"{where}.{name}")
            if c.ndim == 0:
                c = jnp.broadcast_to(c, (channels,))
            if c.ndim != 1 or c.shape[0] not in (1, 3):
                raise ValueError(f"{where}.{name}: expected a number or an RGB triple")
            cols.append(jnp.asarray(c))
        scale = d.get("scale", 1.0)
        if isinstance(scale, bool) or not isinstance(scale, (int, float)) or not scale > 0:
            raise ValueError(f"{where}.scale: expected a positive number, got {scale!r}")
        if cols[0].shape != cols[1].shape:
            n = max(cols[0].shape[0], cols[1].shape[0])
            cols = [jnp.broadcast_to(c, (n,)) for c in cols]
        return Checkerboard(cols[0], cols[1], float(scale))
    # "bitmap"
    _expect(d, where, ("type", "file", "image", "wrap", "filter", "raw", "to_uv"))
    wrap = d.get("wrap", "repeat")
    filt = d.get("filter", "bilinear")
    check_choice(wrap, f"{where}.wrap", TEXTURE_WRAP_MODES)
    check_choice(filt, f"{where}.filter", TEXTURE_FILTERS)
    if ("file" in d) == ("image" in d):
        raise ValueError(f"{where}: expected exactly one of 'file' or 'image'")
    if "file" in d:
        path = os.fspath(d["file"])
        if not os.path.isabs(path) and base_dir:
            path = os.path.join(base_dir, path)
        img = _read_bitmap(path, bool(d.get("raw", False)), where)
    else:
        img = np.asarray(as_float_array(d["image"], f"{where}.image"))
    if img.ndim == 2:
        img = img[..., None]
    if img.ndim != 3 or img.shape[-1] not in (1, 3, 4) or min(img.shape[:2]) < 1:
        raise ValueError(f"{where}: expected an (H, W), (H, W, 1|3|4) image, got {img.shape}")
    img = img[..., :3]
    check_finite(img, f"{where}.image")
    to_uv = d.get("to_uv")
    if to_uv is not None:
        to_uv = check_uv_transform(to_uv, f"{where}.to_uv")
    return Texture(jnp.asarray(img), wrap=wrap, filter=filt, to_uv=to_uv)


def texture_min(tex) -> float:
    """Smallest value of a concrete texture (for the loader's range checks)."""
    if isinstance(tex, Checkerboard):
        return float(min(jnp.min(tex.color0), jnp.min(tex.color1)))
    if isinstance(tex, MeshAttribute):  # values live on the meshes (checked by the loader)
        return min(0.0, float(tex.scale))
    return float(jnp.min(tex.image))
