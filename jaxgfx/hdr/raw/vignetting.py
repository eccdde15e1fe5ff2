"""Lens vignetting: a radial polynomial falloff about an optical centre, fitted from a flat field.

The model (the polynomial of colour-hdri's vignette characterisation and of most lens
profiles; Goldman 2010, *Vignette and exposure calibration and compensation*, IEEE TPAMI 32)::

    V(r) = 1 + a r^2 + b r^4 + c r^6,   r = |p - centre| / (half the image diagonal)

so ``r = 1`` at the corners of an image whose optical centre is its middle, and ``V = 1`` at
the centre. :func:`fit_vignetting` fits ``(a, b, c)``, the centre and one scale per channel
(a flat field's colour) by least squares (:func:`jaxgfx.optim.fit_least_squares`) to a
flat-field frame; :func:`devignette` divides it out of an image (and its variance).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array

__all__ = ["Vignetting", "fit_vignetting", "devignette"]


class Vignetting(eqx.Module):
    """``V(r) = 1 + a r^2 + b r^4 + c r^6`` about ``center`` on an image of ``shape``.

    Fields: ``coefficients`` ``(3,)`` ``(a, b, c)``; ``center`` ``(2,)`` ``(y, x)`` in pixels
    (pixel ``(i, j)`` has its centre at ``(i, j)``); ``shape`` ``(H, W)`` the image it was
    fitted on (static; the falloff of another size is refused); ``rms_residual``: the fit's
    RMS relative residual (NaN when built by hand).

    >>> v = Vignetting(jnp.array([-0.3, 0.0, 0.0]), jnp.array([1.5, 1.5]), (4, 4))
    >>> round(float(v.corner_falloff()), 4)  # r = 1 at the corners: 1 - 0.3
    0.7
    """

    coefficients: jax.Array
    center: jax.Array
    shape: tuple = eqx.field(static=True)
    rms_residual: jax.Array = eqx.field(default_factory=lambda: jnp.asarray(jnp.nan))

    def __check_init__(self):
        if np.shape(self.coefficients) != (3,) or np.shape(self.center) != (2,):
            raise ValueError(
                "vignetting: expected coefficients (3,) and center (2,), got "
                f"{np.shape(self.coefficients)} and {np.shape(self.center)}"
            )
        if len(self.shape) != 2 or min(self.shape) < 2:
            raise ValueError(f"vignetting: shape: expected (H, W) >= 2, got {self.shape}")

    def radius(self, y, x):
        """``r`` of pixel coordinates ``(y, x)`` (broadcast), 1 at half the diagonal."""
        h, w = self.shape
        half_diag = 0.5 * float(np.hypot(h - 1, w - 1))
        return jnp.hypot(y - self.center[0], x - self.center[1]) / half_diag

    def of_radius(self, r):
        """``V(r)``."""
        a, b, c = self.coefficients
        r2 = jnp.square(r)
        return 1.0 + r2 * (a + r2 * (b + r2 * c))

    def falloff(self):
        """``V`` at every pixel, ``(H, W)``."""
        h, w = self.shape
        y, x = jnp.meshgrid(jnp.arange(h, dtype=float), jnp.arange(w, dtype=float), indexing="ij")
        return self.of_radius(self.radius(y, x))

    def corner_falloff(self):
        """The mean of ``V`` at the four corner pixels (1: none; 0.7: 30 % darker)."""
        h, w = self.shape
        ys = jnp.array([0.0, 0.0, h - 1.0, h - 1.0])
        xs = jnp.array([0.0, w - 1.0, 0.0, w - 1.0])
        return jnp.mean(self.of_radius(self.radius(ys, xs)))

    def to_dict(self) -> dict:
        """JSON-ready dict (the report's and ``camera.json``'s ``vignetting``)."""
        f = lambda a: np.asarray(a, np.float64).tolist()  # noqa: E731
        rms = float(self.rms_residual)
        return {
            "model": "V(r) = 1 + a r^2 + b r^4 + c r^6, r = 1 at half the image diagonal",
            "coefficients": f(self.coefficients),
            "center_yx_px": f(self.center),
            "shape": list(self.shape),
            "corner_falloff": float(self.corner_falloff()),
            "rms_residual": None if np.isnan(rms) else rms,
        }

    @classmethod
    def from_dict(cls, d: dict, where: str = "vignetting") -> Vignetting:
        """Inverse of :meth:`to_dict` (``where`` names the source in errors)."""
        try:
            return cls(
                jnp.asarray(d["coefficients"], jnp.float32),
                jnp.asarray(d["center_yx_px"], jnp.float32),
                tuple(int(s) for s in d["shape"]),
                jnp.asarray(np.nan if d.get("rms_residual") is None else d["rms_residual"],
                            jnp.float32),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(f"{where}: not a vignetting record ({e!r})") from None


def _blocks(flat: np.ndarray, block: int):
    """Block means ``(h, w, C)`` and block-centre coordinates, and a mask of the blocks with no
    clipped (>= 0.999) or non-positive pixel."""
    h, w, c = flat.shape
    hb, wb = h // block, w // block
    x = flat[: hb * block, : wb * block].reshape(hb, block, wb, block, c)
    means = x.mean(axis=(1, 3))
    ok = np.all((x < 0.999) & (x > 0.0), axis=(1, 3, 4))
    yc = np.arange(hb) * block + (block - 1) / 2.0
    xc = np.arange(wb) * block + (block - 1) / 2.0
    return means, ok, yc, xc


def _residuals(p, args):
    """Relative residuals ``model / data - 1`` of the usable blocks (each block counts alike);
    module level, so the compiled solve is reused across calls of one grid size."""
    means, ok, yy, xx, centre0, half_diag = args
    cy = centre0[0] + half_diag * p["dc"][0]
    cx = centre0[1] + half_diag * p["dc"][1]
    r2 = (jnp.square(yy - cy) + jnp.square(xx - cx)) / half_diag**2
    a, b, c = p["abc"]
    model = (1.0 + r2 * (a + r2 * (b + r2 * c)))[..., None] * jnp.exp(p["log_s"])
    return ok * (model / means - 1.0)


def fit_vignetting(flat, *, cfa: bool = True, grid: int = 48, max_steps: int = 200):
    """Fit :class:`Vignetting` to a flat-field frame; returns it.

    ``flat``: ``(H, W)`` a normalised RAW mosaic (black subtracted, 1 at the white level;
    :meth:`jaxgfx.io.RawImage.normalized`), or ``(H, W, C)`` linear RGB. With ``cfa`` (a
    mosaic) each 2x2 CFA site gets its own scale, so the colour of the light does not count.
    The frame is averaged in blocks (at most ``grid`` per side; noise averages out) and blocks
    holding clipped or non-positive pixels are left out. Raises ``ValueError`` for a frame
    that is too small, not finite, or with too few usable blocks (over- or under-exposed).
    """
    from jaxgfx.optim import fit_least_squares

    f = np.asarray(as_float_array(flat, "flat"), np.float64)
    if f.ndim == 2:
        f = f[..., None]
    if f.ndim != 3 or min(f.shape[:2]) < 16:
        raise ValueError(f"flat: expected (H, W) or (H, W, C) of at least 16x16, got {f.shape}")
    if not np.all(np.isfinite(f)):
        raise ValueError("flat: expected finite values")
    shape = f.shape[:2]
    if cfa and f.shape[2] == 1:  # 2x2 CFA sites as channels, at the sites' mean position
        h2, w2 = (shape[0] // 2) * 2, (shape[1] // 2) * 2
        m = f[:h2, :w2, 0]
        planes = np.stack([m[0::2, 0::2], m[0::2, 1::2], m[1::2, 0::2], m[1::2, 1::2]], -1)
        step, offset = 2.0, 0.5
    else:
        planes, step, offset = f, 1.0, 0.0
    block = max(1, int(np.ceil(max(planes.shape[:2]) / grid)))
    means, ok, yc, xc = _blocks(planes, block)
    yc, xc = yc * step + offset, xc * step + offset
    if ok.sum() < 16:
        raise ValueError(
            f"flat: only {int(ok.sum())} usable blocks (the rest clipped or black); expose "
            "the flat field to mid-range (about half the white level)"
        )
    dt = jnp.float64 if jax.config.jax_enable_x64 else jnp.float32
    centre0 = np.array([(shape[0] - 1) / 2.0, (shape[1] - 1) / 2.0])
    half_diag = 0.5 * float(np.hypot(shape[0] - 1, shape[1] - 1))
    yy, xx = np.meshgrid(yc, xc, indexing="ij")
    data = (
        jnp.asarray(means, dt),
        jnp.asarray(ok, dt)[..., None],
        jnp.asarray(yy, dt),
        jnp.asarray(xx, dt),
        jnp.asarray(centre0, dt),
        jnp.asarray(half_diag, dt),
    )
    level = np.array([np.median(means[..., k][ok]) for k in range(means.shape[-1])])

    p0 = {
        "abc": jnp.zeros(3, dt),
        "dc": jnp.zeros(2, dt),
        "log_s": jnp.asarray(np.log(level), dt),
    }
    res = fit_least_squares(_residuals, p0, args=data, max_steps=max_steps)
    p = res.params
    centre = jnp.asarray(centre0, dt) + half_diag * p["dc"]
    r = np.asarray(_residuals(p, data))
    rms = float(np.sqrt(np.sum(r**2) / (ok.sum() * means.shape[-1])))
    return Vignetting(
        jnp.asarray(p["abc"], jnp.float32),
        jnp.asarray(centre, jnp.float32),
        tuple(int(s) for s in shape),
        jnp.asarray(rms, jnp.float32),
    )


def devignette(image, vignetting: Vignetting, variance=None):
    """``image / V`` (and ``variance / V^2``): ``image`` ``(H, W)`` or ``(H, W, C)`` of the
    vignetting's ``shape`` (another size raises ``ValueError``). Returns the image, or
    ``(image, variance)`` when ``variance`` is given. ``V`` is floored at 1e-3 (finite)."""
    img = as_float_array(image, "image")
    if tuple(img.shape[:2]) != tuple(vignetting.shape):
        raise ValueError(
            f"image: {tuple(img.shape[:2])} pixels, but the vignetting was fitted on "
            f"{tuple(vignetting.shape)}"
        )
    v = jnp.maximum(vignetting.falloff(), 1e-3)
    v = v if img.ndim == 2 else v[..., None]
    if variance is None:
        return img / v
    return img / v, as_float_array(variance, "variance") / jnp.square(v)
