"""The job's figures: fitted response curves (``response.png``), the leave-one-out
self-check (``loo.png``), the exposure-normalised preview (``preview.png``), after a
ghost-free merge the map of which frame each pixel came from (``frames.png``), the vignetting
(``vignetting.png``) and the colour chart's patches and ΔE00 before / after (``chart.png``)."""

from __future__ import annotations

import numpy as np

__all__: list[str] = []  # the job's helpers (tests patch _plot_response here)


def _plot_response(path, responses: dict, truth=None, title="camera response"):
    """Plot g(Z) = ln to_linear(Z) per channel for each fitted response (and the truth,
    shifted by the best constant ln offset, since the anchor is arbitrary) to ``path``."""
    import matplotlib.pyplot as plt

    fig = _response_figure(responses, truth, title)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _response_figure(responses: dict, truth=None, title="camera response"):
    """The figure of :func:`_plot_response`. Only levels 1..255 where a curve is defined
    (``to_linear > 0``) are drawn: at level 0 the exposure is 0 and ln 0 = -inf (clamping it
    stretched the axis to -27 and flattened every curve), and the fits carry no data there."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    z = np.linspace(0.0, 1.0, 256)

    def curve(resp):
        zz = np.ascontiguousarray(np.broadcast_to(z[:, None], (256, resp.channels)), np.float32)
        lin = np.asarray(resp.to_linear_normalized(zz), np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.where(np.isfinite(lin) & (lin > 0), np.log(lin), np.nan)
        g[0] = np.nan  # level 0: no exposure is known there
        return g

    colors = ("tab:red", "tab:green", "tab:blue")
    styles = ["-", "--", "-.", ":"]
    fig, ax = plt.subplots(figsize=(6, 4.2))
    ref = None
    for k, (name, resp) in enumerate(responses.items()):
        g = curve(resp)
        if ref is None:
            ref = g[:, min(1, g.shape[1] - 1)]
        for c in range(g.shape[1]):
            ax.plot(
                z * 255,
                g[:, c],
                styles[k % len(styles)],
                color=colors[c % 3],
                lw=1.2,
                label=name if c == 0 else None,
            )
    if truth is not None:
        g = curve(truth)[:, min(1, truth.channels - 1)]
        sl = slice(10, 246)
        g = g + np.nanmean(ref[sl] - g[sl]) if ref is not None else g
        ax.plot(z * 255, g, color="k", lw=2.5, alpha=0.35, label="ground truth (G)")
    ax.set_xlim(0, 255)
    ax.set_xlabel("pixel level Z (of 255)")
    ax.set_ylabel("g(Z) = ln relative exposure")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _plot_loo(path, loo):
    """Leave-one-out self-check: mean |error| and bias per level band, and per held frame."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    d = loo.to_dict()
    edges = d["band_edges"]
    labels = [f"{edges[i]:g}-{edges[i + 1]:g}" for i in range(len(edges) - 1)]
    nan = float("nan")
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.6))
    x = np.arange(len(labels))
    band = [nan if v is None else v for v in d["per_band"]]
    bias = [nan if v is None else v for v in d["per_band_bias"]]
    a1.bar(x - 0.2, band, 0.4, label="mean |error|")
    a1.bar(x + 0.2, bias, 0.4, label="mean error (bias)")
    a1.axhline(0, color="k", lw=0.8)
    a1.set_xticks(x, labels, fontsize=8)
    a1.set_xlabel("level of the held-out frame (of 255)")
    a1.set_ylabel("predicted - actual (levels)")
    a1.legend(fontsize=8)
    a1.set_title(f"leave-one-out: {d['mean_abs_error']:.2f} levels overall")
    pf = [nan if v is None else v for v in d["per_frame"]]
    a2.bar(np.arange(len(pf)), pf)
    a2.set_xticks(np.arange(len(pf)), [f"{t:.3g} s" for t in d["exposure_times"]], fontsize=8)
    a2.set_xlabel("held-out frame (exposure time)")
    a2.set_ylabel("mean |error| (levels)")
    for a in (a1, a2):
        a.grid(alpha=0.3, axis="y")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _preview(radiance: np.ndarray, key: float) -> np.ndarray:
    """Global Reinhard (2002) with key ``key``, L_white = the maximum (jaxgfx.tonemap)."""
    from jaxgfx.pipelines.tonemap import tonemap_image

    return tonemap_image(radiance, "reinhard", key=key)


def _plot_vignetting(path, vig):
    """``vignetting.png``: the fitted falloff V(r) against radius, and its map."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    v = np.asarray(vig.falloff(), np.float64)
    r_corner = float(np.max(np.asarray(vig.radius(
        np.array([0.0, 0.0, vig.shape[0] - 1.0, vig.shape[0] - 1.0]),
        np.array([0.0, vig.shape[1] - 1.0, 0.0, vig.shape[1] - 1.0])))))  # fmt: skip
    r = np.linspace(0.0, r_corner, 200)
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.6))
    a1.plot(r, np.asarray(vig.of_radius(r)), lw=2)
    a1.set_xlabel("r (1 = half the image diagonal)")
    a1.set_ylabel("V(r), relative illumination")
    a1.set_title(f"corner falloff {float(vig.corner_falloff()):.3f}")
    a1.grid(alpha=0.3)
    im = a2.imshow(v, cmap="viridis")
    a2.plot([float(vig.center[1])], [float(vig.center[0])], "r+", ms=12)
    a2.set_title("V over the frame (+ optical centre)")
    fig.colorbar(im, ax=a2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_chart(path, chart):
    """``chart.png``: each ColorChecker patch as three stripes (reference | before: the file's
    matrix | after: the chart fit) in sRGB, and the per-patch CIEDE2000 before and after."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from jaxgfx.color import linear_to_srgb
    from jaxgfx.hdr.raw import colorchecker_reference, xyz_d50_to_space_matrix

    m = np.asarray(xyz_d50_to_space_matrix("srgb"), np.float64)

    def srgb(xyz):
        lin = np.nan_to_num(np.asarray(xyz, np.float64) @ m.T, nan=0.5)
        return np.asarray(linear_to_srgb(np.clip(lin, 0.0, 1.0).astype(np.float32)))

    cal = chart.calibration
    sw = np.stack([srgb(chart.xyz_reference), srgb(chart.xyz_before), srgb(chart.xyz_after)], 1)
    cell = 12  # px per stripe; 3 stripes and a 4 px gap per patch
    img = np.ones((4 * (cell * 3 + 4), 6 * (cell * 3 + 4), 3), np.float32) * 0.15
    for k in range(24):
        r, c = divmod(k, 6)
        y0, x0 = r * (3 * cell + 4) + 2, c * (3 * cell + 4) + 2
        for j in range(3):
            img[y0 : y0 + 3 * cell, x0 + j * cell : x0 + (j + 1) * cell] = sw[k, j]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 3.9), gridspec_kw={"width_ratios": [1, 1.3]})
    a1.imshow(img, interpolation="nearest")
    a1.set_axis_off()
    a1.set_title("each patch: reference | before | after (sRGB)", fontsize=9)
    before = np.asarray(cal.delta_e_before, np.float64)
    after = np.asarray(cal.delta_e_after, np.float64)
    x = np.arange(before.size)
    s = cal.summary()
    a2.bar(x - 0.2, before, 0.4, label=f"before (median {s['before']['median']:.2f})")
    a2.bar(x + 0.2, after, 0.4, label=f"after, {cal.model} (median {s['after']['median']:.2f})")
    a2.axhline(1.0, color="k", lw=0.8, ls="--")
    names = colorchecker_reference().patch_names
    a2.set_xticks(x, [n.split(" (")[0] for n in names], rotation=90, fontsize=7)
    a2.set_ylabel("CIEDE2000")
    a2.grid(alpha=0.3, axis="y")
    a2.legend(fontsize=8)
    a2.set_title(f"patches used: {s['patches_used']} of {s['patches']}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def frame_colors(times) -> np.ndarray:
    """``(N, 3)`` RGB in [0, 1] of each frame in ``frames.png``: fully saturated hues from blue
    (shortest exposure) through green to red (longest), spaced evenly by exposure rank."""
    from matplotlib.colors import hsv_to_rgb

    from jaxgfx.io import exposure_order

    t = np.asarray(times, np.float64)
    n = t.shape[0]
    rank = np.empty(n, np.int64)
    rank[exposure_order(t)] = np.arange(n)  # the bracket's one sort (stable for equal times)
    hue = (2.0 / 3.0) * (1.0 - rank / max(n - 1, 1))
    return hsv_to_rgb(np.stack([hue, np.ones(n), np.ones(n)], -1))


def frames_map(used, reference, times) -> np.ndarray:
    """``frames.png`` of a ghost-free merge (``DeghostResult.used`` ``(N, H, W)`` and
    ``.reference`` ``(H, W)``): each pixel in the colour of its reference frame
    (:func:`frame_colors`), its brightness ``0.25 + 0.75 k / N`` for ``k`` of the ``N`` frames
    merged there (dim: the pixel came from few frames; full: from all). ``(H, W, 3)`` float32."""
    used = np.asarray(used) > 0.5
    ref = np.asarray(reference, np.int64)
    n = used.shape[0]
    k = used.sum(axis=0)
    value = 0.25 + 0.75 * k / n
    return (frame_colors(times)[ref] * value[..., None]).astype(np.float32)
