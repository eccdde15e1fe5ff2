"""Write synthetic RGB ``.bsdf`` files (Mitsuba's ``measured`` format) tabulated from an analytic
GGX conductor: the test data of tests/data/measured (no RGL file is available offline).

The BRDF is Walter et al.'s GGX microfacet conductor with Schlick's Fresnel (RGB ``F0``) and the
separable Smith masking: ``f cos θ_o = F(ω_i·m) G1(ω_i) G1(ω_o) D(m) / (4 cos θ_i)``. With the
projected area ``σ(ω_i) = cos θ_i / G1(ω_i) = (cos θ_i + sqrt(cos² θ_i + α(φ_i)² sin² θ_i)) / 2``
that is ``rgb · D / (4 σ)`` with ``rgb = F(ω_i·m) G1(ω_o)``: the file's ``jacobian`` flag is set
and its ``rgb`` table holds ``F G1(ω_o)`` (Dupuy & Jakob 2018's parameterisation). The fields:

* ``ndf`` (H, W): ``D(m)`` at ``u_m = (sqrt(2θ_m/π), (φ_m + π)/2π)`` on the grid ``(j/(H-1),
  i/(W-1))`` (``x = u_θ`` along the last axis); ``sigma`` (H, W): ``σ`` likewise over ``u_i``;
* ``vndf`` (P, T, H, W) per viewing direction ``(φ_i, θ_i)``: the density of ``u_m`` under the
  VNDF, ``D(m) <ω_i·m> / σ(ω_i) · 2π² u_θ sin θ_m`` (relative azimuth ``φ_m - φ_i`` for the
  isotropic file, whose ``phi_i`` has one node);
* ``rgb`` (P, T, 3, H, W): ``F G1(ω_o)`` at the directions that the VNDF warp (jaxgfx's
  ``warp_sample``, Mitsuba's continuous ``Marginal2D``) sends the grid of its primary sample
  space to; ``luminance`` (P, T, H, W) its Rec. 709 luminance (the density sampled first).

Usage: ``python tools/make_measured_bsdf.py [OUT_DIR]`` (default tests/data/measured) writes
``ggx_iso.bsdf`` (α = 0.3, F0 = (0.95, 0.64, 0.54), 1 x 9 slices of 32 x 32) and
``ggx_aniso.bsdf`` (α = (0.15, 0.4), F0 = (0.56, 0.57, 0.58), 5 x 7 slices of 16 x 16, φ_i over
a quarter turn: ``reduction`` 4). The analytic BRDF of each is :func:`analytic` here.
``python tools/make_measured_bsdf.py --convergence`` prints the isotropic material's error
against its closed form at tables of 16², 32² and 64² (:func:`convergence`).
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np

FILES = {
    "ggx_iso.bsdf": dict(alpha=(0.3, 0.3), f0=(0.95, 0.64, 0.54), n_phi=1, n_theta=9, res=32),
    "ggx_aniso.bsdf": dict(alpha=(0.15, 0.4), f0=(0.56, 0.57, 0.58), n_phi=5, n_theta=7, res=16),
}
LUM = np.array([0.212671, 0.715160, 0.072169])


def _alpha2(ax, ay, cos_phi2, sin_phi2):
    return ax * ax * cos_phi2 + ay * ay * sin_phi2


def ggx_d(m, ax, ay):
    """GGX ``D(m)`` (Walter et al. 2007; anisotropic as Heitz 2014), ``m`` (..., 3) unit."""
    x, y, z = m[..., 0], m[..., 1], m[..., 2]
    t = (x / ax) ** 2 + (y / ay) ** 2 + z * z
    return np.where(z > 0, 1.0 / (math.pi * ax * ay * t * t), 0.0)


def sigma(w, ax, ay):
    """Projected area of the GGX microsurface seen from ``w``:
    ``(cos + sqrt(cos² + α² sin²)) / 2``."""
    z = w[..., 2]
    s2 = w[..., 0] ** 2 + w[..., 1] ** 2
    a2 = np.where(s2 > 0, (ax * ax * w[..., 0] ** 2 + ay * ay * w[..., 1] ** 2) / np.where(
        s2 > 0, s2, 1.0), ax * ax)  # fmt: skip
    return 0.5 * (z + np.sqrt(z * z + a2 * s2))


def g1(w, ax, ay):
    """Smith masking ``G1 = cos θ / σ`` (0 below the surface)."""
    z = w[..., 2]
    return np.where(z > 0, z / np.maximum(sigma(w, ax, ay), 1e-300), 0.0)


def analytic(wo, wi, alpha, f0):
    """The analytic ``f cos θ_i`` (jaxgfx convention: ``wo`` towards the viewer) of a file's
    GGX conductor, (..., 3)."""
    ax, ay = alpha
    wo, wi = np.asarray(wo, np.float64), np.asarray(wi, np.float64)
    h = wo + wi
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    c = np.clip(np.sum(wo * h, -1), 0.0, 1.0)
    f = np.asarray(f0) + (1.0 - np.asarray(f0)) * ((1.0 - c) ** 5)[..., None]
    val = g1(wo, ax, ay) * g1(wi, ax, ay) * ggx_d(h, ax, ay) / (4.0 * wo[..., 2])
    ok = (wo[..., 2] > 0) & (wi[..., 2] > 0)
    return np.where(ok[..., None], f * val[..., None], 0.0)


def _sph(theta, phi):
    st = np.sin(theta)
    return np.stack([np.cos(phi) * st, np.sin(phi) * st, np.cos(theta)], axis=-1)


def tables(alpha, f0, n_phi, n_theta, res, ndf_res=32):
    """The fields of one file (see the module doc)."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    from jaxgfx.render.bsdf._marginal2d import build_warp, warp_sample

    ax, ay = alpha
    iso = n_phi == 1
    theta_i = np.linspace(0.0, math.pi / 2, n_theta)
    phi_i = np.zeros(1) if iso else np.linspace(-math.pi, -math.pi / 2, n_phi)
    g = np.linspace(0.0, 1.0, ndf_res)
    ux, uy = np.meshgrid(g, g)  # (H, W): x = u_θ along the last axis
    m_grid = _sph(ux * ux * math.pi / 2, (2 * uy - 1) * math.pi)
    ndf = ggx_d(m_grid, ax, ay)
    sig = sigma(m_grid, ax, ay)  # the same (u_θ, u_φ) grid, read as directions ω_i
    r = np.linspace(0.0, 1.0, res)
    vx, vy = np.meshgrid(r, r)
    s_grid = np.stack([vx, vy], axis=-1)
    vndf = np.zeros((len(phi_i), n_theta, res, res))
    rgb = np.zeros((len(phi_i), n_theta, 3, res, res))
    for p, ph in enumerate(phi_i):
        for t, th in enumerate(theta_i):
            wi = _sph(th, ph)
            th_m, ph_m = vx * vx * math.pi / 2, (2 * vy - 1) * math.pi + (ph if iso else 0.0)
            m = _sph(th_m, ph_m)
            cos_im = np.maximum(np.sum(m * wi, -1), 0.0)
            jac = 2 * math.pi**2 * vx * np.sin(th_m)
            vndf[p, t] = ggx_d(m, ax, ay) * cos_im / sigma(wi, ax, ay) * jac
            warp = build_warp(vndf[p, t].astype(np.float32), dtype=jnp.float64)
            u_m, _ = warp_sample(warp, jnp.asarray(s_grid))
            u_m = np.asarray(u_m)
            m = _sph(u_m[..., 0] ** 2 * math.pi / 2,
                     (2 * u_m[..., 1] - 1) * math.pi + (ph if iso else 0.0))  # fmt: skip
            c = np.sum(m * wi, -1)
            wo = 2 * c[..., None] * m - wi
            fr = np.asarray(f0) + (1 - np.asarray(f0)) * ((1 - np.clip(c, 0, 1)) ** 5)[..., None]
            rgb[p, t] = np.moveaxis(fr * g1(wo, ax, ay)[..., None], -1, 0)
    lum = np.einsum("c,ptchw->pthw", LUM, rgb)
    desc = (f"synthetic GGX conductor alpha={alpha} Schlick F0={f0} (jaxgfx "
            "tools/make_measured_bsdf.py)")  # fmt: skip
    return dict(theta_i=theta_i, phi_i=phi_i, ndf=ndf, sigma=sig, vndf=vndf, luminance=lum,
                rgb=rgb, description=desc, jacobian=True)  # fmt: skip


def convergence(n_pairs=4000):
    """The isotropic material tabulated at three resolutions (tables ``res`` x ``res``, ``ndf``
    and ``sigma`` alike; 9 θ_i) against its closed form on random direction pairs: the error is
    the tables' resolution (printed: median and 90th-percentile relative error, mean |error| /
    mean value)."""
    import jax
    import jax.numpy as jnp

    from jaxgfx.render.bsdf import Measured

    kw = dict(FILES["ggx_iso.bsdf"])
    rng = np.random.default_rng(1)
    w = rng.normal(size=(2, n_pairs, 3))
    w[..., 2] = np.abs(w[..., 2])
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    a = analytic(w[0], w[1], kw["alpha"], kw["f0"])
    for res in (16, 32, 64):
        t = tables(**{**kw, "res": res}, ndf_res=res)
        b = Measured(tables=t)
        f = np.asarray(jax.jit(lambda b, x, y: b.eval(x, y))(
            b, jnp.asarray(w[0], jnp.float32), jnp.asarray(w[1], jnp.float32)), np.float64)
        rel = np.abs(f - a) / np.maximum(a, 1e-6)
        print(f"res {res:3d}: median {np.median(rel):.4f}, p90 {np.percentile(rel, 90):.3f}, "
              f"mean |err| / mean {np.abs(f - a).mean() / a.mean():.4f}")


def main(out_dir):
    from jaxgfx.render.bsdf import write_measured

    os.makedirs(out_dir, exist_ok=True)
    for name, kw in FILES.items():
        path = os.path.join(out_dir, name)
        write_measured(path, tables(**kw))
        print(f"wrote {path} ({os.path.getsize(path)} bytes)")


if __name__ == "__main__":
    if sys.argv[1:] == ["--convergence"]:
        convergence()
    else:
        main(sys.argv[1] if len(sys.argv) > 1 else os.path.join("tests", "data", "measured"))
