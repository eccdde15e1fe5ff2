"""Parameter names of render objects: the per-class alias tables and their resolution.

Every class whose description keys differ from its attribute paths declares ONE table,
``PARAMETER_ALIASES: ClassVar[dict[str, tuple[str, ...]]]`` (key -> dotted attribute paths it
sets). Everything that maps names to parameters reads it: :func:`~jaxgfx.render.load_scene`
(texture keys), ``Scene.get`` / ``Scene.replace``, :class:`~jaxgfx.render.Textured` and the
Mitsuba exporter. Names without an alias are attribute names of array fields.

Example: ``RoughConductor.PARAMETER_ALIASES["alpha"]`` is
``("distribution.alpha_u", "distribution.alpha_v")``: setting ``alpha`` sets both.

>>> from jaxgfx.render.bsdf import RoughConductor
>>> parameter_paths(RoughConductor(0.3), "alpha")
(('distribution', 'alpha_u'), ('distribution', 'alpha_v'))
>>> parameter_paths(RoughConductor(0.3), "reflectance")
(('reflectance',),)
"""

from __future__ import annotations

import equinox as eqx

__all__ = ["parameter_paths", "get_path", "array_fields", "revalidate"]


def array_fields(obj) -> list[str]:
    """Names of the array and module fields of ``obj`` (for error messages)."""
    return [n for n, v in vars(obj).items() if eqx.is_array(v) or isinstance(v, eqx.Module)]


def parameter_paths(obj, name: str) -> tuple[tuple[str, ...], ...]:
    """Attribute paths that the parameter ``name`` sets on ``obj``: its class's
    ``PARAMETER_ALIASES`` entry, else ``(name,)`` when ``name`` is an array field.
    ``ValueError`` naming ``name`` and the class otherwise."""
    aliases = getattr(type(obj), "PARAMETER_ALIASES", {})
    if name in aliases:
        return tuple(tuple(p.split(".")) for p in aliases[name])
    if hasattr(obj, name) and eqx.is_array(getattr(obj, name)):
        return ((name,),)
    raise ValueError(f"{name}: not a parameter of {type(obj).__name__}; have {array_fields(obj)}")


def get_path(obj, path):
    """``obj.path[0].path[1]...`` (a ``(name, key)`` tuple entry indexes a dict field)."""
    for f in path:
        obj = getattr(obj, f[0])[f[1]] if isinstance(f, tuple) else getattr(obj, f)
    return obj


def revalidate(obj) -> None:
    """Run the ``__check_init__`` of ``obj`` and of every module nested in its fields, as
    construction would (``eqx.tree_at`` skips them); checks ignore traced values."""
    if not isinstance(obj, eqx.Module):
        return
    for kls in type(obj).__mro__:
        check = kls.__dict__.get("__check_init__")
        if check is not None:
            check(obj)
    for v in vars(obj).values():
        if isinstance(v, eqx.Module):
            revalidate(v)
        elif isinstance(v, dict):
            for w in v.values():
                revalidate(w)
