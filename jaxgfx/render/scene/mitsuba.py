"""Export jaxgfx scene descriptions to Mitsuba 3 (``mi.load_dict``) for comparison renders.

Mitsuba 3 is *not* a dependency of jaxgfx: :func:`to_mitsuba_dict` and
:func:`mitsuba_integrator` build plain Python dictionaries without importing it; only
:func:`render_mitsuba` imports ``mitsuba`` (lazily). Install with ``pip install mitsuba``
(3.5 or newer; tested with 3.9.1). The ``llvm_ad_rgb`` variant needs an LLVM Dr.Jit accepts
(e.g. Debian ``libllvm19`` with ``DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1``
set before ``import mitsuba``); ``scalar_rgb`` runs anywhere.

Mapping of conventions (jaxgfx -> Mitsuba 3), each checked by ``tests/render/test_mitsuba.py``:

* camera: ``perspective`` with ``to_world = look_at(origin, target, up)``, same ``fov`` and
  ``fov_axis`` (``thinlens`` with the same ``aperture_radius`` and ``focus_distance`` for a
  thin-lens camera); a matrix camera with an affine ``view_proj_inverse`` -> ``orthographic`` (its
  default ``near_clip``, ``to_world`` from
  :func:`~jaxgfx.render.scene.mitsuba_conventions.orthographic_to_world`; projective ones are
  refused); film ``hdrfilm`` (RGB, float32); ``box`` filter (radius 0.5 only) or
  ``gaussian`` (``stddev``; Mitsuba truncates at 4 stddev, so ``radius`` must be ``4 stddev``)
  or ``tent`` (``radius``) or ``mitchell`` (``B``, ``C``), ``catmullrom``, ``lanczos``
  (``lobes``), ``sample_border`` on for all but the box (jaxgfx's filter importance sampling
  also draws samples outside the image).
* rectangle ``{center, normal, size: [w, h]}`` -> Mitsuba ``rectangle`` (``[-1, 1]^2`` in its
  local xy plane, normal +z) with ``to_world`` columns ``(s w/2, t h/2, n, center)`` where
  ``(s, t, n)`` is the same Duff et al. 2017 frame jaxgfx builds, so uv and normal agree.
* reflection-only materials are shaded on both sides in jaxgfx unless ``one_sided: true``;
  Mitsuba's ``diffuse``, ``conductor``, ``roughconductor``, ``plastic`` and ``roughplastic`` are
  one-sided (black from behind), so a two-sided one is wrapped in ``twosided`` and a one-sided
  one written as it is. ``dielectric`` and ``roughdielectric`` are not
  wrapped. Emitter shapes without a material
  get a black ``diffuse`` (jaxgfx's default) instead of Mitsuba's grey default.
* anisotropic roughness (``alpha_v``) is exported on rectangles only: jaxgfx's tangent is the
  Duff et al. frame around the normal everywhere, Mitsuba's is ``dp/du`` (longitude on spheres,
  the uv map on meshes), so highlights would be rotated (``NotImplementedError``).
* ``eta`` (interior / exterior IOR) -> ``int_ior = eta``, ``ext_ior = 1``. Conductors with
  ``fresnel: none`` (F = 1) -> Mitsuba ``material: none`` (eta 0, k 1: |F| = 1) times
  ``specular_reflectance``; ``fresnel: conductor`` -> ``eta``, ``k``, ``specular_reflectance``;
  ``fresnel: schlick`` and ``phong`` have no Mitsuba 3 counterpart (``NotImplementedError``).
* area lights emit from the front side in both (Mitsuba ``area`` is one-sided); ``point``
  intensity (W/sr), ``constant`` radiance map directly. ``directional`` -> Mitsuba
  ``directional`` with the same ``direction`` (of travel) and ``irradiance``; ``spot`` ->
  ``spot`` with ``to_world = look_at(position, position + direction, up)`` (it points along its
  local +z), the same ``intensity`` (W/sr on the axis), ``cutoff_angle`` and ``beam_width``
  (degrees; the same linear-in-angle falloff, :class:`jaxgfx.render.emitters.SpotLight`).
* ``thindielectric`` -> ``thindielectric`` (``int_ior = eta``, ``ext_ior = 1``, the specular
  factors); ``blendbsdf`` -> ``blendbsdf`` (``weight``, nested ``bsdf_0`` / ``bsdf_1``, each
  one-sided component wrapped in ``twosided`` as jaxgfx shades it on both sides).
* ``envmap``: both map a direction to ``u = atan2(d_x, -d_z) / 2 pi``, ``v = acos(d_y) / pi``
  (y up). Interpolation differs: jaxgfx places texel centres at ``((i + .5) / W, (j + .5) / H)``
  and clamps v, Mitsuba 3 at ``((i + .5) / W, j / (H - 1))`` (rows at the poles). The map is
  therefore re-gridded (:func:`envmap_for_mitsuba`: ``2H + 1`` rows = the jaxgfx texel rows and
  the midpoints between them, plus the clamped pole rows) so that Mitsuba's bilinear lookup
  equals jaxgfx's exactly, and written as an EXR into ``work_dir``. A ``to_world`` rotation is
  written as ``to_world`` (Mitsuba looks up ``to_world^-1 d``, jaxgfx ``to_world^T d``).
* meshes: ``.obj`` / ``.ply`` files go to Mitsuba's ``obj`` / ``ply`` plugins (``face_normals``
  when the file has no vertex normals: jaxgfx then shades flat, Mitsuba would smooth);
  inline ``vertices`` / ``faces`` are written as a PLY into ``work_dir``; ``translate`` /
  ``scale`` become ``to_world``.
* integrators: jaxgfx ``path`` -> Mitsuba ``path`` with the same ``max_depth`` / ``rr_depth``
  convention; ``direct`` -> Mitsuba ``path`` with ``max_depth = 2`` (Mitsuba's ``direct``
  integrator samples differently; both estimators are unbiased for the same image).
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Mapping

import numpy as np

from jaxgfx._checks import check_choice
from jaxgfx.render.parameters import get_path
from jaxgfx.render.scene.mitsuba_conventions import (
    BSDF_TO_MITSUBA,
    DEFAULTS,
    ONE_SIDED_BSDFS,
    envmap_for_mitsuba,
    look_at_matrix,
    orthographic_to_world,
    rectangle_to_world,
    swap_scalar_checkerboard,
)

__all__ = [
    "to_mitsuba_dict",
    "scene_to_desc",
    "mitsuba_integrator",
    "sensor_dict",
    "render_mitsuba",
    "envmap_for_mitsuba",
    "MITSUBA_INSTALL_HINT",
]

MITSUBA_INSTALL_HINT = (
    "Mitsuba 3 is required for this (not a jaxgfx dependency): `pip install mitsuba` "
    "(>= 3.5). For the llvm_ad_rgb variant also install an LLVM Dr.Jit supports, e.g. "
    "`apt-get install libllvm19` and set "
    "DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1 before importing mitsuba."
)


# -------------------------------------------------------------------------------------------
# small helpers


def _rgb(x) -> dict:
    a = np.broadcast_to(np.asarray(x, np.float64), (3,))
    return {"type": "rgb", "value": [float(v) for v in a]}


def _float(x) -> float:
    a = np.asarray(x, np.float64)
    if a.size != 1:
        raise ValueError(f"expected a scalar, got shape {a.shape}")
    return float(a.reshape(()))


def _transform(m, mi):
    m = np.asarray(m, np.float64)
    if mi is None:
        return m.tolist()
    return mi.ScalarTransform4f(m.tolist())


def _frame_from_normal(n):
    """The (s, t) tangents jaxgfx builds for a rectangle's unit normal (Duff et al. 2017)."""
    from jaxgfx.render.geometry.frame import frame_from_normal

    fr = frame_from_normal(np.asarray(n, np.float64))
    return np.asarray(fr.s, np.float64), np.asarray(fr.t, np.float64)


# -------------------------------------------------------------------------------------------
# materials


def _one_sided(bsdf: dict) -> bool:
    """Mitsuba's plugin is black from behind (ONE_SIDED_BSDFS; a principled with
    ``spec_trans`` scatters on both sides)."""
    return bsdf["type"] in ONE_SIDED_BSDFS and "spec_trans" not in bsdf


def _twosided(bsdf: dict) -> dict:
    """``bsdf`` wrapped in ``twosided`` when Mitsuba's plugin is one-sided (:func:`_one_sided`)."""
    return {"type": "twosided", "bsdf": bsdf} if _one_sided(bsdf) else bsdf


def _conductor_fresnel(m, where) -> dict:
    if m.fresnel == "schlick":
        raise NotImplementedError(
            f"{where}.fresnel: 'schlick' has no Mitsuba 3 counterpart (use 'none' or 'conductor')"
        )
    out = {"specular_reflectance": _rgb(m.reflectance)}
    if m.fresnel == "none":
        out["material"] = "none"
    else:
        out["eta"] = _rgb(m.eta)
        out["k"] = _rgb(m.k)
    return out


def _distribution(m, where) -> dict:
    """Mitsuba's distribution and roughness keys of a microfacet BSDF ``m``, read through its
    ``PARAMETER_ALIASES`` (whose names are Mitsuba's): the isotropic alias (``alpha``, which
    sets several fields) when those fields are equal, else the per-axis ones."""
    dist = m.distribution
    out = {"distribution": dist.type, "sample_visible": bool(dist.sample_visible)}
    values = {}
    for name, paths in type(m).PARAMETER_ALIASES.items():
        vs = [np.asarray(get_path(m, p.split("."))) for p in paths]
        if any(v.size != 1 for v in vs):
            raise ValueError(f"{where}.{name}: expected a scalar roughness")
        values[name] = [_float(v) for v in vs]
    shared = {n: v for n, v in values.items() if len(v) > 1}
    if shared and all(len(set(v)) == 1 for v in shared.values()):
        out.update({n: v[0] for n, v in shared.items()})
    else:
        out.update({n: v[0] for n, v in values.items() if len(v) == 1})
    return out


def _dielectric_keys(m):
    """Mitsuba's keys of a (rough) dielectric: the IOR ratio as ``int_ior`` over an exterior of
    1, and the specular reflectance / transmittance factors."""
    return {
        "int_ior": _float(m.eta),
        "ext_ior": 1.0,
        "specular_reflectance": _rgb(m.specular_reflectance),
        "specular_transmittance": _rgb(m.specular_transmittance),
    }


def _material(md, where, base_dir=None, work_dir=None) -> dict:
    """Mitsuba BSDF dict of one jaxgfx material description (validated by ``make_bsdf``)."""

    if not isinstance(md, Mapping):
        raise ValueError(f"{where}: expected a mapping with a 'type' key")
    md = dict(md)
    one_sided = md.pop("one_sided", False)
    if md.get("type") == "phong":
        raise NotImplementedError(f"{where}.type: 'phong' has no Mitsuba 3 counterpart")
    if one_sided is not False:  # checked as the loader checks it
        from jaxgfx.render.scene._materials import check_one_sided, material_from_desc

        try:
            built = material_from_desc(md, where="", base_dir=base_dir)
        except (ValueError, TypeError) as e:
            raise ValueError(f"{where}: {e}") from None
        one_sided = check_one_sided(one_sided, built, f"{where}.one_sided")
    if md.get("type") in _MAP_KEYS:
        out = _map_material(md, where, base_dir, work_dir)
    else:
        out = _twosided(_textured_bsdf(md, where, base_dir, work_dir))
    # a one-sided material: Mitsuba's plugin as it is (black from behind), no twosided
    return _without_twosided(out) if one_sided else out


def _without_twosided(d: dict) -> dict:
    """``d`` without the ``twosided`` wrappers the writer adds (also around a blend's nested
    BSDFs): the Mitsuba dict of a one-sided material."""
    if d["type"] == "twosided":
        return _without_twosided(d["bsdf"])
    if d["type"] == "blendbsdf":
        return {**d, "bsdf_0": _without_twosided(d["bsdf_0"]),
                "bsdf_1": _without_twosided(d["bsdf_1"])}  # fmt: skip
    return d


# Mitsuba's name of a jaxgfx material key that a texture may drive, where they differ
_MITSUBA_TEXTURE_KEY = {("conductor", "reflectance"): "specular_reflectance",
                        ("roughconductor", "reflectance"): "specular_reflectance"}  # fmt: skip
# texturable in jaxgfx, a plain number in Mitsuba 3 (its plugins read these as floats)
_MITSUBA_FLOAT_ONLY = {("roughplastic", "alpha"): "Mitsuba's roughplastic takes a constant alpha",
                       ("roughplastic", "eta"): "Mitsuba's IORs are constants",
                       ("plastic", "eta"): "Mitsuba's IORs are constants",
                       ("dielectric", "eta"): "Mitsuba's IORs are constants",
                       ("roughdielectric", "eta"): "Mitsuba's IORs are constants",
                       ("thindielectric", "eta"): "Mitsuba's IORs are constants",
                       ("principled", "eta"): "Mitsuba's principled eta is a constant",
                       ("principled", "specular"): "Mitsuba's principled specular is a "
                                                   "constant"}  # fmt: skip


def _uv_transforms(d, mi):
    """``d`` with each checkerboard's ``to_uv`` (nested lists) as ``mi.ScalarTransform4f``
    when ``mi`` is given (``load_dict`` wants transform objects; XML is written from lists)."""
    if mi is None or not isinstance(d, dict):
        return d
    return {k: _transform(v, mi) if k == "to_uv" else _uv_transforms(v, mi) for k, v in d.items()}


def _textured_bsdf(md, where, base_dir, work_dir) -> dict:
    """Mitsuba BSDF dict (not wrapped in ``twosided``) of a material description whose
    parameters may be textures: validated and built as :func:`load_scene` builds it
    (``material_from_desc``); each textured key becomes a nested ``bitmap`` / ``checkerboard``
    texture under Mitsuba's name of the parameter (:func:`_texture_dict`)."""
    from jaxgfx.render.bsdf.textured import Textured, is_texture_desc, texturable_paths
    from jaxgfx.render.scene._materials import material_from_desc

    try:
        m = material_from_desc(dict(md), where="", base_dir=base_dir)
    except (ValueError, TypeError) as e:
        raise ValueError(f"{where}: {e}") from None
    if not isinstance(m, Textured):
        return _mitsuba_bsdf(m, where)
    out = _mitsuba_bsdf(m.bsdf, where)
    for k, tex in m.textures.items():
        if (out["type"], k) in _MITSUBA_FLOAT_ONLY:
            raise NotImplementedError(f"{where}.{k}: {_MITSUBA_FLOAT_ONLY[out['type'], k]} "
                                      "(a texture cannot be exported)")  # fmt: skip
        mk = _MITSUBA_TEXTURE_KEY.get((out["type"], k), k)
        if mk not in out:  # pragma: no cover - every texturable key is mapped above
            raise NotImplementedError(f"{where}.{k}: no Mitsuba parameter takes this texture")
        td = md[k] if is_texture_desc(md.get(k)) else None
        out[mk] = _texture_dict(tex, f"{where}.{k}", work_dir, desc=td, base_dir=base_dir)
        if np.ndim(get_path(m.bsdf, texturable_paths(m.bsdf, k)[0])) == 0:  # Mitsuba's eval_1
            out[mk] = swap_scalar_checkerboard(out[mk])
    return out


def _texture_dict(tex, where, work_dir, *, desc=None, base_dir=None) -> dict:
    """Mitsuba texture dict of a jaxgfx texture object (``Texture`` / ``Checkerboard``).

    ``checkerboard``: ``color0`` / ``color1`` (RGB, or a float for one channel) and ``to_uv``
    the uniform scale. ``bitmap``: a file the description names (``desc["file"]``) is
    referenced by absolute path with its ``raw`` flag; texels (an inline ``image`` or a built
    texture) are written into ``work_dir`` as an 8-bit sRGB PNG (``raw`` false: Mitsuba and
    jaxgfx decode it) when that PNG decodes to exactly these texels (a texture read from an
    8-bit sRGB file), else as a float32 EXR (``raw`` true: linear). ``filter_type`` and
    ``wrap_mode`` are the texture's."""
    from jaxgfx.render.bsdf.textured import Checkerboard

    if isinstance(tex, Checkerboard):

        def colour(c):  # noqa: E306
            c = np.asarray(c, np.float64)
            return _float(c) if c.size == 1 else _rgb(c)

        s = float(tex.scale)
        return {"type": "checkerboard", "color0": colour(tex.color0),
                "color1": colour(tex.color1),
                "to_uv": np.diag([s, s, 1.0, 1.0]).tolist()}  # fmt: skip
    out = {"type": "bitmap"}
    if desc is not None and "file" in desc:
        path = os.fspath(desc["file"])
        if not os.path.isabs(path) and base_dir:
            path = os.path.join(base_dir, path)
        out.update(filename=os.path.abspath(path), raw=bool(desc.get("raw", False)))
    else:
        out.update(_write_texels(np.asarray(tex.image, np.float32), where, work_dir))
    out.update(filter_type=tex.filter, wrap_mode=tex.wrap)
    return out


def _write_texels(img, where, work_dir) -> dict:
    """``{filename, raw}`` of ``img`` (linear texels, ``(H, W, C)``) written into ``work_dir``:
    an 8-bit sRGB PNG when reading it back as jaxgfx and Mitsuba read a non-raw PNG gives
    exactly ``img``, else a float32 EXR (read as is: ``raw``)."""
    from jaxgfx.io import write_exr, write_png
    from jaxgfx.render.bsdf.textured import _read_bitmap

    stem = os.path.join(work_dir(), re.sub(r"[^A-Za-z0-9_]+", "_", where).strip("_"))
    if img.size and np.all(img >= 0) and np.all(img <= 1):
        from jaxgfx.color.transfer import linear_to_srgb

        codes = np.round(np.asarray(linear_to_srgb(img), np.float64) * 255).astype(np.uint8)
        write_png(stem + ".png", codes)
        back = _read_bitmap(stem + ".png", False, where)
        back = back[..., None] if back.ndim == 2 else back
        if back.shape == img.shape and np.array_equal(back, img):
            return {"filename": stem + ".png", "raw": False}
        os.remove(stem + ".png")
    write_exr(stem + ".exr", img)
    return {"filename": stem + ".exr", "raw": True}


def _mitsuba_bsdf(m, where) -> dict:
    """Mitsuba BSDF dict of a BSDF object (not yet wrapped in ``twosided``)."""
    kind = BSDF_TO_MITSUBA.get(type(m).__name__)
    if kind == "diffuse":
        out = {"type": kind, "reflectance": _rgb(m.reflectance)}
    elif kind == "conductor":
        out = {"type": kind, **_conductor_fresnel(m, where)}
    elif kind == "roughconductor":
        out = {"type": kind, **_distribution(m, where), **_conductor_fresnel(m, where)}
    elif kind in ("dielectric", "thindielectric"):
        out = {"type": kind, **_dielectric_keys(m)}
    elif kind == "roughdielectric":
        out = {"type": kind, **_distribution(m, where), **_dielectric_keys(m)}
    elif kind == "plastic":
        out = {
            "type": kind,
            "int_ior": _float(m.eta),
            "ext_ior": 1.0,
            "diffuse_reflectance": _rgb(m.diffuse_reflectance),
            "specular_reflectance": _rgb(m.specular_reflectance),
            "nonlinear": bool(m.nonlinear),
        }
    elif kind == "roughplastic":
        dist = _distribution(m, where)
        if "alpha_u" in dist:
            raise NotImplementedError(f"{where}.alpha: Mitsuba's roughplastic is isotropic")
        out = {
            "type": kind,
            **dist,
            "int_ior": _float(m.eta),
            "ext_ior": 1.0,
            "diffuse_reflectance": _rgb(m.diffuse_reflectance),
            "specular_reflectance": _rgb(m.specular_reflectance),
            "nonlinear": bool(m.nonlinear),
        }
    elif kind == "pplastic":  # eta written as such: Mitsuba's pplastic takes it (a texture too)
        out = {"type": kind, **_distribution(m, where), "eta": _float(m.eta),
               "diffuse_reflectance": _rgb(m.diffuse_reflectance),
               "specular_reflectance": _rgb(m.specular_reflectance)}  # fmt: skip
    elif kind == "circular":
        out = {"type": kind, "transmittance": _rgb(m.transmittance),
               "left_handed": bool(m.left_handed)}  # fmt: skip
    elif kind in ("polarizer", "retarder"):
        out = {"type": kind, "transmittance": _rgb(m.transmittance), "theta": _float(m.theta)}
        if kind == "polarizer":
            out["polarizing"] = bool(m.polarizing)
        else:
            out["delta"] = _float(m.delta)
    elif kind == "blendbsdf":
        # Mitsuba orders the nested BSDFs by name (bsdf_0, bsdf_1; unnamed in XML: document
        # order). Each one-sided component is wrapped in twosided: jaxgfx shades it on both
        # sides, also inside a transmissive blend (BlendBSDF mirrors it below the surface).
        out = {
            "type": kind,
            "weight": _float(m.weight),
            "bsdf_0": _twosided(_mitsuba_bsdf(m.bsdf0, f"{where}.bsdf0")),
            "bsdf_1": _twosided(_mitsuba_bsdf(m.bsdf1, f"{where}.bsdf1")),
        }
    elif kind == "mask":
        # jaxgfx shades a reflection-only nested BSDF on both sides: twosided in Mitsuba
        out = {"type": kind, "opacity": _float(m.opacity),
               "bsdf": _twosided(_mitsuba_bsdf(m.bsdf, f"{where}.bsdf"))}  # fmt: skip
    elif kind == "null":
        out = {"type": kind}
    elif kind == "hair":
        out = {"type": kind, "int_ior": _float(m.eta), "ext_ior": 1.0,
               **{k: _float(getattr(m, k)) for k in HAIR_SCALARS}}  # fmt: skip
        if m.sigma_a is None:
            out.update(eumelanin=_float(m.eumelanin), pheomelanin=_float(m.pheomelanin))
        else:
            out.update(sigma_a=_rgb(m.sigma_a), scale=_float(m.scale))
    elif kind in ("principled", "principledthin"):
        out = _principled_keys(m, where)
    elif kind == "measured":
        out = {"type": kind, "filename": _measured_file(m, where)}
    else:
        raise NotImplementedError(f"{where}.type: {type(m).__name__} has no Mitsuba 3 mapping")
    return out


def _measured_file(m, where) -> str:
    """The ``.bsdf`` file of a ``Measured`` (absolute path), refused when its ``rgb`` is no
    longer the file's (a fit: write it with ``write_measured(path, m.tables())``)."""
    from jaxgfx.render.bsdf import read_measured

    if m.filename is None:
        raise NotImplementedError(
            f"{where}: a Measured built from tables has no file; write one with "
            "jaxgfx.render.bsdf.write_measured"
        )
    if not np.array_equal(np.asarray(m.rgb, np.float32), read_measured(m.filename)["rgb"]):
        raise NotImplementedError(
            f"{where}.rgb: differs from the table of {m.filename}; write it with "
            "write_measured(path, m.tables()) and use that file"
        )
    return m.filename


_MAP_KEYS = {"normalmap": "normalmap", "bumpmap": "height"}
HAIR_SCALARS = ("longitudinal_roughness", "azimuthal_roughness", "scale_tilt")
_MAP_FLAGS = ("flip_invalid_normals", "use_shadowing_function")


def _map_material(md, where, base_dir, work_dir) -> dict:
    """Mitsuba ``normalmap`` / ``bumpmap`` dict of a description (validated by the loader):
    the map as a ``bitmap`` texture (a file the description names is referenced by absolute
    path with its ``raw`` flag; an inline image or a constant is written to ``work_dir`` as a
    float EXR, ``raw``), the nested BSDF (not textured), ``scale`` and both options; wrapped in
    ``twosided`` when the nested BSDF is one-sided in Mitsuba (jaxgfx shades both sides)."""
    from jaxgfx.render import bsdf as B
    from jaxgfx.render.bsdf.textured import is_texture_desc, texture_from_dict
    from jaxgfx.render.scene._materials import material_from_desc

    kind, key = md["type"], _MAP_KEYS[md["type"]]
    nested = md.get("bsdf")
    if not isinstance(nested, Mapping):
        raise ValueError(f"{where}.bsdf: {kind!r} needs a nested material description")
    tex_d = md.get(key)
    try:
        tex = tex_d
        if is_texture_desc(tex_d):
            ch = 3 if kind == "normalmap" else 1
            tex = texture_from_dict(tex_d, f"{where}.{key}", base_dir=base_dir, channels=ch)
        built = material_from_desc(dict(nested), where="bsdf", base_dir=base_dir)
        m = B.make_bsdf({**md, "bsdf": built, key: tex})
    except (ValueError, TypeError) as e:
        raise ValueError(f"{where}: {e}") from None
    inner = _textured_bsdf(nested, f"{where}.bsdf", base_dir, work_dir)  # may be textured
    tex = getattr(m, key)
    if is_texture_desc(tex_d) and "file" in tex_d:
        path = os.fspath(tex_d["file"])
        if not os.path.isabs(path) and base_dir:
            path = os.path.join(base_dir, path)
        bitmap = {"type": "bitmap", "filename": os.path.abspath(path),
                  "raw": bool(tex_d.get("raw", False))}  # fmt: skip
    else:
        from jaxgfx.io import write_exr

        img = np.asarray(getattr(tex, "image", tex), np.float32)
        img = img.reshape(1, 1, -1) if img.ndim == 1 else img
        path = os.path.join(work_dir(), re.sub(r"[^A-Za-z0-9_]", "_", where) + ".exr")
        write_exr(path, img)
        bitmap = {"type": "bitmap", "filename": path, "raw": True}
    if hasattr(tex, "image"):
        bitmap.update(filter_type=tex.filter, wrap_mode=tex.wrap)
    out = {"type": kind, key: bitmap, "bsdf": inner}
    if kind == "bumpmap":
        out["scale"] = _float(m.scale)
    out.update({k: bool(getattr(m, k)) for k in _MAP_FLAGS})
    return {"type": "twosided", "bsdf": out} if _one_sided(inner) else out


PRINCIPLED_WEIGHTS = ("roughness", "metallic", "spec_tint", "anisotropic", "sheen", "sheen_tint",
                      "flatness", "clearcoat", "clearcoat_gloss")  # fmt: skip
PRINCIPLED_RATES = ("diffuse_reflectance_sampling_rate", "main_specular_sampling_rate",
                    "clearcoat_sampling_rate")  # fmt: skip
THIN_WEIGHTS = ("roughness", "eta", "spec_tint", "anisotropic", "sheen", "sheen_tint", "flatness")
THIN_RATES = (
    "diffuse_reflectance_sampling_rate",
    "specular_reflectance_sampling_rate",
    "specular_transmittance_sampling_rate",
    "diffuse_transmittance_sampling_rate",
)
# lobes present only when given (None: absent)
PRINCIPLED_OPTIONAL = {"principled": ("spec_trans",),
                       "principledthin": ("spec_trans", "diff_trans")}  # fmt: skip


def _principled_parts(m):
    """``(kind, weights, rates, optional lobes)`` of a Principled / PrincipledThin."""
    from jaxgfx.render import bsdf as B

    if isinstance(m, B.PrincipledThin):
        return "principledthin", THIN_WEIGHTS, THIN_RATES, PRINCIPLED_OPTIONAL["principledthin"]
    ior = "specular" if m.specular is not None else "eta"
    return ("principled", (*PRINCIPLED_WEIGHTS, ior), PRINCIPLED_RATES,
            PRINCIPLED_OPTIONAL["principled"])  # fmt: skip


def _principled_keys(m, where) -> dict:
    """Mitsuba's ``principled`` / ``principledthin`` keys of a
    :class:`~jaxgfx.render.bsdf.Principled` / :class:`~jaxgfx.render.bsdf.PrincipledThin`
    (same names; ``eta`` or ``specular``, whichever the material holds; ``spec_trans`` /
    ``diff_trans`` only where the lobe is present)."""
    kind, weights, rates, optional = _principled_parts(m)
    out = {"type": kind, "base_color": _rgb(m.base_color)}
    try:
        out.update({k: _float(getattr(m, k)) for k in weights})
        out.update({k: _float(getattr(m, k)) for k in optional if getattr(m, k) is not None})
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None
    out.update({k: getattr(m, k) for k in rates})
    return out


# -------------------------------------------------------------------------------------------
# shapes


def _shape_file(d, where, base_dir, work_dir, ext, write) -> str:
    """The absolute path of a file-backed shape (curves, SDF grid): ``d["filename"]`` resolved
    against ``base_dir``, or inline data written by ``write(path)`` to ``work_dir()`` under a
    name made from ``where`` and ``ext``."""
    if "filename" in d:
        path = os.fspath(d["filename"])
        if not os.path.isabs(path) and base_dir:
            path = os.path.join(base_dir, path)
        return os.path.abspath(path)
    name = re.sub(r"[^A-Za-z0-9]+", "_", where).strip("_")
    path = os.path.join(work_dir(), f"{name}{ext}")
    write(path)
    return path


def _shape(d, where, base_dir, work_dir, mi) -> dict:
    from jaxgfx.render.scene import schema as S

    if not isinstance(d, Mapping) or "type" not in d:
        raise ValueError(f"{where}: expected a mapping with a 'type' key")
    kind = check_choice(d["type"], f"{where}.type", S.SHAPE_TYPES)
    common = ("type", "material", "id")
    if kind == "sdf":
        raise NotImplementedError(f"{where}.type: SDF shapes have no Mitsuba 3 counterpart")
    if kind == "sphere":
        S.expect_keys(d, where, ("type", "center", "radius"), (*common, "frame"))
        c = np.asarray(S.vec(d["center"], f"{where}.center"), np.float64)
        r = float(S.num(d["radius"], f"{where}.radius", positive=True))
        if d.get("frame") is None:
            return {"type": "sphere", "center": c.tolist(), "radius": r}
        S.shape_from_desc(d, where, base_dir)  # validates the frame as load_scene does
        m = np.eye(4)  # Mitsuba: to_world = translate(c) . frame . scale(r)
        m[:3, :3] = np.asarray(d["frame"], np.float64) * r
        m[:3, 3] = c
        return {"type": "sphere", "to_world": _transform(m, mi)}
    if kind in ("linearcurve", "bsplinecurve"):  # a curve text file (written for inline curves)
        from jaxgfx.render.geometry import write_curves

        S.shape_from_desc(d, where, base_dir)  # validated as load_scene does
        path = _shape_file(d, where, base_dir, work_dir, ".txt",
                           lambda p: write_curves(p, d["curves"]))  # fmt: skip
        out = {"type": kind, "filename": path}
        if "to_world" in d:
            out["to_world"] = _transform(np.asarray(d["to_world"], np.float64), mi)
        return out
    if kind == "ellipsoids":  # a PLY file (written for inline ellipsoids), extent, ...
        from jaxgfx.render.geometry import write_ellipsoids_ply
        from jaxgfx.render.scene._ellipsoids import ellipsoids_arrays

        c, s, q, extent = ellipsoids_arrays(d, where, base_dir, S._read_shape_file)
        if "filename" not in d and np.any(s == 0):
            raise NotImplementedError(f"{where}.scales: a scale of 0 has no Mitsuba PLY form "
                                      "(ln 0; Mitsuba's reader clamps to 1e-6)")  # fmt: skip
        path = _shape_file(d, where, base_dir, work_dir, ".ply",
                           lambda p: write_ellipsoids_ply(p, c, s, q))  # fmt: skip
        out = {"type": "ellipsoids", "filename": path, "extent": extent}
        if "scale_factor" in d:
            out["scale_factor"] = float(d["scale_factor"])
        if "to_world" in d:
            out["to_world"] = _transform(np.asarray(d["to_world"], np.float64), mi)
        return out
    if kind == "sdfgrid":  # Mitsuba's sdfgrid: a .vol file (written for inline values)
        from jaxgfx.render.geometry import write_vol

        S.shape_from_desc(d, where, base_dir)  # validated as load_scene does
        path = _shape_file(d, where, base_dir, work_dir, ".vol",
                           lambda p: write_vol(p, np.asarray(d["values"], np.float32)))  # fmt: skip
        out = {"type": "sdfgrid", "filename": path, "normals": d.get("normals", "smooth")}
        if "to_world" in d:
            out["to_world"] = _transform(np.asarray(d["to_world"], np.float64), mi)
        return out
    if kind == "rectangle":
        if "edge_u" in d or "edge_v" in d:
            S.expect_keys(d, where, ("type", "center", "edge_u", "edge_v"), common)
        else:
            S.expect_keys(d, where, ("type", "center", "normal"), (*common, "size"))
        r = S.rectangle_from_desc(d, where)  # validated as load_scene does
        m = rectangle_to_world(r.centers[0], r.edge_u[0], r.edge_v[0])
        return {"type": "rectangle", "to_world": _transform(m, mi)}
    # "mesh"
    sources = ("file", "vertices", "faces", "normals", "uvs", "generator")
    S.expect_keys(d, where, ("type",), (*common, *sources, "translate", "scale", "to_world"))
    from jaxgfx.render.geometry import mesh_io

    # validated exactly as load_scene does (the untransformed mesh: to_world is Mitsuba's)
    m = S.mesh_from_desc({k: d[k] for k in sources if k in d}, where, base_dir)
    if "file" in d:
        path = os.fspath(d["file"])
        if not os.path.isabs(path) and base_dir:
            path = os.path.join(base_dir, path)
        ext = os.path.splitext(path)[1].lower()
        out = {"type": ext[1:], "filename": os.path.abspath(path)}
        if ext == ".obj":  # jaxgfx reads the file's v as is; Mitsuba flips it by default
            out["flip_tex_coords"] = False
    else:  # inline or generated: written as a PLY (with its normals and uvs)
        name = re.sub(r"[^A-Za-z0-9]+", "_", where).strip("_")
        path = os.path.join(work_dir(), f"{name}.ply")
        mesh_io.save_ply(path, m)
        out = {"type": "ply", "filename": path}
    out["face_normals"] = m.normals is None
    mat = np.eye(4)
    if "translate" in d or "scale" in d:
        sc = np.broadcast_to(np.asarray(d.get("scale", 1.0), np.float64), (3,))
        tr = np.asarray(S.vec(d.get("translate", [0.0, 0.0, 0.0]), f"{where}.translate"))
        mat = np.diag([*sc, 1.0])
        mat[:3, 3] = tr
    if "to_world" in d:  # applied after translate / scale (as schema.mesh_from_desc)
        S.mesh_from_desc({"vertices": [[0.0, 0, 0]], "faces": [[0, 0, 0]],
                          "to_world": d["to_world"]}, where, None)  # fmt: skip
        mat = np.asarray(d["to_world"], np.float64) @ mat
    if not np.allclose(mat, np.eye(4)):
        out["to_world"] = _transform(mat, mi)
    return out


def _instances(d, where, i, base_dir, work_dir, mi, material_of, default) -> dict:
    """``{type: instances}`` -> a ``shapegroup`` ``group_I`` of the member shapes and one
    ``instance`` ``instance_I_K`` per matrix referring to it (nothing for an empty group)."""
    from jaxgfx.render.geometry.instance import check_instance_transforms
    from jaxgfx.render.scene import schema as S

    S.expect_keys(d, where, ("type", "shapes", "to_world"))
    if not isinstance(d["shapes"], (list, tuple)):
        raise ValueError(f"{where}.shapes: expected a list of shape descriptions")
    if not d["shapes"] or (isinstance(d["to_world"], (list, tuple)) and not d["to_world"]):
        return {}
    mats = check_instance_transforms(d["to_world"], f"{where}.to_world")
    group = {"type": "shapegroup"}
    for j, sd in enumerate(d["shapes"]):
        w = f"{where}.shapes[{j}]"
        if isinstance(sd, Mapping) and sd.get("type") == "instances":
            raise ValueError(f"{w}: nested instancing is not supported (as in Mitsuba 3)")
        sh = _shape(sd, w, base_dir, work_dir, mi)
        sh["bsdf"] = material_of(sd, w, default, sd["type"])
        group[f"shape_{j}"] = sh
    out = {f"group_{i}": group}
    for k, m in enumerate(mats):
        out[f"instance_{i}_{k}"] = {"type": "instance",
                                    "shapegroup": {"type": "ref", "id": f"group_{i}"},
                                    "to_world": _transform(m, mi)}  # fmt: skip
    return out


class _WorkDir:
    """The folder for generated files, created on first use (a temp folder when None)."""

    def __init__(self, path):
        self.path = None if path is None else os.fspath(path)

    def __call__(self) -> str:
        if self.path is None:
            self.path = tempfile.mkdtemp(prefix="jaxgfx_mitsuba_")
        os.makedirs(self.path, exist_ok=True)
        return self.path


# -------------------------------------------------------------------------------------------
# public API


def _image_sensor(cam, where, mi) -> dict:
    """The Mitsuba sensor (without film and sampler) of a validated perspective, thin-lens or
    affine matrix camera description: ``perspective`` / ``thinlens`` / ``orthographic``."""
    if "view_proj_inverse" in cam:  # Mitsuba's default near_clip, where the rays start
        ortho = orthographic_to_world(cam["view_proj_inverse"], cam["width"], cam["height"],
                                      DEFAULTS["near_clip"])  # fmt: skip
        if ortho is None:
            raise NotImplementedError(
                f"{where}.view_proj_inverse: a projective matrix camera has no Mitsuba sensor "
                "(look-at cameras and affine matrix cameras, as `orthographic`, are exported)"
            )
        return {"type": "orthographic", "to_world": _transform(ortho, mi)}
    sensor = {
        "type": "perspective",
        "fov": float(cam["fov"]),
        "fov_axis": str(cam.get("fov_axis", "x")),
        "to_world": _transform(
            look_at_matrix(cam["origin"], cam["target"], cam.get("up", [0.0, 1.0, 0.0])), mi
        ),
    }
    if "aperture_radius" in cam:  # a thin lens (validated: both keys)
        sensor["type"] = "thinlens"
        sensor["aperture_radius"] = float(cam["aperture_radius"])
        sensor["focus_distance"] = float(cam["focus_distance"])
    return sensor


def to_mitsuba_dict(desc, *, base_dir=None, work_dir=None, mi=None, refs=False) -> dict:
    """Convert a jaxgfx scene description into a Mitsuba 3 ``load_dict`` dictionary.

    ``desc``: the mapping or YAML path :func:`jaxgfx.render.scene.load_scene` accepts (relative
    mesh / envmap files are resolved against ``base_dir``, default the YAML's folder).
    ``work_dir``: folder for files Mitsuba needs that the description does not provide (the
    re-gridded environment map, PLYs of inline meshes); a fresh temporary folder by default.
    ``mi``: the imported ``mitsuba`` module (with a variant set) to wrap 4x4 transforms in
    ``mi.ScalarTransform4f``; without it transforms are nested lists (row-major, column vectors)
    and this function imports nothing from Mitsuba. ``refs``: every material becomes a
    top-level BSDF keyed by its name, referenced by the shapes (``{"type": "ref", "id":
    name}``; what :func:`jaxgfx.render.scene.mitsuba_xml.save_scene` writes); else each shape
    holds a copy of its BSDF.

    Returns ``{"type": "scene", "sensor": ..., "<shape or emitter id>": ...}`` without an
    integrator (see :func:`mitsuba_integrator`). The sensor's sampler has ``sample_count`` 16;
    :func:`render_mitsuba` passes ``spp`` explicitly. Conventions mapped: see the module
    docstring. Unknown keys raise ``ValueError`` naming the field; features Mitsuba 3 lacks
    (``phong``, Schlick Fresnel, projective matrix cameras, box filters with radius != 0.5, Gaussian
    filters not truncated at 4 stddev) raise ``NotImplementedError`` naming the field.

    Example: ``to_mitsuba_dict(desc)["sensor"]["fov"] == desc["camera"]["fov"]``.
    """
    from jaxgfx.render.scene import schema as S

    if isinstance(desc, (str, os.PathLike)):
        from jaxgfx.config import read_yaml

        base_dir = base_dir or os.path.dirname(os.path.abspath(os.fspath(desc)))
        desc = read_yaml(desc)
    S.expect_keys(desc, "scene", ("camera", "shapes"), ("materials", "emitters", "film"))
    work_dir = _WorkDir(work_dir)

    # -- sensor
    cam = desc["camera"]
    meter = cam.get("type") if isinstance(cam, Mapping) else None
    subs = None
    if meter == "batch":  # each camera's sensor (Mitsuba sizes their films width / N x height)
        bc = S.build_camera(cam)  # validated as load_scene does
        subs = {f"sensor_{i}": _image_sensor(c, f"camera.cameras.{i}", mi)
                for i, c in enumerate(cam["cameras"])}  # fmt: skip
        cam = {"width": bc.width, "height": bc.height}
    elif meter is not None:
        S.build_camera(cam, base_dir=base_dir)  # validated as load_scene does
        cam = {**cam, "width": 1, "height": 1}
    else:
        # validate exactly as load_scene does (keys, fov range, resolution, degenerate look-at,
        # a thin lens's aperture and focus)
        S.build_camera(cam)
    film_d = desc.get("film", {}) or {}
    S.expect_keys(film_d, "film", (), S.FILM_KEYS)
    fname = film_d.get("filter", "box")
    from jaxgfx.render.film import make_filter

    rf = make_filter(fname, **{k: v for k, v in film_d.items() if k != "filter"})
    film = {
        "type": "hdrfilm",
        "width": int(cam["width"]),
        "height": int(cam["height"]),
        "pixel_format": "rgb",
        "component_format": "float32",
    }
    if fname == "box":
        if float(rf.radius) != 0.5:
            raise NotImplementedError("film.radius: Mitsuba's box filter has radius 0.5 only")
        film["rfilter"] = {"type": "box"}
    elif fname == "tent":
        film["rfilter"] = {"type": "tent", "radius": float(rf.radius)}
        film["sample_border"] = True  # as for the Gaussian: jaxgfx samples beyond the border
    elif fname == "mitchell":
        film["rfilter"] = {"type": "mitchell", "B": float(rf.B), "C": float(rf.C)}
        film["sample_border"] = True
    elif fname == "catmullrom":
        film["rfilter"] = {"type": "catmullrom"}
        film["sample_border"] = True
    elif fname == "lanczos":
        film["rfilter"] = {"type": "lanczos", "lobes": int(rf.lobes)}
        film["sample_border"] = True
    else:
        if abs(float(rf.radius) - 4.0 * float(rf.stddev)) > 1e-6 * float(rf.radius):
            raise NotImplementedError(
                "film.radius: Mitsuba's gaussian filter is truncated at 4 stddev; "
                f"got radius {rf.radius} with stddev {rf.stddev}"
            )
        film["rfilter"] = {"type": "gaussian", "stddev": float(rf.stddev)}
        film["sample_border"] = True
    meter_shape = None
    if subs is not None:
        sensor = {"type": "batch", **subs}
    elif meter == "radiancemeter":
        sensor = {"type": "radiancemeter", "origin": [float(x) for x in cam["origin"]],
                  "direction": [float(x) for x in cam["direction"]]}  # fmt: skip
    elif meter == "distant":  # Mitsuba sets the ray origins from the scene's bounds itself
        sensor = {"type": "distant", "direction": [float(x) for x in cam["direction"]]}
        if isinstance(cam["target"], Mapping):  # only sampled: not geometry, as in Mitsuba
            sensor["target"] = _shape(cam["target"], "camera.target", base_dir, work_dir, mi)
            sensor["target"].pop("bsdf", None)
        elif not float(cam.get("radius", 0.0)) > 0:  # a disk: Mitsuba's bounding-sphere disk
            sensor["target"] = [float(x) for x in cam["target"]]
    elif meter == "irradiancemeter":  # nested in its shape, made invisible (null BSDF): the
        # meter's shape is not part of a jaxgfx scene's geometry unless listed in its shapes
        sensor = {"type": "irradiancemeter"}
        meter_shape = _shape(cam["shape"], "camera.shape", base_dir, work_dir, mi)
        meter_shape["bsdf"] = {"type": "null"}
    else:
        sensor = _image_sensor(cam, "camera", mi)
    sensor["film"] = film
    sensor["sampler"] = {"type": "independent", "sample_count": 16}
    out: dict = {"type": "scene", "sensor": sensor}
    if meter_shape is not None:
        meter_shape["sensor"] = out.pop("sensor")
        out["irradiance_meter"] = meter_shape

    # -- materials
    mats_desc = desc.get("materials", {}) or {}
    if not isinstance(mats_desc, Mapping):
        raise ValueError("materials: expected a mapping from names to material descriptions")
    mats = {str(k): _uv_transforms(_material(v, f"materials.{k}", base_dir, work_dir), mi)
            for k, v in mats_desc.items()}  # fmt: skip
    default = _twosided({"type": "diffuse", "reflectance": _rgb(DEFAULTS["diffuse.reflectance"])})
    black = {"type": "diffuse", "reflectance": _rgb(0.0)}

    def material_of(d, where, fallback, shape_type=None):
        name = d.get("material")
        if not name:
            return fallback
        if name not in mats:
            raise ValueError(f"{where}.material: unknown material {name!r}; have {list(mats)}")
        m = mats[name]  # a two-sided material's BSDF is inside its `twosided` wrapper
        inner = m["bsdf"] if m.get("type") == "twosided" else m
        aniso = "alpha_u" in inner or inner.get("anisotropic", 0.0) != 0.0
        if aniso and shape_type in ("sphere", "mesh"):
            # jaxgfx's tangent is the Duff et al. frame around the normal; Mitsuba's is dp/du
            # (longitude on spheres, the uv parametrisation on meshes): rotated highlights.
            raise NotImplementedError(
                f"{where}.material: anisotropic {name!r} on a {shape_type}: the tangent frames "
                "of jaxgfx and Mitsuba differ there (rectangles only)"
            )
        return {"type": "ref", "id": name} if refs else mats[name]

    if refs:
        for name, m in mats.items():
            reserved = name in ("type", "sensor", "integrator")
            if reserved or re.fullmatch(r"(shape|emitter)_\d+", name):
                raise ValueError(f"materials.{name}: the name clashes with a Mitsuba object id")
            out[name] = m

    # -- shapes
    shapes = desc["shapes"]
    if not isinstance(shapes, (list, tuple)):
        raise ValueError("shapes: expected a list")
    if not shapes:
        raise ValueError("shapes: the scene has no geometry")
    given = set()  # the descriptions' ids: unnamed objects' keys avoid them
    for d in [*shapes, *(desc.get("emitters", []) or [])]:
        if isinstance(d, Mapping):
            given |= {d.get("id"), (d.get("shape") or {}).get("id") if d.get("type") == "area"
                      and isinstance(d.get("shape"), Mapping) else None}  # fmt: skip

    def key(d, where, fallback):
        """The object's Mitsuba id: its description's ``id`` (Mitsuba's ids are global: one
        that is also a material's or another object's is refused), else ``fallback`` (made
        unique: ``_`` appended while a description's id or a material has it)."""
        ident = d.get("id") if isinstance(d, Mapping) else None
        if ident is None:
            if fallback is None:
                return None
            while fallback in given or fallback in out:
                fallback += "_"
            return fallback
        from jaxgfx.render.scene.scene import id_problem

        problem = id_problem(ident)
        if problem:
            raise ValueError(f"{where}.id: {problem}")
        if ident in out or ident in ("type", "integrator"):
            raise ValueError(f"{where}.id: {ident!r} is also the id of another Mitsuba "
                             "object (a material, shape or emitter: Mitsuba's ids are "
                             "global)")  # fmt: skip
        return ident

    for i, sd in enumerate(shapes):
        where = f"shapes[{i}]"
        if isinstance(sd, Mapping) and sd.get("type") == "instances":  # shapegroup + instances
            out.update(_instances(sd, where, i, base_dir, work_dir, mi, material_of, default))
            continue
        sh = _shape(sd, where, base_dir, work_dir, mi)
        sh["bsdf"] = material_of(sd, where, default, sd["type"])
        out[key(sd, where, f"shape_{i}")] = sh

    # -- emitters
    em = desc.get("emitters", []) or []
    if not isinstance(em, (list, tuple)):
        raise ValueError("emitters: expected a list")
    n_env = 0
    for i, ed in enumerate(em):
        where = f"emitters[{i}]"
        if not isinstance(ed, Mapping) or "type" not in ed:
            raise ValueError(f"{where}: expected a mapping with a 'type' key")
        kind = check_choice(ed["type"], f"{where}.type", S.EMITTER_TYPES)
        if kind in ("area", "directionalarea"):
            S.expect_keys(ed, where, ("type", "shape", "radiance"), ("material", "id"))
            if isinstance(ed["shape"], Mapping) and "material" in ed["shape"]:
                raise ValueError(f"{where}.shape.material: put 'material' on the emitter")
            sh = _shape(ed["shape"], f"{where}.shape", base_dir, work_dir, mi)
            sh["bsdf"] = material_of(ed, where, black, ed["shape"]["type"])
            rad = (
                _emission(ed["radiance"], where, base_dir, work_dir, mi)
                if kind == "area"
                else _rgb(S.rgb(ed["radiance"], f"{where}.radiance"))
            )
            sh["emitter"] = {"type": kind, "radiance": rad}
            # the shape (the top-level object) by its id, else by the emitter's
            shape_key = ed["shape"].get("id") if isinstance(ed["shape"], Mapping) else None
            top = key(ed["shape"] if shape_key else ed, where, f"emitter_{i}")
            if refs and ed.get("id") not in (None, top):  # the nested <emitter id=...> (XML)
                sh["emitter"]["id"] = key(ed, where, None)
            out[top] = sh
        elif kind == "point":
            S.expect_keys(ed, where, ("type", "position", "intensity"), ("id",))
            out[key(ed, where, f"emitter_{i}")] = {
                "type": "point",
                "position": np.asarray(S.vec(ed["position"], f"{where}.position")).tolist(),
                "intensity": _rgb(S.rgb(ed["intensity"], f"{where}.intensity")),
            }
        elif kind in ("constant", "envmap", "sunsky"):
            n_env += 1
            if n_env > 1:
                raise ValueError(f"{where}: only one environment emitter is supported")
            if kind == "sunsky":
                out[key(ed, where, f"emitter_{i}")] = _sunsky_dict(ed, where, mi)
            elif kind == "constant":
                S.expect_keys(ed, where, ("type", "radiance"), ("id",))
                out[key(ed, where, f"emitter_{i}")] = {
                    "type": "constant",
                    "radiance": _rgb(S.rgb(ed["radiance"], f"{where}.radiance")),
                }
            else:
                img = S.envmap_image(ed, where, base_dir)
                from jaxgfx.io import write_exr

                path = os.path.join(work_dir(), f"envmap_{i}.exr")
                write_exr(path, envmap_for_mitsuba(img))
                scale = S.num(ed.get("scale", 1.0), f"{where}.scale")
                out[key(ed, where, f"emitter_{i}")] = env = {"type": "envmap", "filename": path,
                                                            "scale": float(scale)}  # fmt: skip
                rot = S.envmap_rotation(ed, where)
                if rot is not None:  # Mitsuba looks up to_world^-1 d, as jaxgfx to_world^T d
                    m = np.eye(4)
                    m[:3, :3] = rot
                    env["to_world"] = _transform(m, mi)
        else:  # "directional" / "spot" (check_choice above admits only S.EMITTER_TYPES)
            out[key(ed, where, f"emitter_{i}")] = _delta_light(ed, where, mi, base_dir, work_dir)
    return out


def _sunsky_dict(ed, where, mi) -> dict:
    """Mitsuba ``sunsky`` dict of a jaxgfx description, validated as :func:`load_scene`
    validates it: the description's ``sun_direction`` or location / time keys as given (Mitsuba
    places the sun itself), the other parameters with their defaults made explicit."""
    from jaxgfx.render.scene._sunsky import sunsky_from_desc
    from jaxgfx.render.sunsky import TIME_KEYS

    sky = sunsky_from_desc(ed, where)
    d = {"type": "sunsky"}
    if "sun_direction" in ed:
        d["sun_direction"] = np.asarray(ed["sun_direction"], np.float64).tolist()
    else:
        d.update({k: ed[k] for k in TIME_KEYS if k in ed})
    alb = np.asarray(sky.albedo, np.float64)
    d.update(turbidity=float(sky.turbidity), sun_scale=float(sky.sun_scale),
             sky_scale=float(sky.sky_scale), sun_aperture=float(sky.sun_aperture),
             complex_sun=bool(sky.complex_sun),
             albedo=float(alb[0]) if np.all(alb == alb[0]) else _rgb(alb))  # fmt: skip
    if sky.to_world is not None:
        m = np.eye(4)
        m[:3, :3] = np.asarray(sky.to_world, np.float64)
        d["to_world"] = _transform(m, mi)
    return d


def _emission(rad, where, base_dir, work_dir, mi):
    """Mitsuba ``radiance`` of an area light's description: an ``rgb`` dict, or a ``bitmap`` /
    ``checkerboard`` texture dict (validated and built as :func:`load_scene` builds it)."""
    from jaxgfx.render.bsdf.textured import is_texture_desc
    from jaxgfx.render.scene import schema as S
    from jaxgfx.render.scene._materials import emission_from_desc

    if not is_texture_desc(rad):
        return _rgb(S.rgb(rad, where))
    tex = emission_from_desc(rad, f"{where}.radiance", base_dir=base_dir, rgb=S.rgb)
    out = _texture_dict(tex, f"{where}.radiance", work_dir, desc=rad, base_dir=base_dir)
    if getattr(tex, "to_uv", None) is not None:  # a bitmap's affine uv map (2 x 3)
        (a, b, c), (d, e, f) = tex.to_uv
        out["to_uv"] = [[a, b, 0.0, c], [d, e, 0.0, f], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
    return _uv_transforms(out, mi)


def _delta_light(ed, where, mi, base_dir=None, work_dir=None) -> dict:
    """Mitsuba ``directional`` / ``spot`` / ``projector`` dict of a jaxgfx emitter
    description, validated as :func:`load_scene` validates it (the same light objects are
    built); a spot's projected texture and a projector's irradiance texture as
    :func:`_texture_dict` writes a material's."""
    from jaxgfx.render.emitters import DirectionalLight, SpotLight
    from jaxgfx.render.scene import schema as S
    from jaxgfx.render.scene._lights import SPOT_TEXTURE_KEYS, projector_from_desc, spot_texture

    if ed["type"] == "projector":
        light = projector_from_desc(ed, where, base_dir)
        irr = ed.get("irradiance")
        return _projector_dict(light, mi, work_dir, where, desc=irr if isinstance(irr, dict)
                               else None, base_dir=base_dir)  # fmt: skip
    try:
        if ed["type"] == "directional":
            S.expect_keys(ed, where, ("type", "direction", "irradiance"), ("id",))
            light = DirectionalLight.create(
                S.rgb(ed["irradiance"], f"{where}.irradiance"),
                S.vec(ed["direction"], f"{where}.direction"),
            )
        else:
            S.expect_keys(ed, where, ("type", "position", "direction", "intensity"),
                          ("cutoff_angle", "beam_width", "id", *SPOT_TEXTURE_KEYS))  # fmt: skip
            texture, up = spot_texture(ed, where, base_dir)
            light = SpotLight.create(
                S.vec(ed["position"], f"{where}.position"),
                S.vec(ed["direction"], f"{where}.direction"),
                S.rgb(ed["intensity"], f"{where}.intensity"),
                S.num(ed.get("cutoff_angle", DEFAULTS["spot.cutoff_angle"]),
                      f"{where}.cutoff_angle"),
                None if "beam_width" not in ed else S.num(ed["beam_width"], f"{where}.beam_width"),
                texture=texture, up=up,
            )  # fmt: skip
    except ValueError as e:
        msg = str(e)
        raise ValueError(msg if msg.startswith(where) else f"{where}.{msg}") from None
    # the description's direction normalised in float64 (the light object holds float32)
    out = _delta_light_dict(light, mi, direction=np.asarray(ed["direction"], np.float64))
    if getattr(light, "texture", None) is not None:
        out["texture"] = _texture_dict(light.texture, f"{where}.texture", work_dir,
                                       desc=ed["texture"], base_dir=base_dir)  # fmt: skip
    return out


def _projector_dict(light, mi, work_dir, where, *, desc=None, base_dir=None) -> dict:
    """Mitsuba ``projector`` dict of a :class:`~jaxgfx.render.emitters.ProjectorLight`:
    ``to_world = look_at(position, position + direction, up)`` (the same frame), the horizontal
    ``fov``, ``scale`` and the irradiance (an ``rgb`` for a 1 x 1 texture, else a bitmap)."""
    p = np.asarray(light.position, np.float64)
    fr = np.asarray(light.frame, np.float64)
    img = np.asarray(light.irradiance.image, np.float64)
    if desc is None and img.shape[:2] == (1, 1):
        irr = _rgb(img[0, 0])
    else:
        irr = _texture_dict(light.irradiance, f"{where}.irradiance", work_dir, desc=desc,
                            base_dir=base_dir)  # fmt: skip
    return {"type": "projector", "to_world": _transform(look_at_matrix(p, p + fr[2], fr[1]), mi),
            "fov": _float(light.fov), "fov_axis": "x", "scale": _float(light.scale),
            "irradiance": irr}  # fmt: skip


def _delta_light_dict(light, mi, direction=None) -> dict:
    """Mitsuba dict of a ``DirectionalLight`` / ``SpotLight`` object: the directional light by
    its ``direction`` (Mitsuba's alternative to ``to_world``), the spot light by
    ``to_world = look_at(position, position + direction, up)`` (Mitsuba's spot points along its
    local +z; ``up`` is any perpendicular, the cone is round) and both angles in degrees."""
    from jaxgfx.render.emitters import DirectionalLight

    d = np.asarray(light.direction if direction is None else direction, np.float64)
    d = d / np.linalg.norm(d)
    if isinstance(light, DirectionalLight):
        return {"type": "directional", "direction": d.tolist(),
                "irradiance": _rgb(light.irradiance)}  # fmt: skip
    p = np.asarray(light.position, np.float64)
    up = _frame_from_normal(d)[0] if light.up is None else np.asarray(light.up, np.float64)
    return {
        "type": "spot",
        "to_world": _transform(look_at_matrix(p, p + d, up), mi),
        "intensity": _rgb(light.intensity),
        "cutoff_angle": _float(light.cutoff_angle),
        "beam_width": _float(light.beam_width),
    }


def _list(x):
    return np.asarray(x, np.float64).tolist()


def _texture_desc(tex) -> dict:
    """The description of a texture object (``bitmap`` texels inline)."""
    from jaxgfx.render.bsdf.textured import Checkerboard

    if isinstance(tex, Checkerboard):
        return {"type": "checkerboard", "color0": _list(tex.color0),
                "color1": _list(tex.color1), "scale": float(tex.scale)}  # fmt: skip
    out = {"type": "bitmap", "image": np.asarray(tex.image, np.float32),
           "wrap": tex.wrap, "filter": tex.filter}  # fmt: skip
    if tex.to_uv is not None:
        out["to_uv"] = [list(r) for r in tex.to_uv]
    return out


def _radiance_desc(light):
    """An area light's ``radiance``: an RGB list or a texture description."""
    return _texture_desc(light.radiance) if light.textured else _list(light.radiance)


def _bsdf_desc(m, where) -> dict:
    """The description (``make_bsdf`` keys) of a BSDF object."""
    from jaxgfx.render import bsdf as B
    from jaxgfx.render.bsdf.textured import Textured

    if isinstance(m, Textured):  # the plain BSDF's keys, the textured ones as textures
        from jaxgfx.render.bsdf.textured import Checkerboard

        out = _bsdf_desc(m.bsdf, where)
        for k, tex in m.textures.items():
            if isinstance(tex, Checkerboard):
                out[k] = {"type": "checkerboard", "color0": _list(tex.color0),
                          "color1": _list(tex.color1), "scale": float(tex.scale)}  # fmt: skip
            else:
                out[k] = {"type": "bitmap", "image": np.asarray(tex.image, np.float32),
                          "wrap": tex.wrap, "filter": tex.filter}  # fmt: skip
            if k == "alpha":  # the texture sets both alphas
                out.pop("alpha_v", None)
        return out
    if isinstance(m, B.Diffuse):
        return {"type": "diffuse", "reflectance": _list(m.reflectance)}
    conductor = {}
    if isinstance(m, (B.Mirror, B.RoughConductor)):
        conductor = {"reflectance": _list(m.reflectance), "fresnel": m.fresnel}
        if m.eta is not None:
            conductor["eta"] = _list(m.eta)
        if m.k is not None:
            conductor["k"] = _list(m.k)
    if isinstance(m, B.Mirror):
        return {"type": "conductor", **conductor}
    if isinstance(m, (B.RoughConductor, B.RoughPlastic)):
        dist = m.distribution
        micro = {"distribution": dist.type, "alpha": _list(dist.alpha_u),
                 "sample_visible": bool(dist.sample_visible)}  # fmt: skip
        if isinstance(m, B.RoughConductor):
            return {"type": "roughconductor", **micro, "alpha_v": _list(dist.alpha_v), **conductor}
        return {"type": "roughplastic", **micro, "eta": _list(m.eta),
                "diffuse_reflectance": _list(m.diffuse_reflectance),
                "specular_reflectance": _list(m.specular_reflectance),
                "nonlinear": bool(m.nonlinear)}  # fmt: skip
    if isinstance(m, B.PolarizedPlastic):
        dist = m.distribution
        return {"type": "pplastic", "distribution": dist.type, "alpha": _list(dist.alpha_u),
                "alpha_v": _list(dist.alpha_v), "sample_visible": bool(dist.sample_visible),
                "eta": _list(m.eta), "diffuse_reflectance": _list(m.diffuse_reflectance),
                "specular_reflectance": _list(m.specular_reflectance)}  # fmt: skip
    if isinstance(m, B.Polarizer):
        return {"type": "polarizer", "transmittance": _list(m.transmittance),
                "theta": _list(m.theta), "polarizing": bool(m.polarizing)}  # fmt: skip
    if isinstance(m, B.CircularPolarizer):
        return {"type": "circular", "transmittance": _list(m.transmittance),
                "left_handed": bool(m.left_handed)}  # fmt: skip
    if isinstance(m, B.Retarder):
        return {"type": "retarder", "transmittance": _list(m.transmittance),
                "theta": _list(m.theta), "delta": _list(m.delta)}  # fmt: skip
    if isinstance(m, B.RoughDielectric):
        dist = m.distribution
        return {"type": "roughdielectric", "distribution": dist.type,
                "alpha": _list(dist.alpha_u), "alpha_v": _list(dist.alpha_v),
                "sample_visible": bool(dist.sample_visible), "eta": _list(m.eta),
                "specular_reflectance": _list(m.specular_reflectance),
                "specular_transmittance": _list(m.specular_transmittance)}  # fmt: skip
    if isinstance(m, B.SmoothPlastic):
        return {"type": "plastic", "eta": _list(m.eta),
                "diffuse_reflectance": _list(m.diffuse_reflectance),
                "specular_reflectance": _list(m.specular_reflectance),
                "nonlinear": bool(m.nonlinear)}  # fmt: skip
    if isinstance(m, B.ThinDielectric):
        return {"type": "thindielectric", "eta": _list(m.eta),
                "specular_reflectance": _list(m.specular_reflectance),
                "specular_transmittance": _list(m.specular_transmittance)}  # fmt: skip
    if isinstance(m, B.BlendBSDF):
        return {"type": "blendbsdf", "weight": _list(m.weight),
                "bsdf0": _bsdf_desc(m.bsdf0, f"{where}.bsdf0"),
                "bsdf1": _bsdf_desc(m.bsdf1, f"{where}.bsdf1")}  # fmt: skip
    if isinstance(m, B.Null):
        return {"type": "null"}
    if isinstance(m, B.Mask):
        return {"type": "mask", "opacity": _list(m.opacity),
                "bsdf": _bsdf_desc(m.bsdf, f"{where}.bsdf")}  # fmt: skip
    if isinstance(m, (B.NormalMap, B.BumpMap)):
        kind = "normalmap" if isinstance(m, B.NormalMap) else "bumpmap"
        key = _MAP_KEYS[kind]
        tex = getattr(m, key)
        td = (_list(tex) if not hasattr(tex, "image") else
              {"type": "bitmap", "image": np.asarray(tex.image, np.float32), "wrap": tex.wrap,
               "filter": tex.filter})  # fmt: skip
        out = {"type": kind, "bsdf": _bsdf_desc(m.bsdf, f"{where}.bsdf"), key: td}
        if kind == "bumpmap":
            out["scale"] = _float(m.scale)
        return {**out, **{k: bool(getattr(m, k)) for k in _MAP_FLAGS}}
    if isinstance(m, (B.Principled, B.PrincipledThin)):
        kind, weights, rates, optional = _principled_parts(m)
        out = {"type": kind, "base_color": _list(m.base_color)}
        out.update({k: _list(getattr(m, k)) for k in weights})
        out.update({k: _list(getattr(m, k)) for k in optional if getattr(m, k) is not None})
        return {**out, **{k: getattr(m, k) for k in rates}}
    if isinstance(m, B.Measured):
        return {"type": "measured", "filename": _measured_file(m, where)}
    if isinstance(m, B.Hair):
        out = {
            "type": "hair",
            "eta": _list(m.eta),
            **{k: _list(getattr(m, k)) for k in HAIR_SCALARS},
        }
        if m.sigma_a is None:
            return {**out, "eumelanin": _list(m.eumelanin), "pheomelanin": _list(m.pheomelanin)}
        return {**out, "sigma_a": _list(m.sigma_a), "scale": _list(m.scale)}
    if isinstance(m, B.SmoothDielectric):
        return {"type": "dielectric", "eta": _list(m.eta),
                "specular_reflectance": _list(m.specular_reflectance),
                "specular_transmittance": _list(m.specular_transmittance)}  # fmt: skip
    raise NotImplementedError(f"{where}: {type(m).__name__} has no Mitsuba 3 mapping")


def scene_to_desc(scene) -> dict:
    """A description (what :func:`jaxgfx.render.scene.load_scene` takes) of a built
    :class:`~jaxgfx.render.scene.Scene`, with its current parameter values: a fitted scene can
    be saved (:func:`jaxgfx.render.scene.mitsuba_xml.save_scene`) or exported. Spheres and
    rectangles become one shape each (rectangles by ``edge_u`` / ``edge_v``), a mesh one
    inline mesh per material it uses, the loader's own ``__default__`` / ``__black__``
    materials ``jaxgfx_default`` / ``jaxgfx_black``, a matrix camera its ``view_proj_inverse``.
    Normal and bump maps keep their texture as an inline image. SDF shapes, Phong and textured
    materials (also inside a normal or bump map) raise ``NotImplementedError`` naming the object.
    Host function.

    Example: ``load_scene(scene_to_desc(load_scene(desc)))`` renders like ``desc``.
    """
    from jaxgfx.render.camera import (
        BatchCamera,
        DistantSensor,
        IrradianceMeter,
        MatrixCamera,
        PerspectiveCamera,
        RadianceMeter,
        ThinLensCamera,
    )
    from jaxgfx.render.emitters import (
        ConstantEnvironment,
        DirectionalAreaLight,
        DirectionalLight,
        ProjectorLight,
    )
    from jaxgfx.render.film import (
        CatmullRomFilter,
        GaussianFilter,
        LanczosFilter,
        MitchellFilter,
        TentFilter,
    )
    from jaxgfx.render.geometry import (
        BSplineCurves,
        Ellipsoids,
        Instances,
        LinearCurves,
        Rectangles,
        SDFGridShape,
        Spheres,
        TriangleMesh,
    )
    from jaxgfx.render.sunsky import SunSky

    def image_camera(cam):
        if isinstance(cam, MatrixCamera):
            return {"view_proj_inverse": _list(cam.view_proj_inverse), "width": int(cam.width),
                    "height": int(cam.height)}  # fmt: skip
        cam_d = {"origin": _list(cam.origin), "target": _list(cam.target), "up": _list(cam.up),
                 "fov": float(cam.fov), "fov_axis": cam.fov_axis, "width": int(cam.width),
                 "height": int(cam.height)}  # fmt: skip
        if isinstance(cam, ThinLensCamera):
            cam_d["aperture_radius"] = float(cam.aperture_radius)
            cam_d["focus_distance"] = float(cam.focus_distance)
        return cam_d

    cam = scene.camera
    if isinstance(cam, (MatrixCamera, PerspectiveCamera, ThinLensCamera)):
        cam_d = image_camera(cam)
    elif isinstance(cam, BatchCamera):
        cam_d = {"type": "batch", "cameras": [image_camera(c) for c in cam.cameras]}
    elif isinstance(cam, RadianceMeter):
        cam_d = {"type": "radiancemeter", "origin": _list(cam.origin),
                 "direction": _list(cam.direction)}  # fmt: skip
    elif isinstance(cam, IrradianceMeter):
        cam_d = {"type": "irradiancemeter"}  # its shape: below, once `one` is defined
    elif isinstance(cam, DistantSensor):  # a shape target: below, once `one` is defined
        cam_d = {"type": "distant", "direction": _list(cam.direction),
                 "target": _list(cam.target), "distance": float(cam.distance)}  # fmt: skip
        if cam.shape is None and cam.lens_uniforms:
            cam_d["radius"] = float(cam.radius)
    else:  # pragma: no cover - a Scene holds one of the three
        raise NotImplementedError(f"camera: {type(cam).__name__} has no Mitsuba 3 mapping")
    desc = {
        "camera": cam_d,
        "materials": {},
        "shapes": [],
        "emitters": [],
    }
    rf = scene.rfilter
    if isinstance(rf, GaussianFilter):
        desc["film"] = {"filter": "gaussian", "stddev": float(rf.stddev),
                        "radius": float(rf.radius)}  # fmt: skip
    elif isinstance(rf, TentFilter):
        desc["film"] = {"filter": "tent", "radius": float(rf.radius)}
    elif isinstance(rf, MitchellFilter):
        desc["film"] = {"filter": "mitchell", "B": float(rf.B), "C": float(rf.C)}
    elif isinstance(rf, CatmullRomFilter):
        desc["film"] = {"filter": "catmullrom"}
    elif isinstance(rf, LanczosFilter):
        desc["film"] = {"filter": "lanczos", "lobes": int(rf.lobes)}
    else:
        desc["film"] = {"filter": "box", "radius": float(rf.radius)}
    internal = {"__default__": "jaxgfx_default", "__black__": "jaxgfx_black"}
    names = [internal.get(n, n) for n in scene.material_names]
    for i, (n, m) in enumerate(zip(names, scene.materials, strict=True)):
        desc["materials"][n] = _bsdf_desc(m, f"materials.{n}")
        if scene.one_sided and scene.one_sided[i]:
            desc["materials"][n]["one_sided"] = True

    def one(shape, mats, where, keep):
        """Shape descriptions of ``shape``, each with a material when ``keep`` says so."""
        mats = np.asarray(mats)
        mesh = getattr(shape, "mesh", shape)
        out = []
        if isinstance(shape, Spheres):
            for j in range(shape.radii.shape[0]):
                d = {"type": "sphere", "center": _list(shape.centers[j]),
                     "radius": float(shape.radii[j])}  # fmt: skip
                if shape.frames is not None:
                    d["frame"] = _list(shape.frames[j])
                out.append((d, mats[j]))
        elif isinstance(shape, (LinearCurves, BSplineCurves)):
            from jaxgfx.render.geometry import curve_lists

            kind = "linearcurve" if isinstance(shape, LinearCurves) else "bsplinecurve"
            out.append(({"type": kind, "curves": curve_lists(shape)}, mats[0]))
        elif isinstance(shape, Ellipsoids):
            out.append(({"type": "ellipsoids", "centers": _list(shape.centers),
                         "scales": _list(shape.scales), "quaternions": _list(shape.quaternions),
                         "extent": shape.extent}, mats[0]))  # fmt: skip
        elif isinstance(shape, SDFGridShape):
            out.append(({"type": "sdfgrid", "values": _list(shape.grid.values),
                         "normals": shape.normals}, mats[0]))  # fmt: skip
        elif isinstance(shape, Rectangles):
            for j in range(shape.centers.shape[0]):
                out.append(({"type": "rectangle", "center": _list(shape.centers[j]),
                             "edge_u": _list(shape.edge_u[j]),
                             "edge_v": _list(shape.edge_v[j])}, mats[j]))  # fmt: skip
        elif isinstance(shape, Instances):  # the group's member, then its matrices
            n = shape.n_prims
            members = one(shape.shape, mats[:n], where, keep)
            return [({"type": "instances", "shapes": [{**d, "material": k} if keep else d],
                      "to_world": _list(shape.to_world)}, None) for d, k in members]  # fmt: skip
        elif isinstance(mesh, TriangleMesh):
            faces = np.asarray(mesh.faces)
            for mi_ in dict.fromkeys(mats.tolist()):
                d = {"type": "mesh", "vertices": _list(mesh.vertices),
                     "faces": faces[mats == mi_].tolist()}  # fmt: skip
                if mesh.normals is not None:
                    d["normals"] = _list(mesh.normals)
                if mesh.uvs is not None:
                    d["uvs"] = _list(mesh.uvs)
                out.append((d, mi_))
        else:
            raise NotImplementedError(f"{where}: {type(shape).__name__} has no Mitsuba 3 mapping")
        return [(d, names[int(k)]) for d, k in out] if keep else [(d, None) for d, _ in out]

    if isinstance(cam, DistantSensor) and cam.shape is not None:
        sh = cam.shape
        n = sh.faces.shape[0] if isinstance(sh, TriangleMesh) else sh.centers.shape[0]
        (cam_d["target"], _), *more = one(sh, np.zeros(n, int), "camera", False)
        if more:  # pragma: no cover - a sphere / rectangle batch of one or a mesh
            raise NotImplementedError("camera.target: one shape per distant sensor")
    if isinstance(cam, IrradianceMeter):
        sh = cam.shape
        n = sh.faces.shape[0] if isinstance(sh, TriangleMesh) else sh.centers.shape[0]
        (cam_d["shape"], _), *more = one(sh, np.zeros(n, int), "camera", False)
        if more:  # pragma: no cover - a sphere / rectangle batch of one or a mesh
            raise NotImplementedError("camera.shape: one shape per irradiance meter")

    # ids (Scene.object_ids): (kind, index, row) -> id
    ids = {(k, i, r): ident for ident, k, i, r, _ in getattr(scene, "object_ids", ())}

    def named(d, kind, index, row=None):
        ident = ids.get((kind, index, row))
        return {**d, "id": ident} if ident is not None else d

    def rows(shape_descs, i):
        """Each row of a sphere / rectangle batch by its own id; a mesh (one description per
        material it uses) by the mesh's id when it is one description."""
        batch = isinstance(scene.shapes[i], (Spheres, Rectangles))
        if not batch and len(shape_descs) > 1:
            return shape_descs
        return [(named(d, "shape", i, j if batch else None), n)
                for j, (d, n) in enumerate(shape_descs)]  # fmt: skip

    lit = {a.shape_index: (j, a) for j, a in enumerate(scene.area_lights)}
    dlit = [e for e in scene.delta_lights if isinstance(e, DirectionalAreaLight)]
    lit.update({a.shape_index: (j, a) for j, a in enumerate(dlit)})
    for i, (shape, mats) in enumerate(zip(scene.shapes, scene.shape_materials, strict=True)):
        if i in lit:
            j, light = lit[i]
            if isinstance(light, DirectionalAreaLight):
                kind, rad = "directionalarea", _list(light.radiance)
            else:
                kind, rad = "area", _radiance_desc(light)
            for d, name in rows(one(shape, mats, f"emitters.{kind}.{i}", True), i):
                e = named({"type": kind, "shape": d, "radiance": rad}, kind, j)
                if name != "jaxgfx_black":
                    e["material"] = name
                desc["emitters"].append(e)
            continue
        for d, name in rows(one(shape, mats, f"shapes.{i}", True), i):
            if d["type"] != "instances":
                d["material"] = name
            desc["shapes"].append(d)
    pl = scene.point_lights
    if pl is not None:
        for j, (p_, q) in enumerate(
            zip(np.asarray(pl.positions), np.asarray(pl.intensities), strict=True)
        ):
            desc["emitters"].append(named({"type": "point", "position": _list(p_),
                                           "intensity": _list(q)}, "point", 0, j))  # fmt: skip
    env = scene.environment
    if isinstance(env, ConstantEnvironment):
        desc["emitters"].append(named({"type": "constant", "radiance": _list(env.radiance)},
                                      "environment", 0))  # fmt: skip
    elif isinstance(env, SunSky):
        ed = {"type": "sunsky", "sun_direction": _list(env.sun_direction),
              "turbidity": float(env.turbidity), "albedo": _list(env.albedo),
              "sun_scale": float(env.sun_scale), "sky_scale": float(env.sky_scale),
              "sun_aperture": float(env.sun_aperture),
              "complex_sun": bool(env.complex_sun)}  # fmt: skip
        if env.to_world is not None:
            ed["to_world"] = np.asarray(env.to_world, np.float64).tolist()
        desc["emitters"].append(named(ed, "environment", 0))
    elif env is not None:
        ed = {"type": "envmap", "image": np.asarray(env.image, np.float32),
              "scale": float(env.scale)}  # fmt: skip
        if env.to_world is not None:
            ed["to_world"] = np.asarray(env.to_world, np.float64).tolist()
        desc["emitters"].append(named(ed, "environment", 0))
    counts = {"directional": 0, "spot": 0, "projector": 0}
    for e in scene.delta_lights:  # directional, spot and projector lights, in their order
        if isinstance(e, DirectionalAreaLight):  # written with its shape, above
            continue
        if isinstance(e, DirectionalLight):
            d = {"type": "directional", "direction": _list(e.direction),
                 "irradiance": _list(e.irradiance)}  # fmt: skip
        elif isinstance(e, ProjectorLight):
            d = {"type": "projector", "position": _list(e.position),
                 "direction": _list(e.direction), "up": _list(e.up), "fov": _list(e.fov),
                 "scale": _list(e.scale), "irradiance": _texture_desc(e.irradiance)}  # fmt: skip
        else:
            d = {"type": "spot", "position": _list(e.position), "direction": _list(e.direction),
                 "intensity": _list(e.intensity), "cutoff_angle": _list(e.cutoff_angle),
                 "beam_width": _list(e.beam_width)}  # fmt: skip
            if e.texture is not None:
                d.update(texture=_texture_desc(e.texture), up=_list(e.up))
        desc["emitters"].append(named(d, d["type"], counts[d["type"]]))
        counts[d["type"]] += 1
    used = {d.get("material") for d in desc["shapes"] + desc["emitters"]}
    used |= {m.get("material") for d in desc["shapes"] for m in d.get("shapes", ())}
    desc["materials"] = {k: v for k, v in desc["materials"].items() if k in used}
    return desc


def sensor_dict(d) -> dict:
    """The sensor of a :func:`to_mitsuba_dict` result: top-level, or nested in the shape of an
    irradiance meter."""
    return d["sensor"] if "sensor" in d else d["irradiance_meter"]["sensor"]


def mitsuba_integrator(
    name: str = "path", *, max_depth: int = 3, rr_depth: int = 5, hide_emitters: bool = False
) -> dict:
    """Mitsuba 3 integrator dict for a jaxgfx integrator name.

    ``"path"`` -> ``{"type": "path", "max_depth": max_depth, "rr_depth": rr_depth}`` (same
    depth convention: 1 emitters only, 2 direct light, 3 one indirect bounce); ``"direct"`` ->
    the same with ``max_depth = 2`` (as jaxgfx's ``direct``); ``"ptracer"`` -> Mitsuba's
    ``ptracer`` with the same ``max_depth`` / ``rr_depth`` (and ``hide_emitters``, which only
    ``ptracer`` takes: ``ValueError`` for the others). ``whitted`` and ``aov`` have no
    Mitsuba counterpart (``NotImplementedError``); other names raise ``ValueError``. The
    Mitsuba names ``"prb"`` / ``"prb_basic"`` (path replay backpropagation: jaxgfx's
    ``PathIntegrator(adjoint="replay")``, with ``strategy="bsdf"`` for ``prb_basic``) are
    written as they are, with ``max_depth`` and ``rr_depth``, and so are ``"prb_projective"``
    and ``"direct_projective"`` (jaxgfx's ``path`` / ``direct`` with ``visibility="edge"``;
    the latter with ``max_depth = 2``, as Mitsuba overrides it).

    Example: ``mitsuba_integrator("direct")["max_depth"] == 2``.
    """
    for arg, v in (("max_depth", max_depth), ("rr_depth", rr_depth)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{arg}: expected a positive integer, got {v!r}")
    mitsuba_names = ("ptracer", "prb", "prb_basic", "prb_projective", "direct_projective")
    if name in ("direct", "direct_projective"):
        max_depth = 2
    elif name in ("whitted", "aov"):
        raise NotImplementedError(f"integrator: {name!r} has no Mitsuba 3 counterpart")
    elif name not in ("path",) + mitsuba_names:
        raise ValueError(
            "integrator: expected 'path', 'direct', 'ptracer', 'prb', 'prb_basic', "
            f"'prb_projective' or 'direct_projective', got {name!r}"
        )
    if not isinstance(hide_emitters, bool):
        raise ValueError(f"hide_emitters: expected a bool, got {hide_emitters!r}")
    if hide_emitters and name != "ptracer":
        raise ValueError(
            f"hide_emitters: jaxgfx's {name!r} does not hide emitters ('ptracer' does)"
        )
    kind = name if name in mitsuba_names else "path"
    out = {"type": kind, "max_depth": int(max_depth), "rr_depth": int(rr_depth)}
    if hide_emitters:
        out["hide_emitters"] = True
    return out


def import_mitsuba(variant: str = "scalar_rgb"):
    """Import ``mitsuba`` and set ``variant``; ``ImportError`` with install hints otherwise."""
    try:
        import mitsuba as mi
    except ImportError as e:
        raise ImportError(MITSUBA_INSTALL_HINT) from e
    if variant not in mi.variants():
        raise ImportError(f"variant: {variant!r} is not available; have {mi.variants()}")
    try:
        mi.set_variant(variant)
    except Exception as e:  # Dr.Jit raises plain exceptions when its LLVM backend is missing
        raise ImportError(f"variant: could not set {variant!r}: {e}. {MITSUBA_INSTALL_HINT}") from e
    return mi


def render_mitsuba(
    desc,
    *,
    spp: int,
    integrator: str = "path",
    max_depth: int = 3,
    rr_depth: int = 5,
    variant: str = "scalar_rgb",
    seed: int = 0,
    base_dir=None,
    work_dir=None,
) -> np.ndarray:
    """Render a jaxgfx scene description with Mitsuba 3: ``(H, W, 3)`` float32 radiance.

    Host function (not traced). Imports ``mitsuba`` lazily and sets ``variant`` (``ImportError``
    with install instructions when missing). ``integrator`` / ``max_depth`` / ``rr_depth``
    follow :func:`jaxgfx.render.render.render` (see :func:`mitsuba_integrator`); ``seed`` selects
    Mitsuba's sampler stream (different seeds give independent images).
    """
    if isinstance(spp, bool) or not isinstance(spp, (int, np.integer)) or spp < 1:
        raise ValueError(f"spp: expected a positive integer, got {spp!r}")
    integ = mitsuba_integrator(integrator, max_depth=max_depth, rr_depth=rr_depth)
    mi = import_mitsuba(variant)
    # generated files (envmap, inline meshes) are read by load_dict; a temp folder is removed
    tmp = tempfile.TemporaryDirectory(prefix="jaxgfx_mitsuba_") if work_dir is None else None
    try:
        wd = tmp.name if tmp is not None else work_dir
        d = to_mitsuba_dict(desc, base_dir=base_dir, work_dir=wd, mi=mi)
        d["integrator"] = integ
        sensor_dict(d)["sampler"]["sample_count"] = int(spp)
        scene = mi.load_dict(d)
    finally:
        if tmp is not None:
            tmp.cleanup()
    img = mi.render(scene, spp=int(spp), seed=int(seed))
    return np.array(img, dtype=np.float32)[..., :3]


__all__ += ["import_mitsuba"]
