"""Mitsuba 3's ``sunsky`` emitter as :class:`jaxgfx.render.sunsky.SunSky` (RGB Hosek-Wilkie sky
and sun): the shipped data against the Mitsuba wheel's files, the sky against a direct table
lookup, the sun's position against closed-form solar geometry, the sampler (chi² of the sky's
and the sun's parts, MIS against pure cosine sampling in expectation), FD gradients of every
leaf, hard cases, bad input (descriptions, XML with file and line), the writer round trip and
the program without the optional parts. Against Mitsuba 3 itself (eval, sun position, a render):
tests/render/test_sunsky_mitsuba.py (``mitsuba`` marker)."""

from __future__ import annotations

import importlib.util
import math
import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render._sunsky_data import FIELDS, NPZ_PATH, read_tensor_file
from jaxgfx.render.geometry.frame import frame_from_normal
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba import scene_to_desc, to_mitsuba_dict
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene
from jaxgfx.render.sunsky import SunSky, _disc, sun_coordinates, sun_direction_at
from jaxgfx.testing import chi2_test

CIE_Y = 1.0 / 106.7502593994140625


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _elev_dir(elev_deg, az_deg=30.0):
    e, a = math.radians(elev_deg), math.radians(az_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def _upper(n, seed=0):
    d = np.random.default_rng(seed).normal(size=(n, 3))
    d[:, 2] = np.abs(d[:, 2])
    return _unit(d)


_eval = jax.jit(lambda e, d: e.eval(d))
_spe = jax.jit(lambda e, u: (*e.sample(u), e.pdf(e.sample(u)[0]), e.eval(e.sample(u)[0])))


# -- data ---------------------------------------------------------------------------------


def test_data_subset_matches_mitsuba_wheel():
    """Every array of sunsky_rgb.npz that ORIGIN.md says is copied equals the Mitsuba wheel's
    field bit for bit (dtype and values), read by jaxgfx's own tensor-file reader; skipped
    without the wheel (its files are found without importing Mitsuba)."""
    spec = importlib.util.find_spec("mitsuba")
    if spec is None or spec.origin is None:
        pytest.skip("the Mitsuba wheel is not installed")
    src = os.path.join(os.path.dirname(spec.origin), "data", "sunsky")
    if not os.path.isdir(src):
        pytest.skip(f"{src}: no sunsky data in this Mitsuba")
    with np.load(NPZ_PATH) as z:
        for k, (fname, field) in FIELDS.items():
            orig = read_tensor_file(os.path.join(src, fname))[field]
            assert z[k].dtype == orig.dtype and z[k].shape == orig.shape, k
            assert np.array_equal(z[k], orig), k
        assert z["cie_xyz"].shape == (11, 3) and np.all(z["cie_xyz"][0] == 0)


# -- the sky: a direct lookup of the tables ---------------------------------------------------


def _hw_formula(p, rad, cos_theta, gamma):
    """Hosek-Wilkie 2012, eq. 9, parameters as stored (A..G, I, H), per channel."""
    a, b, c, d, e, f, g, i, h = p.T
    cg = math.cos(gamma)
    chi = (1 + cg * cg) / (1 + h * h - 2 * h * cg) ** 1.5
    return ((1 + a * np.exp(b / (cos_theta + 0.01)))
            * (c + d * np.exp(e * gamma) + f * cg * cg + g * chi + i * math.sqrt(cos_theta))
            * rad)  # fmt: skip


@pytest.mark.parametrize("turbidity, albedo, elev", [(1.0, 0.0, 90.0), (4.0, 1.0, 90.0),
                                                    (10.0, 0.0, 11.25), (6.0, 1.0, 11.25)])
def test_sky_is_the_papers_formula_on_the_raw_tables(x64, turbidity, albedo, elev):
    """At an integer turbidity and albedo 0 or 1 only the sun's elevation is interpolated: by
    the quintic Bezier in ``x = (2 eta / pi)^(1/3)`` over the six control points. The sun at
    the zenith (x clamped to 1 - 2^-24: the last control point, to 3e-7) and at 11.25 deg
    (x = 1/2: Bernstein weights (1, 5, 10, 10, 5, 1) / 32): the radiance is the paper's formula
    (Hosek and Wilkie 2012, eq. 9) on rows of the raw tables (read from the npz directly)
    times Mitsuba's CIE Y factor, rtol 1e-5 (measured 3e-7). Power: the last two parameters
    in the paper's letter order (H before I) miss by more than 10 %."""
    sun = _elev_dir(elev, 30.0) if elev < 90 else np.array([0.0, 0.0, 1.0])
    sky = SunSky.create(sun, turbidity=turbidity, albedo=albedo, sun_scale=0.0)
    w = np.array([0, 0, 0, 0, 0, 1.0]) if elev == 90 else np.array([1, 5, 10, 10, 5, 1]) / 32
    with np.load(NPZ_PATH) as z:
        p = np.tensordot(w, z["sky_params_rgb"][int(turbidity) - 1, int(albedo)], 1)  # (3, 9)
        rad = w @ z["sky_rad_rgb"][int(turbidity) - 1, int(albedo)]  # (3,)
    dirs = _unit([[0.0, 0.0, 1.0], [1.0, 0.3, 1.0], [0.2, -1.0, 0.4], [1.0, 0.0, 0.02]])
    got = np.asarray(_eval(sky, jnp.asarray(dirs)))
    gam = [math.acos(np.clip(d @ sun, -1, 1)) for d in dirs]
    ref = np.stack([_hw_formula(p, rad, d[2], g) for d, g in zip(dirs, gam, strict=True)]) * CIE_Y
    np.testing.assert_allclose(got, ref, rtol=1e-5)
    swapped = np.stack([_hw_formula(p[:, [0, 1, 2, 3, 4, 5, 6, 8, 7]], rad, d[2], g)
                        for d, g in zip(dirs, gam, strict=True)]) * CIE_Y  # fmt: skip
    assert np.max(np.abs(swapped / ref - 1)) > 0.1


@pytest.mark.parametrize("turbidity, node", [(2.0, 6), (9.0, 0), (5.0, 29)])
def test_sun_disc_is_the_tables_irradiance_over_its_solid_angle(x64, turbidity, node):
    """The simple sun at an integer turbidity and a node of the irradiance table (elevation
    2 + 3 node degrees): its radiance is the table's spectral irradiance converted to linear
    Rec. 709 (the mean over the 11 wavelengths of the CIE 1931 functions times the sRGB
    matrix), times Mitsuba's constants 467.069280386 / 106.75, over the disc's solid angle
    ``2 pi (1 - cos h)`` with Mitsuba's float32 ``cos h`` (h = 0.2679 deg): rtol 1e-6."""
    sun = _elev_dir(2.0 + 3.0 * node - (1e-9 if node == 29 else 0.0), -40.0)
    e = SunSky.create(sun, turbidity=turbidity)
    m = np.array([[3.240479, -1.537150, -0.498535], [-0.969256, 1.875991, 0.041556],
                  [0.055648, -0.204043, 1.057311]])  # fmt: skip
    with np.load(NPZ_PATH) as z:
        irr = z["sun_irradiance"][int(turbidity) - 1, node].astype(np.float64)
        rgb = np.mean((z["cie_xyz"] @ m.T) * irr[:, None], 0)
    omc = 1.0 - float(np.cos(np.float32(np.float32(0.2679) * np.float32(math.pi / 180))))
    ref = rgb * 467.069280386 * CIE_Y / (2 * math.pi * omc)
    got = np.asarray(_eval(e, jnp.asarray(sun[None])))[0]
    sky = np.asarray(_eval(eqx.tree_at(lambda x: x.sun_scale, e, jnp.asarray(0.0)),
                           jnp.asarray(sun[None])))[0]  # fmt: skip
    np.testing.assert_allclose(got - sky, ref, rtol=1e-6)


# -- the sun's position -------------------------------------------------------------------


def test_sun_position_closed_form():
    """Solar geometry by hand: at the June 2010 solstice (declination 23.44 deg) Tokyo's
    (latitude 35.6894 N, longitude 139.6917 E, UTC+9) noon elevation is 90 - 35.6894 + 23.44 =
    77.75 deg, reached at 11:43 local time (the 135 E meridian, 4.7 deg west: 18.8 min earlier,
    and the equation of time, -1.7 min); at the March equinox (2010-03-20, declination -0.2
    deg) the sun passes 0.2 deg from the zenith of (0 N, 0 E) at 12:07 UTC. Both within 0.1
    deg. Mitsuba's frame: at that noon the sun is at +X (azimuth from north minus pi), in the
    morning at -Y, in the afternoon at +Y; below the horizon at midnight."""
    th, ph = sun_coordinates(2010, 6, 21, 11, 43, 0, 35.6894, 139.6917, 9)
    assert abs((90 - math.degrees(th)) - 77.75) < 0.1
    assert abs(ph) < math.radians(1.0)  # phi = azimuth - pi: the sun due south at +X
    th, _ = sun_coordinates(2010, 3, 20, 12, 7, 0, 0.0, 0.0, 0)
    assert abs(math.degrees(th) - 0.2) < 0.1
    morning = sun_direction_at(latitude=35.6894, longitude=139.6917, timezone=9, hour=8.0)
    evening = sun_direction_at(latitude=35.6894, longitude=139.6917, timezone=9, hour=16.0)
    night = sun_direction_at(hour=0.5)
    assert morning[1] < -0.3 and evening[1] > 0.3 and night[2] < -0.3
    rot = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(sun_direction_at(rot, hour=8.0), rot @ sun_direction_at(hour=8.0))


# -- sampling -------------------------------------------------------------------------------


def test_sample_pdf_eval_agree_under_jit(x64):
    """The sampler's density and radiance are :meth:`pdf` and :meth:`eval` at the returned
    direction (rotated emitter, complex sun); directions are unit, densities positive."""
    rot = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])
    e = SunSky.create(rot @ _elev_dir(25.0), turbidity=5.5, albedo=[0.1, 0.4, 0.8],
                      complex_sun=True, sun_aperture=4.0, to_world=rot)  # fmt: skip
    u = jax.random.uniform(jax.random.key(0), (20_000, 2), jnp.float64)
    wi, pdf, li, pdf2, li2 = (np.asarray(x) for x in _spe(e, u))
    np.testing.assert_allclose(np.linalg.norm(wi, axis=-1), 1.0, rtol=1e-12)
    np.testing.assert_allclose(pdf, pdf2, rtol=1e-9)
    np.testing.assert_allclose(li, li2, rtol=1e-9, atol=1e-12)
    assert np.all(pdf > 0) and np.all(np.isfinite(li))
    # about the sun's share of the samples fall in its cone (in the local frame: rot^T wi)
    local = wi @ rot
    near = np.degrees(np.arccos(np.clip(local @ _elev_dir(25.0), -1, 1))) <= 2.0
    w_sun = 1 - float(e._sky_weight(jnp.float64))
    assert abs(near.mean() - w_sun) < 0.02, (near.mean(), w_sun)


def test_chi2_sky_part(x64):
    """The sky's sampler (sun_scale 0: every sample from the sky's tabulated density) against
    its pdf: chi² on 128 x 128 cells uniform in (cos theta, phi), each upper one exactly a
    cell of the tabulation (the pdf is constant in it: the quadrature is exact)."""
    e = SunSky.create(_elev_dir(12.0), turbidity=2.5, sun_scale=0.0)
    ok, p, det = chi2_test(jax.jit(lambda u1, u2: e.sample(u2)[0]), jax.jit(lambda w: e.pdf(w)),
                           key=jax.random.key(1), n_samples=1 << 19, res_theta=128,
                           res_phi=128, ires=2)  # fmt: skip
    assert ok, (p, det["message"])
    assert abs(det["pdf_integral"] - 1) < 1e-6


def test_chi2_sun_cone(x64):
    """The sun's sampler (sky_scale 0) against its pdf in the sun's frame: an aperture of
    51.68 deg puts the cone's edge (cos = 0.9, Mitsuba's float32 value) on a cell edge of a
    40-row grid, so the uniform cap is integrated exactly. Power: the same sampler fed
    ``u0^2`` instead of ``u0`` (samples crowding the cone's axis) fails."""
    s = _elev_dir(50.0)
    e = SunSky.create(s, sky_scale=0.0, sun_aperture=2 * math.degrees(math.acos(0.9)))
    assert abs(_disc(e.sun_aperture)[0] - 0.1) < 1e-7
    fr = frame_from_normal(jnp.asarray(s))
    to_local = lambda w: jnp.stack([w @ fr.s, w @ fr.t, w @ fr.n], -1)  # noqa: E731
    pdf = jax.jit(lambda w: e.pdf(w[..., 0:1] * fr.s + w[..., 1:2] * fr.t + w[..., 2:3] * fr.n))
    sample = jax.jit(lambda u: to_local(e.sample(u)[0]))
    ok, p, det = chi2_test(lambda u1, u2: sample(u2), pdf, key=jax.random.key(2),
                           n_samples=200_000, res_theta=40, res_phi=16, ires=4)  # fmt: skip
    assert ok, (p, det["message"])
    ok, _, _ = chi2_test(lambda u1, u2: sample(u2.at[:, 0].set(u2[:, 0] ** 2)), pdf,
                         key=jax.random.key(2), n_samples=200_000, res_theta=40, res_phi=16,
                         ires=4)  # fmt: skip
    assert not ok


def _cosine_hemisphere(u, n):
    r, phi = jnp.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
    fr = frame_from_normal(jnp.broadcast_to(n, (u.shape[0], 3)))
    z = jnp.sqrt(jnp.maximum(1 - u[:, 0], 0.0))
    return ((r * jnp.cos(phi))[:, None] * fr.s + (r * jnp.sin(phi))[:, None] * fr.t
            + z[:, None] * fr.n)  # fmt: skip


@jax.jit
def _diffuse_estimators(e, n, u_light, u_bsdf):
    """Per sample, the reflected radiance / albedo of a Lambertian surface of normal ``n``:
    pure cosine (BSDF) sampling, and one light plus one cosine sample with the power
    heuristic (what the path integrator's MIS does)."""
    wb = _cosine_hemisphere(u_bsdf, n)
    cb = jnp.maximum(wb @ n, 0.0)
    lb = e.eval(wb)
    pure = lb  # L cos / pi / (cos / pi)
    wl, pl, ll = e.sample(u_light)
    cl = jnp.maximum(wl @ n, 0.0)
    bl = cl / math.pi
    w_l = pl**2 / (pl**2 + bl**2)
    w_b = (cb / math.pi) ** 2 / ((cb / math.pi) ** 2 + e.pdf(wb) ** 2)
    mis = ll * (cl / math.pi * w_l / pl)[:, None] + lb * w_b[:, None]
    return pure, jnp.where(jnp.isfinite(mis), mis, 0.0)


@pytest.mark.parametrize("normal", [(0.0, 0.0, 1.0), (0.8, 0.1, 0.6), (-0.7, 0.0, 0.7)])
def test_mis_equals_pure_bsdf_sampling_in_expectation(x64, normal):
    """A Lambertian surface under the sky and a 10-degree sun (large enough that cosine
    sampling finds it): the MIS estimator (the emitter's sampler + cosine sampling, power
    heuristic) and pure cosine sampling agree within 4 standard errors per channel (2^18
    samples each, normals facing, tilted to, and turned from the sun)."""
    e = SunSky.create(_elev_dir(40.0, 0.0), turbidity=3.0, sun_aperture=10.0)
    n = jnp.asarray(_unit(normal))
    k = jax.random.split(jax.random.key(7), 2)
    m = 1 << 18
    pure, mis = (np.asarray(x) for x in _diffuse_estimators(
        e, n, jax.random.uniform(k[0], (m, 2), jnp.float64),
        jax.random.uniform(k[1], (m, 2), jnp.float64)))  # fmt: skip
    se = np.sqrt(pure.var(0) / m + mis.var(0) / m)
    assert np.all(np.abs(pure.mean(0) - mis.mean(0)) < 4 * se), (pure.mean(0), mis.mean(0), se)
    assert np.all(mis.std(0) < pure.std(0))  # MIS is the lower-variance one


# -- gradients ------------------------------------------------------------------------------


def _loss(leaves, e, dirs, w):
    sd, turb, alb, sun_s, sky_s = leaves
    e = eqx.tree_at(lambda x: (x.sun_direction, x.turbidity, x.albedo, x.sun_scale, x.sky_scale),
                    e, (sd, turb, alb, sun_s, sky_s))  # fmt: skip
    return jnp.sum(w * e.eval(dirs))


_vg_j = jax.jit(jax.value_and_grad(_loss))  # one program for values and gradients
N_DIRS = 26  # one direction count for the gradient and hard-case tests: shared programs


@pytest.mark.parametrize("complex_sun", [False, True])
def test_fd_gradients_of_every_leaf(x64, complex_sun):
    """d/d(sun_direction, turbidity, albedo, sun_scale, sky_scale) of a weighted sum of eval
    (sky directions, near the horizon, near the sun and inside its disc) against central
    differences (h = 1e-6) within 1e-5 of the leaf's largest component (the complex sun's
    limb darkening makes d/d sun_direction ~1e7 across the disc, and its FD noise ~1e-3):
    the sky's Bezier in the sun's elevation, the
    turbidity and albedo interpolation, the sun's irradiance table in elevation and the
    complex sun's limb darkening all carry derivatives."""
    s = _elev_dir(33.0)
    e = SunSky.create(s, turbidity=3.4, albedo=[0.2, 0.5, 0.7], sun_scale=0.8, sky_scale=1.3,
                      complex_sun=complex_sun)  # fmt: skip
    t = np.cross(s, [0.0, 0.0, 1.0])
    t /= np.linalg.norm(t)
    h = _disc(e.sun_aperture)[1]
    inside = [math.cos(f * h) * s + math.sin(f * h) * t for f in (0.2, 0.6)]
    near = _unit([[1, 0.2, 0.03], [0.3, 1, 0.6], s + 0.05 * t])
    dirs = jnp.asarray(np.concatenate([_upper(N_DIRS - 5, 3), near[:2], np.stack(inside),
                                       near[2:]]))  # fmt: skip
    w = jnp.asarray(np.random.default_rng(4).uniform(0.5, 1.5, (dirs.shape[0], 3)))
    leaves = (e.sun_direction, e.turbidity, e.albedo, e.sun_scale, e.sky_scale)
    grads = _vg_j(leaves, e, dirs, w)[1]
    for i, x in enumerate(leaves):
        flat = np.asarray(x, np.float64).reshape(-1)
        fd = np.zeros_like(flat)
        for j in range(flat.size):
            step = np.zeros_like(flat)
            step[j] = 1e-6
            lp, lm = [*leaves], [*leaves]
            lp[i] = jnp.asarray((flat + step).reshape(np.shape(x)))
            lm[i] = jnp.asarray((flat - step).reshape(np.shape(x)))
            fd[j] = (float(_vg_j(tuple(lp), e, dirs, w)[0])
                     - float(_vg_j(tuple(lm), e, dirs, w)[0])) / 2e-6  # fmt: skip
        ad = np.asarray(grads[i], np.float64).reshape(-1)
        assert np.max(np.abs(ad - fd)) <= 1e-5 * np.max(np.abs(fd)), (i, ad, fd)


# -- hard cases -----------------------------------------------------------------------------

HARD_DIRS = _unit([[0, 0, 1], [1, 0, 0], [0, 1, 0], [0.3, 0.2, -0.5], [0, 0, -1],
                   [1, 1, 1e-7]])  # fmt: skip


@pytest.mark.parametrize("kw", [
    {"sun": (1.0, 0.0, 0.0)},  # exactly on the horizon: black, as Mitsuba
    {"sun": (1.0, 0.0, 1e-6)},  # just above it
    {"sun": (1.0, 0.0, -0.1)},  # below: Mitsuba renders black
    {"sun": (0.0, 0.0, 1.0), "turbidity": 10.0},  # at the zenith
    {"sun": (0.3, 0.1, 0.5), "turbidity": 1.0, "sky_scale": 0.0},
    {"sun": (0.3, 0.1, 0.5), "sun_scale": 0.0, "albedo": 1.0},
    {"sun": (0.3, 0.1, 0.5), "albedo": 0.0, "complex_sun": True},
])  # fmt: skip
def test_hard_cases_values_and_gradients_finite(x64, kw):
    """Values and gradients (all five leaves) finite at the horizon, below it, at the zenith,
    looking straight at the sun (gamma = 0) and away from it (gamma = pi), at turbidity 1 and
    10 and with either scale 0; a sun below or exactly on the horizon (Mitsuba's float32 puts
    it 4e-8 below) gives 0 everywhere. (Values may be
    negative: the sun near the horizon has a negative blue in linear Rec. 709, as in Mitsuba,
    which warns that it leaves them unclamped.)"""
    kw = dict(kw)
    s = np.asarray(kw.pop("sun"))
    e = SunSky.create(s, **kw)
    dirs = np.concatenate([HARD_DIRS, _unit([s, -s])])
    dirs = jnp.asarray(np.concatenate([dirs, _upper(N_DIRS - len(dirs), 5)]))
    val = np.asarray(_eval(e, dirs))
    assert np.all(np.isfinite(val))
    leaves = (e.sun_direction, e.turbidity, e.albedo, e.sun_scale, e.sky_scale)
    g = _vg_j(leaves, e, dirs, jnp.ones((dirs.shape[0], 3)))[1]
    assert all(np.all(np.isfinite(np.asarray(x))) for x in g)
    if s[2] <= 0:
        assert np.all(val == 0)  # (and so the sampler's radiance, eval at its direction)
    elif kw.get("sky_scale", 1.0) > 0:
        assert val[:3].sum() > 0  # the sky is lit


# -- scene descriptions, XML, writer ---------------------------------------------------------


def _desc(**sky):
    return {
        "camera": {"origin": [0, -4, 1.2], "target": [0, 0, 0.4], "up": [0, 0, 1], "fov": 40,
                   "width": 8, "height": 8},  # fmt: skip
        "shapes": [{"type": "sphere", "center": [0, 0, 0.5], "radius": 0.5, "material": "d"},
                   {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 0, 1],
                    "size": [8, 8], "material": "d"}],  # fmt: skip
        "materials": {"d": {"type": "diffuse", "reflectance": 0.5}},
        "emitters": [{"type": "sunsky", **sky}],
    }


@pytest.mark.parametrize("sky, msg", [
    ({"turbidity": 11.0}, r"emitters\[0\]\.turbidity: expected a number in \[1, 10\]"),
    ({"albedo": [0.2, 1.5, 0.1]}, r"emitters\[0\]\.albedo: expected values in \[0, 1\]"),
    ({"sun_scale": -1.0}, r"emitters\[0\]\.sun_scale: expected a non-negative"),
    ({"sun_direction": [0, 0, 1], "hour": 9.0}, r"emitters\[0\]: give either sun_direction"),
    ({"month": 13}, r"emitters\[0\]\.month: expected an integer in \[1, 12\]"),
    ({"year": 2010.5}, r"emitters\[0\]\.year: expected an integer"),
    ({"latitude": 95.0}, r"emitters\[0\]\.latitude: expected degrees in \[-90, 90\]"),
    ({"sun_direction": [0, 0, 0]}, r"emitters\[0\]\.sun_direction: expected a nonzero"),
    ({"sun_aperture": 0.0}, r"emitters\[0\]\.sun_aperture: expected degrees in \(0, 180\)"),
    ({"complex_sun": "yes"}, r"emitters\[0\]\.complex_sun: expected true or false"),
    ({"to_world": np.diag([2.0, 1, 1]).tolist()}, r"emitters\[0\]\.to_world: expected a rotation"),
    ({"sun_size": 1.0}, r"emitters\[0\]: unknown key\(s\) \['sun_size'\]"),
])  # fmt: skip
def test_bad_descriptions_name_the_key(sky, msg):
    with pytest.raises(ValueError, match=msg):
        load_scene(_desc(**sky))
    with pytest.raises(ValueError, match=msg):  # the exporter validates the same way
        to_mitsuba_dict(_desc(**sky))


XML = """<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, -4, 1" target="0, 0, 0" up="0, 0, 1"/>
        </transform><film type="hdrfilm"><integer name="width" value="8"/>
        <integer name="height" value="8"/></film></sensor>
    <shape type="sphere"/>
    <emitter type="sunsky">
        {body}
    </emitter>
</scene>
"""


@pytest.mark.parametrize("body, msg", [
    ('<float name="turbidity" value="0.5"/>', "parameter 'turbidity': expected a number in"),
    ('<rgb name="albedo" value="0.5, 1.2, 0.1"/>', "parameter 'albedo': expected values in"),
    ('<texture type="bitmap" name="albedo"><string name="filename" value="x.png"/></texture>',
     "parameter 'albedo': textures are not supported"),
    ('<vector name="sun_direction" value="0, 0, 1"/>\n<float name="hour" value="9"/>',
     "parameter 'sun_direction': give either sun_direction"),
    ('<integer name="month" value="0"/>', "parameter 'month': expected an integer in"),
    ('<transform name="to_world"><scale value="2"/></transform>',
     "parameter 'to_world': a sunsky's to_world must be a rotation"),
    ('<float name="sun_aperture" value="-1"/>', "parameter 'sun_aperture': expected degrees"),
    ('<float name="sun_radius" value="1"/>', "parameter 'sun_radius' is not supported"),
])  # fmt: skip
def test_bad_xml_names_file_line_and_parameter(tmp_path, body, msg):
    p = tmp_path / "s.xml"
    p.write_text(XML.format(body=body))
    with pytest.raises(ValueError, match=rf"s\.xml:\d+: .*{msg}"):
        read_xml(str(p))


def test_xml_and_writer_round_trip(tmp_path):
    """XML (location / time, albedo, rotation, complex sun) -> load -> save_scene -> read_xml
    -> load: the same leaves; Scene.parameters lists the five leaves; to_mitsuba_dict keeps the
    description's location / time keys (Mitsuba places the sun itself); a replace out of
    range is refused."""
    p = tmp_path / "s.xml"
    p.write_text(XML.format(body="""<float name="hour" value="10.5"/>
        <integer name="month" value="3"/>
        <float name="turbidity" value="6.5"/>
        <rgb name="albedo" value="0.1, 0.2, 0.3"/>
        <boolean name="complex_sun" value="true"/>
        <float name="sun_scale" value="0.5"/>
        <transform name="to_world"><rotate x="1" angle="-90"/></transform>"""))
    x = read_xml(str(p))
    ed = x.desc["emitters"][0]
    assert ed["hour"] == 10.5 and ed["month"] == 3 and "sun_direction" not in ed
    s1 = load_scene(x.desc)
    e1 = s1.environment
    np.testing.assert_allclose(e1.sun_direction, np.asarray(e1.to_world) @ sun_direction_at(
        hour=10.5, month=3), rtol=1e-6, atol=1e-7)  # fmt: skip
    d = to_mitsuba_dict(x.desc)
    md = next(v for v in d.values() if isinstance(v, dict) and v.get("type") == "sunsky")
    assert md["hour"] == 10.5 and md["month"] == 3 and md["complex_sun"] is True
    s2 = load_scene(read_xml(save_scene(s1, str(tmp_path / "w.xml"))).desc)
    e2 = s2.environment
    for k in ("sun_direction", "turbidity", "albedo", "sun_scale", "sky_scale", "to_world"):
        np.testing.assert_allclose(getattr(e2, k), getattr(e1, k), rtol=1e-6, atol=1e-7)
    assert (e2.complex_sun, e2.sun_aperture) == (True, 0.5358)
    assert scene_to_desc(s1)["emitters"][0]["type"] == "sunsky"
    params = [q for q in s1.parameters() if q.path.startswith("emitters")]
    assert [q.bounds for q in params[1:5]] == [(1.0, 10.0), (0.0, 1.0), (0.0, math.inf),
                                                (0.0, math.inf)]  # fmt: skip
    paths = [q.path for q in params]
    assert paths == [f"emitters.environment.{k}" for k in  # (to_world as an envmap's: listed,
                     ("sun_direction", "turbidity", "albedo", "sun_scale", "sky_scale",
                      "to_world")]  # without derivative)
    with pytest.raises(ValueError, match=r"turbidity: expected a number in \[1, 10\]"):
        s1.replace("emitters.environment.turbidity", 11.0)


def _lowered(e):
    return jax.jit(lambda e, d: e.eval(d)).lower(e, jnp.zeros((4, 3))).as_text()


def test_optional_parts_compile_only_when_used():
    """An identity to_world is stored as none (the program is byte-identical to the emitter
    without one); the simple sun's program holds no complex-sun table (10 x 45 x 3 x 4 x 6),
    the complex one's does."""
    s = _elev_dir(20.0)
    plain = SunSky.create(s)
    assert SunSky.create(s, to_world=np.eye(4)).to_world is None
    assert _lowered(SunSky.create(s, to_world=np.eye(3))) == _lowered(plain)
    assert "10x45x3x4x6" not in _lowered(plain)
    assert "10x45x3x4x6" in _lowered(SunSky.create(s, complex_sun=True))


def _meter_loss(x, key, scene):
    s = scene.replace("emitters.environment.turbidity", x)
    return jnp.mean(render(s, key, spp=64, integrator="direct"))


@pytest.mark.slow  # slow: ~55 s on 2 cores at load 5 (compiling the direct integrator + grad)
def test_render_gradient_in_turbidity_equals_finite_differences(x64):
    """Through the renderer: an irradiance meter on a diffuse square under the sunsky (direct
    integrator: sun and sky by light sampling and BSDF sampling with MIS), d mean / d
    turbidity by AD against central differences with the same random numbers (h = 1e-4) for
    4 keys: equal within 1e-6 relative (the sampling density is frozen at creation, so the
    estimator is smooth in turbidity; measured agreement 1e-9)."""
    from jaxgfx.testing import ad_fd_per_key

    rect = {"type": "rectangle", "center": [0, 0, 0], "normal": [0, 0, 1], "size": [1, 1]}
    scene = load_scene({
        "camera": {"type": "irradiancemeter", "shape": {**rect, "center": [0, 0, 0.001]}},
        "shapes": [{**rect, "material": "d"}],
        "materials": {"d": {"type": "diffuse", "reflectance": 0.5}},
        "emitters": [{"type": "sunsky", "sun_direction": [0.5, 0.2, 0.8], "turbidity": 3.4}],
    })  # fmt: skip
    _, ad, fd = ad_fd_per_key(_meter_loss, jnp.asarray(3.4), jax.random.split(jax.random.key(0),
                              4), 1e-4, args=(scene,))  # fmt: skip
    assert np.all(np.abs(ad) > 0.01)
    np.testing.assert_allclose(ad, fd, rtol=1e-6)
