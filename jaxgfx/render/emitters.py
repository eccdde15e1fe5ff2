"""Emitters: point lights, area lights (emitting shapes), constant and image environments.

Conventions follow Mitsuba 3:

- ``PointLights``: ``intensity`` in W/sr (radiance-like units per steradian); irradiance at
  distance r falls off as ``intensity / r^2``.
- ``AreaLight``: a shape of the scene emits ``radiance`` from its front side (the side its
  geometric normal points to): a constant, or a texture looked up at the surface ``uv``; it is
  also ordinary geometry (it occludes and is hit).
- ``DirectionalLight``: a distant light, ``irradiance`` (W/m^2 on a surface facing it) arriving
  along ``direction`` (the direction the light travels, Mitsuba's ``direction``); a delta light.
- ``SpotLight``: a point light at ``position`` with axis ``direction``, ``intensity`` (W/sr) on
  the axis, full intensity inside ``beam_width`` and Mitsuba's linear-in-angle falloff
  ``(cutoff - theta) / (cutoff - beam_width)`` to zero at ``cutoff_angle`` (degrees, as in
  Mitsuba's XML); a delta light, differentiable in both angles. An optional projected
  ``texture`` (Mitsuba's spot ``texture``) scales the intensity by the texel the direction maps
  to: ``uv = 0.5 + 0.5 (x, y) / (z tan(cutoff))`` in the light's frame (``x`` = left of the
  ``up`` vector seen along ``direction``, as Mitsuba's ``look_at``).
- ``ProjectorLight``: Mitsuba's ``projector``, a pinhole that projects an ``irradiance``
  texture through a perspective frustum (``fov``): a white diffuse plane facing it at distance
  1 receives irradiance ``pi * scale * E(uv)`` everywhere in the frustum (the ``1 / cos^3``
  that makes a projected constant truly constant on the plane); a delta light.
- ``DirectionalAreaLight``: Mitsuba's ``directionalarea``, a shape emitting ``radiance`` only
  along its normal; seen by the particle tracer only (as in Mitsuba).
- ``ConstantEnvironment``: radiance arriving from every direction.
- ``EnvironmentMap``: latitude-longitude image, y-up, with Mitsuba's mapping
  ``u = atan2(d_x, -d_z) / (2 pi)`` (wrapped to [0, 1)), ``v = acos(d_y) / pi``; importance
  sampled by luminance x sin(theta) through a piecewise-constant 2-D distribution.

All sampling routines take uniform numbers and return solid-angle densities.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_finite, check_nonnegative, is_concrete
from jaxgfx._math import (
    safe_arccos,
    safe_atan2,
    safe_div,
    safe_normalize,
    safe_sqrt,
    sincos,
    sum_last,
    take_rows,
)
from jaxgfx.color import LUMINANCE_WEIGHTS
from jaxgfx.render.bsdf import rgb_param
from jaxgfx.render.bsdf.texture import Texture, lookup
from jaxgfx.render.bsdf.textured import texture_eval, texture_min
from jaxgfx.render.geometry.frame import rotation_to_local, rotation_to_world
from jaxgfx.render.sampling import Distribution2D

__all__ = [
    "PointLights",
    "AreaLight",
    "DirectionalAreaLight",
    "DirectionalLight",
    "SpotLight",
    "ProjectorLight",
    "ConstantEnvironment",
    "EnvironmentMap",
    "direction_to_latlong",
    "latlong_to_direction",
]


class PointLights(eqx.Module):
    """``positions (P, 3)`` and ``intensities (P, 3)`` (W/sr)."""

    positions: jnp.ndarray
    intensities: jnp.ndarray

    def __check_init__(self):  # also runs on Scene.replace (concrete values only)
        check_finite(self.positions, "position")
        check_nonnegative(self.intensities, "intensities")

    @classmethod
    def create(cls, positions, intensities):
        p = as_float_array(positions, "position")
        check_finite(p, "position")
        p = p.reshape(-1, 3)
        i = rgb_param(intensities, "intensity").reshape(-1, 3)
        if i.shape[0] != p.shape[0]:
            raise ValueError("intensity: expected one RGB intensity per point light")
        return cls(p, i)

    @property
    def count(self) -> int:
        return self.positions.shape[0]

    def sample(self, index, p):
        """Direction, distance and incident radiance-equivalent from light ``index`` at ``p``.

        Returns ``(wi, dist, Li)`` where ``Li = I / dist^2`` (a delta distribution: pdf 1).
        """
        lp = take_rows(self.positions, index)
        v = lp - p
        d2 = sum_last(v * v)
        dist = safe_sqrt(d2)
        wi = safe_div(v, dist[..., None])
        li = safe_div(take_rows(self.intensities, index), d2[..., None])
        return wi, dist, li


def _unit_direction(d, name):
    d = as_float_array(d, name)
    check_finite(d, name)
    if d.shape != (3,):
        raise ValueError(f"{name}: expected 3 numbers, got shape {d.shape}")
    n = float(jnp.linalg.norm(d))
    if not n > 0:
        raise ValueError(f"{name}: expected a nonzero vector")
    return d / n


class DirectionalLight(eqx.Module):
    """Distant light (Mitsuba ``directional``): ``irradiance (3,)`` arriving along the unit
    ``direction (3,)`` (the direction of travel). Light sampling only (a delta light): from any
    point the light is ``wi = -direction`` at infinite distance with ``Li = irradiance``."""

    irradiance: jnp.ndarray
    direction: jnp.ndarray

    def __check_init__(self):
        check_nonnegative(self.irradiance, "irradiance")
        check_finite(self.direction, "direction")

    @classmethod
    def create(cls, irradiance, direction):
        return cls(rgb_param(irradiance, "irradiance"), _unit_direction(direction, "direction"))

    def sample(self, p):
        """``(wi, dist, Li)`` at points ``p (..., 3)`` (pdf 1: a delta light)."""
        shape = p.shape[:-1]
        wi = jnp.broadcast_to(-safe_normalize(self.direction.astype(p.dtype)), p.shape)
        dist = jnp.full(shape, jnp.inf, p.dtype)
        li = jnp.broadcast_to(self.irradiance.astype(p.dtype), p.shape)
        return wi, dist, li


class SpotLight(eqx.Module):
    """Spot light (Mitsuba ``spot``): ``position (3,)``, unit axis ``direction (3,)``,
    ``intensity (3,)`` (W/sr on the axis), ``cutoff_angle`` and ``beam_width`` (degrees).

    Falloff with the angle ``theta`` from the axis (Mitsuba 3 ``SpotLight::falloff_curve``):
    1 for ``theta <= beam_width``, ``(cutoff - theta) / (cutoff - beam_width)`` between, 0 for
    ``theta >= cutoff``. Continuous in ``theta``, so images are differentiable in both angles
    without a boundary term. Light sampling only (a delta light).

    ``texture`` (optional :class:`~jaxgfx.render.bsdf.texture.Texture`, RGB): Mitsuba's
    projected texture, looked up at ``uv = 0.5 + 0.5 (x, y) / (z tan(cutoff))`` of the direction
    in the light's frame (``z`` = ``direction``, ``x`` = ``normalize(cross(up, z))``, ``y`` =
    ``cross(z, x)``; ``up`` is stored only with a texture). The cone's disc is inscribed in
    the texture's square; the texels (and ``cutoff_angle``, through ``uv``) are differentiable.
    Without a texture the light's program is the untextured one.
    """

    position: jnp.ndarray
    direction: jnp.ndarray
    intensity: jnp.ndarray
    cutoff_angle: jnp.ndarray
    beam_width: jnp.ndarray
    texture: Texture | None = None
    up: jnp.ndarray | None = None

    def __check_init__(self):
        check_finite(self.position, "position")
        check_finite(self.direction, "direction")
        check_nonnegative(self.intensity, "intensity")
        check_finite(self.cutoff_angle, "cutoff_angle")
        check_finite(self.beam_width, "beam_width")
        if is_concrete(self.cutoff_angle) and is_concrete(self.beam_width):
            c, b = float(self.cutoff_angle), float(self.beam_width)
            if not 0 < c <= 180:
                raise ValueError(f"cutoff_angle: expected degrees in (0, 180], got {c}")
            if not 0 <= b <= c:
                raise ValueError(f"beam_width: expected degrees in [0, cutoff_angle], got {b}")

    @classmethod
    def create(cls, position, direction, intensity, cutoff_angle=20.0, beam_width=None, *,
               texture=None, up=None):  # fmt: skip
        """Mitsuba's defaults: ``cutoff_angle`` 20 degrees, ``beam_width`` 3/4 of it.
        ``texture``: a :class:`Texture` (1 or 3 channels) or ``None``; ``up`` (with a texture
        only; default ``(0, 1, 0)``): orients the texture around the axis."""
        p = as_float_array(position, "position")
        check_finite(p, "position")
        if p.shape != (3,):
            raise ValueError(f"position: expected 3 numbers, got shape {p.shape}")
        c = as_float_array(cutoff_angle, "cutoff_angle")
        if c.shape != ():
            raise ValueError(f"cutoff_angle: expected a number, got shape {c.shape}")
        b = 0.75 * c if beam_width is None else as_float_array(beam_width, "beam_width")
        if b.shape != ():
            raise ValueError(f"beam_width: expected a number, got shape {b.shape}")
        d = _unit_direction(direction, "direction")
        if texture is None:
            if up is not None:
                raise ValueError("up: only a spot light with a texture takes an up vector")
            return cls(p, d, rgb_param(intensity, "intensity"), c, b)
        tex = _rgb_texture(texture, "texture")
        u = _up_vector([0.0, 1.0, 0.0] if up is None else up, d)
        return cls(p, d, rgb_param(intensity, "intensity"), c, b, tex, u)

    def falloff(self, cos_theta):
        """Mitsuba's falloff curve at ``cos_theta`` (cosine to the axis), in [0, 1]."""
        dt = cos_theta.dtype
        cutoff = jnp.deg2rad(self.cutoff_angle.astype(dt))
        beam = jnp.deg2rad(self.beam_width.astype(dt))
        theta = safe_arccos(cos_theta)
        # the ratio only where it is selected, so an equal beam and cutoff gives no 0 / 0
        ramp = safe_div(cutoff - theta, cutoff - beam)
        f = jnp.where(theta <= beam, 1.0, jnp.clip(ramp, 0.0, 1.0))
        return jnp.where(theta < cutoff, f, 0.0)

    def sample(self, p):
        """``(wi, dist, Li)`` at points ``p (..., 3)`` (pdf 1: a delta light)."""
        v = self.position.astype(p.dtype) - p
        d2 = sum_last(v * v)
        dist = safe_sqrt(d2)
        wi = safe_div(v, dist[..., None])
        axis = safe_normalize(self.direction.astype(p.dtype))
        cos_theta = -sum_last(wi * axis)
        li = self.intensity.astype(p.dtype) * safe_div(self.falloff(cos_theta), d2)[..., None]
        if self.texture is not None:
            li = li * self.texture_value(-wi)
        return wi, dist, li

    def texture_uv(self, d):
        """Mitsuba's ``direction_to_uv`` of world directions ``d (..., 3)`` leaving the light
        (``(0.5, 0.5)`` on the axis; the cone's edge touches the square's sides)."""
        frame = _look_at_frame(self.direction.astype(d.dtype), self.up.astype(d.dtype))
        loc = d @ frame.T
        t = jnp.tan(jnp.deg2rad(self.cutoff_angle.astype(d.dtype)))
        z = loc[..., 2] * t
        return 0.5 + 0.5 * safe_div(loc[..., :2], z[..., None])

    def texture_value(self, d):
        """The projected texture (RGB) toward world directions ``d (..., 3)``."""
        # inside the cone uv lies in [0, 1]; the clip only keeps the lookup finite where the
        # falloff is 0 (behind the light, z -> 0)
        uv = jnp.clip(self.texture_uv(d), -1.0, 2.0)
        return lookup(self.texture, uv).astype(d.dtype)


def _rgb_texture(tex, name):
    """``tex`` as an RGB :class:`Texture` (one channel repeated three times)."""
    if not isinstance(tex, Texture):
        raise TypeError(f"{name}: expected a Texture, got {type(tex).__name__}")
    c = tex.image.shape[-1]
    if c == 1:
        return Texture(jnp.repeat(tex.image, 3, -1), wrap=tex.wrap, filter=tex.filter,
                       to_uv=tex.to_uv)  # fmt: skip
    if c != 3:
        raise ValueError(f"{name}: expected a texture of 1 or 3 channels, got {c}")
    check_nonnegative(tex.image, f"{name}.image")
    return tex


def _up_vector(up, d):
    u = as_float_array(up, "up")
    check_finite(u, "up")
    if u.shape != (3,):
        raise ValueError(f"up: expected 3 numbers, got shape {u.shape}")
    n = float(jnp.linalg.norm(u))
    if not n > 0 or float(jnp.linalg.norm(jnp.cross(u / n, d))) < 1e-6:
        raise ValueError(f"up: expected a vector not parallel to the direction, got {up!r}")
    return u / n


def _look_at_frame(d, up):
    """Rows ``(x, y, z)`` of Mitsuba's ``look_at`` frame: ``z = d``, ``x = cross(up, z)``
    normalised ("left" in the image), ``y = cross(z, x)``."""
    z = safe_normalize(d)
    x = safe_normalize(jnp.cross(up, z))
    return jnp.stack([x, jnp.cross(z, x), z])


class ProjectorLight(eqx.Module):
    """Projector (Mitsuba 3 ``projector``): a pinhole at ``position`` looking along
    ``direction`` with ``up``, projecting the ``irradiance`` texture (RGB
    :class:`~jaxgfx.render.bsdf.texture.Texture`, a constant is a 1 x 1 one) times ``scale``
    through the frustum of horizontal field of view ``fov`` (degrees; the vertical one follows
    from the texture's aspect ``W / H``), the reciprocal of a perspective camera.

    A point at ``(x, y, z)`` in the light's frame (``z`` along ``direction``, ``x`` =
    ``normalize(cross(up, z))`` the image's left, ``y = cross(z, x)``) maps to
    ``u = 0.5 - 0.5 x / (z tan(fov / 2))``, ``v = 0.5 - 0.5 (W / H) y / (z tan(fov / 2))``
    (texel row 0 at the top, the image upright on a wall facing the projector); outside
    ``[0, 1]^2`` or behind (``z <= 0``) it gets nothing. The light arriving at distance ``r``
    is ``Li = pi * scale * E(uv) * r / z^3`` (= ``pi scale E / (z^2 cos theta)``, Mitsuba's
    ``sample_direction``): a plane facing the projector at distance ``z`` receives irradiance
    ``pi * scale * E(uv) / z^2``, constant across the plane for a constant texture. A delta
    light (pdf 1); differentiable in the texels, ``scale``, ``position`` and ``fov``.
    """

    position: jnp.ndarray
    frame: jnp.ndarray
    irradiance: Texture
    scale: jnp.ndarray
    fov: jnp.ndarray

    def __check_init__(self):
        check_finite(self.position, "position")
        check_finite(self.frame, "frame")
        check_nonnegative(self.irradiance.image, "irradiance")
        check_nonnegative(self.scale, "scale")
        check_finite(self.fov, "fov")
        if is_concrete(self.fov) and not 0 < float(self.fov) < 180:
            raise ValueError(f"fov: expected degrees in (0, 180), got {float(self.fov)}")

    @classmethod
    def create(cls, position, direction, irradiance=1.0, *, fov, up=(0.0, 1.0, 0.0), scale=1.0,
               fov_axis="x"):  # fmt: skip
        """``irradiance``: an RGB value (a 1 x 1 texture, as Mitsuba's constant) or a
        :class:`Texture`; ``fov`` along ``fov_axis`` ``"x"`` or ``"y"`` (converted to the
        horizontal one with the texture's aspect ratio)."""
        p = as_float_array(position, "position")
        check_finite(p, "position")
        if p.shape != (3,):
            raise ValueError(f"position: expected 3 numbers, got shape {p.shape}")
        d = _unit_direction(direction, "direction")
        frame = _look_at_frame(d, _up_vector(up, d))
        if isinstance(irradiance, Texture):
            tex = _rgb_texture(irradiance, "irradiance")
        else:
            tex = Texture(rgb_param(irradiance, "irradiance").reshape(1, 1, 3))
        s = as_float_array(scale, "scale")
        if s.shape != ():
            raise ValueError(f"scale: expected a number, got shape {s.shape}")
        check_nonnegative(s, "scale")
        f = as_float_array(fov, "fov")
        if f.shape != () or not 0 < float(f) < 180:
            raise ValueError(f"fov: expected degrees in (0, 180), got {fov!r}")
        if fov_axis not in ("x", "y"):
            raise ValueError(f"fov_axis: expected 'x' or 'y', got {fov_axis!r}")
        if fov_axis == "y":  # tan(fov_x / 2) = aspect tan(fov_y / 2)
            h, w = tex.image.shape[:2]
            # (host arithmetic: ``f`` is concrete here, checked above)
            f = as_float_array(2.0 * math.degrees(math.atan(w / h * math.tan(
                math.radians(float(f)) / 2.0))), "fov")  # fmt: skip
        return cls(p, frame, tex, s, f)

    @property
    def aspect(self) -> float:
        h, w = self.irradiance.image.shape[:2]
        return w / h

    @property
    def direction(self):
        return self.frame[2]

    @property
    def up(self):
        return self.frame[1]

    def local(self, p):
        """Points ``p (..., 3)`` in the projector's frame."""
        return (p - self.position.astype(p.dtype)) @ self.frame.astype(p.dtype).T

    def uv(self, loc):
        """Image coordinates of points ``loc (..., 3)`` in the projector's frame, and whether
        they lie in the frustum (``z > 0``, ``uv`` in ``[0, 1]^2``)."""
        t = jnp.tan(jnp.deg2rad(self.fov.astype(loc.dtype)) * 0.5)
        z = loc[..., 2]
        front = z > 0
        zt = jnp.where(front, z, 1.0) * t
        u = 0.5 - 0.5 * loc[..., 0] / zt
        v = 0.5 - 0.5 * self.aspect * loc[..., 1] / zt
        uv = jnp.stack([u, v], -1)
        inside = front & jnp.all((uv >= 0) & (uv <= 1), -1)
        return uv, inside

    def sample(self, p):
        """``(wi, dist, Li)`` at points ``p (..., 3)`` (pdf 1: a delta light)."""
        v = self.position.astype(p.dtype) - p
        d2 = sum_last(v * v)
        dist = safe_sqrt(d2)
        wi = safe_div(v, dist[..., None])
        loc = self.local(p)
        uv, inside = self.uv(loc)
        e = lookup(self.irradiance, jnp.clip(uv, 0.0, 1.0)).astype(p.dtype)
        z = jnp.where(inside, loc[..., 2], 1.0)
        cos = jnp.where(inside, safe_div(z, dist), 1.0)  # cosine to the axis, in (0, 1]
        k = math.pi * self.scale.astype(p.dtype) / (z * z * cos)
        li = jnp.where(inside[..., None], e * k[..., None], 0.0)
        return wi, dist, li


class AreaLight(eqx.Module):
    """``radiance`` emitted from the front side of scene shape ``shape_index``: an RGB
    ``(3,)`` constant, or a texture (:class:`~jaxgfx.render.bsdf.texture.Texture` bitmap or
    :class:`~jaxgfx.render.bsdf.textured.Checkerboard`) evaluated at the surface point's ``uv``
    as Mitsuba 3's ``area`` emitter evaluates its ``radiance`` texture (a one-channel texture is
    grey). The texels are differentiable leaves (``emitters.area.I.radiance.image``).

    Example: ``AreaLight(jnp.ones(3), 0).radiance_at(jnp.zeros((2, 2)))`` is ``ones((2, 3))``.
    """

    radiance: jnp.ndarray | eqx.Module
    shape_index: int = eqx.field(static=True)

    def __check_init__(self):  # also runs on Scene.replace (concrete values only)
        if not self.textured:
            check_nonnegative(self.radiance, "radiance")
            return
        if not all(is_concrete(x) for x in jax.tree_util.tree_leaves(self.radiance)):
            return
        lo = texture_min(self.radiance)
        if not lo >= 0:  # NaN fails too
            raise ValueError(f"radiance: texture values must be non-negative, got min {lo}")

    @property
    def textured(self) -> bool:
        """Whether ``radiance`` is a texture (static: known at trace time)."""
        return not eqx.is_array(self.radiance)

    def radiance_at(self, uv):
        """Emitted radiance ``(..., 3)`` at surface coordinates ``uv (..., 2)`` (the hit's or the
        sampled point's ``uv``; a constant radiance is broadcast). Front-side and visibility
        tests are the caller's."""
        if not self.textured:
            return jnp.broadcast_to(self.radiance.astype(uv.dtype), uv.shape[:-1] + (3,))
        val = texture_eval(self.radiance, uv).astype(uv.dtype)
        return jnp.broadcast_to(val, val.shape[:-1] + (3,))

    @property
    def samples_texture(self) -> bool:
        """Whether light samples follow the texture (a bitmap without ``to_uv``; static)."""
        return isinstance(self.radiance, Texture) and self.radiance.to_uv is None

    def uv_distribution(self, dtype) -> Distribution2D:
        """Sampling density on ``[0, 1]²`` of a bitmap radiance (``samples_texture``): as
        Mitsuba 3's bitmap ``sample_position``, proportional to each texel's luminance (Rec. 709
        Y of linear RGB); for bilinear lookup the luminance is first spread by the separable
        ``(1/8, 3/4, 1/8)`` filter (wrapping for ``repeat``, clamped otherwise), as
        :class:`EnvironmentMap` does, so every point of nonzero radiance has nonzero density
        (Mitsuba instead offsets the texel sample by a tent). Piecewise constant per texel; built
        from the texels without derivative (the density is frozen, the radiance is not)."""
        img = jax.lax.stop_gradient(self.radiance.image).astype(dtype)
        if img.shape[-1] >= 3:
            lum = img[..., :3] @ jnp.asarray(LUMINANCE_WEIGHTS["rec709"], dtype)
        else:
            lum = img[..., 0]
        lum = jnp.maximum(lum, 0.0)
        if self.radiance.filter == "bilinear":
            for axis in (0, 1):
                if self.radiance.wrap == "repeat":
                    a, b = jnp.roll(lum, 1, axis=axis), jnp.roll(lum, -1, axis=axis)
                else:  # clamp / mirror: the edge texel is its own neighbour
                    n = lum.shape[axis]
                    idx = jnp.arange(n)
                    a = jnp.take(lum, jnp.maximum(idx - 1, 0), axis=axis)
                    b = jnp.take(lum, jnp.minimum(idx + 1, n - 1), axis=axis)
                lum = 0.75 * lum + 0.125 * (a + b)
        return Distribution2D(lum)


class DirectionalAreaLight(eqx.Module):
    """Mitsuba 3's ``directionalarea``: scene shape ``shape_index`` (sampled through ``shape``,
    its untransformed geometry) emits ``radiance`` (RGB ``(3,)``) only along its geometric
    normal, a delta distribution in direction. As in Mitsuba, nothing connects to it from the
    camera side: a camera ray or a BSDF sample that hits the shape sees no emission, and light
    sampling (next-event estimation) returns zero (:meth:`sample`; it still counts in the
    uniform light choice, as Mitsuba's emitter sampling counts it). Only the particle tracer
    (``ptracer``) emits from it: a point uniform by area and the ray along the normal there,
    weight ``radiance * area`` (Mitsuba's ``sample_ray``). ``radiance`` is differentiable
    (``emitters.directionalarea.I.radiance``)."""

    radiance: jnp.ndarray
    shape: eqx.Module
    shape_index: int = eqx.field(static=True)

    def __check_init__(self):  # also runs on Scene.replace (concrete values only)
        check_nonnegative(self.radiance, "radiance")

    def sample(self, p):
        """Light sampling from points ``p``: zero radiance (a direction drawn towards the
        light has probability 0 of being its normal); ``(wi, dist, Li)`` as the delta lights'."""
        batch = p.shape[:-1]
        wi = jnp.broadcast_to(jnp.asarray([0.0, 0.0, 1.0], p.dtype), batch + (3,))
        return wi, jnp.ones(batch, p.dtype), jnp.zeros(batch + (3,), p.dtype)


class ConstantEnvironment(eqx.Module):
    """Uniform radiance from all directions; sampled uniformly over the sphere."""

    radiance: jnp.ndarray

    def __check_init__(self):  # also runs on Scene.replace (concrete values only)
        check_nonnegative(self.radiance, "radiance")

    def eval(self, d):
        return jnp.broadcast_to(self.radiance, d.shape)

    def sample(self, u):
        z = 1.0 - 2.0 * u[..., 0]
        r = safe_sqrt(1.0 - z * z)
        phi = 2.0 * math.pi * u[..., 1]
        sp, cp = sincos(phi)
        wi = jnp.stack([r * cp, r * sp, z], -1)
        pdf = jnp.full(u.shape[:-1], 1.0 / (4.0 * math.pi), u.dtype)
        return wi, pdf, self.eval(wi)

    def pdf(self, d):
        return jnp.full(d.shape[:-1], 1.0 / (4.0 * math.pi), d.dtype)


def direction_to_latlong(d):
    """Unit direction (..., 3) -> (u, v) in [0, 1)^2 (Mitsuba envmap convention, y up)."""
    u = safe_atan2(d[..., 0], -d[..., 2]) / (2.0 * math.pi)
    u = u - jnp.floor(u)
    v = safe_arccos(jnp.clip(d[..., 1], -1.0, 1.0)) / math.pi
    return jnp.stack([u, v], -1)


def latlong_to_direction(uv):
    """Inverse of :func:`direction_to_latlong`; also returns ``sin(theta)``."""
    phi = uv[..., 0] * 2.0 * math.pi
    theta = uv[..., 1] * math.pi
    st, ct = sincos(theta)
    sp, cp = sincos(phi)
    d = jnp.stack([st * sp, ct, -st * cp], -1)
    return d, st


class EnvironmentMap(eqx.Module):
    """Lat-long environment ``image (H, W, 3)`` (linear radiance) times ``scale``, optionally
    turned by ``to_world`` (a 3x3 orthogonal matrix, Mitsuba's envmap ``to_world`` rotation):
    a world direction ``d`` looks up the map at the local direction ``to_world^T d``, samples
    are drawn in the local frame and turned out by ``to_world`` (the solid-angle density is
    unchanged by a rotation). ``to_world`` is ``None`` for the identity (no extra operation in
    the program: an unrotated map compiles as before); it carries no derivative."""

    image: jnp.ndarray
    scale: jnp.ndarray
    distribution: Distribution2D
    to_world: jnp.ndarray | None = None

    @staticmethod
    def check_to_world(m, name="envmap.to_world"):
        """The 3x3 rotation of an envmap ``to_world`` ``m`` (3x3 or 4x4 affine; a 4x4's
        translation is ignored, as for any direction), ``None`` for ``None`` or the identity; a
        non-orthogonal matrix (scale, shear) raises ``ValueError`` naming ``name``."""
        if m is None:
            return None
        a = np.asarray(as_float_array(m, name), np.float64)
        if a.shape == (4, 4):
            if not np.allclose(a[3], [0, 0, 0, 1]):
                raise ValueError(f"{name}: expected an affine 4x4 matrix (last row 0 0 0 1)")
            a = a[:3, :3]
        if a.shape != (3, 3) or not np.all(np.isfinite(a)):
            raise ValueError(f"{name}: expected a finite 3x3 or 4x4 matrix, got shape {a.shape}")
        if not np.allclose(a.T @ a, np.eye(3), atol=1e-6):
            raise ValueError(f"{name}: expected a rotation (an orthogonal matrix); a scale or "
                             "shear of an environment map is not supported")  # fmt: skip
        return None if np.allclose(a, np.eye(3), rtol=0, atol=1e-12) else a

    @classmethod
    def create(cls, image, scale=1.0, to_world=None):
        """``to_world``: ``None``, or a 3x3 (or 4x4 affine; its translation is ignored, as for
        any direction) orthogonal matrix; a scale or shear is refused (``ValueError`` naming
        ``envmap.to_world``); the identity is stored as ``None``."""
        rot = cls.check_to_world(to_world)
        img = as_float_array(image, "envmap.image")
        check_finite(img, "envmap.image")
        if img.ndim != 3 or img.shape[-1] < 3 or min(img.shape[:2]) < 2:
            raise ValueError(f"envmap.image: expected (H>=2, W>=2, 3), got shape {img.shape}")
        img = jnp.maximum(img[..., :3], 0.0)
        h = img.shape[0]
        theta = (jnp.arange(h) + 0.5) / h * math.pi
        lum = img @ jnp.asarray(LUMINANCE_WEIGHTS["rec709"], img.dtype)
        # The radiance is looked up bilinearly, so a texel's area also sees its neighbours.
        # Sample proportionally to the bilinear radiance averaged over each texel: separable
        # weights (1/8, 3/4, 1/8), wrapping in u, clamped in v (pbrt-v4 likewise builds its
        # envmap distribution from the filtered lookup). With the raw texels, the half-texel
        # ring around a bright texel got the density of its dark neighbours: light-only
        # sampling of a sharp 2x2-texel sun had variance 8.7 and was 8 % low at 512 spp.
        lum = 0.75 * lum + 0.125 * (jnp.roll(lum, 1, axis=1) + jnp.roll(lum, -1, axis=1))
        up = jnp.concatenate([lum[:1], lum[:-1]], axis=0)
        down = jnp.concatenate([lum[1:], lum[-1:]], axis=0)
        lum = 0.75 * lum + 0.125 * (up + down)
        dist = Distribution2D(lum * jnp.sin(theta)[:, None])
        rot = None if rot is None else jnp.asarray(rot, img.dtype)
        return cls(img, jnp.asarray(scale, img.dtype), dist, rot)

    def _local(self, d):
        """World direction -> the map's frame (``to_world^T d``; ``d`` itself without one)."""
        return rotation_to_local(self.to_world, d)

    def _world(self, d):
        return rotation_to_world(self.to_world, d)

    def _lookup(self, uv):
        # bilinear with wrap in u and clamp in v (texel centres at (i + 0.5) / n)
        h, w = self.image.shape[:2]
        x = uv[..., 0] * w - 0.5
        y = uv[..., 1] * h - 0.5
        x0 = jnp.floor(x)
        y0 = jnp.floor(y)
        fx = (x - x0)[..., None]
        fy = (y - y0)[..., None]
        x0 = x0.astype(jnp.int32)
        y0 = y0.astype(jnp.int32)
        xa, xb = x0 % w, (x0 + 1) % w
        ya, yb = jnp.clip(y0, 0, h - 1), jnp.clip(y0 + 1, 0, h - 1)
        im = self.image
        top = im[ya, xa] * (1 - fx) + im[ya, xb] * fx
        bot = im[yb, xa] * (1 - fx) + im[yb, xb] * fx
        return top * (1 - fy) + bot * fy

    def eval(self, d):
        return self.scale * self._lookup(direction_to_latlong(self._local(d)))

    def sample(self, u):
        uv, pdf_uv = self.distribution.sample(u)
        wl, st = latlong_to_direction(uv)
        pdf = safe_div(pdf_uv, 2.0 * math.pi * math.pi * st)
        # piecewise-constant sampling density, bilinear radiance (exact pdf of the sampler);
        # sampled in the map's frame, turned out by to_world (a rotation keeps the density)
        wi = self._world(wl)
        return wi, pdf, self.scale * self._lookup(direction_to_latlong(wl))

    def pdf(self, d):
        d = self._local(d)
        uv = direction_to_latlong(d)
        st = safe_sqrt(1.0 - d[..., 1] ** 2)
        return safe_div(self.distribution.pdf(uv), 2.0 * math.pi * math.pi * st)
