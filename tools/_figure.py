"""What the ``tools/*_figure.py`` scripts share (imported by name: the scripts run as
``python tools/<name>.py``, so this folder is on ``sys.path``, as for ``tools/mutate.py``)."""

from __future__ import annotations

import os
import time


def srgb_display(img, gain=1.0):
    """A linear RGB image ``(H, W, 3)`` as sRGB in [0, 1] for display: ``gain · img`` clipped to
    [0, 1], encoded by ``linear_to_srgb``, clipped again."""
    import numpy as np

    from jaxgfx.color.transfer import linear_to_srgb

    return np.clip(np.asarray(linear_to_srgb(np.clip(gain * np.asarray(img), 0, 1))), 0, 1)


def save_figure(fig, out):
    """Write the matplotlib figure ``fig`` to ``out``, creating its folder."""
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    fig.savefig(out)


def jaxgfx_and_mitsuba_figure(desc, spp, out, *, scene=None, max_depth=3):
    """The side-by-side figure of a scene description ``desc``: jaxgfx's render (path tracer,
    ``max_depth``, ``spp``, key 0; of ``scene`` when given, else of ``load_scene(desc)``) and,
    when ``mitsuba`` is installed, Mitsuba 3's render of the same description
    (``render_mitsuba``), titled, one panel each, written as a PNG to ``out``. Prints each
    image's channel means and the process CPU seconds of its render (compile included for
    jaxgfx)."""
    import jax
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from jaxgfx.render import load_scene, render

    sc = load_scene(desc) if scene is None else scene
    t0 = time.process_time()
    img = np.asarray(render(sc, jax.random.key(0), spp=spp, integrator="path",
                            max_depth=max_depth))  # fmt: skip
    images = [(img, f"jaxgfx, path, {spp} spp", time.process_time() - t0)]
    try:
        from jaxgfx.render.scene.mitsuba import render_mitsuba

        t0 = time.process_time()
        ref = render_mitsuba(desc, spp=spp, integrator="path", max_depth=max_depth)
        images.append((ref, f"Mitsuba 3, path, {spp} spp", time.process_time() - t0))
    except ImportError:
        pass
    fig = plt.figure(figsize=(4.2 * len(images), 3.4), dpi=100)
    for k, (im, title, cpu) in enumerate(images):
        ax = fig.add_axes([k / len(images), 0.0, 1 / len(images), 0.9])
        ax.imshow(srgb_display(im))
        ax.set_title(title, fontsize=9)
        ax.axis("off")
        print(f"{title}: mean {np.asarray(im).mean(axis=(0, 1)).round(4).tolist()}, "
              f"{cpu:.1f} s CPU")  # fmt: skip
    save_figure(fig, out)
    print(f"wrote {out}")
