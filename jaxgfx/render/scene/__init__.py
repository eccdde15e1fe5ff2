"""jaxgfx.render.scene: the scene description (dict / YAML) and the :class:`Scene` pytree.

``schema`` (validators and builders shared by the loader and the exporter), ``load``
(:func:`load_scene`), ``scene`` (:class:`Scene` with ``get`` / ``replace`` by parameter path)
``mitsuba`` (export to Mitsuba 3 for comparison renders) and ``mitsuba_xml``
(:func:`read_xml`: Mitsuba 3 XML scenes -> descriptions; ``load_scene`` reads ``.xml``
files). See docs/render_scenes.md.
"""

from jaxgfx.render.scene.load import BVH_MIN_TRIANGLES as BVH_MIN_TRIANGLES
from jaxgfx.render.scene.load import load_scene as load_scene
from jaxgfx.render.scene.mitsuba_xml import XMLScene as XMLScene
from jaxgfx.render.scene.mitsuba_xml import read_xml as read_xml
from jaxgfx.render.scene.scene import Scene as Scene
from jaxgfx.render.scene.schema import EMITTER_TYPES as EMITTER_TYPES
from jaxgfx.render.scene.schema import SHAPE_TYPES as SHAPE_TYPES
from jaxgfx.render.scene.schema import envmap_image as envmap_image

__all__ = [
    "Scene",
    "load_scene",
    "read_xml",
    "XMLScene",
    "SHAPE_TYPES",
    "EMITTER_TYPES",
    "BVH_MIN_TRIANGLES",
    "envmap_image",
]
