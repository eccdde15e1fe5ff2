"""Measured BRDFs of the RGL material database: Dupuy & Jakob 2018 (Mitsuba 3 ``measured``).

Dupuy & Jakob, "An Adaptive Parameterization for Efficient Material Acquisition and
Rendering" (SIGGRAPH Asia 2018) store a reflectance measurement in coordinates adapted to the
material: the outgoing direction is parameterised by the half vector ``m``, and ``m`` by the
primary sample space of the material's own visible-normal distribution (VNDF). A ``.bsdf``
file (a Mitsuba tensor file, :func:`jaxgfx.io.tensor_file.read_tensor_file`) holds, for the
viewing direction ``ω_i = (θ_i, φ_i)`` on the grid ``theta_i`` x ``phi_i``:

* ``ndf`` (H, W): the microfacet distribution ``D(m)`` over ``u_m = (sqrt(2θ_m / π),
  (φ_m + π) / 2π)`` (``x`` = the ``θ`` coordinate, the last axis);
* ``sigma`` (H, W): the projected area ``σ(ω_i) = ∫ D(m) <ω_i·m> dm`` over ``u_i``;
* ``vndf`` (P, T, H, W): the VNDF's density over ``u_m`` per slice (a :mod:`Marginal2D
  <jaxgfx.render.bsdf._marginal2d>` warp; ``φ_m`` relative to ``φ_i`` when isotropic);
* ``rgb`` (P, T, 3, H', W'): the reflectance over the warp's primary sample space ``s``;
* ``luminance`` (P, T, H', W'): a density over ``s`` (the luminance of ``rgb``) sampled first;
* ``jacobian`` (uint8): if set, ``eval`` is multiplied by ``D(m) / (4 σ(ω_i))``;
* ``theta_i`` (T,), ``phi_i`` (P,) in radians; ``description`` (UTF-8 bytes).

``eval(ω_o, ω_i) = rgb(s(m)) [D(m) / (4 σ(ω_o))]`` with ``m`` the half vector and ``s(m)`` the
inverted VNDF warp (Mitsuba's ``si.wi`` is jaxgfx's ``wo``); the slices are interpolated
linearly in ``(φ, θ)`` of the viewing direction. ``sample`` warps ``(u_y, u_x)`` by the
luminance, then by the VNDF; ``pdf = p_vndf(u_m) p_lum(s) / (2π² u_θ sin θ_m · 4 ω_o·m)``.
Isotropic files have at most two ``phi_i`` nodes; anisotropic ones cover ``2π / reduction``
of azimuth (``reduction`` 2 or 4: the viewing direction is mirrored into the stored part, as
Mitsuba). Reflection only, one-sided (0 below the surface). Files with ``wavelengths`` (the
spectral ones) are refused: jaxgfx renders RGB.
"""

from __future__ import annotations

import math
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._math import safe_atan2, safe_div, safe_sqrt, vdot
from jaxgfx.io.tensor_file import read_tensor_file, write_tensor_file
from jaxgfx.render.bsdf._base import (
    BSDF,
    check_rgb,
    glossy_sample,
    mask3,
    prep_dirs,
    sample_setup,
)
from jaxgfx.render.bsdf._marginal2d import (
    Warp2D,
    bilinear,
    build_warp,
    param_corners,
    warp_eval,
    warp_invert,
    warp_sample,
)

__all__ = ["Measured", "read_measured", "write_measured", "MEASURED_FIELDS"]

MEASURED_FIELDS = ("theta_i", "phi_i", "ndf", "sigma", "vndf", "luminance", "rgb",
                   "description", "jacobian")  # fmt: skip
"""The fields an RGB ``.bsdf`` file must hold (Mitsuba's ``measured`` reads these)."""

_LUM = (0.212671, 0.715160, 0.072169)  # Rec. 709 luminance (the synthetic files' luminance)
_PI = math.pi


def _expect(path, f, name, dtype, ndim, shape=None):
    a = f[name]
    want = f"{np.dtype(dtype).name} with {ndim} axes" + (f" of shape {shape}" if shape else "")
    ok = a.dtype == dtype and a.ndim == ndim
    if ok and shape is not None:
        ok = all(s is None or s == t for s, t in zip(shape, a.shape, strict=True))
    if not ok:
        raise ValueError(f"{path}: field {name!r}: expected {want}, got "
                         f"{a.dtype.name} of shape {a.shape}")  # fmt: skip


def read_measured(path) -> dict:
    """The validated fields of an RGB ``.bsdf`` file (Mitsuba's ``measured`` checks, each with
    its own message naming the file and the field): NumPy arrays, ``description`` a ``str`` and
    ``jacobian`` a ``bool``. ``ValueError`` for a spectral file (``wavelengths``), a missing
    field, a wrong dtype / number of axes / shape, grids smaller than 2 x 2, or ``theta_i`` /
    ``phi_i`` not increasing."""
    path = os.fspath(path)
    return _check_fields(path, read_tensor_file(path))


def _check_fields(path, f) -> dict:
    """:func:`read_measured`'s checks of the fields ``f`` (errors start with ``path``)."""
    if "wavelengths" in f:
        raise ValueError(f"{path}: a spectral measurement (field 'wavelengths'): Mitsuba "
                         "renders these only in its spectral variants and jaxgfx renders RGB; "
                         "use the material's RGB .bsdf file")  # fmt: skip
    for k in MEASURED_FIELDS:
        if k not in f:
            raise ValueError(f"{path}: missing field {k!r} (an RGB measured BSDF needs "
                             f"{', '.join(MEASURED_FIELDS)}; has {sorted(f)})")  # fmt: skip
    _expect(path, f, "description", np.uint8, 1)
    _expect(path, f, "theta_i", np.float32, 1)
    _expect(path, f, "phi_i", np.float32, 1)
    n_p, n_t = f["phi_i"].shape[0], f["theta_i"].shape[0]
    _expect(path, f, "ndf", np.float32, 2)
    _expect(path, f, "sigma", np.float32, 2)
    _expect(path, f, "vndf", np.float32, 4, (n_p, n_t, None, None))
    _expect(path, f, "rgb", np.float32, 5, (n_p, n_t, 3, None, None))
    h, w = f["rgb"].shape[3:]
    if h != w:
        raise ValueError(f"{path}: field 'rgb': expected square (H, W) tables, got {(h, w)}")
    _expect(path, f, "luminance", np.float32, 4, (n_p, n_t, h, w))
    _expect(path, f, "jacobian", np.uint8, 1, (1,))
    for k in ("ndf", "sigma", "vndf", "rgb"):
        if min(f[k].shape[-2:]) < 2:
            raise ValueError(f"{path}: field {k!r}: tables must be at least 2 x 2, got "
                             f"{f[k].shape}")  # fmt: skip
    for k in ("theta_i", "phi_i"):
        if n := f[k].shape[0]:
            if n > 1 and not np.all(np.diff(f[k]) > 0):
                raise ValueError(f"{path}: field {k!r}: expected increasing values, got {f[k]}")
        else:
            raise ValueError(f"{path}: field {k!r}: expected at least one value")
    for k in ("ndf", "sigma", "vndf", "luminance", "rgb", "theta_i", "phi_i"):
        if not np.all(np.isfinite(f[k])):
            raise ValueError(f"{path}: field {k!r}: non-finite values")
    for k in ("ndf", "sigma", "vndf", "luminance", "rgb"):
        if np.any(f[k] < 0):
            raise ValueError(f"{path}: field {k!r}: negative values (min {f[k].min()})")
    for k in ("vndf", "luminance"):  # sampled: every slice must integrate to > 0
        dead = np.argwhere(f[k].sum(axis=(2, 3)) <= 0)
        if dead.size:
            raise ValueError(f"{path}: field {k!r}: the slice (phi_i, theta_i) = "
                             f"{tuple(int(i) for i in dead[0])} is all zero (cannot be "
                             "sampled)")  # fmt: skip
    out = {k: f[k] for k in MEASURED_FIELDS}
    out["description"] = bytes(f["description"]).decode("utf-8", "replace")
    out["jacobian"] = bool(f["jacobian"][0])
    return out


def _as_file_fields(fields: dict) -> dict:
    """``fields`` with the file's dtypes (float32 tables, uint8 ``description`` / ``jacobian``)."""
    out = {}
    for k in MEASURED_FIELDS:
        v = fields[k]
        if k == "description":
            out[k] = np.frombuffer(str(v).encode("utf-8"), np.uint8)
        elif k == "jacobian":
            out[k] = np.asarray([1 if bool(np.asarray(v).reshape(-1)[0]) else 0], np.uint8)
        else:
            out[k] = np.asarray(v, np.float32)
    return out


def write_measured(path, fields: dict) -> None:
    """Write an RGB ``.bsdf`` file from ``fields`` (the keys of :data:`MEASURED_FIELDS`; arrays
    are stored as float32, ``description`` a ``str``, ``jacobian`` a bool), then read it back
    through :func:`read_measured` (so a malformed table fails here, naming the field)."""
    missing = [k for k in MEASURED_FIELDS if k not in fields]
    if missing:
        raise ValueError(f"fields: missing {missing}")
    write_tensor_file(path, _as_file_fields(fields))
    read_measured(path)


def _elevation(d):
    """``acos(d_z)`` of a unit vector, stable near the pole (Mitsuba's ``elevation``)."""
    dist = safe_sqrt(d[..., 0] ** 2 + d[..., 1] ** 2 + (d[..., 2] - 1.0) ** 2)
    return 2.0 * jnp.arcsin(jnp.clip(0.5 * dist, -1.0, 1.0))


def _atan2(y, x):
    """``atan2`` as drjit computes it: a signed zero ``y`` counts as +0 (``-0`` -> +π, not -π,
    for ``x < 0``); 0 at the origin with a zero gradient."""
    return safe_atan2(jnp.where(y == 0, 0.0, y), x)


def _theta2u(t):
    return safe_sqrt(t * (2.0 / _PI))


def _phi2u(p):
    return (p + _PI) * (0.5 / _PI)


def _mulsign_neg(v, s):
    """``v`` times the negated sign of ``s`` (drjit ``mulsign_neg``: +0 counts as positive)."""
    return jnp.where(jnp.signbit(s), v, -v)


class Measured(BSDF):
    """Mitsuba 3's ``measured`` BRDF (RGL database, RGB ``.bsdf`` files; see the module doc).

    ``Measured(filename)`` reads a file; ``Measured(tables=read_measured(path))`` builds from
    the fields of :func:`read_measured` (e.g. synthetic tables). ``rgb`` (P, T, 3, H, W) is the
    differentiable parameter (fit it or a scale of it); the warps (``ndf``, ``sigma``, VNDF and
    luminance CDFs) are private tables built on the host, as Mitsuba's constructor builds them.
    ``eval`` / ``pdf`` / ``sample`` follow Mitsuba's ``measured.cpp`` step by step.

    Example: ``Measured("tests/data/measured/ggx_gold_iso.bsdf").eval(wo, wi)``.
    """

    rgb: jnp.ndarray
    _ndf: Warp2D
    _sigma: Warp2D
    _vndf: Warp2D
    _luminance: Warp2D
    _theta_i: jnp.ndarray
    _phi_i: jnp.ndarray
    isotropic: bool = eqx.field(static=True)
    jacobian: bool = eqx.field(static=True)
    reduction: int = eqx.field(static=True)
    filename: str | None = eqx.field(static=True)
    description: str = eqx.field(static=True)

    def __init__(self, filename=None, *, tables=None):
        if (filename is None) == (tables is None):
            raise ValueError("filename: give exactly one of a .bsdf filename and tables")
        if filename is not None:
            if not isinstance(filename, (str, os.PathLike)):
                raise TypeError(f"filename: expected a path, got {type(filename).__name__}")
            try:
                tables = read_measured(filename)
            except OSError as e:
                raise ValueError(f"filename: cannot read {os.fspath(filename)!r}: "
                                 f"{e.strerror or e}") from None  # fmt: skip
            except ValueError as e:
                raise ValueError(f"filename: {e}") from None
            self.filename = os.path.abspath(os.fspath(filename))
        else:
            if not isinstance(tables, dict):
                raise TypeError(f"tables: expected a dict, got {type(tables).__name__}")
            missing = [k for k in MEASURED_FIELDS if k not in tables]
            if missing:
                raise ValueError(f"tables: missing {missing}")
            tables = _check_fields("tables", _as_file_fields(tables))
            self.filename = None
        phi = np.asarray(tables["phi_i"], np.float32)
        theta = np.asarray(tables["theta_i"], np.float32)
        self.isotropic = phi.shape[0] <= 2
        # Mitsuba leaves m_reduction unset for isotropic files; no mirroring then (an isotropic
        # table is symmetric in φ_m - φ_i, so mirroring would not change the values)
        self.reduction = 0 if self.isotropic else int(np.rint(2 * _PI / (phi[-1] - phi[0])))
        self.jacobian = bool(tables["jacobian"])
        self.description = str(tables["description"])
        n_slices = phi.shape[0] * theta.shape[0]
        vndf = np.asarray(tables["vndf"], np.float32)
        lum = np.asarray(tables["luminance"], np.float32)
        self._ndf = build_warp(np.asarray(tables["ndf"], np.float32), normalize=False,
                               sampling=False)  # fmt: skip
        self._sigma = build_warp(np.asarray(tables["sigma"], np.float32), normalize=False,
                                 sampling=False)  # fmt: skip
        self._vndf = build_warp(vndf.reshape(n_slices, *vndf.shape[2:]))
        self._luminance = build_warp(lum.reshape(n_slices, *lum.shape[2:]))
        self._theta_i = jnp.asarray(theta)
        self._phi_i = jnp.asarray(phi)
        self.rgb = jnp.asarray(tables["rgb"], jnp.float32)

    def __check_init__(self):
        check_rgb(jnp.moveaxis(self.rgb, 2, -1) if jnp.ndim(self.rgb) == 5 else self.rgb, "rgb")
        if jnp.ndim(self.rgb) != 5:
            raise ValueError(f"rgb: expected (phi_i, theta_i, 3, H, W), got {jnp.shape(self.rgb)}")

    @property
    def albedo(self):
        return jnp.mean(self.rgb, axis=(0, 1, 3, 4))

    # -- shared steps ------------------------------------------------------------------------

    def _tables(self):
        """The private tables, outside differentiation (only ``rgb`` is a parameter; this keeps
        the gradient programs small)."""
        return jax.lax.stop_gradient((self._ndf, self._sigma, self._vndf, self._luminance,
                                      self._theta_i, self._phi_i))  # fmt: skip

    def _reduce(self, wi):
        """Mitsuba's ``m_reduction`` mirroring: the signs ``(sx, sy)`` and the mirrored ``wi``."""
        if self.reduction < 2:
            one = -jnp.ones_like(wi[..., 0])
            return one, one, wi
        sy = wi[..., 1]
        sx = wi[..., 0] if self.reduction == 4 else sy
        wi = jnp.stack([_mulsign_neg(wi[..., 0], sx), _mulsign_neg(wi[..., 1], sy),
                        wi[..., 2]], axis=-1)  # fmt: skip
        return sx, sy, wi

    def _mirror(self, v, sx, sy):
        if self.reduction < 2:
            return v
        return jnp.stack([_mulsign_neg(v[..., 0], sx), _mulsign_neg(v[..., 1], sy), v[..., 2]],
                         axis=-1)  # fmt: skip

    def _spec(self, sample, u_m, u_wi, corners, tabs):
        """``rgb`` at the primary sample ``sample`` (..., 3), times ``D / (4 σ)`` if the file
        sets ``jacobian``."""
        p, t = self.rgb.shape[:2]
        spec = bilinear(self.rgb.reshape(p * t, *self.rgb.shape[2:]), sample, corners)
        if self.jacobian:
            d = warp_eval(tabs[0], u_m)
            sig = warp_eval(tabs[1], u_wi)
            spec = spec * safe_div(d, 4.0 * sig)[..., None]
        return spec

    def _coords(self, wi, m):
        """``(θ_i, φ_i, u_wi, u_m)`` of the (mirrored) viewing direction and half vector."""
        theta_i, phi_i = _elevation(wi), _atan2(wi[..., 1], wi[..., 0])
        theta_m, phi_m = _elevation(m), _atan2(m[..., 1], m[..., 0])
        u_wi = jnp.stack([_theta2u(theta_i), _phi2u(phi_i)], axis=-1)
        uy = _phi2u(phi_m - phi_i if self.isotropic else phi_m)
        u_m = jnp.stack([_theta2u(theta_m), uy - jnp.floor(uy)], axis=-1)
        return theta_i, phi_i, u_wi, u_m

    @staticmethod
    def _corners(phi_i, theta_i, tabs):
        return param_corners([phi_i, theta_i], [tabs[5], tabs[4]])

    @staticmethod
    def _jacobian(u_mx, sin_theta_m, wi, m):
        """``dω_o / du_m``: ``max(2π² u_θ sin θ_m, 1e-6) · 4 (ω_i·m)``."""
        return jnp.maximum(2.0 * _PI**2 * u_mx * sin_theta_m, 1e-6) * 4.0 * vdot(wi, m)

    def _eval_pdf(self, wo, wi, want_eval):
        wo, wi = prep_dirs(wo, wi)
        shape = jnp.broadcast_shapes(wo.shape, wi.shape)
        v_i, v_o = jnp.broadcast_to(wo, shape), jnp.broadcast_to(wi, shape)  # Mitsuba wi, wo
        valid = (v_i[..., 2] > 0) & (v_o[..., 2] > 0)
        sx, sy, v_i = self._reduce(v_i)
        v_o = self._mirror(v_o, sx, sy)
        # a direction pair in the lower hemisphere would make m = 0: evaluate at +z instead
        up = jnp.asarray([0.0, 0.0, 1.0], v_i.dtype)
        v_i = jnp.where(valid[..., None], v_i, up)
        v_o = jnp.where(valid[..., None], v_o, up)
        m = v_o + v_i
        m = m / jnp.sqrt(vdot(m, m, keepdims=True))
        theta_i, phi_i, u_wi, u_m = self._coords(v_i, m)
        tabs = self._tables()
        corners = self._corners(phi_i, theta_i, tabs)
        sample, vndf_pdf = warp_invert(tabs[2], u_m, corners)
        if want_eval:
            return mask3(valid, self._spec(sample, u_m, u_wi, corners, tabs))
        lum_pdf = warp_eval(tabs[3], sample, corners)
        sin_m = safe_sqrt(m[..., 0] ** 2 + m[..., 1] ** 2)
        pdf = safe_div(vndf_pdf * lum_pdf, self._jacobian(u_m[..., 0], sin_m, v_i, m))
        return jnp.where(valid, pdf, 0.0)

    # -- interface -----------------------------------------------------------------------------

    def eval(self, wo, wi):
        return self._eval_pdf(wo, wi, True)

    def pdf(self, wo, wi):
        return self._eval_pdf(wo, wi, False)

    def sample(self, wo, u1, u2):
        wo, u1, u2, shape = sample_setup(wo, u1, u2)
        dt = wo.dtype
        front = wo[..., 2] > 0
        v_i = jnp.where(front[..., None], wo, jnp.asarray([0.0, 0.0, 1.0], dt))
        sx, sy, v_i = self._reduce(v_i)
        theta_i, phi_i = _elevation(v_i), _atan2(v_i[..., 1], v_i[..., 0])
        u_wi = jnp.stack([_theta2u(theta_i), _phi2u(phi_i)], axis=-1)
        tabs = self._tables()
        corners = self._corners(phi_i, theta_i, tabs)
        u = jnp.broadcast_to(jnp.stack([u2[..., 1], u2[..., 0]], axis=-1), shape + (2,))
        sample, lum_pdf = warp_sample(tabs[3], u, corners)
        u_m, ndf_pdf = warp_sample(tabs[2], sample, corners)
        phi_m = (2.0 * u_m[..., 1] - 1.0) * _PI
        theta_m = jnp.square(u_m[..., 0]) * (_PI / 2)
        if self.isotropic:
            phi_m = phi_m + phi_i
        st, ct = jnp.sin(theta_m), jnp.cos(theta_m)
        m = jnp.stack([jnp.cos(phi_m) * st, jnp.sin(phi_m) * st, ct], axis=-1)
        jac = self._jacobian(u_m[..., 0], st, v_i, m)
        wi = 2.0 * vdot(m, v_i, keepdims=True) * m - v_i
        pdf = safe_div(ndf_pdf * lum_pdf, jac)
        spec = self._spec(sample, u_m, u_wi, corners, tabs)
        wi = self._mirror(wi, sx, sy)
        valid = front & (wi[..., 2] > 0) & (pdf > 0)
        weight = safe_div(spec, pdf[..., None])
        return glossy_sample(wi, pdf, weight, valid, shape, dt)

    # -- host helpers ----------------------------------------------------------------------------

    def tables(self) -> dict:
        """The fields to write this BSDF back as a ``.bsdf`` file (:func:`write_measured`):
        the file's own tables with the current ``rgb`` (e.g. after a fit)."""
        if self.filename is None:
            raise ValueError("tables: this Measured was built from tables, not a file; keep "
                             "the tables you built it from")  # fmt: skip
        f = read_measured(self.filename)
        f["rgb"] = np.asarray(self.rgb, np.float32)
        return f
