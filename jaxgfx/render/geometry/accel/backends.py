"""Traversal backends behind the renderer's two-phase intersection.

A backend finds the closest (or any) triangle of a mesh along each ray; the differentiable hit
record is then recomputed in JAX from the primitive id, so images and gradients do not depend on
the backend (up to ties between triangles at equal distance). Backends:

=========  ==============================================  ===================================
name       engine                                          install
=========  ==============================================  ===================================
``embree`` Embree 4 (CPU) via ``embreex``, ``pure_callback``  ``pip install jaxgfx[embree]``
``warp``   NVIDIA Warp ``mesh_query_ray`` (CPU or CUDA),    ``pip install jaxgfx[warp]``
           ``wp.jax_kernel`` (XLA FFI)
``jax``    the pure-JAX BVH (``bvh_sah``),   always available (the reference)
           wavefront traversal; portable, vmappable
=========  ==============================================  ===================================

``"auto"`` picks the fastest available for JAX's default device (measured in
docs/performance.md): CPU: embree, warp, jax; GPU: warp, jax.
"""

from __future__ import annotations

import weakref

import equinox as eqx
import jax

from jaxgfx.render.geometry.accel._host import HostTraversal as HostTraversal
from jaxgfx.render.geometry.accel._host import lookup_native as lookup_native
from jaxgfx.render.geometry.accel.embree import EmbreeMesh as EmbreeMesh
from jaxgfx.render.geometry.accel.embree import build_embree as build_embree
from jaxgfx.render.geometry.accel.embree import embree_available as embree_available
from jaxgfx.render.geometry.accel.warp_nvidia import WarpMesh as WarpMesh
from jaxgfx.render.geometry.accel.warp_nvidia import build_warp as build_warp
from jaxgfx.render.geometry.accel.warp_nvidia import warp_available as warp_available

__all__ = [
    "ACCEL_BACKENDS",
    "EmbreeMesh",
    "HostTraversal",
    "WarpMesh",
    "accel_of",
    "available_backends",
    "build_embree",
    "build_traversal",
    "build_warp",
    "embree_available",
    "lookup_native",
    "resolve_backend",
    "scene_with_accel",
    "warp_available",
]


def _build_jax(mesh):
    from jaxgfx.render.geometry.accel.bvh_sah import build_bvh

    return build_bvh(mesh)


ACCEL_BACKENDS = {"embree": build_embree, "warp": build_warp, "jax": _build_jax}
"""Backend name -> builder ``(mesh) -> traversal object`` (``closest_t``, ``occluded``,
``intersect``, ``mesh``)."""

_AVAILABLE = {"embree": embree_available, "warp": warp_available, "jax": lambda: True}
_PREFERENCE = {"cpu": ("embree", "warp", "jax"), "gpu": ("warp", "jax")}


def available_backends() -> tuple[str, ...]:
    """Names of the backends whose optional dependency imports."""
    return tuple(k for k in ACCEL_BACKENDS if _AVAILABLE[k]())


def resolve_backend(accel: str = "auto") -> str:
    """``accel`` checked and ``"auto"`` resolved to a concrete backend name.

    Raises ``ValueError`` for unknown names and ``ImportError`` (with the install hint) for a
    backend whose dependency is missing.
    """
    if accel == "auto":
        pref = _PREFERENCE.get(jax.default_backend(), ("jax",))
        return next(k for k in pref if _AVAILABLE[k]())
    if not isinstance(accel, str) or accel not in ACCEL_BACKENDS:
        raise ValueError(f"accel: expected 'auto' or one of {tuple(ACCEL_BACKENDS)}, got {accel!r}")
    if not _AVAILABLE[accel]():
        pkg = {"embree": "embreex", "warp": "warp-lang"}[accel]
        raise ImportError(f"accel={accel!r} needs {pkg}: pip install 'jaxgfx[{accel}]'")
    return accel


def build_traversal(mesh, accel: str = "auto"):
    """Traversal object for ``mesh`` from backend ``accel`` (see :data:`ACCEL_BACKENDS`)."""
    return ACCEL_BACKENDS[resolve_backend(accel)](mesh)


def accel_of(shape) -> str | None:
    """Backend name of a traversal object, or of the one an
    :class:`~jaxgfx.render.geometry.instance.Instances` shares (``None`` for anything else)."""
    from jaxgfx.render.geometry.accel.bvh_sah import BVH

    if hasattr(shape, "to_world") and hasattr(shape, "n_prims"):  # Instances (no import cycle)
        return accel_of(shape.shape)

    if isinstance(shape, EmbreeMesh):
        return "embree"
    if isinstance(shape, WarpMesh):
        return "warp"
    if isinstance(shape, BVH):
        return "jax"
    return None


# (id(vertices), id(faces), backend) -> (weakref(vertices), weakref(faces), traversal object
# holding a placeholder mesh: the cache must not keep the mesh arrays alive)
_BUILT: dict = {}


def _cached_build(mesh, name):
    from jaxgfx.render.geometry.mesh import TriangleMesh

    key = (id(mesh.vertices), id(mesh.faces), name)
    hit = _BUILT.get(key)
    if hit is not None and hit[0]() is mesh.vertices and hit[1]() is mesh.faces:
        return eqx.tree_at(lambda b: b.mesh, hit[2], mesh)
    for k in [k for k, v in _BUILT.items() if v[0]() is None or v[1]() is None]:
        del _BUILT[k]
    built = ACCEL_BACKENDS[name](mesh)
    placeholder = TriangleMesh([[0.0, 0.0, 0.0]] * 3, [[0, 1, 2]])
    _BUILT[key] = (
        weakref.ref(mesh.vertices),
        weakref.ref(mesh.faces),
        eqx.tree_at(lambda b: b.mesh, built, placeholder),
    )
    return built


def scene_with_accel(scene, accel: str = "auto"):
    """Copy of ``scene`` whose triangle meshes are traced by backend ``accel``.

    Every shape that is a traversal object (JAX BVH, Embree, Warp) is rebuilt over its
    ``mesh`` with the chosen backend; other shapes (analytic shapes, small brute-force meshes,
    SDFs) are kept. Builds are cached per mesh arrays, so calling this (or
    ``render(..., accel=...)``) again with the same scene costs no rebuild.
    """
    name = resolve_backend(accel)
    shapes = []
    for s in scene.shapes:
        cur = accel_of(s)
        if cur is None or cur == name:
            shapes.append(s)
        elif hasattr(s, "to_world"):  # Instances: rebuild the one shared structure
            shapes.append(eqx.tree_at(lambda i: i.shape, s, _cached_build(s.shape.mesh, name)))
        else:
            shapes.append(_cached_build(s.mesh, name))
    return eqx.tree_at(lambda sc: sc.shapes, scene, tuple(shapes))
