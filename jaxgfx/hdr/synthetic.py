"""Synthetic HDR scenes and bracketed exposure stacks with known ground truth.

Used by the tests, the benchmarks and ``make demo``: a scene radiance map with a known
dynamic range, ground-truth response curves, and a sensor simulation (photon shot noise,
read noise, clipping, quantisation).
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._checks import check_choice, check_nonnegative, check_positive
from ..color import LUMINANCE_WEIGHTS
from ._curves import ANALYTIC_KINDS
from ._model import CameraResponse
from .camera import Camera
from .noise import NoiseModel

__all__ = [
    "synthetic_radiance",
    "synthetic_response",
    "make_bracketed_stack",
    "BracketedStack",
    "SYNTHETIC_RESPONSES",
    "jpeg_roundtrip",
    "make_jpeg_stack",
    "outdoor_hdr_scene",
    "smooth_hdr_scene",
    "hard_hdr_scenes",
    "CANON_EOS_5D_MARK_II",
    "colorchecker_scene",
    "write_dng_bracket",
    "MovingStack",
    "make_moving_object_stack",
    "response_from_curve",
    "read_dorf_curves",
]

SYNTHETIC_RESPONSES = ("gamma2.2", *(k for k in ANALYTIC_KINDS if k != "linear"))
"""Ground-truth responses by name: a gamma-2.2 power law and the analytic curves of
:meth:`CameraResponse.analytic` (the identity ``"linear"`` aside)."""


class BracketedStack(NamedTuple):
    """Output of :func:`make_bracketed_stack`.

    ``images`` ``(N, H, W, C)`` (uint8 / uint16 / float), ``exposure_times`` ``(N,)``,
    ``radiance`` ``(H, W, C)`` ground truth, ``response`` the true :class:`CameraResponse`,
    ``noise`` the :class:`NoiseModel` used (normalised units), ``linear`` ``(N, H, W, C)``
    clean exposures
    ``radiance · t`` before noise and clipping.
    """

    images: jax.Array
    exposure_times: jax.Array
    radiance: jax.Array
    response: CameraResponse
    noise: NoiseModel
    linear: jax.Array


def synthetic_radiance(key, height: int, width: int, *, dynamic_range: float = 1e4, channels=3):
    """A deterministic structured HDR scene ``(height, width, channels)`` with values in
    ``[1 / dynamic_range, 1]`` (min and max both attained).

    Content, in log10 radiance: a horizontal ramp spanning the range, a grid of flat patches
    (uniform steps through the range), a smooth vertical shading, a band-limited texture
    (from ``key``), coloured tints per channel, and a bright "sun" disc (the maximum) with a
    glow in the upper right. Example: ``synthetic_radiance(key, 64, 64).max() → 1.0``.
    """
    for v, nm in ((height, "height"), (width, "width")):
        if isinstance(v, bool) or not isinstance(v, int) or v < 8:
            raise ValueError(f"{nm}: expected an integer >= 8, got {v!r}")
    check_positive(dynamic_range, "dynamic_range")
    if dynamic_range <= 1:
        raise ValueError(f"dynamic_range: expected a ratio > 1, got {dynamic_range}")
    return _radiance_jit(key, jnp.asarray(dynamic_range, jnp.float32), height, width, channels)


@functools.partial(jax.jit, static_argnums=(2, 3, 4))
def _radiance_jit(key, dynamic_range, height, width, channels):
    yy, xx = jnp.meshgrid(
        jnp.linspace(0.0, 1.0, height), jnp.linspace(0.0, 1.0, width), indexing="ij"
    )
    f = 0.8 * xx + 0.15 * (1.0 - yy)
    # patches: 6 x 6 grid in the lower-left area
    py = jnp.floor(yy * 6.0)
    px = jnp.floor(xx * 6.0)
    patch_level = (py * 6.0 + px) / 35.0
    in_patch = (jnp.mod(yy * 6.0, 1.0) > 0.2) & (jnp.mod(xx * 6.0, 1.0) > 0.2) & (py >= 3)
    f = jnp.where(in_patch, patch_level, f)
    # texture: low-resolution noise upsampled bilinearly
    k1, k2 = jax.random.split(key)
    coarse = jax.random.normal(k1, (height // 4 + 2, width // 4 + 2))
    tex = jax.image.resize(coarse, (height, width), method="linear")
    f = f + 0.04 * tex
    # sun: disc at the maximum plus glow
    r = jnp.sqrt((yy - 0.18) ** 2 + (xx - 0.82) ** 2)
    f = jnp.where(r < 0.06, 2.0, f + 0.3 * jnp.exp(-((r / 0.15) ** 2)))
    lo, hi = jnp.min(f), jnp.max(jnp.where(r < 0.06, -jnp.inf, f))
    span = jnp.log10(dynamic_range)
    # map non-sun content to [-span, -0.15*span]; the sun to 0
    logv = jnp.where(r < 0.06, 0.0, (f - lo) / (hi - lo) * 0.85 * span - span)
    tints = jnp.asarray([1.0, 0.8, 0.6, 0.9])[:channels]
    tint_shift = (
        jnp.log10(tints)[None, None, :] * (1.0 - jnp.exp(-(((f - lo) / (hi - lo)) ** 2)))[..., None]
    )
    logv = logv[..., None] + jnp.where((r < 0.06)[..., None], 0.0, tint_shift)
    logv = jnp.clip(logv, -span, 0.0)
    # make sure the minimum is attained exactly
    logv = logv.at[-1, 0, :].set(-span)
    del k2
    return (10.0**logv).astype(jnp.float32)


def synthetic_response(name: str, *, channels: int = 3) -> CameraResponse:
    """A ground-truth response curve: ``"gamma2.2"``, ``"srgb"``, ``"s-curve"``,
    ``"filmic"`` (ACES-like shoulder), ``"log"`` (log encoding, ``ln(1 + 100x)``),
    ``"camera"`` (a JPEG-like in-camera curve: a toe ``x² (1+c) / (x+c)``, ``c = 0.003``, a
    shoulder ``x (1+k) / (x+k)``, ``k = 1.5``, then sRGB; relative exposure
    ``x(z)/x(128/255)`` = 0.009 at z = 2/255 and 6.5 at 250/255, close to a measured Canon JPEG)
    and ``"camera-offset"`` (the same with a lifted black: level 0.03 at zero exposure).

    All map linear ``x ∈ [0, 1]`` (1 = clipping) to normalised levels with ``f(1) = 1``,
    anchored like every response (``to_linear(0.5) = 1``). Example:
    ``synthetic_response("gamma2.2").from_linear_normalized(1.0)`` → ``0.5``.
    """
    check_choice(name, "name", SYNTHETIC_RESPONSES)
    if name == "gamma2.2":
        return CameraResponse.gamma(2.2, channels=channels)
    assert name in ANALYTIC_KINDS
    return CameraResponse.analytic(name, channels=channels)


def response_from_curve(
    irradiance, brightness, *, n_levels: int = 1024, anchor="mid", floor: float = 1e-7
) -> CameraResponse:
    """A tabulated ground-truth response from a measured curve ``brightness = f(irradiance)``.

    ``irradiance``, ``brightness``: ``(K,)`` (one curve, one channel) or ``(K, C)`` samples,
    both normalised to ``[0, 1]`` with ``f(1) = 1`` (1 = the clipping level), ``irradiance``
    strictly increasing and ``brightness`` non-decreasing — the form of the DoRF database
    (Grossberg & Nayar 2003, :func:`read_dorf_curves`). The curve is inverted by linear
    interpolation onto ``n_levels`` uniform levels and stored as a ``"table"``
    :class:`CameraResponse` of ``ln x`` (``x`` floored at ``floor`` so level 0 stays finite),
    so :func:`make_bracketed_stack` / :func:`make_jpeg_stack` can expose through it. Data
    preparation (NumPy, not traced); the result's ``params`` are differentiable leaves.

    Example: a linear curve, anchored at mid grey (``to_linear`` of level 0.5 is 1):
    ``response_from_curve([0, .5, 1], [0, .5, 1]).from_linear_normalized(0.5)`` → ``0.25``.
    """
    irr = np.asarray(irradiance, np.float64)
    bri = np.asarray(brightness, np.float64)
    if irr.ndim == 1:
        irr = irr[:, None]
    if bri.ndim == 1:
        bri = bri[:, None]
    if irr.ndim != 2 or irr.shape[0] < 2:
        raise ValueError(f"irradiance: expected shape (K,) or (K, C), K >= 2, got {irr.shape}")
    if bri.ndim != 2 or bri.shape[0] != irr.shape[0] or irr.shape[1] not in (1, bri.shape[1]):
        raise ValueError(
            f"brightness: expected {irr.shape[0]} samples like irradiance "
            f"({np.asarray(irradiance).shape}), got {np.asarray(brightness).shape}"
        )
    for a, nm in ((irr, "irradiance"), (bri, "brightness")):
        if not np.all(np.isfinite(a)) or a.min() < 0.0 or a.max() > 1.0:
            raise ValueError(f"{nm}: expected finite values in [0, 1]")
    if np.any(np.diff(irr, axis=0) <= 0):
        raise ValueError("irradiance: expected strictly increasing samples")
    if np.any(np.diff(bri, axis=0) < 0):
        raise ValueError("brightness: expected a non-decreasing (monotone) curve")
    if isinstance(n_levels, bool) or not isinstance(n_levels, int) or n_levels < 8:
        raise ValueError(f"n_levels: expected an integer >= 8, got {n_levels!r}")
    check_positive(floor, "floor")
    irr = np.broadcast_to(irr, bri.shape)
    z = np.linspace(0.0, 1.0, n_levels)
    cols = []
    for c in range(bri.shape[1]):
        # flat runs of brightness: interpolate over their midpoints (np.interp needs
        # increasing abscissae); the clipping level maps to irradiance 1
        b, keep = np.unique(bri[:, c], return_index=True)
        x = np.interp(z, b, irr[keep, c])
        cols.append(np.log(np.maximum(x, floor)))
    table = np.stack(cols, axis=1)
    from ._model import resolve_anchor

    return CameraResponse(
        jnp.asarray(table, jnp.float32), "table", "measured", 1.0, resolve_anchor(anchor)
    )


def read_dorf_curves(path) -> dict:
    """Read a DoRF-format curve file (Grossberg & Nayar's "Database of Response Functions":
    blocks of 6 lines ``name``, a graph label, ``I =``, the irradiance samples, ``B =``, the
    brightness samples). Returns ``{name: (irradiance, brightness)}`` as NumPy arrays; feed a
    curve to :func:`response_from_curve`. ``ValueError`` naming the file and line for a
    malformed block."""
    with open(path) as f:
        lines = [ln.rstrip("\n") for ln in f]
    while lines and not lines[-1].strip():
        lines.pop()
    if not lines or len(lines) % 6:
        raise ValueError(
            f"{path}: expected blocks of 6 lines (DoRF format), got {len(lines)} lines"
        )
    out = {}
    for i in range(0, len(lines), 6):
        if lines[i + 2].strip() != "I =" or lines[i + 4].strip() != "B =":
            raise ValueError(f"{path}:{i + 3}: expected 'I =' and 'B =' lines in a DoRF block")
        try:
            irr = np.asarray(lines[i + 3].split(), np.float64)
            bri = np.asarray(lines[i + 5].split(), np.float64)
        except ValueError:
            raise ValueError(f"{path}:{i + 4}: non-numeric curve samples") from None
        if irr.shape != bri.shape or irr.size < 2:
            raise ValueError(f"{path}:{i + 4}: I and B must have the same number (>= 2) of samples")
        out[lines[i].strip()] = (irr, bri)
    return out


def make_bracketed_stack(
    key,
    radiance,
    exposure_times,
    response,
    *,
    bits: int | None = 8,
    gain: float = 1e-4,
    read_sigma: float = 1e-3,
    clip: bool = True,
) -> BracketedStack:
    """Simulate a bracketed capture of ``radiance`` ``(H, W, C)`` (or ``(H, W)``).

    Frame ``j`` sees linear exposure ``x = radiance · t_j`` (1 = the clipping level),
    perturbed by Poisson–Gaussian noise ``x + sqrt(gain · x) n₁ + read_sigma n₂`` (Gaussian
    approximation of shot noise; ``gain`` is 1 / full-well in normalised units), clipped to
    ``[0, 1]`` when ``clip``, mapped through ``response`` (a :class:`CameraResponse`,
    ``x = 1`` ↦ level 1 whatever its anchor), and quantised to ``bits`` (8 → uint8,
    16 → uint16, ``None`` → float in ``[0, 1]``, no quantisation). ``gain = read_sigma = 0``
    gives noise-free data.
    """
    check_nonnegative(gain, "gain")
    check_nonnegative(read_sigma, "read_sigma")
    if bits not in (8, 16, None):
        raise ValueError(f"bits: expected 8, 16 or None, got {bits!r}")
    radiance = jnp.asarray(radiance)
    squeeze = radiance.ndim == 2
    if squeeze:
        radiance = radiance[..., None]
    if radiance.ndim != 3:
        raise ValueError(f"radiance: expected shape (H, W) or (H, W, C), got {radiance.shape}")
    t = jnp.asarray(exposure_times, radiance.dtype)
    if t.ndim != 1 or t.shape[0] < 1:
        raise ValueError(f"exposure_times: expected shape (N,), got {t.shape}")
    check_positive(t, "exposure_times")
    if not isinstance(response, CameraResponse):
        raise TypeError(f"response: expected a CameraResponse, got {type(response).__name__}")
    out = _stack_jit(
        key,
        radiance,
        t,
        response,
        jnp.asarray(gain, radiance.dtype),
        jnp.asarray(read_sigma, radiance.dtype),
        bits=bits,
        clip=clip,
    )
    if squeeze:
        out = out._replace(
            images=out.images[..., 0], radiance=out.radiance[..., 0], linear=out.linear[..., 0]
        )
    return out


@functools.partial(jax.jit, static_argnames=("bits", "clip"))
def _stack_jit(key, radiance, t, response, gain, read_sigma, *, bits, clip):
    c = radiance.shape[-1]
    lin = radiance[None] * t[:, None, None, None]
    dt = radiance.dtype
    noise = NoiseModel(jnp.full((c,), gain, dt), jnp.full((c,), read_sigma**2, dt))
    # the exposure times are applied above (lin is what the sensor sees): exposure 1 here
    camera = Camera(response, jnp.ones((), radiance.dtype), noise=noise, bits=bits, clip=clip)
    img = camera.capture(lin, key)
    return BracketedStack(img, t, radiance, response, noise, lin)


def jpeg_roundtrip(images, *, quality: int = 90, subsampling: str = "4:2:0"):
    """Encode and decode 8-bit frames with Pillow's JPEG codec (host-only NumPy, not traced).

    ``images``: ``(N, H, W, 3)`` or ``(H, W, 3)`` uint8 (or ``(..., H, W)`` grey). Returns the
    decoded uint8 frames, same shape: 8×8 DCT block artefacts and, for colour with
    ``subsampling="4:2:0"`` (the camera default), half-resolution chroma. ``quality``: 1–100
    (90: a typical in-camera "fine" setting).
    """
    import io

    import numpy as np
    from PIL import Image

    check_choice(subsampling, "subsampling", ("4:4:4", "4:2:2", "4:2:0"))
    if isinstance(quality, bool) or not isinstance(quality, int) or not 1 <= quality <= 100:
        raise ValueError(f"quality: expected an integer in 1..100, got {quality!r}")
    a = np.asarray(images)
    if a.dtype != np.uint8:
        raise TypeError(f"images: expected uint8 frames, got dtype {a.dtype}")
    grey = a.ndim in (2, 3) and not (a.ndim == 3 and a.shape[-1] == 3)
    frames = a.reshape((-1,) + a.shape[-2:]) if grey else a.reshape((-1,) + a.shape[-3:])
    sub = {"4:4:4": 0, "4:2:2": 1, "4:2:0": 2}[subsampling]
    out = []
    for f in frames:
        buf = io.BytesIO()
        Image.fromarray(np.ascontiguousarray(f)).save(
            buf, format="JPEG", quality=quality, subsampling=sub
        )
        buf.seek(0)
        out.append(np.asarray(Image.open(buf).convert("L" if grey else "RGB")))
    return np.stack(out).reshape(a.shape)


def make_jpeg_stack(
    key,
    radiance,
    exposure_times,
    response,
    *,
    gain: float = 1e-4,
    read_sigma: float = 1e-3,
    quality: int = 90,
    subsampling: str = "4:2:0",
    max_shift: float = 0.0,
) -> BracketedStack:
    """A bracketed stack as hostile as real camera JPEGs (host-side; not jittable).

    Like :func:`make_bracketed_stack` with ``bits=8`` (shot + read noise, clipping, the
    response: use ``"camera"`` / ``"camera-offset"`` for a toe, a shoulder and a black offset),
    then every frame goes through :func:`jpeg_roundtrip` (Pillow, ``quality``, ``subsampling``).
    ``max_shift > 0`` misaligns the frames: frame ``j`` sees the radiance translated by a
    uniform random ``(dy, dx)`` in ``[-max_shift, max_shift]`` pixels (bilinear,
    :func:`jaxgfx.hdr.shift_image`), as from a handheld bracket; the first frame is unshifted.
    ``radiance`` in the result is the unshifted ground truth.
    """
    if isinstance(response, str):
        response = synthetic_response(response, channels=jnp.asarray(radiance).shape[-1])
    check_nonnegative(max_shift, "max_shift")
    t = jnp.asarray(exposure_times, jnp.float32)
    k_noise, k_shift = jax.random.split(key)
    if max_shift > 0:
        from .align import shift_image

        rad = jnp.asarray(radiance)
        shifts = jax.random.uniform(k_shift, (t.shape[0], 2), minval=-max_shift, maxval=max_shift)
        shifts = shifts.at[0].set(0.0)
        keys = jax.random.split(k_noise, t.shape[0])
        parts = [
            make_bracketed_stack(
                keys[j],
                shift_image(rad, shifts[j]),
                t[j : j + 1],
                response,
                bits=8,
                gain=gain,
                read_sigma=read_sigma,
            )
            for j in range(t.shape[0])
        ]
        st = parts[0]._replace(
            images=jnp.concatenate([p.images for p in parts]),
            exposure_times=t,
            radiance=rad,
            linear=jnp.concatenate([p.linear for p in parts]),
        )
    else:
        st = make_bracketed_stack(
            k_noise, radiance, t, response, bits=8, gain=gain, read_sigma=read_sigma
        )
    imgs = jpeg_roundtrip(st.images, quality=quality, subsampling=subsampling)
    return st._replace(images=jnp.asarray(imgs))


# ----------------------------------------------------------------------------------------
# host-side NumPy HDR scenes for tone mapping (benchmarks, figures, tests: one owner)


def outdoor_hdr_scene(H: int, W: int, seed: int = 0):
    """A synthetic HDR scene: sky gradient with a sun (1e5:1), textured ground, a dark
    interior with a window, coloured patches; ~5 decades of luminance. Host-side NumPy
    ``(H, W, 3)`` float32 (the tone-mapping benchmark's and figure's scene)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    yy /= H - 1
    xx /= W - 1
    sky = (np.exp(3.0 * (1 - yy)) * 2.0)[..., None] * np.array([0.55, 0.75, 1.0], np.float32)
    ground = (0.3 + 0.15 * np.sin(60 * xx) * np.cos(45 * yy))[..., None] * np.array(
        [0.55, 0.45, 0.3], np.float32
    )
    img = np.where((yy > 0.6)[..., None], ground, sky)
    room = (xx < 0.35) & (yy > 0.25)
    img = np.where(room[..., None], 0.02 * img / img.mean(), img)
    window = room & (np.abs(xx - 0.17) < 0.06) & (np.abs(yy - 0.45) < 0.08)
    img = np.where(window[..., None], np.array([3.0, 3.2, 3.5], np.float32) * 8, img)
    for i, c in enumerate(([0.8, 0.1, 0.1], [0.1, 0.6, 0.1], [0.1, 0.2, 0.8], [0.8, 0.8, 0.1])):
        patch = (np.abs(xx - (0.5 + 0.12 * i)) < 0.04) & (np.abs(yy - 0.8) < 0.06)
        img = np.where(patch[..., None], np.array(c, np.float32), img)
    sun = (yy - 0.2) ** 2 + ((xx - 0.75) * W / H) ** 2 < 0.0015
    img = np.where(sun[..., None], np.array([1.0, 0.95, 0.85], np.float32) * 2e4, img)
    img = img * np.exp(0.05 * rng.standard_normal((H, W, 1))).astype(np.float32)
    return img.astype(np.float32)


def smooth_hdr_scene(H=32, W=48, *, seed=0, zeros=False, dynamic_range=1e4):
    """A smooth HDR scene: sky gradient, a bright disc ("sun"), textured ground, coloured
    patches; ``dynamic_range`` ~ max / min of the non-zero pixels; ``zeros``: a black corner.
    Host-side NumPy ``(H, W, 3)`` float32."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    yy /= max(H - 1, 1)
    xx /= max(W - 1, 1)
    sky = np.exp(np.log(dynamic_range) * 0.35 * (1.0 - yy))[..., None] * np.array([0.6, 0.8, 1.0])
    ground = (0.05 + 0.04 * np.sin(40 * xx) * np.cos(30 * yy))[..., None] * np.array(
        [0.7, 0.55, 0.35]
    )
    img = np.where((yy > 0.55)[..., None], ground, sky)
    d2 = (yy - 0.25) ** 2 + (xx - 0.7) ** 2
    img += (d2 < 0.01)[..., None] * dynamic_range * 0.3 * np.array([1.0, 0.95, 0.8])
    img *= np.exp(0.1 * rng.standard_normal((H, W, 1)))
    if zeros:
        img[-max(H // 6, 1) :, : max(W // 3, 1)] = 0.0
    return img.astype(np.float32)


def hard_hdr_scenes(n=96, block=16, seed=0):
    """Issue 27: HDR scenes with exact-zero backgrounds, ~10^9:1 range and a 10^6 sun, built
    from ``block``-sized regions (for block-mean order checks); positions scale with ``n``.
    ``{name: (n, n, 3) float32}``."""
    rng = np.random.default_rng(seed)
    nb = n // block
    yy, xx = np.mgrid[0:n, 0:n] * (96.0 / n)  # layout drawn on a 96 x 96 canvas
    r2 = (96.0 / n) ** 2  # one pixel, squared, in canvas units
    out = {}
    # 1: patchwork of flat regions 1e-3..1e3 (a third exactly zero) and a sun
    lev = 10.0 ** rng.uniform(-3, 3, (nb, nb))
    lev[rng.random((nb, nb)) < 0.33] = 0.0
    img = np.kron(lev, np.ones((block, block)))
    img = img * np.exp(0.05 * rng.standard_normal((n, n)))
    img[(yy - 40) ** 2 + (xx - 56) ** 2 < max(25, 2 * r2)] = 1e6
    out["patches_sun"] = img
    # 2: black sky with stars (3 x 3 canvas-px dots 1..1e5) and a moon
    img = np.zeros((n, n))
    for _ in range(24):
        y, x = rng.integers(2, 93, 2)
        img[(np.abs(yy - y) <= max(1, 0.5 * 96 / n)) & (np.abs(xx - x) <= max(1, 0.5 * 96 / n))] = (
            10.0 ** rng.uniform(0, 5)
        )
    img[(yy - 20) ** 2 + (xx - 70) ** 2 < max(36, 2 * r2)] = 1e6
    out["stars"] = img
    # 3: zero background, a lit room (1e-2..1) with a window (1e2) and a sun (1e6)
    img = np.zeros((n, n))
    room = (yy >= 16) & (yy < 80) & (xx >= 8) & (xx < 88)
    img[room] = 0.02 * np.exp(3.0 * xx[room] / 96.0)
    img[(yy >= 24) & (yy < 56) & (xx >= 48) & (xx < 80)] = 100.0
    img[(yy - 40) ** 2 + (xx - 64) ** 2 < max(16, 2 * r2)] = 1e6
    out["room"] = img * np.exp(0.05 * rng.standard_normal((n, n)))
    col = np.array([1.0, 0.9, 0.7])
    return {k: (v[..., None] * col).astype(np.float32) for k, v in out.items()}


#: Canon EOS 5D Mark II colour tags as Adobe DNG Converter writes them (ColorMatrix1 for
#: standard light A, ColorMatrix2 for D65; ColorMatrix2 equals dcraw's ``adobe_coeff`` entry
#: {4716, 603, -830, -7798, 15474, 2480, -1496, 1937, 6651} / 10000). Values as published in
#: colour-hdri's documentation and tests (BSD-3-Clause), which read them from such a DNG.
CANON_EOS_5D_MARK_II = {
    "color_matrix1": (
        (0.5309, -0.0229, -0.0336),
        (-0.6241, 1.3265, 0.3337),
        (-0.0817, 0.1215, 0.6664),
    ),
    "color_matrix2": (
        (0.4716, 0.0603, -0.0830),
        (-0.7798, 1.5474, 0.2480),
        (-0.1496, 0.1937, 0.6651),
    ),
    "calibration_illuminant1": 17,
    "calibration_illuminant2": 21,
}


def _patch_scene(rng, height, width, patch, dynamic_range):
    """Linear Rec.709 radiance: ``patch``-pixel squares of random in-gamut colours (saturated
    to near-grey) whose luminances span ``dynamic_range``, plus a smooth colour ramp band."""
    gh, gw = -(-height // patch), -(-width // patch)
    rgb = rng.uniform(0.0, 1.0, (gh, gw, 3)) ** 2
    grey = rng.uniform(0.0, 1.0, (gh, gw, 1))
    rgb = grey * rgb.mean(-1, keepdims=True) + (1 - grey) * rgb + 0.01
    y = rgb @ np.array(LUMINANCE_WEIGHTS["rec709"])
    lum = np.exp(rng.uniform(np.log(1.0 / dynamic_range), 0.0, (gh, gw)))
    rgb = rgb * (lum / y)[..., None]
    img = np.kron(rgb, np.ones((patch, patch, 1)))[:height, :width]
    band = slice(0, max(2, height // 8))  # a smooth hue ramp: demosaicing has edges to fight
    u = np.linspace(0, 2 * np.pi, width)
    ramp = 0.5 + 0.4 * np.stack([np.cos(u), np.cos(u - 2.1), np.cos(u + 2.1)], -1)
    img[band] = 0.3 * ramp[None]
    return img


def colorchecker_scene(height: int, width: int, corners, *, background: float = 0.18,
                       body: float = 0.03, gap: float = 0.15, supersample: int = 3):  # fmt: skip
    """A ColorChecker photographed in perspective: linear Rec.709 ``(H, W, 3)`` (float64) under
    D65, in reflectance units (the chart's white patch at ``Y ≈ 0.88``).

    The patch grid's outer corners are ``corners`` ``(4, 2)`` ``(x, y)`` in
    :data:`jaxgfx.hdr.raw.chart.CORNER_ORDER`; each of its 24 cells shows its patch
    (:func:`jaxgfx.hdr.raw.chart.colorchecker_reference`, ICC D50 Bradford-adapted to D65) with
    a border of ``gap / 2`` of the cell in the chart body's grey ``body``; outside the grid, a
    grey ``background``. Each pixel averages ``supersample²`` points (antialiased edges).
    """
    from ..color import chromatic_adaptation_matrix, rgb_to_xyz_matrix
    from .raw.chart import _check_corners, _homography, colorchecker_reference

    c = np.asarray(_check_corners(np.asarray(corners, np.float64), (height, width)), np.float64)
    ref = colorchecker_reference()
    cat = np.asarray(chromatic_adaptation_matrix(jnp.asarray(ref.illuminant_xy), "D65"),
                     np.float64)  # fmt: skip
    patches = ref.xyz @ (np.linalg.inv(rgb_to_xyz_matrix("rec709")) @ cat).T  # (24, 3)
    hinv = np.linalg.inv(np.asarray(_homography(jnp.asarray(c)), np.float64))
    o = (np.arange(supersample) + 0.5) / supersample - 0.5
    y, x, dy, dx = np.meshgrid(np.arange(height), np.arange(width), o, o, indexing="ij")
    q = np.stack([x + dx, y + dy, np.ones_like(x)], -1) @ hinv.T
    u, v = q[..., 0] / q[..., 2], q[..., 1] / q[..., 2]
    inside = (u >= 0) & (u < 1) & (v >= 0) & (v < 1)
    col, row = (
        np.clip(np.floor(u * 6), 0, 5).astype(int),
        np.clip(np.floor(v * 4), 0, 3).astype(int),
    )
    fu, fv = u * 6 - col, v * 4 - row
    on_patch = inside & (np.minimum(fu, 1 - fu) >= gap / 2) & (np.minimum(fv, 1 - fv) >= gap / 2)
    out = np.where(inside[..., None], body, background) * np.ones(3)
    out = np.where(on_patch[..., None], patches[row * 6 + col], out)
    return out.mean(axis=(2, 3))


def write_dng_bracket(
    folder,
    *,
    seed: int = 0,
    height: int = 64,
    width: int = 96,
    exposure_times=(1.0, 4.0, 16.0),
    camera: dict = CANON_EOS_5D_MARK_II,
    scene_white: str = "D65",
    dynamic_range: float = 300.0,
    patch: int = 8,
    black: int = 512,
    white: int = 15000,
    electrons_at_white: float | None = 60000.0,
    read_dn: float = 2.0,
    cfa_pattern: str = "RGGB",
    scene=None,
    true_camera: dict | None = None,
):
    """Write a synthetic bracket of DNGs carrying a camera's colour tags and as-shot neutral,
    rendered from a radiance map of known colours; returns ``(paths, rgb709)``.

    ``scene``: the radiance map, linear Rec.709 ``(height, width, 3)`` (e.g.
    :func:`colorchecker_scene`; colours outside the Rec.709 gamut have negative components);
    default the seeded patches below. ``true_camera``: colour
    tags of the camera that *renders* the scene (its sensitivities; default ``camera``), while
    ``camera``'s are written: a DNG profile that is off, as a chart calibration fixes.

    The scene (:func:`_patch_scene`, seeded) is linear Rec.709 under ``scene_white``; the
    sensor sees ``XYZtoCamera(scene_white) · XYZ``, with ``XYZtoCamera`` the camera's
    ColorMatrix1/2 interpolated at the white's temperature
    (:func:`jaxgfx.hdr.raw.dng_xyz_to_camera`), scaled so the white (Y = 1) gives the neutral
    with max 1; the brightest patch reaches the white level in the longest frame. Each frame:
    Bayer sampling, shot noise (``electrons_at_white`` at the white level, about a
    full-frame sensor's full well at base ISO; ``None``: none) and read noise (``read_dn``),
    rounding, clipping. AsShotNeutral is the white's camera response.
    ``rgb709`` ``(H, W, 3)`` is the scene in the units of ``radiance.exr`` for the default
    colour space (normalised signal per second of exposure).
    """
    import os

    import jax.numpy as jnp

    from jaxgfx import color, io
    from jaxgfx.image.bayer import BAYER_PATTERNS

    from .raw.color import DngColorProfile, dng_xyz_to_camera

    check_choice(cfa_pattern, "cfa_pattern", BAYER_PATTERNS)
    rng = np.random.default_rng(seed)
    if scene is None:
        rgb = _patch_scene(rng, height, width, patch, dynamic_range)
    else:
        rgb = np.asarray(scene, np.float64)
        if rgb.shape != (height, width, 3) or not np.all(np.isfinite(rgb)):
            raise ValueError(f"scene: expected finite ({height}, {width}, 3), got {rgb.shape}")
    m709 = color.rgb_to_xyz_matrix("rec709")
    wxy = np.asarray(color.WHITEPOINTS[scene_white], np.float64)
    wxyz = np.array([wxy[0] / wxy[1], 1.0, (1 - wxy.sum()) / wxy[1]])
    tags = {k: np.ravel(v).astype(np.float64) for k, v in camera.items()}
    true_tags = tags if true_camera is None else {
        k: np.ravel(v).astype(np.float64) for k, v in true_camera.items()}  # fmt: skip
    prof = DngColorProfile.from_tags(true_tags, "true_camera")
    xyz_to_cam = np.asarray(dng_xyz_to_camera(prof, jnp.asarray(wxy)), np.float64)
    # the scene's colours seen under its white: adapt from D65 (Rec.709's white) to it
    cat = np.asarray(
        color.chromatic_adaptation_matrix("D65", jnp.asarray(wxy, jnp.float32)), np.float64
    )
    cam_white = xyz_to_cam @ wxyz
    scale = 1.0 / cam_white.max()
    cam = np.einsum("ij,hwj->hwi", scale * xyz_to_cam @ cat @ m709, rgb)
    neutral = cam_white * scale
    times = np.asarray(exposure_times, np.float64)
    k = 1.0 / (cam.max() * times.max()) * 1.05  # the brightest patch clips in the longest frame
    ch = {"R": 0, "G": 1, "B": 2}
    idx = np.zeros((height, width), int)
    for i, c in enumerate(cfa_pattern):
        idx[i // 2 :: 2, i % 2 :: 2] = ch[c]
    plane = np.take_along_axis(cam, idx[..., None], -1)[..., 0]
    os.makedirs(folder, exist_ok=True)
    paths = []
    for n, t in enumerate(times):
        sig = plane * k * t  # normalised signal, 1 at the white level
        e = np.clip(sig, 0, 2)
        if electrons_at_white is not None:
            e = rng.poisson(e * electrons_at_white) / electrons_at_white
        dn = black + e * (white - black) + rng.normal(0, read_dn, sig.shape)
        mosaic = np.clip(np.round(dn), 0, white).astype(np.uint16)
        path = os.path.join(os.fspath(folder), f"frame{n}.dng")
        io.write_dng(
            path,
            mosaic,
            cfa_pattern=cfa_pattern,
            black_level=black,
            white_level=white,
            exposure_time=float(t),
            camera_whitebalance=neutral[1] / neutral,
            color_matrix=np.reshape(tags["color_matrix1"], (3, 3)),
            calibration_illuminant1=int(tags["calibration_illuminant1"][0]),
            color_matrix2=None
            if "color_matrix2" not in tags
            else np.reshape(tags["color_matrix2"], (3, 3)),
            calibration_illuminant2=int(tags.get("calibration_illuminant2", [17])[0]),
            make="Canon",
            model="EOS 5D Mark II (synthetic)",
        )
        paths.append(path)
    return paths, rgb * k


# ----------------------------------------------------------------------------------------
# brackets of scenes that move (ghost-free merging: jaxgfx.hdr.deghost)


class MovingStack(NamedTuple):
    """Output of :func:`make_moving_object_stack`: ``stack`` the bracket (its ``radiance`` is
    the static background), ``frames_radiance`` ``(N, H, W, C)`` the radiance each frame saw
    (ground truth of a merge referenced to that frame), ``object_masks`` ``(N, H, W)`` where
    the object was in each frame."""

    stack: BracketedStack
    frames_radiance: jax.Array
    object_masks: jax.Array


def make_moving_object_stack(
    key,
    radiance,
    exposure_times,
    response,
    *,
    centers,
    radius: float,
    level: float,
    bits: int | None = 8,
    gain: float = 1e-4,
    read_sigma: float = 1e-3,
) -> MovingStack:
    """A bracket of ``radiance`` ``(H, W, C)`` with a textured disc (``radius`` px, mean
    radiance ``level`` x a cool tint, +-30 % texture that moves with it) at ``centers[j] =
    (row, col)`` in frame ``j``: an object that moves between the exposures. Each frame is
    simulated as :func:`make_bracketed_stack` (noise, clipping, quantisation, independent
    noise per frame). Example: ``make_moving_object_stack(key, E, t, resp, centers=[(8, 8),
    (8, 20)], radius=4, level=0.1)``."""
    radiance = jnp.asarray(radiance)
    if radiance.ndim != 3:
        raise ValueError(f"radiance: expected shape (H, W, C), got {radiance.shape}")
    t = jnp.asarray(exposure_times, radiance.dtype)
    n = t.shape[0] if t.ndim == 1 else -1
    centers = np.asarray(centers, np.float64)
    if centers.shape != (n, 2):
        raise ValueError(f"centers: expected shape ({n}, 2), one (row, col) per frame")
    check_positive(radius, "radius")
    check_positive(level, "level")
    H, W, C = radiance.shape
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    rng = np.random.default_rng(0)
    tex_coarse = rng.standard_normal((8, 8))
    tint = np.array([0.7, 0.9, 1.2, 1.0])[:C]
    frames, masks = [], []
    for cy, cx in centers:
        r2 = (yy - cy) ** 2 + (xx - cx) ** 2
        inside = r2 <= radius * radius
        # texture in the object's own coordinates (it moves with the object)
        u = np.clip((yy - cy) / radius * 3.5 + 4, 0, 7).astype(int)
        v = np.clip((xx - cx) / radius * 3.5 + 4, 0, 7).astype(int)
        tex = 1.0 + 0.3 * np.tanh(tex_coarse[u, v])
        obj = (level * tex)[..., None] * tint
        frames.append(np.where(inside[..., None], obj, np.asarray(radiance, np.float64)))
        masks.append(inside)
    frames_radiance = jnp.asarray(np.stack(frames), radiance.dtype)
    keys = jax.random.split(key, n)
    imgs = [
        make_bracketed_stack(
            keys[j],
            frames_radiance[j],
            t[j : j + 1],
            response,
            bits=bits,
            gain=gain,
            read_sigma=read_sigma,
        )
        for j in range(n)
    ]
    stack = BracketedStack(
        jnp.concatenate([s.images for s in imgs]),
        t,
        radiance,
        imgs[0].response,
        imgs[0].noise,
        jnp.concatenate([s.linear for s in imgs]),
    )
    return MovingStack(stack, frames_radiance, jnp.asarray(np.stack(masks)))
