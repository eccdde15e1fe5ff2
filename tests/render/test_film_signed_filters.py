"""Reconstruction filters with negative lobes (issue 24): Mitsuba 3's ``mitchell``,
``catmullrom`` and ``lanczos`` as :class:`~jaxgfx.render.film.MitchellFilter`,
:class:`~jaxgfx.render.film.CatmullRomFilter`, :class:`~jaxgfx.render.film.LanczosFilter`,
importance-sampled from ``|f|`` with signed sample weights (pbrt-v4). Their values against
Mitsuba's ``eval`` (``mitsuba``), the tabulated sampler against quadrature, the signed-weight
estimator unbiased on a step edge (closed form by quadrature), the estimator plumbing exact,
the scene-file rows, and a same-run render against Mitsuba 3. The filters have no continuous
parameter that a render differentiates (``B``, ``C``, ``lobes`` are static): nothing to
differentiate."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

from jaxgfx.render.film import (
    CatmullRomFilter,
    LanczosFilter,
    MitchellFilter,
    make_filter,
    pixel_samples,
)
from jaxgfx.render.render import render
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene


def _mitchell(x, b, c):  # Mitchell & Netravali 1988, eq. 8 (independent of film.py)
    x = abs(x)
    if x < 1:
        return ((12 - 9 * b - 6 * c) * x**3 + (-18 + 12 * b + 6 * c) * x**2 + (6 - 2 * b)) / 6
    if x < 2:
        return ((-b - 6 * c) * x**3 + (6 * b + 30 * c) * x**2 + (-12 * b - 48 * c) * x
                + (8 * b + 24 * c)) / 6  # fmt: skip
    return 0.0


def _lanczos(x, a):
    x = abs(x)
    if x == 0:
        return 1.0
    return (
        0.0
        if x > a
        else math.sin(math.pi * x) * math.sin(math.pi * x / a) / (math.pi**2 * x * x / a)
    )


CASES = [
    (MitchellFilter(), lambda x: _mitchell(x, 1 / 3, 1 / 3), {"type": "mitchell"}),
    (MitchellFilter(B=0.2, C=0.4), lambda x: _mitchell(x, 0.2, 0.4),
     {"type": "mitchell", "B": 0.2, "C": 0.4}),
    (CatmullRomFilter(), lambda x: _mitchell(x, 0.0, 0.5), {"type": "catmullrom"}),
    (LanczosFilter(), lambda x: _lanczos(x, 3), {"type": "lanczos"}),
    (LanczosFilter(lobes=2), lambda x: _lanczos(x, 2), {"type": "lanczos", "lobes": 2}),
]  # fmt: skip
IDS = ["mitchell", "mitchell-B.2-C.4", "catmullrom", "lanczos3", "lanczos2"]


def _quad(f, a, b, r):
    pts = [p for p in np.arange(-r, r + 1) if a < p < b]  # kinks and zeros at the integers
    return integrate.quad(f, a, b, points=pts or None, limit=200, epsabs=1e-13)[0]


@pytest.mark.usefixtures("x64")
@pytest.mark.parametrize(("filt", "ref", "_"), CASES, ids=IDS)
def test_eval_is_the_closed_form(filt, ref, _):
    xs = np.linspace(-3.3, 3.3, 133)
    ours = np.asarray(jax.jit(lambda x: filt.eval(x))(jnp.asarray(xs)))
    np.testing.assert_allclose(ours, [ref(x) for x in xs], atol=1e-12)
    # finite values and gradients at 0 (Lanczos' 0/0) and at the radius
    g = jax.vmap(jax.grad(lambda x: filt.eval(x)))(jnp.array([0.0, 1e-9, filt.radius]))
    assert np.all(np.isfinite(np.asarray(g)))


@pytest.mark.mitsuba
@pytest.mark.parametrize(("filt", "_", "mdict"), CASES, ids=IDS)
def test_eval_matches_mitsuba(filt, _, mdict):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    rf = mi.load_dict(mdict)
    assert float(rf.radius()) == filt.radius
    xs = np.linspace(-3.3, 3.3, 133)
    theirs = np.array([float(rf.eval(float(x))) for x in xs])
    # Mitsuba evaluates in float32 (its sin a polynomial fit): measured max |diff| < 1e-6
    np.testing.assert_allclose(np.asarray(filt.eval(jnp.asarray(xs))), theirs, atol=2e-6)


@pytest.mark.usefixtures("x64")
@pytest.mark.parametrize(("filt", "ref", "_"), CASES, ids=IDS)
def test_sampler_inverts_the_cdf_of_abs_f_and_weight_scale(filt, ref, _):
    """x = sample(u) satisfies ∫_{-r}^{x} |f| / ∫|f| = u (scipy quad); every weight is
    ±(∫|f| / ∫f)² with the sign of f(x) f(y)."""
    r = filt.radius
    total_abs = _quad(lambda x: abs(ref(x)), -r, r, r)
    total = _quad(ref, -r, r, r)
    assert filt.weight_scale == pytest.approx((total_abs / total) ** 2, rel=1e-6)
    # the tails (|f|'s negative lobes hold a few % of its mass) and the middle
    u = np.concatenate([np.linspace(0.002, 0.03, 15), np.linspace(0.05, 0.95, 19),
                        np.linspace(0.97, 0.998, 15)])  # fmt: skip
    uu = jnp.asarray(np.stack([u, np.roll(u, 7)], -1))
    off = np.asarray(jax.jit(filt.sample)(uu))
    cdf = np.array([_quad(lambda x: abs(ref(x)), -r, x, r) for x in off[:, 0]]) / total_abs
    np.testing.assert_allclose(cdf, u, atol=2e-6)
    w = np.asarray(jax.jit(filt.sample_weight)(jnp.asarray(off)))
    sign = np.sign([ref(a) * ref(b) for a, b in off])
    np.testing.assert_allclose(w, sign * (total_abs / total) ** 2, rtol=1e-6)
    assert np.any(w < 0)  # the negative lobes are sampled


@pytest.mark.usefixtures("x64")
@pytest.mark.parametrize(("filt", "ref", "_"), CASES[::2], ids=IDS[::2])
def test_signed_estimator_is_unbiased_on_a_step_edge(filt, ref, _):
    """Image L(x, y) = [x > 4.3] on a 9 x 1 film: the pixel mean of w L over 16384 samples
    (pixel_samples, stratified) against the filtered value ∫_{4.3-c}^{r} f / ∫f at the pixel
    centre c (quadrature), within 4 standard errors of the per-pixel sample mean
    (``sd/√n``; stratification only lowers the true error)."""
    n = 16384
    px, w = jax.jit(
        lambda k: pixel_samples(k, 9, 1, n, filt, dtype=jnp.float64, with_weights=True)
    )(jax.random.key(7))
    vals = np.asarray(w) * (np.asarray(px[..., 0]) > 4.3)  # (1, 9, n)
    est, se = vals.mean(-1)[0], vals.std(-1, ddof=1)[0] / math.sqrt(n)
    r = filt.radius
    total = _quad(ref, -r, r, r)
    c = np.arange(9) + 0.5
    exact = np.array([_quad(ref, max(4.3 - ci, -r), r, r) if 4.3 - ci < r else 0.0
                      for ci in c]) / total  # fmt: skip
    z = np.abs(est - exact) / np.maximum(se, 1e-12)
    assert np.all((z < 4) | (np.abs(est - exact) < 1e-9)), (est, exact, z)
    # power: the same samples without the sign (the normalised |f|) miss somewhere by > 8 se
    unsigned = (np.abs(np.asarray(w)) * (np.asarray(px[..., 0]) > 4.3)).mean(-1)[0]
    assert (np.abs(unsigned / filt.weight_scale**0.5 - exact) / np.maximum(se, 1e-12)).max() > 8


def _half_plane_desc(filt, **opts):
    # a black rectangle hiding the right half of the view of a constant sky: the image-space
    # edge is the column x = 4 of the 8 x 4 film (camera on the axis, looking down -z)
    return {
        "camera": {"origin": [0, 0, 5], "target": [0, 0, 0], "fov": 60, "width": 8,
                   "height": 4},
        "materials": {"black": {"type": "diffuse", "reflectance": 0.0}},
        "shapes": [{"type": "rectangle", "center": [2.0, 0, 0], "normal": [0, 0, 1],
                    "size": [4.0, 40.0], "material": "black"}],
        "emitters": [{"type": "constant", "radiance": 1.0}],
        "film": {"filter": filt, **opts},
    }  # fmt: skip


# slow: the one-pass-per-step scan, ~5 s on 2 cores (compile)
@pytest.mark.parametrize("per_step", [pytest.param(None, marks=pytest.mark.slow), 1 << 16])
def test_render_weights_each_sample_by_its_sign(per_step):
    """render() with a Lanczos filter equals the mean of w [sample left of the edge] over the
    same camera samples (pixel_samples with the render's key): the estimator multiplies each
    pass by its weights, one pass per step or several (``rays_per_step``)."""
    from jaxgfx.render.estimator import render_partial, resolve_integrator

    scene = load_scene(_half_plane_desc("lanczos"))
    key, spp = jax.random.key(5), 16
    f = jax.jit(lambda s, k: render_partial(s, k, resolve_integrator("path", max_depth=1),
                                            spp=spp, rays_per_step=per_step) / spp)  # fmt: skip
    img = np.asarray(f(scene, key))
    # under jit: eagerly, its op-by-op compiles cost more than the render's (measured)
    samples = jax.jit(lambda k: pixel_samples(k, 8, 4, spp, scene.rfilter, dtype=scene.dtype,
                                              with_weights=True))  # fmt: skip
    px, w = samples(jax.random.split(key)[0])
    ref = (np.asarray(w) * (np.asarray(px[..., 0]) < 4.0)).mean(-1)
    np.testing.assert_allclose(img, np.broadcast_to(ref[..., None], img.shape), atol=1e-5)
    assert img.min() < -0.05 and img.max() > 1.05  # the sign is applied


def test_film_options_and_errors():
    assert make_filter("mitchell", B=0.0, C=0.5).B == 0.0
    assert make_filter("lanczos", lobes=2).radius == 2.0
    with pytest.raises(ValueError, match="filter.radius: not an option of the 'mitchell'"):
        make_filter("mitchell", radius=2.0)
    with pytest.raises(ValueError, match="filter.lobes"):
        make_filter("lanczos", lobes=0)
    with pytest.raises(ValueError, match="filter.B"):
        make_filter("mitchell", B=float("nan"))
    with pytest.raises(ValueError, match="filter: expected one of"):
        make_filter("sinc")
    s = load_scene(_half_plane_desc("mitchell", B=0.25, C=0.375))
    assert s.rfilter == MitchellFilter(B=0.25, C=0.375)
    with pytest.raises(ValueError, match="film"):
        load_scene(_half_plane_desc("mitchell", lobes2=1))


XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="2"/></integrator>
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/>
    </transform>
    <sampler type="independent"><integer name="sample_count" value="64"/></sampler>
    <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/>
      <boolean name="sample_border" value="true"/>
      {rfilter}</film>
  </sensor>
  <shape type="rectangle"><transform name="to_world"><scale x="0.7" y="0.9"/>
      <rotate z="1" angle="20"/></transform>
    <emitter type="area"><rgb name="radiance" value="4, 2, 1"/></emitter></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="5"/><translate z="-1"/>
    </transform><bsdf type="diffuse"><rgb name="reflectance" value="0.2"/></bsdf></shape>
</scene>
"""
RFILTERS = {
    "mitchell": '<rfilter type="mitchell"><float name="B" value="0.25"/>'
                '<float name="C" value="0.375"/></rfilter>',
    "catmullrom": '<rfilter type="catmullrom"/>',
    "lanczos": '<rfilter type="lanczos"><integer name="lobes" value="2"/></rfilter>',
}  # fmt: skip


def test_xml_rows_load_and_are_written_back(tmp_path):
    want = {"mitchell": MitchellFilter(B=0.25, C=0.375), "catmullrom": CatmullRomFilter(),
            "lanczos": LanczosFilter(lobes=2)}  # fmt: skip
    for name, rf in RFILTERS.items():
        p = tmp_path / f"{name}.xml"
        p.write_text(XML.format(rfilter=rf))
        scene = load_scene(read_xml(str(p)).desc)
        assert scene.rfilter == want[name]
        back = load_scene(read_xml(save_scene(scene, str(tmp_path / f"w_{name}.xml"))).desc)
        assert back.rfilter == want[name]
    p.write_text(XML.format(rfilter='<rfilter type="lanczos"><integer name="lobes" value="0"/>'
                                    "</rfilter>"))  # fmt: skip
    with pytest.raises(ValueError, match=r"lanczos.xml.*lobes"):
        read_xml(str(p))
    p.write_text(XML.format(rfilter='<rfilter type="catmullrom"><float name="B" value="0"/>'
                                    "</rfilter>"))  # fmt: skip
    with pytest.raises(ValueError, match="B"):
        read_xml(str(p))


def _block_z(a, b, n=2):
    """|z| of n x n block means of replicate stacks (K, H, W, 3), Welch standard errors plus a
    floor of 1e-3 of the image mean: where a filter's tail barely reaches an emitter (blocks
    that Mitsuba, splatting uniform samples with weight f, puts at ~3e-4 of the image mean)
    jaxgfx, drawing offsets from |f|, may draw no sample there at all in K x spp samples, and
    a block with zero sample variance would make any Mitsuba value an infinite z."""
    k = a.shape[0]

    def blocks(x):
        return x.reshape(k, x.shape[1] // n, n, x.shape[2] // n, n, 3).mean((2, 4))

    ba, bb = blocks(a), blocks(b)
    var = ba.var(0, ddof=1) / k + bb.var(0, ddof=1) / k + (1e-3 * np.abs(a.mean())) ** 2
    return np.abs(ba.mean(0) - bb.mean(0)) / np.sqrt(var + 1e-12)


@pytest.mark.mitsuba
@pytest.mark.slow  # slow: ~7 s each on 2 cores (K = 8 renders of 24² at 64 spp, each side)
@pytest.mark.parametrize("name", ["mitchell", "lanczos"])
def test_signed_filter_renders_like_mitsuba(name, tmp_path):
    """An emitting rectangle seen directly (its edges ring under these filters), rendered K = 8
    times by each renderer from one XML file (``sample_border`` on, as jaxgfx samples beyond the
    border): every 2 x 2 block mean within 5 standard errors (Welch). Power: Mitsuba's render
    with the box filter is rejected."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    k = 8
    p = tmp_path / "f.xml"
    p.write_text(XML.format(rfilter=RFILTERS[name]))
    x = read_xml(str(p))
    scene = load_scene(x.desc)
    keys = jax.random.split(jax.random.key(3), k)
    f = jax.jit(jax.vmap(lambda key: render(scene, key, spp=64, integrator=x.integrator,
                                            max_depth=x.max_depth)))  # fmt: skip
    a = np.asarray(f(keys), np.float64)
    ms = mi.load_file(str(p))
    b = np.stack([np.array(mi.render(ms, spp=64, seed=s))[..., :3] for s in range(k)])
    assert np.all(np.isfinite(a)) and a.min() < -0.01  # negative ringing present
    z = _block_z(a, b.astype(np.float64))
    print(f"{name}: block max |z| {z.max():.2f}", end=" ")
    assert z.max() < 5, z.max()
    box = mi.load_string(XML.format(rfilter='<rfilter type="box"/>'))
    c = np.stack([np.array(mi.render(box, spp=64, seed=s))[..., :3] for s in range(k)])
    power = _block_z(a, c.astype(np.float64)).max()
    print(f"box-filter power: max |z| {power:.1f}")
    assert power > 5, power
