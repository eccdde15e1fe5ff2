"""Colour calibration from a photographed ColorChecker: patch sampling, the fit, its application.

Why in :mod:`jaxgfx.hdr.raw`: the chart calibrates a *camera* (camera RGB -> CIE XYZ and its
white balance), the job of :mod:`jaxgfx.hdr.raw.color` beside it, whose DNG matrix is the
"before" of a fit and whose colour spaces are the outputs; and the fit runs through
:func:`jaxgfx.optim.fit_least_squares`, which :mod:`jaxgfx.color` cannot import (``optim``
imports ``color``: docs/architecture.md's import order).

- **Reference** (:func:`colorchecker_reference`): the 24 patches of the X-Rite ColorChecker
  Classic, "ColorChecker24 - After November 2014" (xyY under ICC D50) as colour-science ships
  them (``colour.CCS_COLOURCHECKERS``), read once on the host with NumPy, never traced.
- **Sampling** (:func:`chart_patch_means`): the chart's four corner points (the outer corners
  of the patch grid, in the order top-left, top-right, bottom-right, bottom-left: dark skin is
  the top-left patch, black the bottom-right) define the projective map (homography) of the
  unit square onto the image (Heckbert 1989, *Fundamentals of Texture Mapping and Image
  Warping*, §2.2.3, square -> quadrilateral); each patch is sampled on a ``samples x samples``
  grid over its inner area (``margin`` of the cell left out on every side) by bilinear
  interpolation, and its robust mean is the interquartile mean per channel.
- **Models** (:data:`CHART_MODELS`): ``XYZ = M · t(g ⊙ rgb)`` with ``g`` the white-balance
  gains and ``t`` the terms: ``"matrix"`` ``t = (r, g, b)``, ``M`` 3x3; ``"root-polynomial"``
  of degree 2 (Finlayson, Mackiewicz & Hurlbert 2015, *Color correction using
  root-polynomial regression*, IEEE TIP 24(5), eq. 9) ``t = (r, g, b, sqrt(rg), sqrt(gb),
  sqrt(rb))``, ``M`` 3x6. Both are homogeneous of degree 1: scaling the exposure scales the
  output (the root-polynomial's point over plain polynomials).
- **Fit** (:func:`fit_chart_matrix`): Levenberg-Marquardt (:func:`jaxgfx.optim.fit_least_squares`)
  on CIEDE2000 (Sharma, Wu & Dalal 2005) between ``Lab(M t)`` and the reference, written as
  :func:`jaxgfx.color.delta_e_2000_residuals` (3 residuals per patch whose norm is ΔE00, smooth
  where the colours meet), started from the linear least-squares solution in XYZ. With
  ``white_balance`` the gains ``g`` (green = 1) are fitted jointly and ``M`` is constrained to
  map the balanced neutral ``(1, 1, 1)`` to the illuminant's white (``M · t(1) = s · XYZ_w``):
  the white balance carries the light, the matrix the sensor (darktable's "color calibration"
  splits them the same way); without it ``g = 1`` and ``M`` is free.

Everything on arrays is jittable and differentiable (sampling w.r.t. the image and the corners,
the residuals w.r.t. the matrix and gains); the reference lookup and the fit's driver run on
the host.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice, is_concrete
from jaxgfx._math import safe_sqrt
from jaxgfx.color import (
    RGB_SPACES,
    WHITEPOINTS,
    chromatic_adaptation_matrix,
    delta_e_2000,
    delta_e_2000_residuals,
    rgb_to_xyz_matrix,
    whitepoint_xyz,
    xyz_to_lab,
)

from .color import COLORSPACES

__all__ = [
    "CHART_MODELS",
    "COLORCHECKER24",
    "CORNER_ORDER",
    "ChartReference",
    "ChartCalibration",
    "colorchecker_reference",
    "chart_homography",
    "chart_sample_points",
    "chart_patch_means",
    "chart_terms",
    "chart_delta_e",
    "fit_chart_matrix",
    "apply_chart_calibration",
]

CHART_MODELS = ("matrix", "root-polynomial")
"""Camera RGB -> XYZ models of :func:`fit_chart_matrix` (module doc)."""

COLORCHECKER24 = "ColorChecker24 - After November 2014"
"""The default reference: colour-science's name of the current X-Rite ColorChecker Classic."""

CORNER_ORDER = ("top-left", "top-right", "bottom-right", "bottom-left")
"""The order of a chart's four corner points ``(x, y)`` (pixels; pixel ``(i, j)`` is centred
at ``x = j, y = i``): the outer corners of the patch grid as the chart is read (dark skin
top-left, black bottom-right), whatever its orientation in the image."""


class ChartReference(NamedTuple):
    """Reference values of a chart (host NumPy, float64): ``patch_names`` (row-major),
    ``xyY`` and ``xyz`` ``(P, 3)`` (white ``Y = 1``) under the chart's ``illuminant_xy``."""

    name: str
    patch_names: tuple[str, ...]
    xyY: np.ndarray
    xyz: np.ndarray
    illuminant_xy: np.ndarray


@functools.lru_cache(maxsize=8)
def _read_chart(name: str):
    import colour  # host only, on first use

    charts = colour.CCS_COLOURCHECKERS
    check_choice(name, "chart", tuple(k for k in charts if " " in k))
    c = charts[name]
    names = tuple(c.data.keys())
    xyY = np.asarray([c.data[k] for k in names], np.float64)
    return names, xyY, np.asarray(c.illuminant, np.float64)


def colorchecker_reference(name: str = COLORCHECKER24) -> ChartReference:
    """The reference values of the chart ``name`` (a key of ``colour.CCS_COLOURCHECKERS``;
    default :data:`COLORCHECKER24`), read from colour-science on the host (NumPy; cached).

    >>> ref = colorchecker_reference()
    >>> ref.patch_names[0], ref.patch_names[18], ref.xyz.shape
    ('dark skin', 'white 9.5 (.05 D)', (24, 3))
    >>> round(float(ref.xyz[18, 1]), 4)  # the white patch
    0.8807
    """
    names, xyY, ill = _read_chart(name)
    x, y, Y = xyY[:, 0], xyY[:, 1], xyY[:, 2]
    xyz = np.stack([x * Y / y, Y, (1.0 - x - y) * Y / y], -1)
    return ChartReference(name, names, xyY.copy(), xyz, ill.copy())


# ------------------------------------------------------------------------------ geometry


def _check_corners(corners, image_hw=None):
    c = as_float_array(corners, "corners")
    if c.shape != (4, 2):
        raise ValueError(
            f"corners: expected shape (4, 2), four (x, y) points in the order "
            f"{', '.join(CORNER_ORDER)}, got {tuple(c.shape)}"
        )
    if not is_concrete(c):
        return c
    p = np.asarray(c, np.float64)
    if not np.all(np.isfinite(p)):
        raise ValueError("corners: expected finite coordinates")
    if image_hw is not None:
        h, w = image_hw
        for k, (x, y) in enumerate(p):
            if not (-0.5 <= x <= w - 0.5 and -0.5 <= y <= h - 0.5):
                raise ValueError(
                    f"corners: the {CORNER_ORDER[k]} point (x={x:g}, y={y:g}) lies outside the "
                    f"{w}x{h} image (x in [-0.5, {w - 0.5:g}], y in [-0.5, {h - 0.5:g}])"
                )
    d = np.roll(p, -1, axis=0) - p  # edges TL->TR, TR->BR, BR->BL, BL->TL
    cross = d[:, 0] * np.roll(d, -1, axis=0)[:, 1] - d[:, 1] * np.roll(d, -1, axis=0)[:, 0]
    if not np.all(cross > 0):
        raise ValueError(
            "corners: not a convex quadrilateral in the order "
            f"{', '.join(CORNER_ORDER)} (x right, y down): got {p.tolist()}"
        )
    return c


def chart_homography(corners):
    """The ``(3, 3)`` projective map of the unit square onto the quadrilateral ``corners``
    ``(4, 2)`` (``(u, v)`` = ``(0, 0), (1, 0), (1, 1), (0, 1)`` -> the corners in
    :data:`CORNER_ORDER`): ``(x, y, 1) ∝ H (u, v, 1)``. Heckbert (1989) §2.2.3, closed form.

    >>> H = chart_homography(jnp.array([[0.0, 0], [4, 0], [4, 2], [0, 2]]))
    >>> [float(v) for v in H @ jnp.array([0.5, 0.5, 1.0])]
    [2.0, 1.0, 1.0]
    """
    c = _check_corners(corners)
    return _homography(c)


def _homography(c):
    x0, x1, x2, x3 = c[:, 0]
    y0, y1, y2, y3 = c[:, 1]
    sx, sy = x0 - x1 + x2 - x3, y0 - y1 + y2 - y3
    dx1, dx2, dy1, dy2 = x1 - x2, x3 - x2, y1 - y2, y3 - y2
    den = dx1 * dy2 - dx2 * dy1
    g = (sx * dy2 - dx2 * sy) / den
    h = (dx1 * sy - sx * dy1) / den
    return jnp.stack(
        [
            jnp.stack([x1 - x0 + g * x1, x3 - x0 + h * x3, x0]),
            jnp.stack([y1 - y0 + g * y1, y3 - y0 + h * y3, y0]),
            jnp.stack([g, h, jnp.ones_like(g)]),
        ]
    )


def _check_grid(rows, cols, margin, samples):
    for v, n in ((rows, "rows"), (cols, "cols"), (samples, "samples")):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{n}: expected an integer >= 1, got {v!r}")
    if not (isinstance(margin, (int, float)) and 0.0 <= margin < 0.5):
        raise ValueError(f"margin: expected a fraction of a patch in [0, 0.5), got {margin!r}")


def chart_sample_points(corners, *, rows: int = 4, cols: int = 6, margin: float = 0.25,
                        samples: int = 12):  # fmt: skip
    """Image points ``(rows * cols, samples**2, 2)`` ``(x, y)`` where each patch is sampled: a
    ``samples x samples`` grid over the patch's inner area (``margin`` of the cell cut on each
    side), patches row-major from the top-left corner, mapped by :func:`chart_homography`."""
    _check_grid(rows, cols, margin, samples)
    c = _check_corners(corners)
    t = margin + (1.0 - 2.0 * margin) * (np.arange(samples) + 0.5) / samples  # within a cell
    r, s, i, j = np.meshgrid(np.arange(rows), np.arange(cols), t, t, indexing="ij")
    uv = np.stack([(s + j) / cols, (r + i) / rows], -1).reshape(rows * cols, samples**2, 2)
    uv = jnp.asarray(uv, c.dtype)
    q = jnp.einsum(
        "ij,psj->psi", _homography(c), jnp.concatenate([uv, jnp.ones_like(uv[..., :1])], -1)
    )
    return q[..., :2] / q[..., 2:]


def chart_patch_means(image, corners, *, rows: int = 4, cols: int = 6, margin: float = 0.25,
                      samples: int = 12, saturation: float | None = None):  # fmt: skip
    """The robust mean of every patch of a chart in ``image``: ``(rows * cols, C)``.

    ``image`` ``(H, W)`` or ``(H, W, C)`` (linear, e.g. the merged camera RGB); ``corners``
    ``(4, 2)`` the ``(x, y)`` pixel coordinates of the patch grid's outer corners in
    :data:`CORNER_ORDER` (top-left, top-right, bottom-right, bottom-left); patches row-major
    (the ColorChecker's order: dark skin ... bluish green, orange ..., white ... black). Each
    patch is sampled bilinearly at :func:`chart_sample_points` (its inner area: ``margin`` of
    the cell, 0.25 by default, left out on every side: the gaps and the patch edges) and
    reduced to the interquartile mean per channel (robust to specks and demosaic fringes).
    ``saturation``: a patch with a sample at or above it (any channel), or a non-finite one,
    is NaN (left out by :func:`fit_chart_matrix`). Jittable (``rows``, ``cols``, ``samples``
    static) and differentiable in the image and the corners.

    Raises ``ValueError`` naming the argument: a wrong shape, a corner outside the image, or
    corners that do not form a convex quadrilateral in that order.

    >>> img = jnp.zeros((4, 6)).at[2:, 3:].set(1.0)  # 2x2 patches of 3x2 pixels
    >>> chart_patch_means(img, jnp.array([[-0.5, -0.5], [5.5, -0.5], [5.5, 3.5], [-0.5, 3.5]]),
    ...                   rows=2, cols=2).tolist()
    [0.0, 0.0, 0.0, 1.0]
    """
    img = as_float_array(image, "image")
    if img.ndim not in (2, 3) or min(img.shape[:2]) < 2:
        raise ValueError(f"image: expected (H, W) or (H, W, C) of at least 2x2, got {img.shape}")
    squeeze = img.ndim == 2
    img = img[..., None] if squeeze else img
    c = _check_corners(corners, img.shape[:2])
    pts = chart_sample_points(c.astype(img.dtype), rows=rows, cols=cols, margin=margin,
                              samples=samples)  # fmt: skip
    out = _patch_means(img, pts, saturation)
    return out[:, 0] if squeeze else out


def _patch_means(img, pts, saturation):
    coords = [pts[..., 1], pts[..., 0]]  # (row, col)

    def channel(plane):
        return jax.scipy.ndimage.map_coordinates(plane, coords, order=1, mode="nearest")

    v = jnp.moveaxis(jax.vmap(channel, in_axes=-1, out_axes=-1)(img), 1, 0)  # (S, P, C)
    n = v.shape[0]
    lo, hi = n // 4, n - n // 4
    iqm = jnp.mean(jnp.sort(v, axis=0)[lo:hi], axis=0)
    bad = ~jnp.all(jnp.isfinite(v), axis=(0, 2))
    if saturation is not None:
        bad = bad | jnp.any(v >= saturation, axis=(0, 2))
    return jnp.where(bad[:, None], jnp.nan, iqm)


# ------------------------------------------------------------------------------ models


def chart_terms(rgb, model: str = "matrix"):
    """The model's terms of camera RGB ``(..., 3)``: ``"matrix"`` ``(..., 3)`` (``rgb``),
    ``"root-polynomial"`` ``(..., 6)`` ``(r, g, b, sqrt(rg), sqrt(gb), sqrt(rb))``
    (Finlayson et al. 2015, degree 2; negative values count as 0 under the roots).
    Homogeneous of degree 1: ``chart_terms(k rgb) = k chart_terms(rgb)`` for ``k > 0``.

    >>> chart_terms(jnp.array([4.0, 1.0, 9.0]), "root-polynomial").tolist()
    [4.0, 1.0, 9.0, 2.0, 3.0, 6.0]
    """
    check_choice(model, "model", CHART_MODELS)
    rgb = jnp.asarray(rgb)
    if model == "matrix":
        return rgb
    p = jnp.maximum(rgb, 0.0)
    r, g, b = p[..., 0], p[..., 1], p[..., 2]
    roots = jnp.stack([safe_sqrt(r * g), safe_sqrt(g * b), safe_sqrt(r * b)], -1)
    return jnp.concatenate([rgb, roots], -1)


def _n_terms(model):
    return 3 if model == "matrix" else 6


def _predict(matrix, gains, rgb, model):
    return jnp.einsum("ik,...k->...i", matrix, chart_terms(rgb * gains, model))


def chart_delta_e(camera_rgb, reference_lab, matrix, *, gains=None, model: str = "matrix",
                  illuminant: str = "D50"):  # fmt: skip
    """Per-patch CIEDE2000 ``(P,)`` of the model ``XYZ = matrix · t(gains ⊙ camera_rgb)``
    against ``reference_lab`` ``(P, 3)`` (CIELAB under ``illuminant``, white ``Y = 1``).
    ``camera_rgb`` ``(P, 3)``, ``matrix`` ``(3, K)`` (K = 3 or 6, :func:`chart_terms`),
    ``gains`` ``(3,)`` (default 1). Jittable, differentiable in ``matrix`` and ``gains``."""
    check_choice(model, "model", CHART_MODELS)
    check_choice(illuminant, "illuminant", WHITEPOINTS)
    m = as_float_array(matrix, "matrix")
    if m.shape != (3, _n_terms(model)):
        raise ValueError(f"matrix: expected shape (3, {_n_terms(model)}) for model {model!r}, "
                         f"got {m.shape}")  # fmt: skip
    rgb = as_float_array(camera_rgb, "camera_rgb")
    g = jnp.ones(3, m.dtype) if gains is None else as_float_array(gains, "gains")
    lab = xyz_to_lab(_predict(m, g, rgb, model), white=illuminant)
    return delta_e_2000(lab, as_float_array(reference_lab, "reference_lab"))


@dataclasses.dataclass(frozen=True)
class _Residuals:
    """The fit's residual function (hashable by value, so the compiled solve is reused)."""

    model: str
    white_balance: bool

    def unpack(self, p, white):
        if not self.white_balance:
            return p["m"], jnp.ones(3, p["m"].dtype)
        a = p["a"]
        last = p["s"] * white - jnp.sum(a, axis=1)  # M · t(1, 1, 1) = s · XYZ_white
        lg = p["log_g"]
        gains = jnp.stack([jnp.exp(lg[0]), jnp.ones_like(lg[0]), jnp.exp(lg[1])])
        return jnp.concatenate([a, last[:, None]], axis=1), gains

    def __call__(self, p, args):
        rgb, ref_lab, valid, white = args
        m, g = self.unpack(p, white)
        lab = xyz_to_lab(_predict(m, g, rgb, self.model), white=white)
        r = delta_e_2000_residuals(lab, ref_lab)
        return jnp.where(valid[:, None], r, 0.0)


# ------------------------------------------------------------------------------ the result


class ChartCalibration(eqx.Module):
    """A chart fit: camera RGB -> CIE XYZ under ``illuminant`` as ``matrix · t(gains ⊙ rgb)``.

    Fields: ``matrix`` ``(3, K)`` (:func:`chart_terms`; K = 3 ``"matrix"``, 6
    ``"root-polynomial"``), ``gains`` ``(3,)`` white-balance gains (green 1; all 1 without
    ``white_balance``), ``neutral`` ``(3,)`` the camera RGB (max 1) that maps to the
    illuminant's white, ``delta_e_before`` / ``delta_e_after`` ``(P,)`` per-patch CIEDE2000
    (NaN: a patch left out), ``model``, ``illuminant``, ``white_balance`` and ``before``
    (what "before" was) static. XYZ is in the chart's units (its white patch at ``Y ≈ 0.88`` at
    the photographed exposure); :meth:`normalized` rescales so that ``neutral`` maps to
    ``Y = 1`` (the DNG convention of :func:`jaxgfx.hdr.raw.color_transform`).

    >>> cal = ChartCalibration(jnp.eye(3), jnp.ones(3), jnp.ones(3), jnp.zeros(1), jnp.zeros(1))
    >>> apply_chart_calibration(cal, jnp.array([0.2, 0.5, 0.1])).tolist()
    [0.2, 0.5, 0.1]
    """

    matrix: jax.Array
    gains: jax.Array
    neutral: jax.Array
    delta_e_before: jax.Array
    delta_e_after: jax.Array
    model: str = eqx.field(static=True, default="matrix")
    illuminant: str = eqx.field(static=True, default="D50")
    white_balance: bool = eqx.field(static=True, default=True)
    before: str = eqx.field(static=True, default="")

    def __check_init__(self):
        if self.model not in CHART_MODELS:
            check_choice(self.model, "model", CHART_MODELS)
        if self.illuminant not in WHITEPOINTS:
            check_choice(self.illuminant, "illuminant", WHITEPOINTS)
        k = _n_terms(self.model)
        if np.shape(self.matrix) != (3, k) or np.shape(self.gains) != (3,):
            raise ValueError(
                f"chart calibration: expected matrix (3, {k}) for {self.model!r} and gains (3,), "
                f"got {np.shape(self.matrix)} and {np.shape(self.gains)}"
            )

    def normalized(self) -> ChartCalibration:
        """The same calibration scaled so that ``neutral`` (max 1) maps to ``Y = 1``."""
        y = _predict(self.matrix, self.gains, self.neutral, self.model)[1]
        return dataclasses.replace(self, matrix=self.matrix / y)

    def camera_to_xyz_matrix(self):
        """``(3, 3)`` ``matrix · diag(gains)`` of the ``"matrix"`` model (camera RGB -> XYZ
        under the illuminant, white balance included); for ``"root-polynomial"`` its Jacobian
        at ``neutral`` (exact for greys: the model is homogeneous of degree 1)."""
        if self.model == "matrix":
            return self.matrix * self.gains[None, :]
        return jax.jacfwd(lambda x: _predict(self.matrix, self.gains, x, self.model))(self.neutral)

    def summary(self) -> dict:
        """Median / mean / max ΔE00 before and after (patches used), and patch counts."""
        out: dict = {}
        for k, v in (("before", self.delta_e_before), ("after", self.delta_e_after)):
            v = np.asarray(v, np.float64)
            v = v[np.isfinite(v)]
            out[k] = {
                "median": float(np.median(v)) if v.size else None,
                "mean": float(np.mean(v)) if v.size else None,
                "max": float(np.max(v)) if v.size else None,
            }
        out["patches_used"] = int(np.sum(np.isfinite(np.asarray(self.delta_e_after))))
        out["patches"] = int(np.size(self.delta_e_after))
        return out

    def to_dict(self) -> dict:
        """JSON-ready dict (the report's ``chart`` and ``camera.json``'s ``chart``)."""
        f = lambda a: [None if not np.isfinite(v) else v for v in  # noqa: E731
                       np.asarray(a, np.float64).ravel().tolist()]  # fmt: skip
        return {
            "model": self.model,
            "illuminant": self.illuminant,
            "white_balance": self.white_balance,
            "formula": "XYZ = matrix @ terms(gains * camera_rgb); terms: "
            + (
                "(r, g, b)"
                if self.model == "matrix"
                else "(r, g, b, sqrt(rg), sqrt(gb), sqrt(rb)) (Finlayson et al. 2015)"
            ),  # fmt: skip
            "matrix": np.asarray(self.matrix, np.float64).tolist(),
            "gains": f(self.gains),
            "neutral": f(self.neutral),
            "delta_e_before": f(self.delta_e_before),
            "delta_e_after": f(self.delta_e_after),
            "before_source": self.before,
            **self.summary(),
        }

    @classmethod
    def from_dict(cls, d: dict, where: str = "chart") -> ChartCalibration:
        """Inverse of :meth:`to_dict` (``where`` names the source in errors)."""
        try:
            nan = lambda v: np.asarray([np.nan if x is None else x for x in v])  # noqa: E731
            return cls(
                jnp.asarray(np.asarray(d["matrix"], np.float64)),
                jnp.asarray(np.asarray(d["gains"], np.float64)),
                jnp.asarray(np.asarray(d["neutral"], np.float64)),
                jnp.asarray(nan(d.get("delta_e_before", []))),
                jnp.asarray(nan(d.get("delta_e_after", []))),
                str(d["model"]),
                str(d["illuminant"]),
                bool(d.get("white_balance", True)),
                str(d.get("before_source", "")),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"{where}: not a chart calibration record ({e!r})") from None


def _xyz_to_space(colorspace, illuminant, dtype):
    """XYZ under ``illuminant`` -> ``colorspace`` of :data:`COLORSPACES` (Bradford)."""
    check_choice(colorspace, "colorspace", tuple(s for s in COLORSPACES if s != "camera"))
    white = "D65" if colorspace == "xyz" else RGB_SPACES[colorspace].white
    cat = chromatic_adaptation_matrix(illuminant, white, method="bradford", dtype=dtype)
    if colorspace == "xyz":
        return cat
    return jnp.asarray(np.linalg.inv(rgb_to_xyz_matrix(colorspace)), dtype) @ cat


def apply_chart_calibration(calibration: ChartCalibration, rgb, variance=None, *,
                            colorspace: str | None = None):  # fmt: skip
    """Camera RGB ``(..., 3)`` through a :class:`ChartCalibration`: XYZ under its illuminant
    (``colorspace=None``), or a linear space of :data:`jaxgfx.hdr.raw.COLORSPACES` (``"rec709"``
    linear Rec.709/sRGB primaries, ``"xyz"`` XYZ adapted to D65, ...; Bradford from the
    illuminant to the space's white). With ``variance`` ``(..., 3)`` also the output variance,
    propagated through the model's Jacobian per pixel (channels independent; exact for the
    matrix model). Jittable; ``colorspace`` static."""
    rgb = as_float_array(rgb, "rgb")
    if rgb.shape[-1:] != (3,):
        raise ValueError(f"rgb: expected shape (..., 3), got {rgb.shape}")
    m = jnp.asarray(calibration.matrix, rgb.dtype)
    g = jnp.asarray(calibration.gains, rgb.dtype)
    if colorspace is not None:
        m = _xyz_to_space(colorspace, calibration.illuminant, rgb.dtype) @ m

    def f(x):
        return _predict(m, g, x, calibration.model)

    if variance is None:
        return f(rgb)
    var = as_float_array(variance, "variance")
    out = f(rgb)
    acc = jnp.zeros_like(out)
    for j in range(3):
        e = jnp.zeros_like(rgb).at[..., j].set(1.0)
        d = jax.jvp(f, (rgb,), (e,))[1]
        acc = acc + d * d * var[..., j : j + 1]
    return out, acc


# ------------------------------------------------------------------------------ the fit

_MIN_PATCHES = {"matrix": 5, "root-polynomial": 8}


def _lstsq_start(t, xyz, white, white_balance, n_terms):
    """Linear least squares in XYZ (host, float64): free ``M`` (3, K), or with white balance
    the constrained ``(A (3, K-1), s)`` of ``M = [A, s w - A 1]``."""
    if not white_balance:
        return np.linalg.lstsq(t, xyz, rcond=None)[0].T, None
    p, k = t.shape
    rows, rhs = [], []
    for i in range(3):  # unknowns: A (3 x (K-1)) row-major, then s
        d = np.zeros((p, 3 * (k - 1) + 1))
        d[:, i * (k - 1) : (i + 1) * (k - 1)] = t[:, : k - 1] - t[:, k - 1 : k]
        d[:, -1] = white[i] * t[:, k - 1]
        rows.append(d)
        rhs.append(xyz[:, i])
    sol = np.linalg.lstsq(np.concatenate(rows), np.concatenate(rhs), rcond=None)[0]
    return sol[:-1].reshape(3, k - 1), sol[-1]


def fit_chart_matrix(camera_rgb, reference=None, *, reference_space: str = "xyz",
                     model: str = "matrix", white_balance: bool = True, illuminant: str = "D50",
                     before=None, before_source: str | None = None,
                     max_steps: int = 200) -> ChartCalibration:  # fmt: skip
    """Fit camera RGB -> XYZ (and the white balance) to a chart by least squares on CIEDE2000.

    Args:
      camera_rgb: ``(P, 3)`` the patches' linear camera RGB (:func:`chart_patch_means`); any
        exposure. Patches with a non-finite channel (clipped: ``saturation`` of
        :func:`chart_patch_means`) or no positive one (zero) are left out.
      reference: ``(P, 3)`` the patches' reference in ``reference_space`` (``"xyz"``: CIE XYZ
        under ``illuminant`` with white ``Y = 1``; ``"lab"``: CIELAB under ``illuminant``);
        default the ColorChecker of :func:`colorchecker_reference` (its D50 values,
        Bradford-adapted when ``illuminant`` is another white).
      model: ``"matrix"`` (3x3) or ``"root-polynomial"`` (3x6, Finlayson et al. 2015).
      white_balance: fit gains ``(g_R, 1, g_B)`` jointly with a matrix that maps the balanced
        neutral to the illuminant's white (module doc); ``False``: no gains, a free matrix.
      illuminant: the white of the output XYZ and of CIELAB (a name of
        :data:`jaxgfx.color.WHITEPOINTS`; D50, the ICC profile connection space, by default).
      before: ``(3, 3)`` a camera RGB -> XYZ(``illuminant``) matrix to report as "before"
        (e.g. the DNG matrix), its exposure matched to the reference by one least-squares scale
        of Y; default: the linear least-squares start of the fit. ``before_source`` says
        what it was (the report's words).
      max_steps: Levenberg-Marquardt steps.

    Returns a :class:`ChartCalibration` (per-patch ΔE00 before and after, NaN where a patch was
    left out). Raises ``ValueError`` naming the argument: wrong shapes, fewer usable patches
    than the model needs (5 for the matrix, 8 for the root-polynomial; all clipped or zero is
    one such case), an unknown model / space / illuminant. The solve is one compiled
    Levenberg-Marquardt program (:func:`jaxgfx.optim.fit_least_squares`), reused across calls
    with the same model, white balance and patch count.
    """
    from jaxgfx.optim import fit_least_squares

    check_choice(model, "model", CHART_MODELS)
    check_choice(reference_space, "reference_space", ("xyz", "lab"))
    check_choice(illuminant, "illuminant", WHITEPOINTS)
    if not isinstance(white_balance, bool):
        raise ValueError(f"white_balance: expected True or False, got {white_balance!r}")
    rgb = np.asarray(as_float_array(camera_rgb, "camera_rgb"), np.float64)
    if rgb.ndim != 2 or rgb.shape[1] != 3:
        raise ValueError(f"camera_rgb: expected shape (P, 3) (patches x RGB), got {rgb.shape}")
    dt = jnp.float64 if jax.config.jax_enable_x64 else jnp.float32
    wxyz = np.asarray(whitepoint_xyz(illuminant, like=jnp.zeros((), dt)), np.float64)
    if reference is None:
        ref = colorchecker_reference()
        xyz = ref.xyz
        if np.abs(ref.illuminant_xy - np.asarray(WHITEPOINTS[illuminant])).max() > 1e-3:
            cat = chromatic_adaptation_matrix(jnp.asarray(ref.illuminant_xy, dt), illuminant,
                                              method="bradford")  # fmt: skip
            xyz = xyz @ np.asarray(cat, np.float64).T
        ref_lab = np.asarray(xyz_to_lab(jnp.asarray(xyz, dt), white=illuminant), np.float64)
    else:
        r = np.asarray(as_float_array(reference, "reference"), np.float64)
        if r.shape != rgb.shape:
            raise ValueError(
                f"reference: expected shape {rgb.shape} (one {reference_space.upper()} per "
                f"patch of camera_rgb), got {r.shape}"
            )
        if not np.all(np.isfinite(r)):
            raise ValueError("reference: expected finite values")
        if reference_space == "xyz":
            xyz = r
            ref_lab = np.asarray(xyz_to_lab(jnp.asarray(r, dt), white=illuminant), np.float64)
        else:
            from jaxgfx.color import lab_to_xyz

            ref_lab = r
            xyz = np.asarray(lab_to_xyz(jnp.asarray(r, dt), white=illuminant), np.float64)
    if xyz.shape != rgb.shape:
        raise ValueError(
            f"camera_rgb: expected {xyz.shape[0]} patches (the reference chart's), got "
            f"{rgb.shape[0]}"
        )
    valid = np.all(np.isfinite(rgb), axis=1) & np.any(rgb > 0, axis=1)
    need = _MIN_PATCHES[model]
    if valid.sum() < need:
        raise ValueError(
            f"camera_rgb: {int(valid.sum())} usable patches of {rgb.shape[0]} (the rest "
            f"clipped, zero or non-finite); the {model} model needs at least {need}: check the "
            "chart's corners and its exposure"
        )
    k = 1.0 / rgb[valid].max()  # the fit on rgb in (0, 1]; M scales back (degree 1)
    rgb_n = np.where(valid[:, None], rgb * k, 1.0)
    nt = _n_terms(model)
    t_lin = rgb_n[valid]
    p_lin = np.linalg.lstsq(t_lin, xyz[valid], rcond=None)[0].T  # (3, 3) camera -> XYZ
    gains0 = np.ones(3)
    if white_balance:
        n0 = np.linalg.solve(p_lin, wxyz)
        if np.all(n0 > 0):
            gains0 = n0[1] / n0
    t = np.asarray(chart_terms(jnp.asarray(rgb_n[valid] * gains0), model), np.float64)
    m0, s0 = _lstsq_start(t, xyz[valid], wxyz, white_balance, nt)
    if white_balance:
        p0 = {"a": jnp.asarray(m0, dt), "s": jnp.asarray(s0, dt),
              "log_g": jnp.asarray(np.log(gains0[[0, 2]]), dt)}  # fmt: skip
        start = np.concatenate([m0, (s0 * wxyz - m0.sum(1))[:, None]], 1)
    else:
        p0 = {"m": jnp.asarray(m0, dt)}
        start = m0
    fn = _Residuals(model, white_balance)
    args = (jnp.asarray(rgb_n, dt), jnp.asarray(ref_lab, dt), jnp.asarray(valid),
            jnp.asarray(wxyz, dt))  # fmt: skip
    res = fit_least_squares(fn, p0, args=args, max_steps=max_steps)
    m, g = fn.unpack(res.params, args[3])
    m = m * k
    rgb_j, ref_j = jnp.asarray(np.where(valid[:, None], rgb, 1.0), dt), jnp.asarray(ref_lab, dt)
    nan = jnp.asarray(np.where(valid, 0.0, np.nan), dt)  # patches left out: NaN
    after = nan + chart_delta_e(rgb_j, ref_j, m, gains=g, model=model, illuminant=illuminant)
    if before is None:
        b_m, b_g, b_model = jnp.asarray(start * k, dt), jnp.asarray(gains0, dt), model
        b_src = before_source or "linear least squares in XYZ (the fit's start)"
    else:
        b = np.asarray(as_float_array(before, "before"), np.float64)
        if b.shape != (3, 3) or not np.all(np.isfinite(b)):
            raise ValueError(
                f"before: expected a finite (3, 3) camera -> XYZ matrix, got {b.shape}"
            )
        y_b, y_r = (rgb[valid] @ b.T)[:, 1], xyz[valid, 1]
        scale = float(y_b @ y_r / max(float(y_b @ y_b), 1e-300))
        b_m, b_g, b_model = jnp.asarray(b * scale, dt), jnp.ones(3, dt), "matrix"
        b_src = before_source or "the given matrix (exposure matched in Y)"
    before_de = nan + chart_delta_e(rgb_j, ref_j, b_m, gains=b_g, model=b_model,
                                    illuminant=illuminant)  # fmt: skip
    neutral = _neutral(np.asarray(m, np.float64), np.asarray(g, np.float64), wxyz, p_lin, model,
                       white_balance)  # fmt: skip
    return ChartCalibration(
        m, g, jnp.asarray(neutral, dt), before_de, after, model, illuminant, white_balance,
        f"{b_src}; fit: {res.stop_reason} after {res.n_steps} Levenberg-Marquardt steps",
    )  # fmt: skip


def _neutral(m, g, wxyz, p_lin, model, white_balance):
    """The camera RGB (max 1) that the fitted model maps to the illuminant's white: ``1/g``
    with white balance (exact by the constraint), ``M^-1 w`` for a free matrix, and for a free
    root-polynomial a few Newton steps from the linear fit's neutral."""
    if white_balance:
        n = 1.0 / g
    elif model == "matrix":
        n = np.linalg.solve(m, wxyz)
    else:
        n = np.linalg.solve(p_lin, wxyz)
        n = n / n.max()
        f = lambda x: _predict(jnp.asarray(m), jnp.asarray(g), x, model)  # noqa: E731
        for _ in range(20):  # f(n) = c w: solve for n (3) with c fixed by n's scale
            y = np.asarray(f(jnp.asarray(n)), np.float64)
            c = y[1] / wxyz[1]
            jac = np.asarray(jax.jacfwd(f)(jnp.asarray(n)), np.float64)
            n = n - np.linalg.lstsq(jac - np.outer(wxyz, jac[1] / wxyz[1]), y - c * wxyz,
                                    rcond=None)[0]  # fmt: skip
    return n / np.max(n)
