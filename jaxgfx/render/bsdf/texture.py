"""Image textures with bilinear / nearest lookup and repeat / clamp / mirror wrapping."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from jaxgfx._checks import as_float_array, check_choice, check_image

__all__ = [
    "Texture",
    "MeshAttribute",
    "lookup",
    "check_uv_transform",
    "TEXTURE_WRAP_MODES",
    "TEXTURE_FILTERS",
]

TEXTURE_WRAP_MODES = ("repeat", "clamp", "mirror")
TEXTURE_FILTERS = ("bilinear", "nearest")


class Texture(eqx.Module):
    """An image texture: ``image`` (H, W, C) float array leaf (differentiable texel values).

    ``wrap`` (static): ``"repeat"`` | ``"clamp"`` | ``"mirror"``; ``filter`` (static):
    ``"bilinear"`` | ``"nearest"``. Texture coordinates follow Mitsuba 3's bitmap texture:
    ``u`` runs along the width (columns), ``v`` along the height with ``v = 0`` at the first
    row; texel ``(i, j)`` has its centre at ``((j + 0.5)/W, (i + 0.5)/H)``.
    ``to_uv`` (static, optional): a 2-D affine map ``((a, b, c), (d, e, f))`` applied to the
    hit's ``uv`` first, ``u' = a u + b v + c``, ``v' = d u + e v + f`` (Mitsuba's bitmap
    ``to_uv``: the 2 x 2 part and the translation of its transform); not differentiable.
    """

    image: jnp.ndarray
    wrap: str = eqx.field(static=True, default="repeat")
    filter: str = eqx.field(static=True, default="bilinear")
    to_uv: tuple | None = eqx.field(static=True, default=None)

    def __init__(self, image, *, wrap="repeat", filter="bilinear", to_uv=None):
        img = check_image(image, "image")
        if img.ndim == 2:
            img = img[..., None]
        if img.ndim != 3:
            raise ValueError(f"image: expected shape (H, W) or (H, W, C), got {img.shape}")
        self.image = img
        self.wrap = check_choice(wrap, "wrap", TEXTURE_WRAP_MODES)
        self.filter = check_choice(filter, "filter", TEXTURE_FILTERS)
        self.to_uv = None if to_uv is None else check_uv_transform(to_uv, "to_uv")


def check_uv_transform(m, name):
    """A 2-D affine uv map as a hashable ``((a, b, c), (d, e, f))`` of finite floats (a 3 x 3
    homogeneous matrix is accepted when its last row is ``(0, 0, 1)``); ``ValueError`` naming
    ``name`` otherwise."""
    a = np.asarray(m, np.float64)
    if a.shape == (3, 3):
        if not np.allclose(a[2], [0.0, 0.0, 1.0]):
            raise ValueError(f"{name}: expected an affine map (last row 0, 0, 1), got {a[2]}")
        a = a[:2]
    if a.shape != (2, 3) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected a finite 2 x 3 (or 3 x 3 affine) matrix, got {m!r}")
    return tuple(tuple(float(x) for x in row) for row in a)


def _wrap_index(i, n, mode):
    if mode == "clamp":
        return jnp.clip(i, 0, n - 1)
    if mode == "repeat":
        return jnp.mod(i, n)
    period = jnp.mod(i, 2 * n)
    return jnp.where(period < n, period, 2 * n - 1 - period)


def lookup(tex, uv):
    """Sample a texture at ``uv`` (..., 2) → (..., C); a constant passes through (broadcast).

    Bilinear: ``x = u W - 0.5``, ``y = v H - 0.5``, blend of the four surrounding texels (after
    wrapping their integer indices). Differentiable w.r.t. texel values and ``uv`` (piecewise
    linear in ``uv``). Passing a float / array instead of a :class:`Texture` returns it
    broadcast to ``uv.shape[:-1] + shape`` (ConstantTexture behaviour).

    Example: a 1×2 texture ``[[0], [1]]`` (W = 2) has ``lookup(tex, (0.5, 0.5)) = 0.5``.
    """
    uv = as_float_array(uv, "uv")
    if uv.shape[-1:] != (2,):
        raise ValueError(f"uv: expected shape (..., 2), got {uv.shape}")
    if not isinstance(tex, Texture):
        c = as_float_array(tex, "tex")
        return jnp.broadcast_to(c, uv.shape[:-1] + c.shape)
    if tex.to_uv is not None:
        m = jnp.asarray(tex.to_uv, uv.dtype)
        uv = uv @ m[:, :2].T + m[:, 2]
    img = tex.image
    h, w = img.shape[0], img.shape[1]
    x = uv[..., 0] * w - 0.5
    y = uv[..., 1] * h - 0.5
    if tex.filter == "nearest":
        j = _wrap_index(jnp.floor(x + 0.5).astype(jnp.int32), w, tex.wrap)
        i = _wrap_index(jnp.floor(y + 0.5).astype(jnp.int32), h, tex.wrap)
        return img[i, j]
    x0 = jnp.floor(x)
    y0 = jnp.floor(y)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    j0 = x0.astype(jnp.int32)
    i0 = y0.astype(jnp.int32)
    j1 = _wrap_index(j0 + 1, w, tex.wrap)
    i1 = _wrap_index(i0 + 1, h, tex.wrap)
    j0 = _wrap_index(j0, w, tex.wrap)
    i0 = _wrap_index(i0, h, tex.wrap)
    top = img[i0, j0] * (1.0 - fx) + img[i0, j1] * fx
    bot = img[i1, j0] * (1.0 - fx) + img[i1, j1] * fx
    return top * (1.0 - fy) + bot * fy


class MeshAttribute(eqx.Module):
    """Mitsuba 3's ``mesh_attribute`` texture: the value of a mesh attribute (``vertex_*``:
    interpolated with the hit's barycentrics; ``face_*``: constant per face) times ``scale``.

    ``name`` (static) is the attribute; ``slot`` (static) its place in the hit's ``uv``
    columns, assigned by the scene loader: columns ``2 + 3 slot ... 2 + 3 slot + 2`` (one-channel
    attributes are stored replicated in all three). The values live on the meshes
    (:class:`~jaxgfx.render.geometry.TriangleMesh` ``vertex_attributes`` /
    ``face_attributes``), so gradients w.r.t. them flow through the hit record; ``scale`` is a
    differentiable leaf. A hit on a shape without the attribute reads 0.
    """

    name: str = eqx.field(static=True)
    scale: jnp.ndarray
    slot: int = eqx.field(static=True, default=-1)

    def __call__(self, uv):
        """Value ``(..., 3)`` at hits whose ``uv`` carries the attribute columns."""
        if self.slot < 0:
            raise ValueError(f"mesh_attribute {self.name!r}: no slot assigned (load the scene "
                             "with load_scene, which lays the attributes out)")  # fmt: skip
        k = 2 + 3 * self.slot
        if uv.shape[-1] < k + 3:  # no mesh of the scene has attributes: 0
            return jnp.zeros(uv.shape[:-1] + (3,), uv.dtype)
        return uv[..., k : k + 3] * self.scale.astype(uv.dtype)
