"""Cameras: primary-ray generation.

Two generators, as in lecture 4 of the course notes:

- :class:`PerspectiveCamera` — pinhole from an eye position, a look-at target, an up vector and
  a field of view ("geometric" generator: pixel -> point on an image plane -> normalise).
- :class:`MatrixCamera` — from the inverse of a (view . projection) matrix, so that traced
  images line up exactly with a rasteriser using the same matrices (OpenGL NDC conventions:
  x, y in [-1, 1], y up, z = -1 on the near plane and +1 on the far plane).

Pixel coordinates are continuous: pixel (row i, column j) covers ``[j, j+1) x [i, i+1)``, with
(0, 0) the top-left corner of the image. Conventions follow Mitsuba 3: ``fov`` is in degrees
and by default spans the horizontal axis (``fov_axis="x"``); the image is not mirrored (image
left is the camera's left).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice
from jaxgfx._math import safe_normalize

__all__ = ["PerspectiveCamera", "MatrixCamera", "look_at_basis"]


def look_at_basis(origin, target, up):
    """Orthonormal camera basis ``(right, true_up, forward)`` for a look-at camera."""
    forward = safe_normalize(target - origin)
    right = safe_normalize(jnp.cross(forward, up))
    true_up = jnp.cross(right, forward)
    return right, true_up, forward


def _check_resolution(width, height):
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"{name}: expected a positive integer, got {v!r}")


class PerspectiveCamera(eqx.Module):
    """Pinhole camera from look-at parameters.

    Fields ``origin``, ``target``, ``up`` (3,) and ``fov`` (degrees) are differentiable leaves;
    ``width``, ``height`` (pixels) and ``fov_axis`` ("x" or "y") are static.

    Example: the centre ray of a camera at the origin looking down -z points along -z::

        cam = PerspectiveCamera.look_at([0, 0, 0], [0, 0, -1], [0, 1, 0], 90.0, 4, 4)
        o, d = cam.generate_ray(jnp.array([2.0, 2.0]))   # d == [0, 0, -1]
    """

    origin: jnp.ndarray
    target: jnp.ndarray
    up: jnp.ndarray
    fov: jnp.ndarray
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)
    fov_axis: str = eqx.field(static=True, default="x")

    @classmethod
    def look_at(cls, origin, target, up, fov, width, height, *, fov_axis="x"):
        """Validated constructor (concrete arguments): fov in (0, 180) degrees."""
        _check_resolution(width, height)
        check_choice(fov_axis, "fov_axis", ("x", "y"))
        o = as_float_array(origin, "origin")
        t = as_float_array(target, "target")
        u = as_float_array(up, "up")
        for name, v in (("origin", o), ("target", t), ("up", u)):
            if v.shape != (3,):
                raise ValueError(f"{name}: expected shape (3,), got {v.shape}")
            if not np.all(np.isfinite(np.asarray(v))):
                raise ValueError(f"{name}: expected finite values, got {np.asarray(v)}")
        f = as_float_array(fov, "fov")
        if f.shape != () or not (0.0 < float(f) < 180.0):
            raise ValueError(f"fov: expected a scalar in (0, 180) degrees, got {fov!r}")
        if np.allclose(np.asarray(t), np.asarray(o)):
            raise ValueError("target: must differ from origin")
        d = np.asarray(t) - np.asarray(o)
        if np.linalg.norm(np.cross(d, np.asarray(u))) < 1e-8 * np.linalg.norm(d) * max(
            np.linalg.norm(np.asarray(u)), 1e-30
        ):
            raise ValueError("up: must not be parallel to the viewing direction")
        return cls(o, t, u, f, int(width), int(height), fov_axis)

    @property
    def aspect(self) -> float:
        return self.width / self.height

    def _tan_half(self):
        t = jnp.tan(jnp.deg2rad(self.fov) * 0.5)
        if self.fov_axis == "x":
            return t, t / self.aspect
        return t * self.aspect, t

    def generate_ray(self, pixel):
        """Rays through continuous pixel positions ``pixel (..., 2)`` = (x, y) in pixels.

        Returns ``(o, d)`` of shapes (..., 3), ``d`` unit length.
        """
        pixel = jnp.asarray(pixel)
        right, up, fwd = look_at_basis(self.origin, self.target, self.up)
        tx, ty = self._tan_half()
        sx = (2.0 * pixel[..., 0] / self.width - 1.0) * tx
        sy = (1.0 - 2.0 * pixel[..., 1] / self.height) * ty
        d = sx[..., None] * right + sy[..., None] * up + fwd
        d = safe_normalize(d)
        o = jnp.broadcast_to(self.origin, d.shape)
        return o, d


class MatrixCamera(eqx.Module):
    """Camera from the inverse view-projection matrix (the course's ``EyeRayDir2``).

    ``view_proj_inverse`` (4, 4) maps OpenGL clip/NDC space to world space. A pixel's NDC point
    is unprojected at the near (z=-1) and far (z=+1) planes; the ray starts at the near point and
    points towards the far point. Works for perspective and orthographic projections.
    """

    view_proj_inverse: jnp.ndarray
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)

    @classmethod
    def from_matrix(cls, view_proj_inverse, width, height):
        _check_resolution(width, height)
        m = as_float_array(view_proj_inverse, "view_proj_inverse")
        if m.shape != (4, 4):
            raise ValueError(f"view_proj_inverse: expected shape (4, 4), got {m.shape}")
        if not np.all(np.isfinite(np.asarray(m))) or abs(np.linalg.det(np.asarray(m))) < 1e-30:
            raise ValueError("view_proj_inverse: expected a finite, invertible 4x4 matrix")
        return cls(m, int(width), int(height))

    @classmethod
    def from_view_proj(cls, view, proj, width, height):
        """From separate view and projection matrices (column-vector convention P @ V @ x)."""
        vp = np.asarray(proj, np.float64) @ np.asarray(view, np.float64)
        return cls.from_matrix(np.linalg.inv(vp).astype(np.float32), width, height)

    def generate_ray(self, pixel):
        pixel = jnp.asarray(pixel)
        x = 2.0 * pixel[..., 0] / self.width - 1.0
        y = 1.0 - 2.0 * pixel[..., 1] / self.height
        one = jnp.ones_like(x)

        def unproject(z):
            p = jnp.stack([x, y, z * one, one], axis=-1) @ self.view_proj_inverse.T
            return p[..., :3] / p[..., 3:4]

        near, far = unproject(-1.0), unproject(1.0)
        return near, safe_normalize(far - near)


def perspective_matrix(fov_y_deg, aspect, near, far):
    """OpenGL-style perspective projection (for tests and users building MatrixCameras)."""
    f = 1.0 / np.tan(np.deg2rad(fov_y_deg) / 2)
    return np.array(
        [
            [f / aspect, 0, 0, 0],
            [0, f, 0, 0],
            [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
            [0, 0, -1, 0],
        ]
    )


def look_at_matrix(origin, target, up):
    """OpenGL-style view matrix (world -> camera, camera looks down -z)."""
    o, t, u = (np.asarray(v, np.float64) for v in (origin, target, up))
    f = (t - o) / np.linalg.norm(t - o)
    r = np.cross(f, u)
    r /= np.linalg.norm(r)
    uu = np.cross(r, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = r, uu, -f
    m[:3, 3] = -m[:3, :3] @ o
    return m


__all__ += ["perspective_matrix", "look_at_matrix"]
