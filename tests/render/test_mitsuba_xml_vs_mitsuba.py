"""The XML translation's conventions recomputed live with Mitsuba 3 (``mitsuba`` marker; skips
without it): spectra, named IORs and the roughplastic difference documented in
docs/render_scenes.md."""

from __future__ import annotations

import numpy as np
import pytest

from jaxgfx.render.scene.mitsuba_xml import IOR_TABLE, spectrum_to_rgb

pytestmark = pytest.mark.mitsuba
mi = pytest.importorskip("mitsuba")


@pytest.fixture(scope="module", autouse=True)
def variant():
    mi.set_variant("scalar_rgb")


def _param(scene_xml, suffix):
    p = mi.traverse(mi.load_string(scene_xml))
    (key,) = [k for k in p.keys() if k.endswith(suffix)]
    return np.array(p[key], np.float64)


@pytest.mark.parametrize("emission", [True, False])
def test_spectrum_lists(emission):
    spec = "400:0.1, 480:0.9, 560:0.4, 650:0.7, 720:0.2"
    if emission:
        xml = f'<emitter type="area"><spectrum name="radiance" value="{spec}"/></emitter>'
        suffix = "radiance.value"
    else:
        xml = f'<bsdf type="diffuse"><spectrum name="reflectance" value="{spec}"/></bsdf>'
        suffix = "reflectance.value"
    got = _param(f'<scene version="3.0.0"><shape type="rectangle">{xml}</shape></scene>', suffix)
    pairs = [p.split(":") for p in spec.split(", ")]
    ours = spectrum_to_rgb([float(a) for a, _ in pairs], [float(b) for _, b in pairs],
                           emission=emission)  # fmt: skip
    np.testing.assert_allclose(ours, got, rtol=2e-3, atol=1e-4)


@pytest.mark.parametrize("name", sorted(IOR_TABLE))
def test_named_iors(name):
    xml = (
        '<scene version="3.0.0"><shape type="sphere"><bsdf type="dielectric">'
        f'<string name="int_ior" value="{name}"/><string name="ext_ior" value="vacuum"/>'
        "</bsdf></shape></scene>"
    )
    assert _param(xml, "eta") == pytest.approx(IOR_TABLE[name], rel=1e-6)


def test_roughplastic_eval_difference_is_as_documented():
    import jax.numpy as jnp

    from jaxgfx.render.bsdf import make_bsdf

    wo, wi = [0.3, 0.0, np.sqrt(0.91)], [-0.5, 0.2, np.sqrt(0.71)]
    got = {}
    for alpha in (0.01, 0.4, 1.0):
        rgb = {"type": "rgb", "value": [0.02, 0.2, 0.1]}
        desc = {"type": "roughplastic", "distribution": "ggx", "alpha": alpha}
        b = mi.load_dict({**desc, "int_ior": "bk7", "ext_ior": "air", "diffuse_reflectance": rgb})
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(wo)
        si.sh_frame = mi.Frame3f(mi.Normal3f(0, 0, 1))
        fm = np.array(b.eval(mi.BSDFContext(), si, mi.Vector3f(wi)))[1]
        j = make_bsdf({"type": "roughplastic", "distribution": "ggx", "alpha": alpha,
                       "eta": 1.5046 / 1.000277, "diffuse_reflectance": rgb["value"]})  # fmt: skip
        fj = float(np.asarray(j.eval(jnp.array(wo), jnp.array(wi)))[1])
        got[alpha] = (fj, fm)
    # before the rough coat's tables (bsdf/_coating.py) jaxgfx gave 0.0549 / 0.0708 / 0.0573
    for alpha, (fj, fm) in got.items():
        assert fj == pytest.approx(fm, rel=2e-3), alpha
    np.testing.assert_allclose(
        [got[a][1] for a in (0.01, 0.4, 1.0)], (0.0537, 0.0487, 0.0223), atol=2e-4
    )


def test_roughplastic_small_alpha_eval_matches_mitsuba():
    # α <= 0.01, where R_int is the quadrature of Mitsuba's rule rather than the table's spline
    # (bsdf/_coating.py; the spline alone was off by up to 1.6 % here): measured <= 1.24e-4
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from jaxgfx.render.bsdf import make_bsdf

    wo, wi = [0.3, 0.0, np.sqrt(0.91)], [-0.5, 0.2, np.sqrt(0.71)]
    rgb = [0.2, 0.8, 0.5]
    worst = 0.0

    @jax.jit  # one compile for the 24 (alpha, eta)
    def ours(alpha, eta):
        j = make_bsdf({"type": "roughplastic", "distribution": "ggx", "alpha": 0.5, "eta": 1.5,
                       "diffuse_reflectance": rgb})  # fmt: skip
        leaves = lambda b: (b.distribution.alpha_u, b.distribution.alpha_v, b.eta)  # noqa: E731
        j = eqx.tree_at(leaves, j, (alpha, alpha, eta))
        return j.eval(jnp.array(wo), jnp.array(wi))

    for eta in (1.1, 1.33, 1.5, 1.7, 2.0, 2.5):
        for alpha in (1e-4, 1e-3, 3e-3, 0.01):
            desc = {"type": "roughplastic", "distribution": "ggx", "alpha": alpha}
            b = mi.load_dict({**desc, "int_ior": eta, "ext_ior": 1.0,
                              "diffuse_reflectance": {"type": "rgb", "value": rgb}})  # fmt: skip
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(wo)
            si.sh_frame = mi.Frame3f(mi.Normal3f(0, 0, 1))
            fm = np.array(b.eval(mi.BSDFContext(), si, mi.Vector3f(wi)))
            fj = np.asarray(ours(alpha, eta))
            worst = max(worst, float(np.max(np.abs(fj / fm - 1.0))))
    assert worst < 2.5e-4
