"""A camera's picture style in the fit (issue 25): a 3x3 colour matrix and a global tone curve
between the sensor and the response. Default tests run the loss on small arrays (no render);
end-to-end fits through the renderer are slow-marked."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx import hdr
from jaxgfx.pipelines.fit import prepare_fit
from jaxgfx.pipelines.fit.camera import (
    level_table,
    photo_matrix,
    tone_level_table,
    white_preserving,
)
from jaxgfx.pipelines.fit.loss import photo_losses

from ._helpers import fit_cfg

M_TRUE = [[1.45, -0.3, -0.15], [-0.2, 1.35, -0.15], [0.05, -0.4, 1.35]]  # rows sum to 1
STYLE_FIT = {
    "target": {"synthetic": {"materials.metal.alpha": 0.15}, "spp": 16,
               "camera": {"response": "srgb", "color_matrix": M_TRUE,
                          "tonemap": {"op": "filmic", "exposure": 1.0}}},
    "camera": {"response": {"model": "srgb"}, "color_matrix": M_TRUE,
               "tonemap": {"op": "filmic", "exposure": 1.0}},
}  # fmt: skip
_cfg = functools.partial(fit_cfg, STYLE_FIT)


def _aces(x):  # Narkowicz (2015), the published coefficients
    return x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)


def _reinhard(lm, w):  # Reinhard et al. (2002) eq. 4
    return lm * (1.0 + lm / (w * w)) / (1.0 + lm)


# ------------------------------------------------------------------------- tone curves


def test_tone_curves_match_the_published_curves_and_invert_exactly(x64):
    y = jnp.linspace(0.0, 1.3, 27)
    cases = [
        ("filmic", {"exposure": 0.7}, lambda y: _aces(0.18 * 2**0.7 * y) / _aces(0.18 * 2**0.7)),
        ("reinhard", {"key": 2.5, "white": 1.7},
         lambda y: _reinhard(2.5 * y, 1.7) / _reinhard(2.5, 1.7)),
    ]  # fmt: skip
    for op, p, ref in cases:
        tc = hdr.ToneCurve(op, {k: jnp.asarray(v) for k, v in p.items()})
        t = jax.jit(lambda c, y: c(y))(tc, y)
        np.testing.assert_allclose(np.asarray(t), ref(np.asarray(y)), rtol=1e-12, atol=1e-15)
        assert float(t[0]) == 0.0 and np.all(np.diff(np.asarray(t)) > 0)
        assert float(tc(jnp.ones(()))) == pytest.approx(1.0, rel=1e-14)  # the clip level
        np.testing.assert_allclose(
            np.asarray(jax.jit(lambda c, t: c.inverse(t))(tc, t)),
            np.asarray(y),
            rtol=1e-12,
            atol=1e-15,
        )


def test_tone_inverse_gradients_are_finite_at_black_and_white(x64):
    for op, p in (("filmic", {"exposure": 0.0}), ("reinhard", {"key": 0.18, "white": 4.0})):

        def f(t, p, op=op):
            return jnp.sum(hdr.ToneCurve(op, p).inverse(t))

        p = {k: jnp.asarray(v) for k, v in p.items()}
        g = jax.grad(f, argnums=(0, 1))(jnp.asarray([0.0, 1e-30, 1.0]), p)
        assert all(np.all(np.isfinite(np.asarray(x))) for x in jax.tree.leaves(g))


def test_camera_with_a_picture_style_round_trips():
    tone = hdr.ToneCurve("reinhard", {"key": jnp.asarray(1.5), "white": jnp.asarray(2.0)})
    cam = hdr.Camera(
        hdr.CameraResponse.analytic("srgb", anchor="unit"),
        jnp.asarray(0.8),
        white_balance=jnp.asarray([1.2, 1.0, 0.9]),
        bits=None,
        color_matrix=jnp.asarray(M_TRUE),
        tone=tone,
    )
    rad = jnp.asarray(np.random.default_rng(0).uniform(0.3, 0.9, (6, 3)), jnp.float32)
    z = cam.display(rad)
    # the forward chain written out: y = M (0.8 wb L), t = T(y), z = sRGB OETF(t)
    y = np.maximum((0.8 * np.asarray([1.2, 1.0, 0.9]) * np.asarray(rad)) @ np.asarray(M_TRUE).T, 0)
    t = _reinhard(1.5 * y, 2.0) / _reinhard(1.5, 2.0)
    srgb = np.where(t <= 0.0031308, 12.92 * t, 1.055 * t ** (1 / 2.4) - 0.055)
    np.testing.assert_allclose(np.asarray(z), srgb, rtol=2e-5, atol=2e-6)
    np.testing.assert_allclose(np.asarray(cam.linearize(z)), np.asarray(rad), rtol=2e-4)
    with pytest.raises(ValueError, match=r"color_matrix: expected a \(3, 3\) matrix"):
        hdr.Camera(cam.response, jnp.asarray(1.0), color_matrix=jnp.eye(2))
    with pytest.raises(ValueError, match=r"params: the 'reinhard' tone curve takes"):
        hdr.ToneCurve("reinhard", {"key": 1.0})
    with pytest.raises(ValueError, match=r"params.white: expected a value > 0"):
        hdr.ToneCurve("reinhard", {"key": 1.0, "white": -1.0})


def test_white_preserving_matrix_keeps_grey():
    p = jnp.asarray(np.random.default_rng(1).normal(size=(3, 3)))
    m = white_preserving(p, 1.0)
    np.testing.assert_allclose(np.asarray(m @ jnp.ones(3)), 1.0, rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(white_preserving(p, 0.0)), np.asarray(p))
    # the diagonal of P does not move M (its gradient is zero)
    g = jax.grad(lambda p: jnp.sum(white_preserving(p, 1.0) * jnp.arange(9.0).reshape(3, 3)))(p)
    np.testing.assert_allclose(np.diag(np.asarray(g)), 0.0, atol=1e-6)


# ------------------------------------------------------------------------------ the loss


def _style_problem(tone_op, tone_p, bits=16, n=6):
    """A linear 'render' and its photo through the full chain (known truth), the fit's
    arguments at the truth."""
    rng = np.random.default_rng(3)
    img = jnp.asarray(rng.uniform(0.05, 0.8, (n, n, 3)))
    resp = hdr.CameraResponse.analytic("srgb", anchor="unit")
    tone = hdr.ToneCurve(tone_op, {k: jnp.asarray(v) for k, v in tone_p.items()})
    wb = jnp.asarray([1.3, 1.0, 0.8])
    codes = jnp.stack(
        [
            hdr.Camera(
                resp,
                jnp.asarray(e),
                white_balance=wb,
                bits=bits,
                color_matrix=jnp.asarray(M_TRUE),
                tone=tone,
            )
            .capture(img)
            .astype(jnp.float64)
            for e in (0.5, 0.9)
        ]
    )  # fmt: skip (below the sensor's clip: 0.9 · 1.3 · 0.8 < 1)
    p = {
        "exposure": jnp.asarray(0.5),
        "photo_exposure": jnp.asarray([1.0, 1.8]),
        "white_balance": wb,
        "gamma": jnp.asarray(2.2),
        "curve": jnp.zeros((8, 1)),
        "color_matrix": jnp.asarray(M_TRUE),
        "tone": {k: jnp.asarray(v) for k, v in tone_p.items()},
    }
    args = {
        "weights": jnp.asarray([0.0, 1.0, 0.0]),
        "fixed": jnp.broadcast_to(level_table(resp, bits, jnp.float64), (2**bits, 3)),
        "free": {
            "gamma": 0.0,
            "curve": 0.0,
            "exposure": 1.0,
            "photo_exposure": jnp.asarray([0.0, 1.0]),
            "white_balance": jnp.asarray([1.0, 0.0, 1.0]),
            "color_matrix": 1.0,
            "tone": {k: 1.0 for k in tone_p},
        },
        "white_preserving": 1.0,
    }
    cfg = fit_cfg(
        STYLE_FIT,
        camera={
            "response": "srgb",
            "bits": bits,
            "color_matrix": {"init": M_TRUE, "fit": True},
            "tonemap": {"op": tone_op, **tone_p, "fit": True},
        },
    )
    return cfg, img, codes, p, args


def _style_loss(cfg, img, codes, args, bits, frozen_at=None):
    """The summed loss; ``frozen_at``: the same with each photo's normalising scale (its mean
    linearised target, taken without gradient by the loss) frozen at those parameters — the
    function whose finite differences the loss's gradient is."""
    from jaxgfx.pipelines.fit.camera import fit_level_table
    from jaxgfx.pipelines.fit.loss import photo_gains

    def scale(p, table):
        q = codes.astype(jnp.int32)
        t = jnp.exp(table[q, jnp.arange(3)]) / photo_gains(p, args, 3, False)[:, None, None]
        return jnp.mean(t, axis=(1, 2, 3)) + 1e-6

    def f(p):
        table = fit_level_table(p, args, bits, cfg.camera.tone_op)
        terms = photo_losses(cfg, True, img, codes, p, args, table)
        if frozen_at is not None:
            s0 = scale(frozen_at, fit_level_table(frozen_at, args, bits, cfg.camera.tone_op))
            terms = terms * (scale(p, table) / s0) ** 2
        return jnp.sum(terms)

    return jax.jit(f)


# slow: ~10 s at load 11 on 2 cores (two float64 loss programs)
@pytest.mark.slow
def test_the_full_chain_is_linearised_to_the_truth(x64):
    """16-bit photos through matrix + tone curve + sRGB: at the true camera the loss is the
    quantisation's only (< 1e-9, relative), a 5 % error in one matrix entry or the tone
    parameter costs > 1e3 times more."""
    for op, tp in (("filmic", {"exposure": 1.0}), ("reinhard", {"key": 2.0, "white": 1.5})):
        cfg, img, codes, p, args = _style_problem(op, tp)
        f = _style_loss(cfg, img, codes, args, 16)
        at_truth = float(f(p))
        assert at_truth < 1e-9, op
        off = dict(p, color_matrix=p["color_matrix"].at[0, 1].multiply(1.05))
        assert float(f(off)) > 1e3 * at_truth, op
        for name in tp:
            off = dict(p, tone={**p["tone"], name: p["tone"][name] * 1.05})
            assert float(f(off)) > 1e3 * at_truth, (op, name)


# slow: ~23 s at load 11 on 2 cores (four float64 programs)
@pytest.mark.slow
def test_matrix_and_tone_gradients_match_finite_differences(x64):
    """d loss / d (off-diagonal matrix entries, tone parameters), float64, away from the
    truth; 8-bit photos (the censoring active: some codes clip)."""
    for op, tp in (("filmic", {"exposure": 1.0}), ("reinhard", {"key": 2.0, "white": 1.5})):
        cfg, img, codes, p, args = _style_problem(op, tp, bits=8)
        p0 = dict(
            p,
            color_matrix=p["color_matrix"] + 0.03 * jnp.arange(9.0).reshape(3, 3) / 9,
            tone={k: v * 1.1 for k, v in p["tone"].items()},
        )
        g = jax.grad(_style_loss(cfg, img * 1.4, codes, args, 8))(p0)
        f = _style_loss(cfg, img * 1.4, codes, args, 8, frozen_at=p0)
        h = 1e-6
        probes = [("color_matrix", (0, 1)), ("color_matrix", (2, 0)), ("color_matrix", (1, 2))]
        probes += [("tone", k) for k in tp]
        for name, idx in probes:

            def shifted(d, name=name, idx=idx, p0=p0):
                if name == "tone":
                    return dict(p0, tone={**p0["tone"], idx: p0["tone"][idx] + d})
                return dict(p0, color_matrix=p0["color_matrix"].at[idx].add(d))

            fd = (float(f(shifted(h))) - float(f(shifted(-h)))) / (2 * h)
            ad = float(g["tone"][idx] if name == "tone" else g[name][idx])
            assert abs(fd) > 1e-5, (op, name, idx)
            assert ad == pytest.approx(fd, rel=1e-5), (op, name, idx)
        np.testing.assert_allclose(np.diag(np.asarray(g["color_matrix"])), 0.0, atol=1e-12)


# slow: ~11 s at load 11 on 2 cores (300 Adam steps, float64)
@pytest.mark.slow
def test_matrix_and_tone_curve_are_recovered_from_photos(x64):
    """Adam on the loss alone (the 'render' known): the matrix's six free entries and the
    filmic exposure come back from two 8-bit photos of a random colour image."""
    from jaxgfx.optim import fit

    cfg, img, codes, p, args = _style_problem("filmic", {"exposure": 1.0}, bits=8, n=12)
    f = _style_loss(cfg, img, codes, args, 8)
    start = dict(
        p, color_matrix=jnp.eye(3, dtype=jnp.float64), tone={"exposure": jnp.asarray(-0.5)}
    )
    res = fit(
        lambda q, k: f(q),
        start,
        optimizer="adam",
        learning_rate=0.05,
        steps=300,
        key=jax.random.key(0),
        progress=False,
    )
    m = np.asarray(white_preserving(res.params["color_matrix"], 1.0))
    # measured: 0.0011 and 0.998 (8-bit quantisation); the start is 0.45 and -0.5 away
    assert np.max(np.abs(m - np.asarray(M_TRUE))) < 0.005
    assert float(res.params["tone"]["exposure"]) == pytest.approx(1.0, abs=0.01)


def test_photo_matrix_carries_the_white_balance():
    p = {"color_matrix": jnp.asarray(M_TRUE), "white_balance": jnp.asarray([2.0, 1.0, 0.5])}
    args = {"free": {"color_matrix": 0.0, "white_balance": 0.0}, "white_preserving": 0.0}
    np.testing.assert_allclose(
        np.asarray(photo_matrix(p, args)),
        np.asarray(M_TRUE) * np.asarray([2.0, 1.0, 0.5])[None, :],
        rtol=1e-6,
    )


def test_tone_level_table_is_the_composed_inverse(x64):
    resp = hdr.CameraResponse.gamma(2.2, anchor="unit")
    tc = hdr.ToneCurve("filmic", {"exposure": jnp.asarray(1.5)})
    g = np.asarray(tone_level_table(level_table(resp, 8, jnp.float64), tc))[:, 0]
    z = np.arange(256.0) / 255.0
    z[0], z[255] = 0.5 / 255, 254.5 / 255
    # T̃(e^G) must be the gamma curve's linear value z^2.2
    t = _aces(0.18 * 2**1.5 * np.exp(g)) / _aces(0.18 * 2**1.5)
    np.testing.assert_allclose(t, z**2.2, rtol=1e-10)


# ------------------------------------------------------------------- config and errors


def test_a_picture_style_config_prepares_and_the_plain_one_is_unchanged():
    from jaxgfx.pipelines.fit.job import _initial

    cfg = _cfg()
    prep = prepare_fit(cfg)
    np.testing.assert_array_equal(prep.color_matrix, np.asarray(M_TRUE))
    params, bounds, cam_args = _initial(cfg, prep)
    assert set(params["camera"]["tone"]) == {"exposure"}
    assert float(cam_args["white_preserving"]) == 0.0  # a fixed matrix is taken as given
    # a config without the stages: the parameter and argument trees it had before them
    plain = fit_cfg(STYLE_FIT, camera={"response": "srgb"})
    params, _, cam_args = _initial(plain, prepare_fit(plain))
    assert set(params["camera"]) == {
        "exposure",
        "photo_exposure",
        "white_balance",
        "gamma",
        "curve",
    }
    assert "white_preserving" not in cam_args and "tone" not in cam_args["free"]


def test_picture_style_errors_are_named():
    bad = [
        ({"color_matrix": [[1, 0], [0, 1]]}, r"camera.color_matrix.init: expected a 3x3"),
        ({"color_matrix": [[1, 0, 0], [1, 0, 0], [0, 0, 1]]}, r"matrix is singular"),
        ({"color_matrix": {"init": M_TRUE, "fit": "yes"}}, r"color_matrix.fit: expected true"),
        ({"color_matrix": {"init": [[2, 0, 0], [0, 1, 0], [0, 0, 1]], "fit": True}},
         r"color_matrix.init: a fitted matrix keeps white .* \[2.0, 1.0, 1.0\]"),
        ({"color_matrix": {"from": "camera.json", "fit": True}}, r"used fixed"),
        ({"color_matrix": {"init": M_TRUE, "scale": 2}}, r"camera.color_matrix.scale"),
        ({"tonemap": {"op": "drago"}}, r"camera.tonemap.op"),
        ({"tonemap": {"op": "reinhard", "gamma": 2}}, r"unknown parameter\(s\) \['gamma'\]"),
        ({"tonemap": {"op": "reinhard", "key": -1}}, r"camera.tonemap.key: expected a number > 0"),
        ({"tonemap": {"op": "filmic", "fit": ["white"]}}, r"camera.tonemap.fit"),
        ({"tonemap": {"exposure": 1.0}}, r"camera.tonemap: expected \{op"),
    ]  # fmt: skip
    for extra, msg in bad:
        with pytest.raises(ValueError, match=msg):
            _cfg(camera={"response": "srgb", **extra})
    with pytest.raises(ValueError, match=r"target.camera.tonemap.op"):
        prepare_fit(_cfg(target={"synthetic": {}, "camera": {"tonemap": {"op": "x"}}}))
    with pytest.raises(ValueError, match=r"target.camera.color_matrix: expected a 3x3"):
        prepare_fit(_cfg(target={"synthetic": {}, "camera": {"color_matrix": [1, 2, 3]}}))


def test_matrix_from_a_camera_profile(tmp_path):
    m = np.asarray(M_TRUE) * np.asarray([1.8, 1.0, 1.4])[None, :]  # gains included
    hdr.save_camera_profile(tmp_path / "camera.json", matrix=m, colorspace="rec709")
    cfg = _cfg(camera={"response": "srgb", "color_matrix": {"from": "camera.json"}})
    prep = prepare_fit(cfg, base_dir=str(tmp_path))
    np.testing.assert_array_equal(prep.color_matrix, m)
    hdr.save_camera_profile(
        tmp_path / "nomatrix.json", response=hdr.CameraResponse.gamma(2.2, code_max=255.0)
    )
    with pytest.raises(ValueError, match=r"color_matrix.from: .*nomatrix.json: .* no colour"):
        prepare_fit(
            _cfg(camera={"response": "srgb", "color_matrix": {"from": "nomatrix.json"}}),
            base_dir=str(tmp_path),
        )
    with pytest.raises(FileNotFoundError, match=r"camera.color_matrix.from: file not found"):
        prepare_fit(
            _cfg(camera={"response": "srgb", "color_matrix": {"from": "nope.json"}}),
            base_dir=str(tmp_path),
        )


# slow: ~110 s at load ~12 on 2 cores (compiles the three-photo fit step, 300 steps at 32x32)
@pytest.mark.slow
def test_picture_style_bracket_recovers_roughness_within_five_percent():
    """configs/picture_style.yaml as it is (matrix + filmic tone curve fixed, exposure auto,
    clipped: unmeasured; a bracket 0.2, 0.8, 3.2 whose darkest photo measures the highlight):
    issue 25's target, alpha within 5 %. Measured (docs/inverse.md 2c): alpha 0.1441 (seed
    0) and 0.1440 (seed 1), i.e. 3.9-4.0 % low — the 8-spp fit's own noise ball (the
    camera-less linear target ends at 0.145); clay albedo max error 0.0021."""
    import os

    from jaxgfx.config import read_yaml
    from jaxgfx.pipelines.fit import FitJob, run_fit

    path = os.path.join(os.path.dirname(__file__), "..", "..", "configs", "picture_style.yaml")
    cfg = read_yaml(path)
    cfg["progress"] = False
    out = run_fit(FitJob.load(cfg, None, base_dir=os.path.dirname(path)))
    alpha = out["params"]["materials.metal.alpha"]
    assert abs(alpha - 0.15) < 0.05 * 0.15, alpha
    assert out["errors"]["materials.clay.reflectance"] < 0.01
