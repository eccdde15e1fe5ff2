"""Which of mitsuba-data's test scenes jaxgfx's Mitsuba XML loader reads (docs/render_scenes.md).

Usage: ``python tools/check_mitsuba_data_scenes.py MITSUBA_DATA`` with ``MITSUBA_DATA`` a checkout
of mitsuba-renderer/mitsuba-data (the docs quote commit 01100fa). Runs
:func:`jaxgfx.render.scene.mitsuba_xml.read_xml` on every ``tests/scenes/*/*.xml`` outside
``participating_media`` (jaxgfx has no media) and prints each scene as ``LOAD`` or ``REFUSED``
with the loader's message (the first unsupported feature), then the counts.
"""

from __future__ import annotations

import glob
import os
import sys

from jaxgfx.render.scene.mitsuba_xml import read_xml


def main(root: str) -> int:
    scenes = os.path.join(root, "tests", "scenes")
    files = sorted(f for f in glob.glob(os.path.join(scenes, "*", "*.xml"))
                   if os.sep + "participating_media" + os.sep not in f)  # fmt: skip
    if not files:
        print(f"{scenes}: no scene files", file=sys.stderr)
        return 2
    n_ok = 0
    for f in files:
        name = os.path.relpath(f, scenes)
        try:
            read_xml(f)
        except (ValueError, NotImplementedError, OSError) as e:
            print(f"REFUSED {name}: {str(e).replace(scenes + os.sep, '')}")
        else:
            n_ok += 1
            print(f"LOAD    {name}")
    print(f"{n_ok} of {len(files)} scene files load")
    return 0


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    sys.exit(main(sys.argv[1]))
