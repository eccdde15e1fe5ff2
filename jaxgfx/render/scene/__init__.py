"""jaxgfx.render.scene: the scene description (dict / YAML) and the :class:`Scene` pytree.

``schema`` (validators and builders shared by the loader and the exporter), ``load``
(:func:`load_scene`), ``scene`` (:class:`Scene` with ``get`` / ``replace`` by parameter path)
and ``mitsuba`` (export to Mitsuba 3 for comparison renders). See docs/render_scenes.md.
"""

from jaxgfx.render.scene.load import BVH_MIN_TRIANGLES as BVH_MIN_TRIANGLES
from jaxgfx.render.scene.load import load_scene as load_scene
from jaxgfx.render.scene.scene import Scene as Scene
from jaxgfx.render.scene.schema import EMITTER_TYPES as EMITTER_TYPES
from jaxgfx.render.scene.schema import SHAPE_TYPES as SHAPE_TYPES
from jaxgfx.render.scene.schema import envmap_image as envmap_image

__all__ = [
    "Scene",
    "load_scene",
    "SHAPE_TYPES",
    "EMITTER_TYPES",
    "BVH_MIN_TRIANGLES",
    "envmap_image",
]
