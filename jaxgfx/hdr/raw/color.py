"""White balance and the camera matrix of a RAW bracket: camera RGB -> a working colour space.

The DNG colour model (Adobe, *Digital Negative Specification* 1.4, chapter 6, "Mapping Camera
Color Space to CIE XYZ Space"), as the DNG SDK implements it (``dng_color_spec``):

- ``XYZtoCamera(g) = AB · CC(g) · CM(g)``: ``CM`` the ColorMatrix1/2 (XYZ -> camera, one per
  calibration illuminant), ``CC`` CameraCalibration1/2 (identity when absent), ``AB`` the
  AnalogBalance diagonal; matrices are interpolated linearly in *inverse* correlated colour
  temperature, ``g = (1/T - 1/T2) / (1/T1 - 1/T2)`` clipped to [0, 1].
- the white balance is a *camera neutral* (AsShotNeutral, or ``1 / gains`` of a grey-world /
  white-patch estimate); its chromaticity ``xy`` solves ``xy = xy(XYZtoCamera(T(xy))^-1 n)``
  (fixed-point iteration from D50; ``T`` by Robertson 1968, :func:`jaxgfx.color.xy_to_cct`);
- camera -> XYZ(D50): with ForwardMatrix1/2, ``FM(g) · diag(AB·CC)^-1 n)^-1 · (AB·CC)^-1``;
  without, ``(XYZtoCamera · CAT(D50 -> xy) / s)^-1`` with the Bradford CAT and ``s`` making the
  normalised neutral (max 1) map to D50 with ``Y = 1``.

Non-DNG RAWs use LibRaw's ``rgb_cam`` (camera -> linear sRGB after LibRaw's white balance).
The result converts XYZ(D50) to the chosen space (:data:`COLORSPACES`) with the Bradford CAT
to that space's white. Everything on arrays is jittable and differentiable in the neutral;
the oracle in the tests is colour-hdri's implementation of the same chapter.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import check_choice
from jaxgfx.color import (
    RGB_SPACES,
    WHITEPOINTS,
    chromatic_adaptation_matrix,
    rgb_to_xyz_matrix,
    whitepoint_xyz,
    xy_to_cct,
)

__all__ = [
    "COLORSPACES",
    "RAW_WHITE_BALANCES",
    "ILLUMINANT_CCT",
    "DngColorProfile",
    "ColorTransform",
    "dng_xyz_to_camera",
    "dng_neutral_to_xy",
    "dng_camera_to_xyz_d50",
    "xyz_d50_to_space_matrix",
    "color_transform",
    "apply_color_transform",
    "exr_chromaticities",
]

COLORSPACES = ("rec709", "srgb", "xyz", "aces2065-1", "acescg", "prophoto", "rec2020", "camera")
"""Output spaces of a RAW merge: linear RGB spaces of :data:`jaxgfx.color.RGB_SPACES`, CIE XYZ
(adapted to D65) or ``"camera"`` (no white balance, no matrix: the sensor's own RGB)."""

RAW_WHITE_BALANCES = ("as_shot", "grey_world", "white_patch")
"""White balance of a RAW merge: the camera's as-shot neutral (DNG AsShotNeutral / LibRaw
``camera_whitebalance``) or an estimate from the merged image (:mod:`jaxgfx.color`)."""

#: EXIF LightSource code -> correlated colour temperature (K), as the DNG SDK maps the
#: CalibrationIlluminant tags (dng_camera_profile.cpp, IlluminantToTemperature).
ILLUMINANT_CCT = {
    17: 2850.0,  # standard light A
    3: 2850.0,  # tungsten
    24: 3200.0,  # ISO studio tungsten
    23: 5000.0,  # D50
    20: 5500.0,  # D55
    1: 5500.0,  # daylight
    9: 5500.0,  # fine weather
    4: 5500.0,  # flash
    18: 5500.0,  # standard light B
    21: 6500.0,  # D65
    19: 6500.0,  # standard light C
    10: 6500.0,  # cloudy weather
    22: 7500.0,  # D75
    11: 7500.0,  # shade
    12: 6400.0,  # daylight fluorescent
    13: 5050.0,  # day white fluorescent
    14: 4150.0,  # cool white fluorescent
    2: 4150.0,  # fluorescent
    15: 3525.0,  # white fluorescent
    16: 2925.0,  # warm white fluorescent
}


class DngColorProfile(eqx.Module):
    """The colour tags of a DNG: ColorMatrix1/2 (XYZ -> camera) at the calibration
    illuminants' temperatures ``cct1``/``cct2``, CameraCalibration1/2, AnalogBalance,
    ForwardMatrix1/2 (``None`` when absent; ``color_matrix2 is None``: one illuminant)."""

    color_matrix1: jax.Array
    color_matrix2: jax.Array | None
    cct1: jax.Array
    cct2: jax.Array
    camera_calibration1: jax.Array
    camera_calibration2: jax.Array
    analog_balance: jax.Array
    forward_matrix1: jax.Array | None = None
    forward_matrix2: jax.Array | None = None

    @classmethod
    def from_tags(cls, tags: dict, name: str = "dng_color") -> DngColorProfile:
        """From :attr:`jaxgfx.io.RawImage.dng_color`; ``ValueError`` naming ``name`` when there
        is no 3x3 ColorMatrix1 (a 3-colour CFA is required)."""
        cm1 = tags.get("color_matrix1")
        if cm1 is None or np.size(cm1) != 9 or not np.all(np.isfinite(cm1)):
            raise ValueError(
                f"{name}: no 3x3 ColorMatrix1 colour tag, so the camera's colours are unknown; "
                "use colorspace 'camera' (--colorspace camera) to keep camera RGB"
            )

        def mat(key):
            v = tags.get(key)
            return None if v is None or np.size(v) != 9 else jnp.asarray(np.reshape(v, (3, 3)))

        def cct(key, default):
            code = tags.get(key)
            code = int(np.ravel(code)[0]) if code is not None and np.size(code) else None
            return jnp.asarray(ILLUMINANT_CCT.get(code, default))

        eye = jnp.eye(3)
        ab = tags.get("analog_balance")
        return cls(
            color_matrix1=mat("color_matrix1"),
            color_matrix2=mat("color_matrix2"),
            cct1=cct("calibration_illuminant1", 6500.0),
            cct2=cct("calibration_illuminant2", 6500.0),
            camera_calibration1=mat("camera_calibration1")
            if mat("camera_calibration1") is not None
            else eye,
            camera_calibration2=mat("camera_calibration2")
            if mat("camera_calibration2") is not None
            else eye,
            analog_balance=jnp.ones(3) if ab is None or np.size(ab) != 3 else jnp.asarray(ab),
            forward_matrix1=mat("forward_matrix1"),
            forward_matrix2=mat("forward_matrix2"),
        )


def _weight(profile: DngColorProfile, cct):
    """Weight of the first calibration illuminant at ``cct`` (inverse-temperature linear)."""
    if profile.color_matrix2 is None:
        return jnp.ones_like(cct)
    t1, t2 = profile.cct1, profile.cct2
    g = (1.0 / cct - 1.0 / t2) / jnp.where(t1 == t2, 1.0, 1.0 / t1 - 1.0 / t2)
    return jnp.where(t1 == t2, 1.0, jnp.clip(g, 0.0, 1.0))


def _mix(a, b, g):
    return a if b is None else g * a + (1.0 - g) * b


def _abcc(profile, g):
    return jnp.diag(profile.analog_balance) @ _mix(
        profile.camera_calibration1, profile.camera_calibration2, g
    )


def dng_xyz_to_camera(profile: DngColorProfile, white_xy):
    """``XYZtoCamera = AB · CC · CM`` interpolated at the temperature of ``white_xy``."""
    g = _weight(profile, xy_to_cct(white_xy))
    return _abcc(profile, g) @ _mix(profile.color_matrix1, profile.color_matrix2, g)


def _xyz(xy):
    return jnp.stack([xy[0] / xy[1], 1.0, (1.0 - xy[0] - xy[1]) / xy[1]])


def dng_neutral_to_xy(profile: DngColorProfile, neutral, *, iterations: int = 30):
    """Chromaticity of the white whose camera response is ``neutral`` (the DNG SDK's
    ``NeutralToXY``: fixed-point iteration from D50)."""

    def step(_, xy):
        xyz = jnp.linalg.solve(dng_xyz_to_camera(profile, xy), neutral)
        return xyz[:2] / jnp.sum(xyz)

    return jax.lax.fori_loop(0, iterations, step, jnp.asarray(WHITEPOINTS["D50"], neutral.dtype))


def dng_camera_to_xyz_d50(profile: DngColorProfile, neutral):
    """Camera RGB -> XYZ(D50) for the camera neutral ``neutral`` ``(3,)``; returns
    ``(matrix, white_xy, cct)``. The neutral, normalised to max 1, maps to D50 with Y = 1."""
    xy = dng_neutral_to_xy(profile, neutral)
    cct = xy_to_cct(xy)
    g = _weight(profile, cct)
    d50 = whitepoint_xyz("D50", like=neutral)
    if profile.forward_matrix1 is not None:
        abcc = _abcc(profile, g)
        cam_white = dng_xyz_to_camera(profile, xy) @ _xyz(xy)
        cam_white = cam_white / jnp.max(cam_white)
        ref = jnp.linalg.solve(abcc, cam_white)
        fm = _mix(profile.forward_matrix1, profile.forward_matrix2, g)
        return fm @ jnp.diag(1.0 / ref) @ jnp.linalg.inv(abcc), xy, cct
    cat = chromatic_adaptation_matrix(d50, _xyz(xy), method="bradford")  # D50 -> white
    pcs_to_cam = dng_xyz_to_camera(profile, xy) @ cat
    pcs_to_cam = pcs_to_cam / jnp.max(pcs_to_cam @ d50)
    return jnp.linalg.inv(pcs_to_cam), xy, cct


def xyz_d50_to_space_matrix(space: str, *, dtype=jnp.float32):
    """XYZ(D50) -> linear ``space`` (Bradford to the space's white; ``"xyz"``: XYZ at D65)."""
    check_choice(space, "colorspace", tuple(s for s in COLORSPACES if s != "camera"))
    white = "D65" if space == "xyz" else RGB_SPACES[space].white
    cat = chromatic_adaptation_matrix("D50", white, method="bradford", dtype=dtype)
    if space == "xyz":
        return cat
    return jnp.asarray(np.linalg.inv(rgb_to_xyz_matrix(space)), dtype) @ cat


class ColorTransform(eqx.Module):
    """Camera RGB -> ``colorspace``: ``matrix`` ``(3, 3)`` (white balance included), the camera
    ``neutral`` it balances to white, that white's ``white_xy`` and ``cct``, and where the
    matrix and the white balance came from."""

    matrix: jax.Array
    neutral: jax.Array
    white_xy: jax.Array
    cct: jax.Array
    colorspace: str = eqx.field(static=True)
    matrix_source: str = eqx.field(static=True)
    white_balance: str = eqx.field(static=True)
    white_balance_source: str = eqx.field(static=True)

    def to_dict(self) -> dict:
        f = lambda a: np.round(np.asarray(a, np.float64), 8).tolist()  # noqa: E731
        return {
            "colorspace": self.colorspace,
            "matrix_camera_to_output": f(self.matrix),
            "matrix_source": self.matrix_source,
            "white_balance": {
                "method": self.white_balance,
                "source": self.white_balance_source,
                "camera_neutral": f(self.neutral),
                "gains": f(jnp.max(self.neutral) / self.neutral),
                "white_xy": f(self.white_xy),
                "cct_K": float(self.cct),
            },
        }


def _neutral(raw, camera_rgb, white_balance):
    """The camera neutral (max 1) and a sentence saying where it came from."""
    from jaxgfx.color import white_balance_grey_world_gains, white_balance_white_patch_gains

    if white_balance == "as_shot":
        n = raw.dng_color.get("as_shot_neutral")
        if n is not None and np.size(n) == 3 and np.all(np.asarray(n) > 0):
            n = np.asarray(n, np.float64)
            return n / n.max(), "DNG AsShotNeutral"
        mul = np.asarray(raw.camera_whitebalance, np.float64)[:3]
        if np.all(mul > 0) and np.all(np.isfinite(mul)):
            n = 1.0 / mul
            return n / n.max(), "LibRaw camera_whitebalance (as shot)"
        raise ValueError(
            f"'{raw.path}': no as-shot white balance (AsShotNeutral / camera multipliers); "
            "use white_balance grey_world or white_patch (--white-balance)"
        )
    img = jnp.asarray(np.maximum(camera_rgb, 0.0), jnp.float32)
    fn = (
        white_balance_grey_world_gains
        if white_balance == "grey_world"
        else (white_balance_white_patch_gains)
    )
    gains = np.asarray(fn(img), np.float64)
    n = 1.0 / gains
    return n / n.max(), f"{white_balance} of the merged camera RGB (jaxgfx.color)"


def color_transform(raw, camera_rgb, *, colorspace="rec709", white_balance="as_shot"):
    """The :class:`ColorTransform` of a RAW bracket: ``raw`` a :class:`jaxgfx.io.RawImage` of
    it (its colour tags and as-shot white balance), ``camera_rgb`` ``(H, W, 3)`` the merged,
    demosaiced camera RGB (for grey-world / white-patch estimates). ``colorspace`` in
    :data:`COLORSPACES` (``"camera"``: identity, no white balance), ``white_balance`` in
    :data:`RAW_WHITE_BALANCES`. One ``ValueError`` naming the file when the RAW has no colour
    matrix."""
    check_choice(colorspace, "colorspace", COLORSPACES)
    check_choice(white_balance, "white_balance", RAW_WHITE_BALANCES)
    if colorspace == "camera":
        one = jnp.ones(3)
        return ColorTransform(
            jnp.eye(3), one, jnp.asarray(WHITEPOINTS["E"]), jnp.asarray(jnp.nan),
            "camera", "none (camera RGB kept)", "none", "none (camera RGB kept)",
        )  # fmt: skip
    rgb_cam = np.asarray(raw.color_matrix, np.float64)[:, :3]
    if "color_matrix1" not in raw.dng_color and (raw.is_dng or not np.any(rgb_cam)):
        raise ValueError(
            f"'{raw.path}': no colour matrix (DNG ColorMatrix1 or LibRaw rgb_cam), so the "
            "camera's colours are unknown; use colorspace 'camera' (--colorspace camera)"
        )
    neutral, wb_source = _neutral(raw, camera_rgb, white_balance)
    neutral = jnp.asarray(neutral, jnp.float64 if jax.config.jax_enable_x64 else jnp.float32)
    to_space = xyz_d50_to_space_matrix(colorspace, dtype=neutral.dtype)
    if "color_matrix1" in raw.dng_color:
        prof = DngColorProfile.from_tags(raw.dng_color, f"'{raw.path}'")
        m, xy, cct = dng_camera_to_xyz_d50(prof, neutral)
        names = "ColorMatrix1/2" if prof.color_matrix2 is not None else "ColorMatrix1"
        if prof.forward_matrix1 is not None:
            names += " + ForwardMatrix"
        src = (
            f"DNG {names} interpolated at {float(cct):.0f} K (DNG spec 1.4 ch. 6; "
            f"CameraCalibration, AnalogBalance applied), Bradford XYZ(D50) -> {colorspace}"
        )
        return ColorTransform(to_space @ m, neutral, xy, cct, colorspace, src, white_balance,
                              wb_source)  # fmt: skip
    d65_to_d50 = chromatic_adaptation_matrix("D65", "D50", method="bradford", dtype=neutral.dtype)
    srgb_to_xyz50 = d65_to_d50 @ jnp.asarray(rgb_to_xyz_matrix("srgb"), neutral.dtype)
    m = to_space @ srgb_to_xyz50 @ jnp.asarray(rgb_cam, neutral.dtype) @ jnp.diag(1.0 / neutral)
    xy = jnp.asarray(WHITEPOINTS["D65"], neutral.dtype)  # the balanced neutral is sRGB white
    return ColorTransform(m, neutral, xy, xy_to_cct(xy), colorspace,
                          f"LibRaw rgb_cam (camera -> sRGB), Bradford to {colorspace}",
                          white_balance, wb_source)  # fmt: skip


def apply_color_transform(image, transform: ColorTransform, variance=None):
    """``image`` ``(..., 3)`` camera RGB through ``transform.matrix``; with ``variance``
    ``(..., 3)`` also the variance (channels treated as independent: ``M² · var``)."""
    m = jnp.asarray(transform.matrix, jnp.asarray(image).dtype)
    out = jnp.einsum("ij,...j->...i", m, image)
    if variance is None:
        return out
    return out, jnp.einsum("ij,...j->...i", m * m, variance)


def exr_chromaticities(colorspace: str):
    """OpenEXR ``chromaticities`` (red, green, blue, white xy; 8 floats) of ``colorspace``;
    ``None`` for ``"camera"`` (unknown primaries)."""
    check_choice(colorspace, "colorspace", COLORSPACES)
    if colorspace == "camera":
        return None
    if colorspace == "xyz":
        return (1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0 / 3.0, 1.0 / 3.0)
    s = RGB_SPACES[colorspace]
    return tuple(float(v) for v in (*np.ravel(s.primaries), *WHITEPOINTS[s.white]))
