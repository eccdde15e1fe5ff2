"""The fit's camera (issue 25): any CameraResponse in the chain, response files, several
photos, texture priors. Default tests never compile a fit step (the loss is called on tiny
arrays or traced with jax.eval_shape); end-to-end fits are slow-marked."""

import functools
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx import hdr
from jaxgfx.pipelines.fit import level_table, prepare_fit
from jaxgfx.pipelines.fit.camera import code_levels, fit_level_table, free_init, free_response
from jaxgfx.pipelines.fit.loss import censored_linear_loss, photo_gains, texture_prior

from ._helpers import fit_cfg

# the shared small fit, from a bracket of three synthetic photos through a camera curve,
# fitted through sRGB
CAMERA_FIT = {
    "target": {"synthetic": {"materials.metal.alpha": 0.15}, "spp": 16,
               "camera": {"response": "camera", "exposures": [0.5, 1.0, 2.0]}},
    "camera": {"response": {"model": "srgb"}},
}  # fmt: skip
_cfg = functools.partial(fit_cfg, CAMERA_FIT)


# ------------------------------------------------------------------ response files (hdr)


def _assert_same_response(q, r):
    assert (q.kind, q.method, q.code_max, q.anchor) == (r.kind, r.method, r.code_max, r.anchor)
    assert q.params.dtype == r.params.dtype
    np.testing.assert_array_equal(np.asarray(q.params), np.asarray(r.params))
    assert set(q.diagnostics) == set(r.diagnostics)
    for k in r.diagnostics:
        np.testing.assert_array_equal(np.asarray(q.diagnostics[k]), np.asarray(r.diagnostics[k]))
    z = jnp.linspace(0, 255, 7)[:, None]
    np.testing.assert_array_equal(np.asarray(q.to_linear(z)), np.asarray(r.to_linear(z)))


# 3.3 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_response_file_round_trips_exactly(tmp_path):
    """Bit-identical arrays (float32 values that no short decimal represents) and fields."""
    rng = np.random.default_rng(0)
    table = np.cumsum(rng.uniform(0.001, 0.1, (256, 3)), axis=0).astype(np.float32) - 5.0
    r = hdr.CameraResponse(jnp.asarray(table), "table", "debevec", 255.0, 0.5,
                           jnp.asarray([1.0, 3.9999, 16.0001], jnp.float32),
                           {"residual_rms": jnp.asarray(rng.uniform(size=3), jnp.float32)})
    q = hdr.load_response(hdr.save_response(tmp_path / "c.json", r), bits=8)
    _assert_same_response(q, r)
    np.testing.assert_array_equal(np.asarray(q.exposure_ratios), np.asarray(r.exposure_ratios))
    p = hdr.CameraResponse(jnp.asarray(rng.normal(size=(6, 3)), jnp.float32), "polynomial",
                           "polynomial", 65535.0, 1.0)
    _assert_same_response(hdr.load_response(hdr.save_response(tmp_path / "p.json", p),
                                            bits=16), p)


# cost: ~40 s at load 5 on 2 cores (compiles the Debevec and polynomial recoveries)
@pytest.mark.slow
@pytest.mark.parametrize("method", ["debevec", "polynomial"])
def test_recovered_response_round_trips_exactly(tmp_path, method):
    key = jax.random.key(0)
    rad = hdr.synthetic_radiance(key, 16, 16, dynamic_range=100.0)
    st = hdr.make_bracketed_stack(key, rad, 4.0 ** jnp.arange(-1, 2), hdr.synthetic_response(
        "camera"))
    r = hdr.recover_response(st.images, st.exposure_times, method=method, n_samples=64)
    _assert_same_response(hdr.load_response(hdr.save_response(tmp_path / "c.json", r), bits=8),
                          r)


def test_load_response_reads_a_calibrate_report(tmp_path):
    """The summary that `jaxgfx calibrate` writes today (report.json 'response.summary')."""
    table = np.linspace(-5, 1, 256, dtype=np.float32)[:, None] * np.ones(3, np.float32)
    rep = {"response": {"method": "debevec", "summary": {
        "params": table.tolist(), "kind": "table", "method": "debevec", "code_max": 255.0,
        "anchor": 0.5}}}
    (tmp_path / "report.json").write_text(json.dumps(rep))
    r = hdr.load_response(tmp_path / "report.json", bits=8)
    assert r.kind == "table" and r.params.shape == (256, 3)
    np.testing.assert_array_equal(np.asarray(r.params), table)
    # to_linear at the anchor (level 127.5) is 1 by construction
    np.testing.assert_allclose(np.asarray(r.to_linear(jnp.full((1, 3), 127.5))), 1.0, rtol=1e-6)


def test_response_file_errors_name_the_file(tmp_path):
    with pytest.raises(FileNotFoundError, match="response file not found: .*nope.json"):
        hdr.load_response(tmp_path / "nope.json")
    p = hdr.save_response(tmp_path / "r16.json", hdr.CameraResponse.gamma(2.2, code_max=65535.0))
    with pytest.raises(ValueError, match=r"r16.json: a 16-bit response .* 8-bit photos"):
        hdr.load_response(p, bits=8)
    (tmp_path / "bad.json").write_text("{not json")
    with pytest.raises(ValueError, match="bad.json: not a JSON response file"):
        hdr.load_response(tmp_path / "bad.json")
    (tmp_path / "raw.json").write_text(json.dumps({"raw_calibration": {}}))
    with pytest.raises(ValueError, match="raw.json: neither a response file"):
        hdr.load_response(tmp_path / "raw.json")


# ------------------------------------------------------------------------- level tables


# 4.0 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_level_table_matches_closed_forms():
    """G[q] = ln f⁻¹(q/255) (unit anchor): gamma z^γ, the sRGB EOTF; slots 0 and 255 are the
    half-codes ½ and 254.5."""
    z = code_levels(8).astype(np.float64) / 255.0
    g = np.asarray(level_table(hdr.CameraResponse.gamma(2.0, anchor="unit"), 8))[:, 0]
    np.testing.assert_allclose(g, 2.0 * np.log(z), rtol=1e-5, atol=1e-5)
    s = np.asarray(level_table(hdr.CameraResponse.analytic("srgb", anchor="unit"), 8))[:, 0]
    lin = np.where(z <= 0.04045, z / 12.92, ((z + 0.055) / 1.055) ** 2.4)
    np.testing.assert_allclose(s, np.log(lin), rtol=1e-5, atol=1e-5)
    # an anchor-'mid' Debevec-style table: the Camera convention x(1) = 1 holds whatever anchor
    t = hdr.CameraResponse(jnp.linspace(-4.0, 1.0, 256)[:, None], "table", "x", 255.0, 0.5)
    gt = np.asarray(level_table(t, 8))[:, 0]
    np.testing.assert_allclose(gt[128], (-4.0 + 5.0 * 128 / 255) - 1.0, atol=1e-5)


def test_free_response_is_monotone_and_starts_at_its_curve():
    u = jax.random.normal(jax.random.key(1), (32, 1)) * 3.0
    g = np.asarray(free_response(u).params)[:, 0]
    assert np.all(np.diff(g) > 0) and g[-1] == 0.0
    srgb = hdr.CameraResponse.analytic("srgb", anchor="unit")
    u0 = free_init(srgb, 33, 1)
    zn = jnp.asarray(np.arange(10, 246) / 255.0)[:, None]
    err = hdr.response_curve_error(free_response(jnp.asarray(u0)), srgb)
    assert float(err) < 0.01  # 33 uniform knots, piecewise linear in ln x
    del zn


def test_fit_level_table_blends_one_slot():
    fixed = level_table(hdr.CameraResponse.analytic("camera", anchor="unit"), 8)
    cam_p = {"gamma": jnp.asarray(1.8), "curve": jnp.asarray(free_init(
        hdr.CameraResponse.gamma(2.2, anchor="unit"), 9, 1))}
    free = {"gamma": 1.0, "curve": 1.0}
    for k, ref in (
        (0, level_table(hdr.CameraResponse.gamma(1.8, anchor="unit"), 8)),
        (1, fixed),
        (2, level_table(free_response(cam_p["curve"]), 8)),
    ):
        w = jnp.zeros(3).at[k].set(1.0)
        got = fit_level_table(cam_p, {"weights": w, "fixed": fixed, "free": free}, 8)
        np.testing.assert_allclose(np.asarray(got), np.asarray(ref), rtol=1e-6, atol=1e-6)


# ------------------------------------------------------------------------------ the loss


def test_censored_linear_loss_is_zero_at_the_truth_for_any_response():
    """Codes made through a response at exposure e: the linearised-and-censored loss of the
    radiance that made them is ~0 (quantisation only), a 10 % brighter one is not; the
    censored (clipped) pixels cost nothing."""
    rng = np.random.default_rng(0)
    rad = rng.uniform(0.01, 3.0, (1, 6, 6, 3)).astype(np.float32)[0]
    for resp in (hdr.CameraResponse.analytic("camera", anchor="unit"),
                 hdr.CameraResponse.gamma(2.4, anchor="unit")):
        e = np.asarray([0.5, 2.0], np.float32)
        codes = np.stack([np.asarray(hdr.Camera(resp, jnp.asarray(ei), bits=8).capture(rad))
                          for ei in e]).astype(np.float32)
        assert (codes == 255).any()
        table = level_table(resp, 8)
        gain = e[:, None] * np.ones(3, np.float32)
        v0 = float(censored_linear_loss(jnp.asarray(rad), jnp.asarray(codes), table, gain, 255.0))
        v1 = float(censored_linear_loss(jnp.asarray(rad * 1.1), jnp.asarray(codes), table, gain,
                                        255.0))
        assert v0 < 2e-4 and v1 > 20 * v0


# 7.2 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_clip_code_censors_a_jpeg_rung_highlight():
    """A highlight 4x above the clip level, photographed and JPEG-compressed (quality 90,
    4:2:0): its clipped codes ring down to ~235-254. Read as exact values (the default, only
    255 censored) they say the true radiance is far too dark; with ``clip_code`` every code >= k
    only bounds it from below at ``f^-1((k - 1/2)/255)``, and the true radiance costs no more
    than the JPEG error of the rest of the photo."""
    resp = hdr.CameraResponse.analytic("camera", anchor="unit")
    rad = np.full((16, 16, 3), 0.2, np.float32)
    rad[4:12, 4:12] = 4.0
    rad[:, :, 2] = np.linspace(0.05, 0.6, 16)[None, :]
    codes = np.asarray(hdr.Camera(resp, jnp.asarray(1.0), bits=8).capture(rad))
    jpeg = hdr.jpeg_roundtrip(codes[None], quality=90).astype(np.float32)
    hi = rad[None] >= 1.0
    assert ((jpeg < 255) & (jpeg >= 235) & hi).any()  # rung: clipped but not 255
    table = level_table(resp, 8)
    img = jnp.asarray(rad)

    def loss(k, im=img):
        return float(censored_linear_loss(im, jnp.asarray(jpeg), table, 1.0, 255.0, None, k))

    floor = float(censored_linear_loss(img, jnp.asarray(jpeg) * ~hi, table, 1.0, 255.0))
    assert loss(None) > 10 * loss(230) and loss(255) == loss(None)
    assert loss(230) < 1.5 * floor
    # the bound is f^-1 at k - 1/2: a render just below it costs, just above it does not
    cam = hdr.Camera(resp, jnp.asarray(1.0), bits=8, clip=False)
    b = float(cam.linearize(jnp.full((3,), 239.5))[0])
    one = jnp.asarray(jpeg[:, 8:9, 8:9, :1])
    assert float(one[0, 0, 0, 0]) >= 240
    t1 = table[:, :1]
    f = lambda v: float(censored_linear_loss(jnp.full((1, 1, 1), v), one, t1, 1.0, 255.0,
                                             None, 240))
    assert f(1.001 * b) == 0.0 and f(0.99 * b) > 0.0
    g = jax.grad(lambda im: censored_linear_loss(im, jnp.asarray(jpeg), table, 1.0, 255.0,
                                                 None, jnp.asarray(240)))(img)
    assert np.all(np.isfinite(np.asarray(g)))


# 4.1 s on a quiet 2-core machine: make test-slow (the default run keeps its cheaper siblings)
@pytest.mark.slow
def test_clipped_unmeasured_drops_only_bounds_another_photo_measures():
    """Two photos (gains 1 and 8) of radiance 0.05 / 0.5: pixel 1 clips in the bright photo
    only, pixel 0 in none. A render too dark at pixel 1 pays its bound in the bright photo by
    default; with ``unmeasured_only`` that term is dropped (the dark photo measures the pixel)
    and the loss equals the dark photo's term alone. A pixel clipped in both keeps its bound."""
    resp = hdr.CameraResponse.gamma(2.2, anchor="unit")
    table = level_table(resp, 8)
    rad = np.asarray([[[0.05], [0.5], [4.0]]], np.float32)  # (1, 3, 1)
    gains = np.asarray([[1.0], [8.0]], np.float32)
    codes = np.stack([np.asarray(hdr.Camera(resp, jnp.asarray(g[0]), bits=8).capture(rad))
                      for g in gains]).astype(np.float32)
    assert codes[:, 0, :, 0].tolist() == [[int(codes[0, 0, 0, 0]), int(codes[0, 0, 1, 0]), 255],
                                          [int(codes[1, 0, 0, 0]), 255, 255]]
    img = jnp.asarray(rad * np.asarray([1.0, 0.02, 1.0], np.float32)[None, :, None])

    def loss(um, im=img):
        return float(censored_linear_loss(im, jnp.asarray(codes), table[:, :1], gains, 255.0,
                                          None, None, um))

    dark = float(censored_linear_loss(img, jnp.asarray(codes[0]), table[:, :1], gains[0],
                                      255.0))
    bright = float(censored_linear_loss(img, jnp.asarray(codes[1]), table[:, :1], gains[1],
                                        255.0))
    assert bright > 0.1 and loss(0.0) == pytest.approx(dark + bright, rel=1e-5)
    assert loss(1.0) == pytest.approx(dark, rel=1e-5)
    # pixel 2 is clipped in both photos: a render below its bound still pays with unmeasured
    low = img.at[0, 2, 0].set(0.01)
    assert loss(1.0, low) > loss(1.0) + 0.01


def test_auto_exposure_recovers_the_exposure_of_a_clipped_bracket():
    """Photos of a render through the calibrated-like camera at exposure 0.126 x (1, 4, 16)
    (clipped, quantised): ``auto_exposure`` finds 0.126 within 2 %, where a fixed start of 1
    is 8x off (the camera_chain calibrated fit then falls into a rough, dark basin)."""
    from jaxgfx.pipelines.fit.job import auto_exposure

    rng = np.random.default_rng(1)
    img = rng.uniform(0.02, 5.0, (12, 12, 3)).astype(np.float32)
    img[0, 0] = 0.0
    resp = hdr.CameraResponse.analytic("camera", anchor="unit")
    e, r = 0.126, np.asarray([1.0, 4.0, 16.0])
    codes = np.stack([np.asarray(hdr.Camera(resp, jnp.asarray(e * ri), bits=8).capture(img))
                      for ri in r]).astype(np.float32)
    assert (codes == 255).mean() > 0.3
    got = auto_exposure(img, codes, level_table(resp, 8), r, 255.0)
    assert abs(got / e - 1) < 0.02
    with pytest.raises(ValueError, match="camera.exposure.auto"):
        auto_exposure(img, np.full_like(codes, 255.0), level_table(resp, 8), r, 255.0)


def test_photo_gains_and_texture_priors_closed_forms():
    cam_p = {"exposure": jnp.asarray(2.0), "photo_exposure": jnp.asarray([1.0, 4.0]),
             "white_balance": jnp.asarray([1.5, 1.0, 0.5])}
    free = {"exposure": 1.0, "photo_exposure": jnp.asarray([0.0, 1.0]),
            "white_balance": jnp.asarray([1.0, 0.0, 1.0])}
    g = np.asarray(photo_gains(cam_p, {"free": free}, 3))
    np.testing.assert_allclose(g, [[3.0, 2.0, 1.0], [12.0, 8.0, 4.0]])
    # gradients only where free
    d = jax.grad(lambda p: photo_gains(p, {"free": free}, 3).sum())(cam_p)
    assert float(d["photo_exposure"][0]) == 0.0 and float(d["white_balance"][1]) == 0.0
    # TV of a ramp of slope s in x: mean |grad| = s (ε-corrected); Laplacian of a ramp = 0
    x = jnp.tile(jnp.arange(5.0)[None, :, None] * 0.1, (4, 1, 1))
    assert float(texture_prior(x, "tv")) == pytest.approx(np.sqrt(0.01 + 1e-6) - 1e-3, rel=1e-5)
    assert float(texture_prior(x, "laplacian")) == pytest.approx(0.0, abs=1e-9)
    y = x.at[2, 2, 0].add(1.0)  # a spike: Laplacian -4 there, +1 at its 3 interior neighbours
    assert float(texture_prior(y, "laplacian")) == pytest.approx((16 + 3) / 6, rel=1e-5)


# cost: 29 s at load 8 (float64 gradients through four camera variants); the default run keeps
# test_zero_and_saturated_photos_give_finite_gradients and the closed forms
@pytest.mark.slow
def test_loss_gradients_match_finite_differences(x64):
    """d loss / d (exposure, gamma, curve) of the censored linear loss, float64."""
    rng = np.random.default_rng(2)
    img = jnp.asarray(rng.uniform(0.02, 2.0, (5, 5, 3)))
    resp = hdr.CameraResponse.analytic("camera", anchor="unit")
    codes = jnp.asarray(np.stack([
        np.asarray(hdr.Camera(resp, jnp.asarray(e), bits=8).capture(img * 1.2))
        for e in (0.5, 1.5)]).astype(np.float64))
    args = {"weights": jnp.asarray([0.0, 0.0, 1.0]), "fixed": jnp.zeros((256, 3)),
            "free": {"gamma": 1.0, "curve": 1.0, "exposure": 1.0,
                     "photo_exposure": jnp.asarray([0.0, 1.0]),
                     "white_balance": jnp.asarray([1.0, 0.0, 1.0])}}
    p0 = {"exposure": jnp.asarray(1.1), "photo_exposure": jnp.asarray([1.0, 3.0]),
          "white_balance": jnp.asarray([1.0, 1.0, 1.0]), "gamma": jnp.asarray(2.2),
          "curve": jnp.asarray(free_init(hdr.CameraResponse.analytic("srgb", anchor="unit"),
                                         9, 1), jnp.float64)}

    @jax.jit
    def f(p):
        table = fit_level_table(p, args, 8)
        return censored_linear_loss(img, codes, table, photo_gains(p, args, 3), 255.0)

    table_of = jax.jit(lambda p: fit_level_table(p, args, 8))

    # the loss normalises each photo by its mean linearised target *without* a gradient (a
    # scale, not a term to minimise): the reference is that loss with the scales frozen at p0
    def lin(p):
        table = np.asarray(table_of(p))
        q = np.asarray(codes).astype(int)
        gain = np.asarray(photo_gains(p, args, 3))
        return np.exp(table[q, np.arange(3)]) / gain[:, None, None, :], q

    t0, _ = lin(p0)
    scale = t0.mean(axis=(1, 2, 3)) + 1e-6

    def ref(p):
        t, q = lin(p)
        x = np.asarray(img)
        e = np.where(q >= 255, np.maximum(t - x, 0), np.where(q <= 0, np.maximum(x - t, 0),
                                                               x - t))
        return float(np.sum((e * e).mean(axis=(1, 2, 3)) / scale**2))

    assert float(f(p0)) == pytest.approx(ref(p0), rel=1e-10)
    g = jax.grad(f)(p0)
    for name, idx in (("exposure", ()), ("photo_exposure", (1,)), ("white_balance", (0,)),
                      ("curve", (3, 0)), ("curve", (7, 0))):
        h = 1e-6
        pp, pm = dict(p0), dict(p0)
        pp[name] = p0[name].at[idx].add(h)
        pm[name] = p0[name].at[idx].add(-h)
        fd = (ref(pp) - ref(pm)) / (2 * h)
        assert abs(fd) > 1e-4, name
        assert float(g[name][idx]) == pytest.approx(fd, rel=1e-5), name


def test_zero_and_saturated_photos_give_finite_gradients():
    img = jnp.zeros((4, 4, 3)).at[0, 0].set(50.0)
    codes = jnp.zeros((2, 4, 4, 3)).at[1].set(255.0)
    table = level_table(hdr.CameraResponse.analytic("camera-offset", anchor="unit"), 8)
    g = jax.grad(lambda im, t: censored_linear_loss(im, codes, t, 1.0, 255.0),
                 argnums=(0, 1))(img, table)
    assert all(np.all(np.isfinite(np.asarray(x))) for x in g)


# ------------------------------------------------------------------- config and targets


def test_a_bracket_config_prepares_without_rendering():
    prep = prepare_fit(_cfg())
    assert prep.ldr and prep.n_targets == 3
    np.testing.assert_allclose(prep.exposures, [1.0, 2.0, 4.0])
    assert prep.fixed_response.kind == "srgb"


def test_response_from_a_file_is_loaded_and_checked(tmp_path):
    p = hdr.save_response(tmp_path / "cam.json", hdr.CameraResponse.gamma(
        2.0, channels=3, code_max=255.0))
    prep = prepare_fit(_cfg(camera={"response": {"from": "cam.json"}}), base_dir=str(tmp_path))
    assert prep.fixed_response.kind == "gamma"
    with pytest.raises(FileNotFoundError, match="camera.response.from: file not found"):
        prepare_fit(_cfg(camera={"response": {"from": "nope.json"}}), base_dir=str(tmp_path))
    p16 = hdr.save_response(tmp_path / "c16.json", hdr.CameraResponse.gamma(
        2.0, code_max=65535.0))
    with pytest.raises(ValueError, match="c16.json: a 16-bit response"):
        prepare_fit(_cfg(camera={"response": {"from": str(p16)}}))
    # from + fit: a free-form table started from the loaded curve
    cfg = _cfg(camera={"response": {"from": str(p), "fit": True}})
    assert cfg.camera.response.model == "table" and cfg.camera.response.curve_kind == "free"


def _photos(tmp_path, sizes, exif=None):
    from PIL import Image

    paths = []
    for i, (w, h) in enumerate(sizes):
        a = np.full((h, w, 3), 40 + 30 * i, np.uint8)
        p = tmp_path / f"p{i}.jpg"
        img = Image.fromarray(a)
        if exif is not None:
            ex = Image.Exif()
            ex[0x829A] = exif[i]
            img.save(p, exif=ex)
        else:
            img.save(p)
        paths.append(str(p))
    return paths


def test_a_bracket_of_files_needs_exposures_and_one_size(tmp_path):
    paths = _photos(tmp_path, [(8, 8), (8, 8)])
    cam = {"response": {"model": "srgb"}}
    with pytest.raises(ValueError, match=r"target\[0\]: .*p0.jpg: no exposure information"):
        prepare_fit(_cfg(target=paths, camera=cam))
    prep = prepare_fit(_cfg(target=[{"file": paths[0], "exposure": 0.01},
                                    {"file": paths[1], "exposure": 0.04}], camera=cam))
    np.testing.assert_allclose(prep.exposures, [1.0, 4.0])
    bad = _photos(tmp_path / "..", [(8, 8), (9, 8)])
    with pytest.raises(ValueError, match=r"target\[1\]: .*size 9x8 .* differs .* 8x8"):
        prepare_fit(_cfg(target=[{"file": b, "exposure": 1.0} for b in bad], camera=cam))


def test_exif_exposures_are_read(tmp_path):
    paths = _photos(tmp_path, [(8, 8), (8, 8)], exif=[0.002, 0.008])
    prep = prepare_fit(_cfg(target=paths, camera={"response": {"model": "srgb"}}))
    np.testing.assert_allclose(prep.exposures, [1.0, 4.0], rtol=1e-6)


def test_prior_and_lr_checks():
    with pytest.raises(ValueError, match=r"params.materials.metal.alpha.prior: a smoothness "
                       r"prior needs a texel grid"):
        prepare_fit(_cfg(params={"materials.metal.alpha": {"init": 0.5, "prior": {"tv": 1.0}}}))
    with pytest.raises(ValueError, match=r"params.materials.metal.alpha.*prior"):
        prepare_fit(_cfg(params={"materials.metal.alpha": {"prior": {"smooth": 1.0}}}))
    with pytest.raises(ValueError, match=r"params.materials.metal.alpha.*lr: expected a positive"):
        prepare_fit(_cfg(params={"materials.metal.alpha": {"lr": -1.0}}))


def test_camera_config_errors():
    with pytest.raises(ValueError, match=r"camera.response.fit: only 'gamma'"):
        _cfg(camera={"response": {"model": "srgb", "fit": True}})
    with pytest.raises(ValueError, match=r"camera.response.init"):
        _cfg(camera={"response": {"model": "table", "fit": True, "init": "cubic"}})
    with pytest.raises(ValueError, match=r"target.camera.exposures\[1\]"):
        prepare_fit(_cfg(target={"synthetic": {}, "camera": {"exposures": [1.0, -2.0]}}))
    with pytest.raises(ValueError, match=r"target.camera.jpeg"):
        prepare_fit(_cfg(target={"synthetic": {}, "camera": {"jpeg": 101}}))
    for bad in (256, 1, 2.5, True):
        with pytest.raises(ValueError, match=r"camera.clip_code: expected an integer"):
            _cfg(camera={"response": "srgb", "clip_code": bad})


# cost: 45 s at load 10 on 2 cores (traces the render's gradient four times, no compile)
@pytest.mark.slow
def test_fit_step_traces_for_every_camera_variant_with_one_structure(tmp_path):
    """gamma, fixed (analytic and loaded) and free-form cameras give arguments of one
    structure and shape, so one compiled fit step serves them all (jax.eval_shape: traced,
    not compiled)."""
    from jaxgfx.pipelines.fit.job import _initial, _target
    from jaxgfx.pipelines.fit.loss import cached_loss

    p = hdr.save_response(tmp_path / "cam.json", hdr.CameraResponse.gamma(
        2.0, channels=3, code_max=255.0))
    cams = [
        {"response": {"model": "gamma", "fit": True}, "exposure": {"fit": True}},
        {"response": {"model": "camera"}},
        {"response": {"from": str(p)}, "exposure": {"fit": True, "per_photo": True}},
        {"response": {"model": "table", "fit": True, "init": "srgb"},
         "white_balance": {"fit": True}},
    ]
    shapes, losses = set(), set()
    prep = prepare_fit(_cfg())
    target = _target(_cfg(), prep)[0]
    assert target.pixels.shape == (3, 8, 8, 3)
    for cam in cams:
        cfg = _cfg(camera=cam)
        prep = prepare_fit(cfg)
        params, _, cam_args = _initial(cfg, prep)
        loss = cached_loss(cfg, prep.paths, True)
        args = (prep.scene, jnp.asarray(target.pixels), cam_args)
        val, grad = jax.eval_shape(jax.value_and_grad(loss), params, jax.random.key(0), args)
        assert val.shape == ()
        shapes.add(str(jax.tree.map(lambda a: (a.shape, a.dtype), (params, cam_args))))
        losses.add(id(loss))
    assert len(shapes) == 1 and len(losses) == 1
