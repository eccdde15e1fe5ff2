"""Von Kries-type chromatic adaptation transforms (CATs) and RGB -> RGB conversion.

A CAT maps XYZ seen under a source white to the corresponding XYZ under a destination white:
``M = A^-1 diag(A w_dst / A w_src) A`` with ``A`` a cone-like response matrix (von Kries
1902 in its modern linear form; Fairchild, *Color Appearance Models*, 3rd ed., §9).

The public functions validate names and white points eagerly, then call one jitted core
(``_*``) with the names static and the white points traced.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_choice
from ._common import as_colour, cast_const, matvec3
from .spaces import _RGB_TO_XYZ, _XYZ_TO_RGB, RGB_SPACES, whitepoint_xyz

__all__ = [
    "CAT_MATRICES",
    "chromatic_adaptation_matrix",
    "chromatic_adaptation",
    "rgb_to_rgb",
]

#: Cone response matrices (XYZ -> LMS-like), as published.
CAT_MATRICES: dict[str, np.ndarray] = {
    # Lam (1985) / Lam & Rigg, linearised Bradford (as used by ICC v4 and Lindbloom).
    "bradford": np.array(
        [[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]]
    ),
    # Hunt-Pointer-Estevez, normalised to D65 (Fairchild 2013, eq. 9.6).
    "von_kries": np.array(
        [[0.40024, 0.70760, -0.08081], [-0.22630, 1.16532, 0.04570], [0.0, 0.0, 0.91822]]
    ),
    # CIECAM02 (CIE 159:2004), Moroney et al. 2002.
    "cat02": np.array(
        [[0.7328, 0.4296, -0.1624], [-0.7036, 1.6975, 0.0061], [0.0030, 0.0136, 0.9834]]
    ),
    # Scaling XYZ directly (the simplest, and worst, "wrong von Kries").
    "xyz_scaling": np.eye(3),
}
_CAT_INV = {k: np.linalg.inv(m) for k, m in CAT_MATRICES.items()}


def _cat_matrix(src_xyz, dst_xyz, method, like):
    A = cast_const(CAT_MATRICES[method], like)
    Ainv = cast_const(_CAT_INV[method], like)
    gain = (dst_xyz @ A.T) / (src_xyz @ A.T)  # (..., 3): batched whites broadcast
    return Ainv @ (gain[..., :, None] * A)


@functools.partial(jax.jit, static_argnames=("method",))
def _cat_matrix_jit(src_xyz, dst_xyz, like, *, method):
    return _cat_matrix(src_xyz, dst_xyz, method, like)


@functools.partial(jax.jit, static_argnames=("method",))
def _adapt(xyz, src_xyz, dst_xyz, *, method):
    return matvec3(_cat_matrix(src_xyz, dst_xyz, method, xyz), xyz)


@functools.partial(jax.jit, static_argnames=("src", "dst", "adaptation"))
def _rgb_to_rgb(rgb, *, src, dst, adaptation):
    M = cast_const(_RGB_TO_XYZ[src], rgb)
    ws, wd = RGB_SPACES[src].white, RGB_SPACES[dst].white
    if adaptation is not None and ws != wd:
        src_w = whitepoint_xyz(ws, like=rgb)
        dst_w = whitepoint_xyz(wd, like=rgb)
        M = _cat_matrix(src_w, dst_w, adaptation, rgb) @ M
    M = cast_const(_XYZ_TO_RGB[dst], rgb) @ M
    return matvec3(M, rgb)


def chromatic_adaptation_matrix(src_white, dst_white, *, method="bradford", dtype=None):
    """The ``(3, 3)`` XYZ -> XYZ von Kries-type adaptation matrix from ``src_white`` to
    ``dst_white``.

    Args:
      src_white, dst_white: white points: a name in
        :data:`jaxgfx.color.spaces.WHITEPOINTS` (``"D50"``, ``"D65"``, ``"A"``, ``"E"``, ...),
        an xy pair ``(2,)`` (normalised to ``Y = 1``) or XYZ ``(3,)`` (used as given, so
        luminance differences are kept). Array whites are differentiable.
      method: ``"bradford"``, ``"von_kries"``, ``"cat02"`` or ``"xyz_scaling"``.
      dtype: output dtype when both whites are names (default float32).

    Example:
      >>> M = chromatic_adaptation_matrix("D65", "D50")
      >>> [round(float(v), 4) for v in M[0]]  # Lindbloom's D65 -> D50 Bradford matrix
      [1.0479, 0.0229, -0.0502]
    """
    check_choice(method, "method", CAT_MATRICES)
    like = jnp.zeros((), dtype or jnp.float32)
    for w in (src_white, dst_white):
        if not isinstance(w, str):
            wd = jnp.asarray(w).dtype
            if jnp.issubdtype(wd, jnp.floating):
                like = jnp.zeros((), jnp.result_type(like, wd))
    src = whitepoint_xyz(src_white, "src_white", like=like)
    dst = whitepoint_xyz(dst_white, "dst_white", like=like)
    return _cat_matrix_jit(src, dst, like, method=method)


def chromatic_adaptation(xyz, src_white, dst_white, *, method="bradford"):
    """Adapt XYZ colours from ``src_white`` to ``dst_white`` (see
    :func:`chromatic_adaptation_matrix`); ``xyz`` is ``(..., 3)``, output has its dtype.

    Example:
      >>> w = chromatic_adaptation(whitepoint_xyz("D65"), "D65", "D50")
      >>> [round(float(v), 4) for v in w]  # D65 white -> D50 white
      [0.9643, 1.0, 0.8251]
    """
    check_choice(method, "method", CAT_MATRICES)
    xyz = as_colour(xyz, "xyz")
    src = whitepoint_xyz(src_white, "src_white", like=xyz)
    dst = whitepoint_xyz(dst_white, "dst_white", like=xyz)
    return _adapt(xyz, src, dst, method=method)


def rgb_to_rgb(rgb, *, src="srgb", dst="prophoto", adaptation="bradford"):
    """Convert *linear* RGB between named spaces through XYZ, adapting white points when they
    differ (e.g. sRGB/D65 -> ProPhoto/D50). ``adaptation=None`` skips the CAT.

    Example:
      >>> [round(float(v), 4) for v in rgb_to_rgb(jnp.ones(3), src="srgb", dst="prophoto")]
      [1.0, 1.0, 1.0]
    """
    check_choice(src, "src", RGB_SPACES)
    check_choice(dst, "dst", RGB_SPACES)
    if adaptation is not None:
        check_choice(adaptation, "adaptation", CAT_MATRICES)
    rgb = as_colour(rgb, "rgb")
    return _rgb_to_rgb(rgb, src=src, dst=dst, adaptation=adaptation)
