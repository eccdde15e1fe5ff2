"""Cameras: primary-ray generation.

Three generators (the first two as in lecture 4 of the course notes):

- :class:`PerspectiveCamera` — pinhole from an eye position, a look-at target, an up vector and
  a field of view ("geometric" generator: pixel -> point on an image plane -> normalise).
- :class:`ThinLensCamera` — the same look-at camera with a thin lens (depth of field): rays
  start on a lens disk of radius ``aperture_radius`` and meet on the plane of focus at distance
  ``focus_distance`` along the viewing axis (Mitsuba 3's ``thinlens`` sensor).
- :class:`RadianceMeter` / :class:`IrradianceMeter` — Mitsuba 3's ``radiancemeter`` and
  ``irradiancemeter`` sensors: a 1 x 1 image measuring the radiance along one ray, or the
  irradiance averaged over a shape's surface.
- :class:`DistantSensor` — Mitsuba 3's ``distant`` sensor: a 1 x 1 image of the radiance
  leaving the scene along one direction, averaged over a target (a point, a shape or a disk).
- :class:`BatchCamera` — Mitsuba 3's ``batch`` sensor: several cameras of one size rendered
  side by side into one image (sub-image ``i`` is columns ``[i w, (i + 1) w)``).
- :class:`MatrixCamera` — from the inverse of a (view . projection) matrix, so that traced
  images line up exactly with a rasteriser using the same matrices (OpenGL NDC conventions:
  x, y in [-1, 1], y up, z = -1 on the near plane and +1 on the far plane).

Pixel coordinates are continuous: pixel (row i, column j) covers ``[j, j+1) x [i, i+1)``, with
(0, 0) the top-left corner of the image. Conventions follow Mitsuba 3: ``fov`` is in degrees
and by default spans the horizontal axis (``fov_axis="x"``); the image is not mirrored (image
left is the camera's left).

A camera's class attribute ``lens_uniforms`` is the number of uniform numbers in ``[0, 1)`` its
``generate_ray`` takes per ray besides the pixel position (0: ``generate_ray(pixel)``; the thin
lens: 2, ``generate_ray(pixel, u_lens)``). The renderer's estimator draws them only for a camera
that asks (:func:`jaxgfx.render.estimator.render_partial`), so pinhole and matrix cameras trace
exactly the rays and images they traced before the thin lens existed.
"""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice, check_nonnegative, check_positive
from jaxgfx._math import safe_normalize
from jaxgfx.render.geometry.area import sample_area
from jaxgfx.render.geometry.frame import frame_from_normal, to_world
from jaxgfx.render.geometry.ray import spawn_ray
from jaxgfx.render.sampling import square_to_cosine_hemisphere, square_to_uniform_disk_concentric

__all__ = [
    "PerspectiveCamera",
    "ThinLensCamera",
    "MatrixCamera",
    "RadianceMeter",
    "IrradianceMeter",
    "BatchCamera",
    "DistantSensor",
    "look_at_basis",
]


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


def _look_at_args(origin, target, up, fov, width, height, fov_axis):
    """The validated look-at arguments ``(origin, target, up, fov)`` as float arrays (concrete
    values): shared by :meth:`PerspectiveCamera.look_at` and :meth:`ThinLensCamera.look_at`."""
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
    return o, t, u, f


def _tan_half(fov, fov_axis, aspect):
    """``(tan_x, tan_y)``: the half extents of the image plane at unit distance."""
    t = jnp.tan(jnp.deg2rad(fov) * 0.5)
    if fov_axis == "x":
        return t, t / aspect
    return t * aspect, t


def _screen(pixel, width, height, tx, ty):
    """Image-plane coordinates ``(s_x, s_y)`` at unit distance of continuous pixel positions."""
    sx = (2.0 * pixel[..., 0] / width - 1.0) * tx
    sy = (1.0 - 2.0 * pixel[..., 1] / height) * ty
    return sx, sy


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

    lens_uniforms: ClassVar[int] = 0

    @classmethod
    def look_at(cls, origin, target, up, fov, width, height, *, fov_axis="x"):
        """Validated constructor (concrete arguments): fov in (0, 180) degrees."""
        o, t, u, f = _look_at_args(origin, target, up, fov, width, height, fov_axis)
        return cls(o, t, u, f, int(width), int(height), fov_axis)

    @property
    def aspect(self) -> float:
        return self.width / self.height

    def _tan_half(self):
        return _tan_half(self.fov, self.fov_axis, self.aspect)

    def generate_ray(self, pixel):
        """Rays through continuous pixel positions ``pixel (..., 2)`` = (x, y) in pixels.

        Returns ``(o, d)`` of shapes (..., 3), ``d`` unit length.
        """
        pixel = jnp.asarray(pixel)
        right, up, fwd = look_at_basis(self.origin, self.target, self.up)
        tx, ty = self._tan_half()
        sx, sy = _screen(pixel, self.width, self.height, tx, ty)
        d = sx[..., None] * right + sy[..., None] * up + fwd
        d = safe_normalize(d)
        o = jnp.broadcast_to(self.origin, d.shape)
        return o, d


class ThinLensCamera(eqx.Module):
    """Look-at camera with a thin lens: depth of field (Mitsuba 3's ``thinlens`` sensor).

    Fields as :class:`PerspectiveCamera` (``origin``, ``target``, ``up`` (3,), ``fov`` in
    degrees; static ``width``, ``height``, ``fov_axis``) plus two differentiable scalars:
    ``aperture_radius`` (the lens radius in world units, >= 0) and ``focus_distance`` (the
    distance of the plane of focus from the lens along the viewing axis, > 0; the plane is
    perpendicular to that axis, as Mitsuba's).

    A ray (:meth:`generate_ray`) starts at a point ``a`` of the lens disk (centre ``origin``,
    spanned by the camera's right and up axes) drawn uniformly by Shirley and Chiu's concentric
    map of two uniform numbers, and passes through the point where the pinhole ray of the same
    pixel meets the plane of focus. So every point on that plane is imaged sharply, and a point
    at depth ``z`` along the axis is spread over a disk (the circle of confusion) of diameter

        c = 2 A |z - f| / (z f)          on the image plane at unit distance,

    that is ``c W / (2 tan(fov_x / 2))`` pixels for an image ``W`` pixels wide (``A`` the
    aperture radius, ``f`` the focus distance). ``aperture_radius`` 0 is the pinhole camera:
    the same rays, bit for bit (tests/render/test_thinlens.py).

    Example: every lens ray of the centre pixel of a camera focused at 2 meets ``(0, 0, -2)``::

        cam = ThinLensCamera.look_at([0, 0, 0], [0, 0, -1], [0, 1, 0], 90.0, 4, 4,
                                     aperture_radius=0.1, focus_distance=2.0)
        o, d = cam.generate_ray(jnp.array([2.0, 2.0]), jnp.array([0.9, 0.3]))
        # o + (2 / -d[2]) * d == [0, 0, -2]
    """

    origin: jnp.ndarray
    target: jnp.ndarray
    up: jnp.ndarray
    fov: jnp.ndarray
    aperture_radius: jnp.ndarray
    focus_distance: jnp.ndarray
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)
    fov_axis: str = eqx.field(static=True, default="x")

    lens_uniforms: ClassVar[int] = 2

    def __check_init__(self):
        # concrete values only (tracers pass): what look_at and Scene.replace refuse
        check_nonnegative(self.aperture_radius, "aperture_radius")
        check_positive(self.focus_distance, "focus_distance")

    @classmethod
    def look_at(
        cls,
        origin,
        target,
        up,
        fov,
        width,
        height,
        *,
        aperture_radius,
        focus_distance,
        fov_axis="x",
    ):
        """Validated constructor (concrete arguments): fov in (0, 180) degrees, a finite
        ``aperture_radius >= 0`` and a finite ``focus_distance > 0`` (world units)."""
        o, t, u, f = _look_at_args(origin, target, up, fov, width, height, fov_axis)
        a = as_float_array(aperture_radius, "aperture_radius")
        fd = as_float_array(focus_distance, "focus_distance")
        if a.shape != () or not (np.isfinite(float(a)) and float(a) >= 0.0):
            raise ValueError(
                f"aperture_radius: expected a finite number >= 0 (world units), got "
                f"{aperture_radius!r}"
            )
        if fd.shape != () or not (np.isfinite(float(fd)) and float(fd) > 0.0):
            raise ValueError(
                f"focus_distance: expected a finite number > 0 (world units), got "
                f"{focus_distance!r}"
            )
        return cls(o, t, u, f, a, fd, int(width), int(height), fov_axis)

    @property
    def aspect(self) -> float:
        return self.width / self.height

    def generate_ray(self, pixel, u_lens):
        """Rays through continuous pixel positions ``pixel (..., 2)`` (pixels) and lens samples
        ``u_lens (..., 2)`` in ``[0, 1)^2`` (broadcast together).

        Returns ``(o, d)`` of shapes (..., 3): ``o`` on the lens disk, ``d`` unit length,
        towards the point of the plane of focus the pinhole ray of ``pixel`` meets.
        """
        pixel = jnp.asarray(pixel)
        right, up, fwd = look_at_basis(self.origin, self.target, self.up)
        tx, ty = _tan_half(self.fov, self.fov_axis, self.aspect)
        sx, sy = _screen(pixel, self.width, self.height, tx, ty)
        lens = self.aperture_radius * square_to_uniform_disk_concentric(u_lens)
        ax, ay = lens[..., 0], lens[..., 1]
        # the focus point is origin + f (sx right + sy up + fwd); from the lens point
        # origin + ax right + ay up the ray direction is, divided by f,
        # (sx - ax / f) right + (sy - ay / f) up + fwd: with ax = ay = 0 the pinhole's
        # operations exactly, so aperture 0 gives the pinhole camera's rays bit for bit
        inv_f = 1.0 / self.focus_distance
        sx = sx - ax * inv_f
        sy = sy - ay * inv_f
        d = sx[..., None] * right + sy[..., None] * up + fwd
        d = safe_normalize(d)
        o = self.origin + ax[..., None] * right + ay[..., None] * up
        return jnp.broadcast_to(o, d.shape), d


class MatrixCamera(eqx.Module):
    """Camera from the inverse view-projection matrix (the course's ``EyeRayDir2``).

    ``view_proj_inverse`` (4, 4) maps OpenGL clip/NDC space to world space. A pixel's NDC point
    is unprojected at the near (z=-1) and far (z=+1) planes; the ray starts at the near point and
    points towards the far point. Works for perspective and orthographic projections.
    """

    view_proj_inverse: jnp.ndarray
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)

    lens_uniforms: ClassVar[int] = 0

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


class RadianceMeter(eqx.Module):
    """Mitsuba 3's ``radiancemeter``: a 1 x 1 image whose pixel is the radiance arriving at
    ``origin`` along the ray ``origin + t direction`` (the limit of a perspective camera as
    its field of view tends to 0: every pixel sample traces the same ray). ``origin`` and
    ``direction`` (3,) are differentiable (a unit ``direction`` is stored).

    Example: in a constant environment of radiance ``L`` with nothing in the way the image is
    ``L``; looking at an area light of radiance ``L`` it is ``L``.
    """

    origin: jnp.ndarray
    direction: jnp.ndarray
    width: ClassVar[int] = 1
    height: ClassVar[int] = 1
    lens_uniforms: ClassVar[int] = 0

    @classmethod
    def create(cls, origin, direction):
        """Validated constructor: finite ``origin`` and nonzero finite ``direction`` (3,)."""
        o = as_float_array(origin, "origin")
        d = as_float_array(direction, "direction")
        for name, v in (("origin", o), ("direction", d)):
            if v.shape != (3,) or not np.all(np.isfinite(np.asarray(v))):
                raise ValueError(f"{name}: expected 3 finite numbers, got {np.asarray(v)!r}")
        n = float(np.linalg.norm(np.asarray(d)))
        if not n > 0:
            raise ValueError("direction: expected a nonzero vector")
        return cls(o, d / n)

    def generate_ray(self, pixel):
        """The meter's ray for every pixel sample ``pixel (..., 2)`` (the position is unused)."""
        shape = jnp.shape(pixel)[:-1] + (3,)
        d = safe_normalize(self.direction)
        return jnp.broadcast_to(self.origin, shape), jnp.broadcast_to(d, shape)


class IrradianceMeter(eqx.Module):
    """Mitsuba 3's ``irradiancemeter``: a 1 x 1 image whose pixel is the irradiance
    (W/m², the incident radiance times the cosine, integrated over the hemisphere of the
    geometric normal) averaged over the surface of ``shape`` (Spheres / Rectangles /
    TriangleMesh, the shape it is attached to, in world space). As Mitsuba's, each sample is
    a point uniform by area (:func:`~jaxgfx.render.geometry.sample_area`) and a
    cosine-weighted direction about its normal, weighted by ``pi`` (:attr:`ray_weight`, applied
    by the renderer): ``E = pi E_cos[L]``. So in a constant environment of radiance ``L`` with
    nothing in the way the image is ``pi L``. The shape's parameters are differentiable (the
    sampled points move with it). The shape is not added to the scene's geometry by this
    class; the XML loader adds it (Mitsuba's sensor shape is ordinary geometry too).
    """

    shape: eqx.Module
    width: ClassVar[int] = 1
    height: ClassVar[int] = 1
    lens_uniforms: ClassVar[int] = 4  # a point on the shape (2), a direction (2)
    ray_weight: ClassVar[float] = math.pi

    def generate_ray(self, pixel, u):
        """A ray from uniform numbers ``u (..., 4)``: point ``u[..., :2]``, cosine-weighted
        direction ``u[..., 2:]`` about the normal there; the origin is offset off the surface
        along the normal (as the integrators' secondary rays). ``pixel`` is unused."""
        p, n, _ = sample_area(self.shape, u[..., :2])
        d = to_world(frame_from_normal(n), square_to_cosine_hemisphere(u[..., 2:]))
        o, d = spawn_ray(p, n, d)
        return o, d


class DistantSensor(eqx.Module):
    """Mitsuba 3's ``distant`` sensor: a 1 x 1 image of the radiance travelling along the unit
    ``direction`` (3,) through a target, averaged over the target. Every ray is
    ``o + t direction`` with ``o = p - distance direction``: ``p`` the ``target`` point (3,)
    (``shape`` and ``radius`` unused), or a point of ``shape`` uniform by area (a Spheres /
    Rectangles / TriangleMesh that is only sampled, not scene geometry), or, with ``radius > 0``
    and no shape, a point uniform on the disk of that radius about ``target`` perpendicular to
    ``direction``; weight 1. ``distance`` must put ``o`` outside every shape in the way
    (Mitsuba: twice the radius of the scene's bounding sphere; with no target it starts the
    rays on the disk ``radius`` back from the sphere's centre). ``direction``, ``target``
    and the shape's parameters are differentiable; ``lens_uniforms`` is 0 for a point and 2
    for a shape or a disk (the point's numbers).

    Example: a sensor looking down at a Lambertian plane of albedo ``rho`` lit by a
    directional light of irradiance ``E`` at angle ``theta`` reads ``rho E cos(theta) / pi``.
    """

    direction: jnp.ndarray
    target: jnp.ndarray
    distance: jnp.ndarray
    radius: jnp.ndarray
    shape: eqx.Module | None = None
    lens_uniforms: int = eqx.field(static=True, default=0)
    width: ClassVar[int] = 1
    height: ClassVar[int] = 1

    @classmethod
    def create(cls, direction, target=None, distance=None, *, shape=None, radius=0.0):
        """Validated constructor: a nonzero finite ``direction`` (stored unit), a finite
        ``target`` point (3,) (or ``None`` with a ``shape``), a finite ``distance > 0`` and a
        finite ``radius >= 0`` (a disk about ``target``; not with a shape)."""
        d = as_float_array(direction, "direction")
        if d.shape != (3,) or not np.all(np.isfinite(np.asarray(d))):
            raise ValueError(f"direction: expected 3 finite numbers, got {np.asarray(d)!r}")
        n = float(np.linalg.norm(np.asarray(d)))
        if not n > 0:
            raise ValueError("direction: expected a nonzero vector")
        if (target is None) == (shape is None):
            raise ValueError("target: expected a point or a shape (one of them)")
        t = jnp.zeros(3, d.dtype) if target is None else as_float_array(target, "target")
        if t.shape != (3,) or not np.all(np.isfinite(np.asarray(t))):
            raise ValueError(f"target: expected 3 finite numbers, got {np.asarray(t)!r}")
        dist = as_float_array(distance, "distance")
        if dist.shape != () or not (np.isfinite(float(dist)) and float(dist) > 0):
            raise ValueError(f"distance: expected a finite number > 0, got {distance!r}")
        r = as_float_array(radius, "radius")
        if r.shape != () or not (np.isfinite(float(r)) and float(r) >= 0):
            raise ValueError(f"radius: expected a finite number >= 0, got {radius!r}")
        if shape is not None and float(r) != 0:
            raise ValueError("radius: a disk target is a point target with a radius, not a shape")
        n_u = 2 if (shape is not None or float(r) > 0) else 0
        return cls(d / n, t, dist, r, shape, n_u)

    def generate_ray(self, pixel, u=None):
        """The rays of pixel samples ``pixel (..., 2)`` (unused) and, for a shape or disk
        target, uniform numbers ``u (..., 2)``. Returns ``(o, d)`` of shapes (..., 3)."""
        shape = jnp.shape(pixel)[:-1] + (3,)
        d = safe_normalize(self.direction)
        if self.shape is not None:
            p, _, _ = sample_area(self.shape, u)
        elif self.lens_uniforms:  # a disk about the target, perpendicular to d
            disk = self.radius * square_to_uniform_disk_concentric(u)
            zero = jnp.zeros_like(disk[..., :1])
            p = self.target + to_world(frame_from_normal(d), jnp.concatenate([disk, zero], -1))
        else:
            p = self.target
        o = p - self.distance * d
        return jnp.broadcast_to(o, shape), jnp.broadcast_to(d, shape)


class BatchCamera(eqx.Module):
    """Mitsuba 3's ``batch`` sensor: ``cameras`` (a tuple of :class:`PerspectiveCamera`,
    :class:`ThinLensCamera` or :class:`MatrixCamera`, all ``w`` x ``h`` pixels) rendered side by
    side into one ``K w`` x ``h`` image, in order: camera ``i`` fills columns
    ``[i w, (i + 1) w)``. As Mitsuba's, a pixel sample at ``x`` belongs to the camera whose
    columns hold ``x`` (clamped to the first / last camera beyond the image), which traces it
    at ``x - i w`` of its own image: a reconstruction filter wider than a pixel mixes the
    neighbouring cameras' rays into the columns at a seam, as Mitsuba's film does. The
    cameras' parameters stay differentiable leaves (``camera.cameras.1.fov``).

    ``lens_uniforms`` is the largest of the cameras' (a thin lens takes the first two of the
    numbers drawn per ray). Every camera generates rays for every sample and each sample keeps
    its own camera's (a select): ``K`` ray generations per sample, cheap next to tracing.

    Example: two pinhole cameras of 4 x 4 make an 8 x 4 image; pixel ``(5.5, 2)`` is camera 1's
    pixel ``(1.5, 2)``::

        a = PerspectiveCamera.look_at([0, 0, 0], [0, 0, -1], [0, 1, 0], 60.0, 4, 4)
        b = PerspectiveCamera.look_at([1, 0, 0], [1, 0, -1], [0, 1, 0], 60.0, 4, 4)
        cam = BatchCamera.create([a, b])   # cam.width == 8
        cam.generate_ray(jnp.array([5.5, 2.0]))   # == b.generate_ray(jnp.array([1.5, 2.0]))
    """

    cameras: tuple
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)
    lens_uniforms: int = eqx.field(static=True, default=0)

    @classmethod
    def create(cls, cameras):
        """Validated constructor: one or more image cameras (not meters, not batches) of the
        same width and height."""
        cams = tuple(cameras)
        if not cams:
            raise ValueError("cameras: expected at least one camera")
        kinds = (PerspectiveCamera, ThinLensCamera, MatrixCamera)
        for i, c in enumerate(cams):
            if not isinstance(c, kinds):
                raise ValueError(
                    f"cameras.{i}: a batch holds perspective, thin-lens or matrix cameras, got "
                    f"{type(c).__name__}"
                )
            if (c.width, c.height) != (cams[0].width, cams[0].height):
                raise ValueError(
                    f"cameras.{i}: every camera of a batch has the same size, got "
                    f"{c.width} x {c.height} and {cams[0].width} x {cams[0].height}"
                )
        n_lens = max(c.lens_uniforms for c in cams)
        return cls(cams, len(cams) * cams[0].width, cams[0].height, n_lens)

    def generate_ray(self, pixel, u_lens=None):
        """Rays through continuous pixel positions ``pixel (..., 2)`` of the whole image;
        ``u_lens (..., lens_uniforms)`` when ``lens_uniforms > 0``. Returns ``(o, d)``."""
        pixel = jnp.asarray(pixel)
        w = self.cameras[0].width
        idx = jnp.clip(jnp.floor(pixel[..., 0] / w), 0, len(self.cameras) - 1)
        o = d = None
        for i, cam in enumerate(self.cameras):
            local = pixel - jnp.asarray([i * w, 0], pixel.dtype)
            if cam.lens_uniforms:
                oi, di = cam.generate_ray(local, u_lens[..., : cam.lens_uniforms])
            else:
                oi, di = cam.generate_ray(local)
            if o is None:
                o, d = oi, di
            else:
                sel = (idx == i)[..., None]
                o, d = jnp.where(sel, oi, o), jnp.where(sel, di, d)
        return o, d


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
