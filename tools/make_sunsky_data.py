"""Build ``jaxgfx/render/data/sunsky/sunsky_rgb.npz`` from Mitsuba 3's sunsky datasets.

Usage: ``python tools/make_sunsky_data.py [MITSUBA_DATA_SUNSKY_DIR]`` (default: the
``mitsuba/data/sunsky/`` folder of the installed Mitsuba wheel, 3.9.1 when this was run).
Needs Mitsuba 3 (``scalar_rgb``) only for the CIE 1931 colour matching functions at the
model's 11 wavelengths (``mi.cie1931_xyz``: Mitsuba's copy of the CIE table, linearly
interpolated; 0 outside 360-830 nm). Writes the arrays named in
:data:`jaxgfx.render._sunsky_data.FIELDS`, unchanged (dtype and values), plus ``cie_xyz``
``(11, 3)`` float64, with ``np.savez_compressed``.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from jaxgfx.render._sunsky_data import FIELDS, NPZ_PATH, read_tensor_file

WAVELENGTHS = [320.0 + 40.0 * i for i in range(11)]


def main(src=None):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    if src is None:
        src = os.path.join(os.path.dirname(mi.__file__), "data", "sunsky")
    files = {f: read_tensor_file(os.path.join(src, f)) for f in {f for f, _ in FIELDS.values()}}
    out = {k: files[f][name] for k, (f, name) in FIELDS.items()}
    out["cie_xyz"] = np.array([list(mi.cie1931_xyz(w)) for w in WAVELENGTHS], np.float64)
    np.savez_compressed(NPZ_PATH, **out)
    print(f"wrote {NPZ_PATH} ({os.path.getsize(NPZ_PATH)} bytes) from {src} "
          f"(Mitsuba {mi.__version__})")  # fmt: skip


if __name__ == "__main__":
    main(*sys.argv[1:2])
