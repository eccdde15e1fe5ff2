"""Normal mapping and bump mapping (Mitsuba 3 ``normalmap`` / ``bumpmap``): BSDF wrappers that
evaluate and sample a nested BSDF in a perturbed shading frame.

Both wrappers are resolved per hit like textured materials: ``at(uv, tangents)`` returns a
:class:`PerturbedBSDF`, a plain BSDF of the integrator's local frame (normal ``+z``). The
integrators pass ``tangents`` (:class:`TangentSpace`, built by
:func:`jaxgfx.render.integrators._common.tangent_space` from the surface's ``dp/du`` and
``dp/dv``) only to materials whose class sets ``needs_tangents``, so scenes without these
wrappers compile to the same program as before.

Tangent space: ``s`` = ``dp/du`` projected onto the shading plane (normalised; ``(1, 0, 0)``
where ``dp/du`` is zero or normal to it), ``t = n_front x s`` and ``n`` = the local ``+z``. On
the back side of a two-sided (reflection-only) material ``n`` is the flipped normal while
``s``, ``t`` stay those of the front (Mitsuba 3 ``twosided`` mirrors the directions through the
tangent plane, which is the same thing).

* ``normalmap``: ``n' = normalize(x s + y t + z n)`` with ``(x, y, z) = 2 c - 1`` and ``c`` the
  RGB texel value (read raw: Mitsuba's ``<boolean name="raw" value="true"/>``).
* ``bumpmap``: a scalar height ``h(u, v)`` times ``scale``; ``dp/du' = dp/du_t + h_u n``,
  ``dp/dv' = dp/dv_t + h_v n`` (``_t``: tangential part), ``n' = normalize(dp/du' x dp/dv')``
  turned to the ``+z`` side. ``h_u, h_v``: the exact derivative of the texture's bilinear
  interpolation in ``uv`` (0 for ``nearest`` filtering); an RGB height map gives its luminance.

The perturbed frame is ``(s', t', n')`` with ``s'`` the Gram–Schmidt projection of ``s``
(``frame_from_normal(n')`` where that degenerates) and ``t' = n' x s'``.

Light leaks (Mitsuba 3's rule): a direction ``wi`` whose side of the unperturbed surface differs
from its side of the perturbed one (``cos θ_i cos θ_i' <= 0``) gets ``eval = pdf = 0``, and a
sampled direction that crosses is discarded (weight and pdf 0: the sampler's lost mass). Where
the map value is the zero vector, ``n' = +z`` (the unperturbed frame).

Two options, both on by default as in Mitsuba 3.9 (its ``normalmap`` / ``bumpmap`` parameters
of the same names):

* ``flip_invalid_normals``: a perturbed normal the viewer ``wo`` is behind
  (``cos θ_o (wo · n') <= 0``) has its tangential part mirrored, ``(x, y, z) -> (-x, -y, z)``
  in the local frame (Schüssler et al., "Microfacet-based normal mapping for robust Monte Carlo
  path tracing", 2017, name this flip). Off: such a ``wo`` is passed on to the nested BSDF,
  whose own rules apply (reflection-only BSDFs return 0: a black pixel).
* ``use_shadowing_function``: ``eval`` and the sample weight are multiplied by
  :func:`shadow_terminator` ``(n', wi)`` (Estevez et al., "A microfacet-based shadowing function
  to solve the bump terminator problem", Ray Tracing Gems, 2019), the ``pdf`` is not.

Checked against Mitsuba 3.9.1's plugins at the BSDF level (``tests/render/
test_mitsuba_xml_normalmap.py``). One difference is kept: for ``bumpmap``, Mitsuba projects the
world-space ``dp/du`` onto the local perturbed normal (mixing coordinate systems), so an
anisotropic nested BSDF's tangent differs from Mitsuba's wherever the shading frame is not the
world frame; jaxgfx uses the tangent ``s`` of the tangent space, as ``normalmap`` does.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array
from jaxgfx._math import safe_normalize, sum_last
from jaxgfx.color import LUMINANCE_WEIGHTS
from jaxgfx.render.bsdf._base import (
    BSDF,
    BSDFSample,
    WrapsBSDF,
    check_scalar,
    float_field,
    mask3,
    prep_dirs,
    sample_setup,
)
from jaxgfx.render.bsdf.texture import Texture, lookup
from jaxgfx.render.geometry.frame import Frame, frame_from_normal, to_local, to_world

__all__ = [
    "NormalMap",
    "BumpMap",
    "PerturbedBSDF",
    "TangentSpace",
    "perturbed_frame",
    "shadow_terminator",
]

_LUMA = LUMINANCE_WEIGHTS["rec709"]


class TangentSpace(eqx.Module):
    """Tangent basis at hits, in the local shading frame: ``s``, ``t`` (..., 3) unit vectors
    in the plane ``z = 0`` (``t = ±(+z x s)``, see the module docstring), and the tangential
    coordinates ``du = (dp/du·s, dp/du·t)``, ``dv = (dp/dv·s, dp/dv·t)`` (..., 2) of the
    surface derivatives (world units per unit ``uv``), used by bump mapping."""

    s: jnp.ndarray
    t: jnp.ndarray
    du: jnp.ndarray
    dv: jnp.ndarray


def _resolve(b, uv):
    return b.at(uv) if hasattr(b, "at") else b


def _as_nested(x, name):
    from jaxgfx.render.bsdf.textured import Textured  # noqa: PLC0415 (import cycle)

    if getattr(x, "needs_tangents", False):
        raise TypeError(f"{name}: a normalmap / bumpmap cannot wrap another one")
    if isinstance(x, (BSDF, Textured)):
        return x
    if x is None:
        raise ValueError(f"{name}: missing nested BSDF")
    raise TypeError(f"{name}: expected a BSDF, got {type(x).__name__}")


def _as_texture(x, name, channels):
    """A :class:`Texture` or a constant array (C,) with ``C`` in ``channels``."""
    if isinstance(x, Texture):
        c = x.image.shape[-1]
    else:
        try:
            x = as_float_array(x, name)
        except (TypeError, ValueError):
            raise TypeError(f"{name}: expected a bitmap texture, got {type(x).__name__}") from None
        if x.ndim == 0:
            x = x[None]
        if x.ndim != 1:
            raise ValueError(f"{name}: expected a texture or a constant (C,), got {x.shape}")
        c = x.shape[0]
    if c not in channels:
        want = " or ".join(str(k) for k in channels)
        raise ValueError(f"{name}: expected a texture with {want} channel(s), got {c}")
    return x


def perturbed_frame(n_local, s) -> Frame:
    """Frame ``(s', t', n')`` (local coordinates) around the perturbed normal ``n_local``
    (..., 3, not necessarily unit) with ``s'`` the projection of the tangent ``s``; ``n' = +z``
    where ``n_local`` is zero, ``frame_from_normal(n')`` where ``s`` is parallel to ``n'``."""
    ok = sum_last(n_local * n_local) > 0
    n = safe_normalize(jnp.where(ok[..., None], n_local, jnp.array([0.0, 0.0, 1.0], s.dtype)))
    sp = s - sum_last(n * s, keepdims=True) * n
    good = sum_last(sp * sp) > 1e-12
    fb = frame_from_normal(n)
    sp = jnp.where(good[..., None], safe_normalize(sp), fb.s)
    tp = jnp.cross(n, sp)
    return Frame(s=sp, t=tp, n=n)


def shadow_terminator(n, w):
    """Estevez et al.'s shadowing factor (Ray Tracing Gems, 2019, ch. 12) as Mitsuba 3 applies it
    to bump and normal maps: ``2 / (1 + sqrt(1 + a² tan² θ_w))`` with
    ``a² = min(tan² θ_n / 8, 1)``, ``θ`` measured from the unperturbed normal ``+z`` (``n``: the
    unit perturbed normal, ``w``: the light direction, both local). 1 for ``n = +z`` or
    ``w = +z``; tends to 0 as ``w`` grazes the surface. Finite values and gradients everywhere
    (``n_z = 0`` gives ``a² = 1``; ``w_z = 0`` gives ~1e-15)."""
    nz2 = n[..., 2] * n[..., 2]
    wz2 = w[..., 2] * w[..., 2]
    tiny = 1e-30
    a2 = jnp.minimum(0.125 * jnp.maximum(1.0 - nz2, 0.0) / jnp.maximum(nz2, tiny), 1.0)
    t2 = jnp.maximum(1.0 - wz2, 0.0) / jnp.maximum(wz2, tiny)
    return 2.0 / (1.0 + jnp.sqrt(1.0 + a2 * t2))


class _ForwardsNested(WrapsBSDF):
    """The flags and albedo of the nested ``bsdf`` (a wrapper changes neither)."""

    @property
    def albedo(self):
        return self.bsdf.albedo


class PerturbedBSDF(_ForwardsNested, BSDF):
    """A BSDF evaluated in a perturbed frame (local coordinates, per ray) with Mitsuba 3's
    light-leak rule, ``flip_invalid_normals`` and ``use_shadowing_function`` (module
    docstring). Built per hit by :class:`NormalMap` / :class:`BumpMap`: ``normal`` (..., 3,
    not necessarily unit) and ``s`` (..., 3) the tangent the frame's ``s'`` is projected from;
    ``normal = None`` (no tangents given, e.g. the albedo AOV) allows only ``albedo``."""

    bsdf: BSDF
    normal: jnp.ndarray | None
    s: jnp.ndarray | None
    flip_invalid_normals: bool = eqx.field(static=True, default=True)
    use_shadowing_function: bool = eqx.field(static=True, default=True)

    @property
    def frame(self) -> Frame:
        """The perturbed frame before ``flip_invalid_normals`` (which depends on ``wo``)."""
        return perturbed_frame(self._normal(), self.s.astype(self.normal.dtype))

    def _normal(self):
        if self.normal is None:
            raise ValueError(
                "tangents: a normalmap / bumpmap material needs the hit's tangent space "
                "(dispatch(..., tangents=tangent_space(...)))"
            )
        return self.normal

    def _frame(self, wo):
        n = self._normal()
        if self.flip_invalid_normals:
            # Mitsuba 3: a normal the viewer is behind gets its tangential part mirrored
            bad = wo[..., 2] * sum_last(wo * n) <= 0
            n = jnp.where(bad[..., None], n * jnp.asarray([-1.0, -1.0, 1.0], n.dtype), n)
        return perturbed_frame(n, self.s.astype(n.dtype))

    def _shadow(self, fr, wi, x):
        if not self.use_shadowing_function:
            return x
        return x * shadow_terminator(fr.n, wi)[..., None]

    def _local(self, wo, wi):
        fr = self._frame(wo)
        wo_p, wi_p = to_local(fr, wo), to_local(fr, wi)
        ok = wi[..., 2] * wi_p[..., 2] > 0
        return fr, wo_p, wi_p, ok

    def eval(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        fr, wo_p, wi_p, ok = self._local(wo, wi)
        return mask3(ok, self._shadow(fr, wi, self.bsdf.eval(wo_p, wi_p)))

    def pdf(self, wo, wi):
        wo, wi = prep_dirs(wo, wi)
        _, wo_p, wi_p, ok = self._local(wo, wi)
        return jnp.where(ok, self.bsdf.pdf(wo_p, wi_p), 0.0)

    def sample(self, wo, u1, u2) -> BSDFSample:
        wo, u1, u2, _ = sample_setup(wo, u1, u2)
        fr = self._frame(wo)
        s = self.bsdf.sample(to_local(fr, wo), u1, u2)
        wi = to_world(fr, s.wi)
        ok = (s.pdf > 0) & (wi[..., 2] * s.wi[..., 2] > 0)
        weight = self._shadow(fr, wi, s.weight)
        return s._replace(wi=wi, pdf=jnp.where(ok, s.pdf, 0.0), weight=mask3(ok, weight))


class _MapBase(_ForwardsNested):
    needs_tangents: ClassVar[bool] = True
    flip_invalid_normals: bool = eqx.field(static=True, default=True)
    use_shadowing_function: bool = eqx.field(static=True, default=True)

    def _normal(self, uv, tangents):  # pragma: no cover - interface
        raise NotImplementedError

    def _set_flags(self, flip_invalid_normals, use_shadowing_function):
        for name, v in (
            ("flip_invalid_normals", flip_invalid_normals),
            ("use_shadowing_function", use_shadowing_function),
        ):
            if not isinstance(v, (bool, np.bool_)):
                raise TypeError(f"{name}: expected a bool, got {type(v).__name__}")
            setattr(self, name, bool(v))

    def at(self, uv, tangents=None) -> PerturbedBSDF:
        """The nested BSDF (textures resolved at ``uv``) in the perturbed frame at the hits."""
        if uv is None:
            raise ValueError("uv: a normalmap / bumpmap material needs the hit uv")
        uv = as_float_array(uv, "uv")
        nested = _resolve(self.bsdf, uv)
        flags = (self.flip_invalid_normals, self.use_shadowing_function)
        if tangents is None:
            return PerturbedBSDF(nested, None, None, *flags)
        n = self._normal(uv, tangents)
        return PerturbedBSDF(
            nested, n, jnp.broadcast_to(tangents.s.astype(n.dtype), n.shape), *flags
        )


class NormalMap(_MapBase):
    """Normal mapping (Mitsuba 3 ``normalmap``): ``bsdf`` shaded with the normal
    ``2 c - 1`` of the RGB texture ``normalmap`` (raw texel values ``c`` in [0, 1], components
    along ``s``, ``t``, ``n`` of the tangent space; module docstring).

    ``bsdf``: a BSDF or textured material; ``normalmap``: a 3-channel
    :class:`~jaxgfx.render.bsdf.texture.Texture` (differentiable texels) or a constant
    (3,). A constant ``(0.5, 0.5, 1)`` reproduces ``bsdf``.
    """

    bsdf: eqx.Module
    normalmap: Texture | jnp.ndarray

    def __init__(
        self, bsdf=None, normalmap=None, *, flip_invalid_normals=True, use_shadowing_function=True
    ):
        self.bsdf = _as_nested(bsdf, "bsdf")
        self._set_flags(flip_invalid_normals, use_shadowing_function)
        if normalmap is None:
            raise ValueError("normalmap: missing texture")
        self.normalmap = _as_texture(normalmap, "normalmap", (3,))

    def _normal(self, uv, tg):
        c = lookup(self.normalmap, uv).astype(uv.dtype) * 2.0 - 1.0
        z = jnp.asarray([0.0, 0.0, 1.0], uv.dtype)
        return c[..., 0:1] * tg.s + c[..., 1:2] * tg.t + c[..., 2:3] * z


def _height(tex, uv):
    h = lookup(tex, uv).astype(uv.dtype)
    if h.shape[-1] == 1:
        return h[..., 0]
    return h[..., :3] @ jnp.asarray(_LUMA, uv.dtype)


class BumpMap(_MapBase):
    """Bump mapping (Mitsuba 3 ``bumpmap``): ``bsdf`` shaded with the normal of the surface
    displaced by ``scale * h(u, v)`` along the normal (first order: module docstring).

    ``bsdf``: a BSDF or textured material; ``height``: a 1- or 3-channel (luminance)
    :class:`~jaxgfx.render.bsdf.texture.Texture`; ``scale``: float (differentiable).
    """

    bsdf: eqx.Module
    height: Texture
    scale: jnp.ndarray = float_field(1.0, "scale")

    def __init__(
        self,
        bsdf=None,
        height=None,
        scale=1.0,
        *,
        flip_invalid_normals=True,
        use_shadowing_function=True,
    ):
        self.bsdf = _as_nested(bsdf, "bsdf")
        self._set_flags(flip_invalid_normals, use_shadowing_function)
        if height is None:
            raise ValueError("height: missing texture")
        if not isinstance(height, Texture):
            raise TypeError(f"height: expected a bitmap texture, got {type(height).__name__}")
        self.height = _as_texture(height, "height", (1, 3))
        self.scale = scale

    def __check_init__(self):
        check_scalar(self.scale, "scale")
        if jnp.ndim(self.scale) != 0:
            raise ValueError(f"scale: expected a scalar, got shape {jnp.shape(self.scale)}")

    def _normal(self, uv, tg):
        ones = jnp.ones(uv.shape[:-1], uv.dtype)
        zeros = jnp.zeros_like(ones)
        f = lambda q: _height(self.height, q)  # noqa: E731
        _, hu = jax.jvp(f, (uv,), (jnp.stack([ones, zeros], -1),))
        _, hv = jax.jvp(f, (uv,), (jnp.stack([zeros, ones], -1),))
        k = self.scale.astype(uv.dtype)
        hu, hv = k * hu, k * hv
        a_u, b_u = tg.du[..., 0], tg.du[..., 1]
        a_v, b_v = tg.dv[..., 0], tg.dv[..., 1]
        # (a_u, b_u, h_u) x (a_v, b_v, h_v) in the tangent space (s, t, n)
        x = b_u * hv - hu * b_v
        y = hu * a_v - a_u * hv
        z = a_u * b_v - b_u * a_v
        sgn = jnp.where(z < 0, -1.0, 1.0).astype(uv.dtype)[..., None]
        zv = jnp.asarray([0.0, 0.0, 1.0], uv.dtype)
        return sgn * (x[..., None] * tg.s + y[..., None] * tg.t + z[..., None] * zv)
