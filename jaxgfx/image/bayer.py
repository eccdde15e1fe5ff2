"""Bayer colour-filter-array (CFA) mosaicking and demosaicing.

A Bayer sensor measures one colour per photosite in a repeating 2 × 2 tile; the pattern name
lists the tile row by row: ``"RGGB"`` means R at (0, 0), G at (0, 1) and (1, 0), B at (1, 1)
(top-left of the image). Demosaicing estimates the two missing colours of every pixel
(lecture 1: "first operation on the way from the real image to the screen").

Borders use mirror reflection about the edge pixel (NumPy ``"reflect"``, ``d c b | a b c d``),
which keeps the CFA phase (a reflected site has the colour of its mirror image), so border
pixels are interpolated with the same kernels as interior ones. Kernels are applied by
shift-and-add (no ``lax.conv``).

Note on OpenCV names: OpenCV's ``COLOR_Bayer<XY>2RGB`` names the pattern by the second row's
2nd and 3rd pixels, so ``"RGGB"`` here is ``cv2.COLOR_BayerBG2RGB`` (``BGGR`` → ``RG``,
``GRBG`` → ``GB``, ``GBRG`` → ``GR``); verified in the tests.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_choice, check_image

__all__ = [
    "BAYER_PATTERNS",
    "DEMOSAIC_METHODS",
    "bayer_masks",
    "bayer_mosaic",
    "demosaic",
    "demosaic_bilinear",
    "demosaic_Malvar2004",
]

BAYER_PATTERNS = ("RGGB", "BGGR", "GRBG", "GBRG")
_CH = {"R": 0, "G": 1, "B": 2}


def _pattern_channels(pattern):
    """Channel index (0 = R, 1 = G, 2 = B) of the 2 × 2 tile, as a (2, 2) NumPy array."""
    check_choice(pattern, "pattern", BAYER_PATTERNS)
    return np.array([_CH[c] for c in pattern]).reshape(2, 2)


def _channel_map(h, w, pattern):
    tile = _pattern_channels(pattern)
    return np.tile(tile, ((h + 1) // 2, (w + 1) // 2))[:h, :w]


def _check_shape(shape):
    try:
        h, w = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ValueError(f"shape: expected (H, W), got {shape!r}") from None
    if h < 1 or w < 1:
        raise ValueError(f"shape: expected positive (H, W), got {shape!r}")
    return h, w


def bayer_masks(shape, pattern="RGGB"):
    """Boolean masks of the R, G and B photosites of an ``(H, W)`` Bayer sensor.

    Returns:
        bool array ``(H, W, 3)``; exactly one channel is True at every pixel (G on half the
        sites, R and B on a quarter each). Any ``H, W >= 1`` (odd sizes allowed).

    Example:
        >>> bayer_masks((2, 2), "RGGB")[..., 0].tolist()
        [[True, False], [False, False]]
    """
    h, w = _check_shape(shape)
    cmap = _channel_map(h, w, pattern)
    return jnp.asarray(cmap[..., None] == np.arange(3))


def bayer_mosaic(rgb, pattern="RGGB"):
    """Simulate a Bayer sensor: keep, at every pixel, the one colour its filter passes.

    Args:
        rgb: ``(..., H, W, 3)`` linear RGB image (any ``H, W >= 1``).
        pattern: ``"RGGB"``, ``"BGGR"``, ``"GRBG"`` or ``"GBRG"``.

    Returns:
        Raw mosaic ``(..., H, W)``, same dtype; linear (differentiable) in ``rgb``.

    Example:
        >>> bayer_mosaic(jnp.ones((2, 2, 3)) * jnp.array([1.0, 2.0, 3.0])).tolist()
        [[1.0, 2.0], [2.0, 3.0]]
    """
    x = check_image(rgb, "rgb", min_ndim=3, channels=3)
    return _mosaic(x, _tile(pattern))


def _tile(pattern):
    """The checked pattern's (2, 2) channel tile as an int32 array: a traced core argument,
    so that one compiled program serves all four patterns."""
    return jnp.asarray(_pattern_channels(pattern), jnp.int32)


def _tile_maps(tile, h, w):
    """Channel of every site, and the channel held by its row (its horizontal neighbour's),
    ``(h, w)`` int32, from the (2, 2) ``tile`` (traceable)."""
    even_row = jax.lax.broadcasted_iota(jnp.int32, (h, 1), 0) % 2 == 0
    even_col = jax.lax.broadcasted_iota(jnp.int32, (1, w), 1) % 2 == 0
    first, second = (
        jnp.where(even_row, tile[0, 0], tile[1, 0]),
        jnp.where(even_row, tile[0, 1], tile[1, 1]),
    )
    return jnp.where(even_col, first, second), jnp.where(even_col, second, first)


@jax.jit
def _mosaic(x, tile):
    h, w = x.shape[-3], x.shape[-2]
    cmap, _ = _tile_maps(tile, h, w)
    return jnp.take_along_axis(x, jnp.broadcast_to(cmap[..., None], x.shape[:-1] + (1,)), -1)[
        ..., 0
    ]


# 5 × 5 kernels as {(dy, dx): weight}; the estimate at p is sum_w w · raw[p + (dy, dx)].
_BILINEAR = {
    "cross": {(-1, 0): 0.25, (1, 0): 0.25, (0, -1): 0.25, (0, 1): 0.25},
    "diag": {(-1, -1): 0.25, (-1, 1): 0.25, (1, -1): 0.25, (1, 1): 0.25},
    "row": {(0, -1): 0.5, (0, 1): 0.5},
    "col": {(-1, 0): 0.5, (1, 0): 0.5},
}


def _malvar_kernels():
    """Malvar, He & Cutler (ICASSP 2004), Fig. 2, in units of 1/8.

    cross: G at R/B sites (α = 1/2); row: R (or B) at a G site whose *row* holds R (or B)
    (β = 5/8); col: its transpose; diag: R at B and B at R (γ = 3/4).
    """
    g_at_rb = {(0, 0): 4, (-1, 0): 2, (1, 0): 2, (0, -1): 2, (0, 1): 2}
    g_at_rb.update({(-2, 0): -1, (2, 0): -1, (0, -2): -1, (0, 2): -1})
    row = {(0, 0): 5, (0, -1): 4, (0, 1): 4, (0, -2): -1, (0, 2): -1, (-2, 0): 0.5, (2, 0): 0.5}
    row.update({(-1, -1): -1, (-1, 1): -1, (1, -1): -1, (1, 1): -1})
    col = {(dx, dy): v for (dy, dx), v in row.items()}
    diag = {(0, 0): 6, (-1, -1): 2, (-1, 1): 2, (1, -1): 2, (1, 1): 2}
    diag.update({(-2, 0): -1.5, (2, 0): -1.5, (0, -2): -1.5, (0, 2): -1.5})
    scale = lambda k: {o: v / 8.0 for o, v in k.items()}
    return {"cross": scale(g_at_rb), "diag": scale(diag), "row": scale(row), "col": scale(col)}


_MALVAR = _malvar_kernels()
_KERNELS = {"bilinear": _BILINEAR, "malvar": _MALVAR}
_PAD = 2


def _apply(padded, kernel, h, w):
    """Shift-and-add correlation of the padded raw with a sparse 5 × 5 kernel."""
    acc = None
    for (dy, dx), wgt in kernel.items():
        sl = padded[..., _PAD + dy : _PAD + dy + h, _PAD + dx : _PAD + dx + w]
        acc = wgt * sl if acc is None else acc + wgt * sl
    return acc


@functools.partial(jax.jit, static_argnames=("method",))
def _demosaic(raw, tile, *, method):
    h, w = raw.shape[-2:]
    cmap, row_colour = _tile_maps(tile, h, w)
    pad = [(0, 0)] * (raw.ndim - 2) + [(_PAD, _PAD), (_PAD, _PAD)]
    p = jnp.pad(raw, pad, mode="reflect")
    est = {name: _apply(p, k, h, w) for name, k in _KERNELS[method].items()}
    out = []
    for c, other in ((0, 2), (2, 0)):
        v = jnp.where((cmap == 1) & (row_colour == c), est["row"], est["col"])
        v = jnp.where(cmap == other, est["diag"], v)
        out.append(jnp.where(cmap == c, raw, v))
    g = jnp.where(cmap == 1, raw, est["cross"])
    return jnp.stack([out[0], g, out[1]], axis=-1)


DEMOSAIC_METHODS = ("bilinear", "malvar")


def demosaic(raw, pattern="RGGB", *, method="malvar"):
    """Reconstruct an RGB image from a Bayer mosaic.

    Methods (both linear in ``raw``, hence differentiable with a constant Jacobian):

    - ``"bilinear"``: each missing colour is the mean of its nearest same-colour neighbours
      (2 or 4 of them). Exact for constant and linear (ramp) images away from the border.
    - ``"malvar"``: gradient-corrected bilinear interpolation of Malvar, He & Cutler, "High-
      quality linear interpolation for demosaicing of Bayer-patterned color images", ICASSP
      2004: bilinear plus a scaled Laplacian of the colour measured at the site
      (α = 1/2, β = 5/8, γ = 3/4; the 5 × 5 kernels of their Fig. 2). Fewer colour fringes,
      ~5 dB higher PSNR than bilinear on natural images (paper).

    Measured samples are returned unchanged: ``bayer_mosaic(demosaic(m)) == m`` exactly.

    Args:
        raw: mosaic ``(..., H, W)`` with ``H, W >= 3`` (odd sizes allowed).
        pattern: ``"RGGB"``, ``"BGGR"``, ``"GRBG"`` or ``"GBRG"``.
        method: ``"bilinear"`` or ``"malvar"``.

    Returns:
        ``(..., H, W, 3)`` RGB of the dtype of ``raw``. Not clipped: Malvar's negative lobes
        can undershoot 0 / overshoot the white level at sharp edges.

    Example:
        >>> demosaic(jnp.full((4, 4), 0.5))[1, 2].tolist()
        [0.5, 0.5, 0.5]
    """
    x = check_image(raw, "raw")
    check_choice(pattern, "pattern", BAYER_PATTERNS)
    check_choice(method, "method", DEMOSAIC_METHODS)
    if x.shape[-2] < 3 or x.shape[-1] < 3:
        raise ValueError(f"raw: expected a mosaic (..., H, W) with H, W >= 3, got {x.shape}")
    return _demosaic(x, _tile(pattern), method=method)


def demosaic_bilinear(raw, pattern="RGGB"):
    """:func:`demosaic` with ``method="bilinear"``."""
    return demosaic(raw, pattern, method="bilinear")


def demosaic_Malvar2004(raw, pattern="RGGB"):  # noqa: N802 (author-year name)
    """:func:`demosaic` with ``method="malvar"`` (Malvar, He & Cutler 2004)."""
    return demosaic(raw, pattern, method="malvar")
