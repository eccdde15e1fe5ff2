"""Several views of a textured plane (docs/inverse.md, "Several views").

    python -m experiments.multiview --config configs/multiview.yaml --out out/multiview
    python -m experiments.multiview --timing --out out/multiview_timing

The default run fits the 64x64 albedo texture of a plane (configs/scenes/multiview_plane.yaml)
from four views (configs/multiview.yaml), each of which sees about a quarter of it, with a tv
prior, and again from the first view alone; it reports the texture's PSNR over the texels the
views see (a texel is seen when the gradient of the views' summed render w.r.t. it is not
zero), over the texels the first view sees and over those it does not, and writes
``result.json`` and ``textures.png`` (truth | four views | one view, each texel 4x4 pixels).

``--timing`` compares, each in a fresh interpreter (no compilation cache), the compile time
and the median step time of configs/inverse_camera.yaml (one photo, gamma and exposure
fitted) with the same scene seen from three views, a bracket of two photos per view, gamma,
exposure and white balance fitted, its views rendered by ``vmap`` or by a Python ``loop``
(:data:`jaxgfx.pipelines.fit.loss.VIEW_BATCHING`).

``--write-texture`` rewrites configs/scenes/multiview_albedo.png (8x8 blocks of uniform random
colours in [0.1, 0.9], seed 3, stored raw).

The hostile case (docs/inverse.md, "Several views: a textured mesh"):

    python -m experiments.multiview --mesh --config configs/multiview_mesh.yaml --out out/mv_mesh

fits the same 64x64 texture on a bumpy height-field mesh (configs/scenes/multiview_mesh.yaml:
slopes to 50 degrees, so each view sees the slopes facing it and the bumps hide the others),
with a rough gold sphere that casts a shadow on it, an area light and a constant light, from
four 8-bit photos through the synthetic "camera" response (toe, shoulder), one exposure per view
(the photo of view v is the one at ``target.camera.exposures[v]`` of the synthetic bracket), with
shot and read noise and JPEG quality 90 (4:2:0) — written as PNG files and fitted as a list of
``{file, exposure, view}`` photos, through a fixed ``camera`` response (the measured curve),
exposures given. It reports the PSNR over the *visible* texels (primary-ray samples of an AOV
render of a texel-index texture: a texel is visible when the views together put >= 0.5 pixel
on it) after each step budget of ``--budgets``, four views against view 0 alone, and the texels'
pixel coverage. Ablations: ``--drop jpeg,noise`` (photos without them), ``--size 128`` (the
views' pixels), ``--bracket`` (every view at every exposure: the synthetic target as it is).
``--write-mesh`` rewrites configs/scenes/multiview_bumps.obj.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import subprocess
import sys
import time

import numpy as np

from experiments._common import emit_json, log

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CONFIGS = os.path.join(ROOT, "configs")
TEXTURE = "materials.plane.reflectance.image"
THREE_VIEWS = [
    {},
    {"origin": [1.6, 1.2, 3.6]},
    {"origin": [-1.6, 1.2, 3.6]},
]


MESH_TEXTURE = "materials.surface.reflectance.image"


def bumps_mesh(n: int = 25, amplitude: float = 0.25, freq: float = 1.5):
    """A height field over [-1, 1]^2, ``y = a cos(pi f x) cos(pi f z)`` on an ``n x n`` vertex
    grid, with the surface's normals and ``uv = ((x + 1) / 2, (1 - z) / 2)``: slopes up to
    ``atan(a pi f)`` (50 degrees by default)."""
    from jaxgfx.render.geometry.mesh import TriangleMesh

    x = np.linspace(-1.0, 1.0, n)
    X, Z = np.meshgrid(x, x, indexing="xy")
    w = np.pi * freq
    Y = amplitude * np.cos(w * X) * np.cos(w * Z)
    hx = -amplitude * w * np.sin(w * X) * np.cos(w * Z)
    hz = -amplitude * w * np.cos(w * X) * np.sin(w * Z)
    nrm = np.stack([-hx, np.ones_like(X), -hz], -1)
    nrm /= np.linalg.norm(nrm, axis=-1, keepdims=True)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    faces = np.concatenate(
        [np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)]
    )
    uv = np.stack([(X + 1) / 2, (1 - Z) / 2], -1)
    return TriangleMesh(
        np.stack([X, Y, Z], -1).reshape(-1, 3).astype(np.float32),
        faces.astype(np.int32),
        nrm.reshape(-1, 3).astype(np.float32),
        uv.reshape(-1, 2).astype(np.float32),
    )


def write_obj(path: str, mesh) -> None:
    """``mesh`` as a compact OBJ (6 decimals; ``v``, ``vt``, ``vn``, ``f v/t/n``)."""
    v, t, n = (np.asarray(a, np.float64) for a in (mesh.vertices, mesh.uvs, mesh.normals))
    with open(path, "w") as fh:
        fh.write("# python -m experiments.multiview --write-mesh (bumps_mesh)\n")
        fh.writelines(f"v {a:.6f} {b:.6f} {c:.6f}\n" for a, b, c in v)
        fh.writelines(f"vt {a:.6f} {b:.6f}\n" for a, b in t)
        fh.writelines(f"vn {a:.6f} {b:.6f} {c:.6f}\n" for a, b, c in n)
        fh.writelines(
            "f " + " ".join(f"{i}/{i}/{i}" for i in (f + 1)) + "\n" for f in np.asarray(mesh.faces)
        )


def texel_coverage(scene, cameras, path: str = MESH_TEXTURE, keys: int = 16) -> np.ndarray:
    """``(V, H, W)``: the pixels each camera puts on each texel of the ``(H, W, 3)`` texture at
    ``path`` (nearest lookup), counted from ``keys`` one-sample AOV renders of a texture whose
    texels hold their own index (R, G) and a marker (B): occlusion by any other shape or by
    the mesh itself is the renderer's."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from jaxgfx.render import render

    h, w = np.asarray(scene.get(path)).shape[:2]
    rows, cols = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    marker = 0.3125
    ids = np.stack([(cols + 0.5) / w, (rows + 0.5) / h, np.full((h, w), marker)], -1)
    s_id = scene.replace(path, jnp.asarray(ids, jnp.float32))
    aov = jax.jit(lambda s, k: render(s, k, spp=1, integrator="aov"))
    out = []
    for cam in cameras:
        sc = eqx.tree_at(lambda q: q.camera, s_id, cam)
        c = np.zeros((h, w))
        for k in range(keys):
            a = np.asarray(aov(sc, jax.random.key(k)))
            hit = np.abs(a[..., 2] - marker) < 1e-4
            col = np.clip(np.floor(a[..., 0][hit] * w).astype(int), 0, w - 1)
            row = np.clip(np.floor(a[..., 1][hit] * h).astype(int), 0, h - 1)
            np.add.at(c, (row, col), 1.0 / keys)
        out.append(c)
    return np.stack(out)


def per_view_photos(cfg, prep, out_dir: str) -> list:
    """The synthetic target of ``cfg`` (``target.views`` each at every exposure of
    ``target.camera.exposures``), one photo per view — view ``v`` at exposure ``v`` of the
    bracket — written to ``out_dir`` as PNG (the JPEG-decoded codes, lossless): the photo list
    ``[{file, exposure, view}]`` of a fit."""
    from jaxgfx.io import write_png
    from jaxgfx.pipelines.fit.job import _target

    t = _target(cfg, prep)[0]
    tc = prep.target_spec["camera"]
    ex = [float(tc.get("exposure", 1.0)) * float(r) for r in tc["exposures"]]
    n_ex = len(ex)
    if n_ex < prep.n_views:
        raise ValueError(
            f"target.camera.exposures: one per view needed ({prep.n_views}), got {n_ex}"
        )
    os.makedirs(out_dir, exist_ok=True)
    photos = []
    for v in range(prep.n_views):
        j = v * n_ex + v
        path = os.path.join(out_dir, f"view{v}.png")
        write_png(path, np.asarray(t.pixels[j]).astype(np.uint8))
        photos.append({"file": path, "exposure": ex[v], "view": prep.view_poses[v]})
    return photos


def photo_errors(codes, clean, curve: str = "camera") -> dict:
    """Per-pixel error of the photos ``codes`` ``(V, H, W, 3)`` against the same photos
    without noise and JPEG ``clean``, over pixels unclipped in both (codes 3..244): RMS in
    codes, RMS relative error of the linear radiance (through the ``curve`` response's level
    table), and the RMS code error of JPEG's Y, Cb, Cr (BT.601) components."""
    from jaxgfx import hdr
    from jaxgfx.pipelines.fit.camera import level_table

    g = np.asarray(level_table(hdr.CameraResponse.analytic(curve, anchor="unit"), 8), np.float64)
    g = np.broadcast_to(g.reshape(256, -1), (256, 3))
    a, b = np.asarray(codes, np.int64), np.asarray(clean, np.int64)

    def lin(q):
        return np.exp(np.take_along_axis(g, q.reshape(-1, 3), 0)).reshape(q.shape)

    ok = (a > 2) & (a < 245) & (b > 2) & (b < 245)
    rel = (lin(a) - lin(b)) / lin(b)

    def ycc(x):
        x = x.astype(np.float64)
        y = 0.299 * x[..., 0] + 0.587 * x[..., 1] + 0.114 * x[..., 2]
        return y, 0.564 * (x[..., 2] - y), 0.713 * (x[..., 0] - y)

    px = ok.all(-1)
    return {
        "rms_codes": float(np.sqrt(np.mean((a - b)[ok] ** 2.0))),
        "rms_relative_linear": float(np.sqrt(np.mean(rel[ok] ** 2))),
        "rms_codes_ycbcr": [
            float(np.sqrt(np.mean((u - w)[px] ** 2))) for u, w in zip(ycc(a), ycc(b), strict=True)
        ],
    }


MESH_EXPOSURES = (1.0, 0.6, 1.6, 2.5)
"""The views' exposures of configs/multiview_mesh.yaml; ``ring_views(n)`` cycles them."""


def ring_views(n: int, radius: float = 3.3, elevation: float = 30.0, fov: float = 32.0) -> list:
    """``n`` views of the mesh's centre ``radius`` away, ``elevation`` degrees above its mean
    plane, at azimuths ``45 + 360 k / n`` degrees: ``n = 4`` gives the four views of
    configs/multiview_mesh.yaml (to the 3 decimals written there)."""
    el = np.radians(elevation)
    views = []
    for k in range(n):
        az = np.radians(45.0 + 360.0 * k / n)
        h = radius * np.cos(el)
        o = [h * np.cos(az), radius * np.sin(el), h * np.sin(az)]
        views.append(
            {
                "origin": [round(float(c), 3) for c in o],
                "target": [0, 0, 0],
                "up": [0, 1, 0],
                "fov": fov,
            }
        )
    return views


def run_mesh(
    config: str,
    out: str | None,
    budgets=(100, 300, 600),
    size: int | None = None,
    drop=(),
    bracket: bool = False,
    jpeg_chroma: str | None = None,
    fits_wanted=("four_views", "view0"),
    n_views: int | None = None,
    tv: float | None = None,
) -> dict:
    """The hostile case (module doc): PSNR over the visible texels against seconds for each
    step budget, four views against view 0 alone. Ablations: ``size`` the views' pixels
    (``render.width`` and ``height``; None: the config's); ``drop`` keys of
    ``target.camera`` to remove (``jpeg``, ``noise``); ``bracket``: fit the synthetic target
    as it is (every view at every exposure) instead of one photo per view; ``jpeg_chroma``
    the fits' ``loss.jpeg_chroma`` (None: the config's); ``fits_wanted`` which fits run;
    ``n_views``: :func:`ring_views` of that many views instead of the config's, view ``v`` at
    exposure ``MESH_EXPOSURES[v % 4]`` (the fit "four_views" then uses all ``n_views``);
    ``tv``: the texture's tv prior weight (None: the config's)."""
    import tempfile

    from jaxgfx.config import config_to_dict, load_config, read_yaml
    from jaxgfx.io import write_png
    from jaxgfx.pipelines.fit import FitConfig, FitJob, prepare_fit, run_fit

    base = os.path.dirname(os.path.abspath(config))
    raw = read_yaml(config)
    if size is not None:
        raw["render"] = dict(raw.get("render", {}), width=size, height=size)
    raw["target"]["camera"] = {k: v for k, v in raw["target"]["camera"].items() if k not in drop}
    if jpeg_chroma is not None:
        raw["loss"] = dict(raw.get("loss", {}), jpeg_chroma=jpeg_chroma)
    if tv is not None:
        raw["params"][MESH_TEXTURE] = dict(raw["params"][MESH_TEXTURE], prior={"tv": tv})
    if n_views is not None:
        raw["target"]["views"] = ring_views(n_views)
        raw["target"]["camera"]["exposures"] = [
            MESH_EXPOSURES[v % len(MESH_EXPOSURES)] for v in range(n_views)
        ]
    cfg = load_config(FitConfig, raw)
    desc = config_to_dict(cfg)
    prep = prepare_fit(cfg, base_dir=base)
    truth = np.asarray(prep.scene.get(MESH_TEXTURE), np.float64)
    t0 = time.perf_counter()
    cov = texel_coverage(prep.scene, prep.views)
    union = cov.sum(axis=0)
    visible = union >= 0.5
    hidden0 = visible & (cov[0] == 0)
    log(
        f"coverage ({time.perf_counter() - t0:.1f} s): visible {visible.mean():.3f} "
        f"(>= 1 px {float((union >= 1).mean()):.3f}, >= 2 px {float((union >= 2).mean()):.3f}), "
        f"median px/texel {float(np.median(union[visible])):.2f}, view 0 sees "
        f"{float((cov[0] > 0).mean()):.3f}, visible but hidden from view 0 {hidden0.mean():.3f}"
    )
    work = out if out is not None else tempfile.mkdtemp(prefix="mv_mesh_")
    t0 = time.perf_counter()
    photos = per_view_photos(cfg, prep, os.path.join(work, "photos"))
    target_seconds = time.perf_counter() - t0
    from PIL import Image

    def read(ps):
        return np.stack([np.asarray(Image.open(p["file"])) for p in ps])

    codes = read(photos)
    clipped = [float((c >= 245).any(-1).mean()) for c in codes]
    log(f"photos ({target_seconds:.1f} s): share of pixels >= code 245 per view {clipped}")
    errors = None
    tc = raw["target"]["camera"]
    if "jpeg" in tc or "noise" in tc:  # the camera's error: against the clean photos
        clean_raw = copy.deepcopy(raw)
        clean_raw["target"]["camera"] = {k: v for k, v in tc.items() if k not in ("jpeg", "noise")}
        clean_cfg = load_config(FitConfig, clean_raw)
        clean_prep = prepare_fit(clean_cfg, base_dir=base)
        clean = read(per_view_photos(clean_cfg, clean_prep, os.path.join(work, "photos_clean")))
        errors = photo_errors(codes, clean, tc.get("response", "camera"))
        log(f"photo errors against the clean photos: {json.dumps(errors)}")

    runs = []
    fits = {}
    if bracket:  # every view at every exposure: the synthetic target itself
        one = dict(desc["target"], views=desc["target"]["views"][:1])
        fits_of = (("four_views", desc["target"]), ("view0", one))
    else:
        fits_of = (("four_views", photos), ("view0", photos[:1]))
    for name, sel in fits_of:
        if name not in fits_wanted:
            continue
        for steps in budgets:
            d = copy.deepcopy(desc)
            d["target"] = sel
            d["optimizer"] = dict(d["optimizer"], steps=int(steps))
            d["progress"] = False
            sub = None if out is None else os.path.join(out, f"{name}_{steps}")
            t = time.perf_counter()
            res = run_fit(FitJob.load(d, sub, base_dir=base, overwrite=True))
            seconds = time.perf_counter() - t
            fit = np.asarray(res["params"][MESH_TEXTURE], np.float64)
            fits[name] = fit
            row = {
                "fit": name,
                "steps": int(steps),
                "seconds": seconds,
                "compile_seconds": res["compile_seconds"],
                "seconds_per_step": res["seconds_per_step"],
                "psnr_visible": psnr(fit, truth, visible),
                "psnr_seen_by_view0": psnr(fit, truth, visible & (cov[0] > 0)),
                "psnr_hidden_from_view0": psnr(fit, truth, hidden0),
                "psnr_visible_ge2px": psnr(fit, truth, union >= 2),
                "psnr_visible_lt1px": psnr(fit, truth, visible & (union < 1)),
            }
            log(json.dumps(row))
            runs.append(row)
    fits.setdefault("view0", np.asarray(prep.init[MESH_TEXTURE], np.float64) + 0 * truth)
    err = np.abs(fits["four_views"] - truth).max(-1)
    block = truth.shape[0] // 8  # the texture's uniform blocks (albedo_texture)
    d = np.minimum(np.arange(truth.shape[0]) % block, block - 1 - np.arange(truth.shape[0]) % block)
    edge = np.minimum(d[:, None], d[None, :]) == 0
    e2 = np.sum((fits["four_views"] - truth) ** 2, -1) / 3
    summary = {
        "texture": list(truth.shape),
        "view_pixels": [int(prep.scene.width), int(prep.scene.height)],
        "views": len(photos),
        "ablation": {
            "tv": tv,
            "n_views": n_views,
            "size": size,
            "drop": list(drop),
            "bracket": bracket,
            "jpeg_chroma": cfg.loss.jpeg_chroma,
        },
        "exposures": [p["exposure"] for p in photos],
        "share_clipped_per_view": clipped,
        "visible": float(visible.mean()),
        "visible_ge1px": float((union >= 1).mean()),
        "visible_ge2px": float((union >= 2).mean()),
        "px_per_visible_texel_median": float(np.median(union[visible])),
        "seen_by_each_view": [float((c > 0).mean()) for c in cov],
        "hidden_from_view0": float(hidden0.mean()),
        "photo_errors": errors,
        "four_views_rms_error_block_edge": float(np.sqrt(np.mean(e2[visible & edge]))),
        "four_views_rms_error_block_inside": float(np.sqrt(np.mean(e2[visible & ~edge]))),
        "init_psnr_visible": psnr(np.asarray(prep.init[MESH_TEXTURE]), truth, visible),
        "worst_visible_texels": {
            "p99_abs_error": float(np.percentile(err[visible], 99)),
            "median_px_of_worst_1pct": float(
                np.median(union[visible][err[visible] >= np.percentile(err[visible], 99)])
            ),
        },
        "runs": runs,
        "load_average": os.getloadavg(),
    }
    if out is not None:
        gap = np.ones((truth.shape[0], 2, 3))
        vis = np.repeat(visible[..., None], 3, -1).astype(np.float64)
        row = np.concatenate([truth, gap, fits["four_views"], gap, fits["view0"], gap, vis], axis=1)
        write_png(
            os.path.join(out, "textures.png"),
            np.round(np.clip(np.kron(row, np.ones((4, 4, 1))), 0, 1) * 255).astype(np.uint8),
        )
        emit_json(summary, os.path.join(out, "result.json"))
    else:
        emit_json(summary)
    return summary


def run_view_counts(
    config: str,
    out: str,
    counts=(3, 6, 12),
    chroma=("none", "4:2:0"),
    steps: int = 300,
    size: int | None = None,
) -> list:
    """PSNR over the visible texels against the number of views (:func:`ring_views`), with
    and without ``loss.jpeg_chroma``: one :func:`run_mesh` (all views only, ``steps``) per
    pair; writes ``view_counts.json`` and ``view_counts.png`` under ``out``."""
    rows = []
    for n in counts:
        for c in chroma:
            sub = os.path.join(out, f"views{n}_{c.replace(':', '')}")
            r = run_mesh(config, sub, (steps,), size, (), False, c, ("four_views",), n)
            run = r["runs"][0]
            rows.append(
                {
                    "views": n,
                    "jpeg_chroma": c,
                    "steps": steps,
                    "psnr_visible": run["psnr_visible"],
                    "psnr_visible_ge2px": run["psnr_visible_ge2px"],
                    "psnr_visible_lt1px": run["psnr_visible_lt1px"],
                    "visible": r["visible"],
                    "px_per_visible_texel_median": r["px_per_visible_texel_median"],
                    "seconds": run["seconds"],
                    "compile_seconds": run["compile_seconds"],
                    "load_average": r["load_average"],
                }
            )
            log(json.dumps(rows[-1]))
            emit_json(rows, os.path.join(out, "view_counts.json"))
    plot_view_counts(rows, os.path.join(out, "view_counts.png"))
    return rows


def plot_view_counts(rows: list, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.2, 3.4))
    for c, mk in (("none", "o-"), ("4:2:0", "s-")):
        rr = sorted((r for r in rows if r["jpeg_chroma"] == c), key=lambda r: r["views"])
        if rr:
            ax.plot(
                [r["views"] for r in rr],
                [r["psnr_visible"] for r in rr],
                mk,
                label=f"loss.jpeg_chroma: {c}",
            )
    ax.axhline(30.0, color="k", ls="--", lw=0.8, label="issue 25's target")
    ax.set_xlabel("views (one JPEG photo each, q 90, 4:2:0)")
    ax.set_ylabel("PSNR over visible texels (dB)")
    ax.set_title("64x64 texture on the bumpy mesh", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def albedo_texture(n: int = 64, seed: int = 3) -> np.ndarray:
    """``(n, n, 3)`` uint8: 8x8 blocks of uniform random colours in [0.1, 0.9]."""
    rng = np.random.default_rng(seed)
    blocks = np.round(rng.uniform(0.1, 0.9, (8, 8, 3)) * 255).astype(np.uint8)
    return np.kron(blocks, np.ones((n // 8, n // 8, 1), np.uint8))


def psnr(a, b, mask) -> float:
    """PSNR (peak 1) of ``a`` against ``b`` over the texels where ``mask`` ``(H, W)``."""
    err = (np.asarray(a, np.float64) - np.asarray(b, np.float64))[mask]
    return float(10 * np.log10(1.0 / max(np.mean(err * err), 1e-30)))


def seen_texels(prep, spp: int = 16) -> np.ndarray:
    """``(V, H, W)``: the texels each view sees (a non-zero gradient of its render's sum)."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from jaxgfx.render import render

    scene = prep.scene
    cams = prep.views if prep.views is not None else (scene.camera,)

    def total(img, cam):
        s = eqx.tree_at(lambda sc: sc.camera, scene.replace(TEXTURE, img), cam)
        return jnp.sum(render(s, jax.random.key(0), spp=spp, integrator="direct", max_depth=2))

    g = jax.jit(jax.grad(total))
    tex = jnp.asarray(scene.get(TEXTURE))
    return np.stack([np.any(np.asarray(g(tex, c)) != 0, axis=-1) for c in cams])


def run_texture(config: str, out: str | None) -> dict:
    from jaxgfx.config import config_to_dict, load_config
    from jaxgfx.io import write_png
    from jaxgfx.pipelines.fit import FitConfig, FitJob, prepare_fit, run_fit

    base = os.path.dirname(os.path.abspath(config))
    cfg = load_config(FitConfig, config)
    desc = config_to_dict(cfg)
    prep = prepare_fit(cfg, base_dir=base)
    truth = np.asarray(prep.scene.get(TEXTURE), np.float64)
    seen = seen_texels(prep)
    union, first = seen.any(axis=0), seen[0]
    log(
        f"texels seen: {union.mean():.3f} by the {len(seen)} views, "
        f"{[round(float(s.mean()), 3) for s in seen]} by each"
    )
    results, fits = {}, {}
    for name, views in (
        ("views", desc["target"]["views"]),
        ("one_view", desc["target"]["views"][:1]),
    ):
        d = copy.deepcopy(desc)
        d["target"]["views"] = views
        d["progress"] = False
        t = time.perf_counter()
        res = run_fit(
            FitJob.load(
                d, None if out is None else os.path.join(out, name), base_dir=base, overwrite=True
            )
        )
        seconds = time.perf_counter() - t
        fit = np.asarray(res["params"][TEXTURE], np.float64)
        fits[name] = fit
        results[name] = {
            "n_views": len(views),
            "psnr_seen": psnr(fit, truth, union),
            "psnr_first_view_seen": psnr(fit, truth, first),
            "psnr_first_view_hidden": psnr(fit, truth, union & ~first),
            "seconds": seconds,
            "compile_seconds": res["compile_seconds"],
            "seconds_per_step": res["seconds_per_step"],
            "view_loss_after": res["views"]["loss_after"],
        }
        log(name, json.dumps({k: v for k, v in results[name].items() if k != "view_loss_after"}))
    summary = {
        "texture": list(truth.shape),
        "texels_seen": float(union.mean()),
        "texels_seen_by_each_view": [float(s.mean()) for s in seen],
        "init_psnr_seen": psnr(np.asarray(prep.init[TEXTURE]), truth, union),
        **results,
    }
    if out is not None:
        os.makedirs(out, exist_ok=True)
        gap = np.ones((truth.shape[0], 2, 3))
        row = np.concatenate([truth, gap, fits["views"], gap, fits["one_view"]], axis=1)
        big = np.kron(row, np.ones((4, 4, 1)))
        write_png(
            os.path.join(out, "textures.png"), np.round(np.clip(big, 0, 1) * 255).astype(np.uint8)
        )
        emit_json(summary, os.path.join(out, "result.json"))
    else:
        emit_json(summary)
    return summary


def timing_config(variant: str) -> dict:
    """The fit of a ``--timing`` variant: ``single`` (configs/inverse_camera.yaml as shipped,
    20 steps) or ``vmap`` / ``loop`` (three views, two photos each, full camera)."""
    from jaxgfx.config import read_yaml

    d = read_yaml(os.path.join(CONFIGS, "inverse_camera.yaml"))
    d["optimizer"] = dict(d["optimizer"], steps=20)
    d["progress"] = False
    if variant != "single":
        d["target"] = dict(d["target"], views=THREE_VIEWS)
        d["target"]["camera"] = dict(
            d["target"]["camera"], exposures=[0.5, 2.0], white_balance=[1.1, 1.0, 0.9]
        )
        d["camera"] = {
            "response": {"model": "gamma", "fit": True, "init": 2.2},
            "exposure": {"init": 1.0, "fit": True},
            "white_balance": {"fit": True},
        }
    return d


def _time_one(variant: str) -> None:
    from jaxgfx.pipelines.fit import FitJob, loss, run_fit

    if variant in ("vmap", "loop"):
        loss.VIEW_BATCH = variant
    res = run_fit(FitJob.load(timing_config(variant), None, base_dir=CONFIGS))
    print(
        json.dumps(
            {
                "variant": variant,
                "compile_seconds": res["compile_seconds"],
                "seconds_per_step": res["seconds_per_step"],
                "n_targets": res["n_targets"],
            }
        )
    )


def run_timing(out: str | None, repeats: int) -> dict:
    env = dict(os.environ, JAXGFX_CACHE_DIR="off")
    rows = []
    for r in range(repeats):
        for variant in ("single", "vmap", "loop"):
            p = subprocess.run(
                [sys.executable, "-m", "experiments.multiview", "--time-one", variant],
                cwd=ROOT,
                env=env,
                capture_output=True,
                text=True,
                check=True,
            )
            row = json.loads(p.stdout.strip().splitlines()[-1])
            row["repeat"] = r
            log(json.dumps(row))
            rows.append(row)
    summary = {"rows": rows}
    for v in ("single", "vmap", "loop"):
        c = [x["compile_seconds"] for x in rows if x["variant"] == v]
        s = [x["seconds_per_step"] for x in rows if x["variant"] == v]
        summary[v] = {
            "compile_seconds_median": float(np.median(c)),
            "seconds_per_step_median": float(np.median(s)),
        }
    for v in ("vmap", "loop"):
        summary[v]["compile_ratio_to_single"] = (
            summary[v]["compile_seconds_median"] / summary["single"]["compile_seconds_median"]
        )
    summary["load_average"] = os.getloadavg()
    if out is not None:
        os.makedirs(out, exist_ok=True)
    emit_json(summary, None if out is None else os.path.join(out, "timing.json"))
    return summary


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--config", default=os.path.join(CONFIGS, "multiview.yaml"))
    p.add_argument("--out", default=None, help="output folder (default: print only)")
    p.add_argument("--timing", action="store_true", help="compile / step time, vmap vs loop")
    p.add_argument("--repeats", type=int, default=2, help="--timing: runs of each variant")
    p.add_argument("--mesh", action="store_true", help="the hostile textured-mesh case")
    p.add_argument(
        "--budgets", default="100,300,600", help="--mesh: the step budgets (comma-separated)"
    )
    p.add_argument("--size", type=int, default=None, help="--mesh: the views' pixels (N x N)")
    p.add_argument("--drop", default="", help="--mesh: target.camera keys to remove (jpeg,noise)")
    p.add_argument("--bracket", action="store_true", help="--mesh: every view at every exposure")
    p.add_argument("--jpeg-chroma", default=None, help="--mesh: the fits' loss.jpeg_chroma")
    p.add_argument("--four-views-only", action="store_true", help="--mesh: skip view 1 alone")
    p.add_argument(
        "--n-views",
        type=int,
        default=None,
        help="--mesh: that many views on a ring (ring_views) instead of the config's",
    )
    p.add_argument(
        "--view-counts",
        default=None,
        help="--mesh: PSNR against the number of views, e.g. 3,6,12 (needs --out)",
    )
    p.add_argument("--tv", type=float, default=None, help="--mesh: the texture's tv weight")
    p.add_argument("--chroma", default="none,4:2:0", help="--view-counts: loss.jpeg_chroma values")
    p.add_argument("--write-texture", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--write-mesh", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--time-one", choices=("single", "vmap", "loop"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.time_one:
        _time_one(a.time_one)
    elif a.write_mesh:
        write_obj(os.path.join(CONFIGS, "scenes", "multiview_bumps.obj"), bumps_mesh())
    elif a.mesh:
        config = a.config
        if config == os.path.join(CONFIGS, "multiview.yaml"):
            config = os.path.join(CONFIGS, "multiview_mesh.yaml")
        drop = tuple(k for k in a.drop.split(",") if k)
        budgets = tuple(int(b) for b in a.budgets.split(","))
        fits_wanted = ("four_views",) if a.four_views_only else ("four_views", "view0")
        if a.view_counts:
            if a.out is None:
                p.error("--view-counts needs --out")
            counts = tuple(int(n) for n in a.view_counts.split(","))
            run_view_counts(config, a.out, counts, tuple(a.chroma.split(",")), budgets[-1], a.size)
        else:
            run_mesh(
                config,
                a.out,
                budgets,
                a.size,
                drop,
                a.bracket,
                a.jpeg_chroma,
                fits_wanted,
                a.n_views,
                a.tv,
            )
    elif a.write_texture:
        from jaxgfx.io import write_png

        write_png(os.path.join(CONFIGS, "scenes", "multiview_albedo.png"), albedo_texture())
    elif a.timing:
        run_timing(a.out, a.repeats)
    else:
        run_texture(a.config, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
