"""The ``ellipsoids`` shape in scene descriptions, Mitsuba XML and the Mitsuba writer
(Mitsuba 3's ``ellipsoids`` plugin; geometry in :mod:`jaxgfx.render.geometry.ellipsoids`).

Description: ``{type: ellipsoids, material, id, extent (3.0), extent_adaptive_clamping
(false only)}`` plus exactly one source, as Mitsuba's plugin takes them:

* ``filename``: an ellipsoid PLY file (:func:`~jaxgfx.render.geometry.ellipsoids.
  read_ellipsoids_ply`), optionally with ``scale_factor`` and ``to_world`` (Mitsuba accepts
  these two with a file only);
* ``centers (N, 3)``, ``scales (N, 3)``, ``quaternions (N, 4)`` (``x y z w``);
* ``data``: ``(N, 10)`` or a flat ``N * 10`` list of rows ``center, scale, quaternion``.

Other keys would be per-ellipsoid attributes in Mitsuba (``opacities``, ``sh_coeffs``, ...),
used only by its volumetric primitive integrators: refused, naming the key.
"""

from __future__ import annotations

import os

import numpy as np

from jaxgfx._checks import as_float_array

__all__ = ["ELLIPSOID_KEYS", "ellipsoids_arrays", "ellipsoids_from_desc", "ellipsoids_xml"]

ELLIPSOID_KEYS = ("type", "material", "id", "filename", "scale_factor", "to_world", "centers",
                  "scales", "quaternions", "data", "extent",
                  "extent_adaptive_clamping")  # fmt: skip

_VOLUMETRIC = ("per-ellipsoid attributes are not supported: in Mitsuba they serve the "
               "volumetric primitive integrators (opacities, spherical harmonics), which a "
               "surface renderer cannot honour")  # fmt: skip


def _check_keys(d, where):
    extra = sorted(set(d) - set(ELLIPSOID_KEYS))
    if extra:
        raise ValueError(f"{where}.{extra[0]}: {_VOLUMETRIC} (an ellipsoids shape takes "
                         f"{sorted(ELLIPSOID_KEYS)})")  # fmt: skip
    if d.get("extent_adaptive_clamping", False) is not False:
        raise ValueError(f"{where}.extent_adaptive_clamping: only false is supported (the "
                         "adaptive extent needs the volumetric 'opacities' attribute)")  # fmt: skip
    sources = [k for k in ("filename", "centers", "data") if k in d]
    if len(sources) != 1:
        raise ValueError(f"{where}: give exactly one of 'filename', 'centers' (with 'scales' "
                         f"and 'quaternions') and 'data'; got {sources}")  # fmt: skip
    if "filename" not in d:
        for k in ("scale_factor", "to_world"):
            if k in d:
                raise ValueError(f"{where}.{k}: only with 'filename' (as in Mitsuba 3)")
    if "centers" in d:
        missing = [k for k in ("scales", "quaternions") if k not in d]
        if missing:
            raise ValueError(f"{where}: 'centers' needs {missing}")
    elif "scales" in d or "quaternions" in d:
        raise ValueError(f"{where}: 'scales' and 'quaternions' go with 'centers'")


def _to_world(x, where):
    m = np.asarray(as_float_array(x, where), np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)) or not np.allclose(m[3], [0, 0, 0, 1]):
        raise ValueError(f"{where}: expected a finite 4x4 affine matrix")
    if not np.linalg.det(m[:3, :3]) > 0:
        raise ValueError(f"{where}: a mirroring or singular transform (det <= 0) cannot "
                         "place ellipsoids")  # fmt: skip
    return m


def _extent(d, where):
    e = d.get("extent", 3.0)
    if isinstance(e, bool) or not isinstance(e, (int, float, np.floating, np.integer)):
        raise ValueError(f"{where}.extent: expected a positive number, got {e!r}")
    if not (np.isfinite(e) and e > 0):
        raise ValueError(f"{where}.extent: expected a positive number, got {e!r}")
    return float(e)


def ellipsoids_arrays(d, where, base_dir, read_file):
    """``(centers, scales, quaternions, extent)`` (NumPy) of a checked description;
    ``read_file(d, where, base_dir, read)`` reads its ``filename`` (schema's, passed in: this
    module sits below the schema)."""
    from jaxgfx.render.geometry.ellipsoids import read_ellipsoids_ply

    _check_keys(d, where)
    extent = _extent(d, where)
    if "filename" in d:
        sf = d.get("scale_factor", 1.0)
        if isinstance(sf, bool) or not isinstance(sf, (int, float)) or not sf > 0:
            raise ValueError(f"{where}.scale_factor: expected a positive number, got {sf!r}")
        tw = _to_world(d["to_world"], f"{where}.to_world") if "to_world" in d else None

        def read(path):
            return read_ellipsoids_ply(path, scale_factor=float(sf), to_world=tw)

        c, s, q = read_file(d, where, base_dir, read)
        return c, s, q, extent
    if "data" in d:
        a = np.asarray(as_float_array(d["data"], f"{where}.data"), np.float64)
        if a.ndim == 1 and a.size % 10 == 0 and a.size:
            a = a.reshape(-1, 10)
        if a.ndim != 2 or a.shape[1] != 10 or a.shape[0] == 0:
            raise ValueError(f"{where}.data: expected shape (N, 10) or (N * 10,) (center, "
                             f"scale, quaternion x y z w per row), got {a.shape}")  # fmt: skip
        return a[:, :3], a[:, 3:6], a[:, 6:], extent
    arrs = []
    for k, w in (("centers", 3), ("scales", 3), ("quaternions", 4)):
        a = np.asarray(as_float_array(d[k], f"{where}.{k}"), np.float64)
        if a.ndim != 2 or a.shape[1] != w or a.shape[0] == 0:
            raise ValueError(f"{where}.{k}: expected shape (N, {w}), got {a.shape}")
        arrs.append(a)
    if not arrs[0].shape[0] == arrs[1].shape[0] == arrs[2].shape[0]:
        raise ValueError(f"{where}: centers, scales and quaternions must have the same number "
                         f"of rows, got {[a.shape[0] for a in arrs]}")  # fmt: skip
    return (*arrs, extent)


def ellipsoids_from_desc(d, where, base_dir, read_file):
    """An :class:`~jaxgfx.render.geometry.Ellipsoids` from its description (module doc;
    ``read_file`` as :func:`ellipsoids_arrays`)."""
    import jax.numpy as jnp

    from jaxgfx.render.geometry import Ellipsoids

    c, s, q, extent = ellipsoids_arrays(d, where, base_dir, read_file)
    try:
        return Ellipsoids(jnp.asarray(c, jnp.float32), jnp.asarray(s, jnp.float32),
                          jnp.asarray(q, jnp.float32), extent=extent)  # fmt: skip
    except ValueError as e:
        raise ValueError(f"{where}.{e}") from None


def ellipsoids_xml(p, obj, doc, m, emitters):
    """``(description, bbox)`` of an XML ``<shape type="ellipsoids">`` (``p`` its parameter
    reader, ``m`` its ``to_world``): ``filename`` (Mitsuba's XML has no tensors), ``extent``,
    ``scale_factor``, ``to_world``; the file is read now for its errors."""
    from jaxgfx.render.geometry.ellipsoids import read_ellipsoids_ply

    if emitters:
        raise ValueError(f"{obj.where}: ellipsoids cannot be an area emitter (Mitsuba's "
                         "ellipsoids have no area sampling: zero positions and pdfs)")  # fmt: skip
    if p.bool("extent_adaptive_clamping", False):
        raise p.err("extent_adaptive_clamping", "only false is supported (the adaptive "
                                                "extent needs the volumetric 'opacities' "
                                                "attribute)")  # fmt: skip
    fname = p.string("filename")
    if fname is None:
        raise ValueError(f"{obj.where}: missing parameter 'filename' (Mitsuba's XML gives "
                         "ellipsoids by a PLY file)")  # fmt: skip
    path = doc.resolve(fname, obj.props["filename"].node, obj.label)
    extent = p.float("extent", 3.0, positive=True)
    sf = p.float("scale_factor", 1.0, positive=True)
    tw = None
    if not np.allclose(m, np.eye(4)):
        if not np.linalg.det(m[:3, :3]) > 0:
            raise p.err("to_world", "a mirroring or singular transform (det <= 0) cannot "
                                    "place ellipsoids")  # fmt: skip
        tw = m
    try:
        c, s, q = read_ellipsoids_ply(path, scale_factor=sf, to_world=tw)
    except ValueError as e:
        raise p.err("filename", str(e)) from None
    sd = {"type": "ellipsoids", "filename": os.path.abspath(path), "extent": extent}
    if sf != 1.0:
        sd["scale_factor"] = sf
    if tw is not None:
        sd["to_world"] = tw.tolist()
    from jaxgfx.render.geometry.ellipsoids import _boxes

    lo, hi = _boxes(c.astype(np.float64), np.abs(s.astype(np.float64)) * extent,
                    q.astype(np.float64))  # fmt: skip
    return sd, np.stack([lo.min(0), hi.max(0)])
