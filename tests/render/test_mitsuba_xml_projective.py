"""Mitsuba's projective-sampling integrators ``direct_projective`` / ``prb_projective`` (issue
24) read as jaxgfx's ``direct`` / ``path`` with edge sampling (``visibility="edge"``): the
loaded integrator and options, Mitsuba's parameters accepted or refused with file and line, the
combinations edge sampling cannot do refused, the writer round trip; the primal image equal to
plain ``direct`` / ``path``; the boundary gradient of a sphere's position against float64
finite differences (slow); the primal against Mitsuba's own renders (``mitsuba``, slow)."""

import importlib
import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgfx.render import render
from jaxgfx.render.estimator import resolve_integrator
from jaxgfx.render.integrators import DirectIntegrator, PathIntegrator
from jaxgfx.render.scene import load_scene
from jaxgfx.render.scene.mitsuba_xml import read_xml, save_scene

# the scene of experiments/projective_mitsuba.py (imported by name: tests do not import
# experiments statically), 4 spp unless said
_scene_xml = importlib.import_module("experiments.projective_mitsuba").scene_xml


def _xml(kind, body="", *, spp=4, **kw):
    return _scene_xml(kind, body, spp=spp, **kw)


def _write(tmp_path, text, name="s.xml"):
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _read(tmp_path, *args, **kw):
    return read_xml(_write(tmp_path, _xml(*args, **kw)))


def test_loaded_integrators_are_direct_and_path_with_edge_sampling(tmp_path):
    """``direct_projective`` -> ``DirectIntegrator`` (Mitsuba overrides its max_depth to 2,
    whatever is given), ``prb_projective`` -> ``PathIntegrator`` with Mitsuba's ADIntegrator
    defaults (max_depth 6, rr_depth 5), adjoint ``ad`` (geometry gradients; replay covers
    materials only), both with ``visibility="edge"``; each resolves to the very integrator
    plain ``direct`` / ``path`` of that depth resolve to (so the primal images are the same)."""
    assert _read(tmp_path, "direct_projective", '<integer name="max_depth" value="0"/>'
                 ).integrator_spec == {"type": "direct"}  # read and ignored, as Mitsuba
    x = _read(tmp_path, "direct_projective", '<integer name="max_depth" value="7"/>')
    assert (x.integrator, x.visibility, x.integrator_spec) == ("direct", "edge",
                                                               {"type": "direct"})  # fmt: skip
    integ = resolve_integrator(x.integrator_spec)
    assert isinstance(integ, DirectIntegrator) and integ == resolve_integrator("direct")
    y = _read(tmp_path, "prb_projective")
    assert (y.integrator, y.max_depth, y.rr_depth, y.adjoint, y.visibility) == (
        "path", 6, 5, "ad", "edge")  # fmt: skip
    integ = resolve_integrator(y.integrator_spec)
    assert isinstance(integ, PathIntegrator)
    assert integ == resolve_integrator("path", max_depth=6, rr_depth=5)
    y = _read(tmp_path, "prb_projective", '<integer name="max_depth" value="-1"/>'
                                          '<integer name="rr_depth" value="3"/>')  # fmt: skip
    assert (y.max_depth, y.rr_depth) == (None, 3)
    for kind in ("path", "prb", "direct"):  # the others: no boundary term
        assert _read(tmp_path, kind).visibility is None


_ALL = """<integer name="sppc" value="32"/><integer name="sppp" value="0"/>
  <integer name="sppi" value="128"/><string name="guiding" value="grid"/>
  <boolean name="guiding_proj" value="false"/><integer name="guiding_rounds" value="3"/>
  <string name="project_seed" value="emitter"/>"""


@pytest.mark.parametrize("kind", ["direct_projective", "prb_projective"])
def test_mitsubas_parameters_are_accepted(tmp_path, kind):
    """Every documented parameter of Mitsuba's projective integrators loads (its values have no
    jaxgfx meaning: the options are those of the bare plugin)."""
    a, b = _read(tmp_path, kind, _ALL), _read(tmp_path, kind)
    assert (a.integrator_spec, a.visibility) == (b.integrator_spec, b.visibility)


@pytest.mark.parametrize("kind, body, name, msg", [
    ("prb_projective", '<integer name="max_depth" value="0"/>', "max_depth", "max_depth -1 or"),
    ("direct_projective", '<integer name="max_depth" value="-2"/>', "max_depth",
     "max_depth -1 or >= 0"),
    ("direct_projective", '<integer name="rr_depth" value="0"/>', "max_depth", "rr_depth >= 1"),
    ("prb_projective", '<integer name="sppc" value="-1"/>', "sppc", "sample count >= 0"),
    ("direct_projective", '<integer name="sppi" value="-4"/>', "sppi", "sample count >= 0"),
    ("prb_projective", '<string name="guiding" value="kdtree"/>', "guiding", "'kdtree' is not"),
    ("prb_projective", '<integer name="guiding_rounds" value="0"/>', "guiding_rounds",
     "positive integer"),
    ("direct_projective", '<string name="project_seed" value="all"/>', "project_seed",
     "'all' is not"),
    ("prb_projective", '<float name="sppc" value="4"/>', "sppc", "expected integer"),
    ("prb_projective", '<boolean name="hide_emitters" value="true"/>', "hide_emitters",
     "'ptracer' only"),
    ("prb_projective", '<integer name="samples_per_pass" value="4"/>', "samples_per_pass",
     "is not supported"),
])  # fmt: skip
def test_bad_values_name_the_file_line_and_parameter(tmp_path, kind, body, name, msg):
    p = _write(tmp_path, _xml(kind, body))
    with pytest.raises(ValueError, match=rf"{p}:2: .*{name}.*{msg}") as e:
        read_xml(p)
    assert kind in str(e.value)


@pytest.mark.parametrize("kw, msg", [
    ({"sensor": "thinlens", "extra": '<float name="aperture_radius" value="0.01"/>'},
     r"s.xml:3: <sensor type='thinlens'>: prb_projective needs a perspective sensor"),
    ({"rfilter": ""}, r"s.xml:2: .*prb_projective needs <rfilter type=\"box\"/> in the film"
                      r".*got 'gaussian'"),
    ({"rfilter": '<rfilter type="tent"/>'}, "got 'tent'"),
    ({"more": '<shape type="linearcurve"><string name="filename" value="c.txt"/></shape>'},
     r"s.xml:\d+: <shape type='linearcurve'>: .*prb_projective with a linearcurve is not "
     r"supported \(jaxgfx's edge sampling does not sample curve silhouettes"),
])  # fmt: skip
def test_what_edge_sampling_cannot_do_is_refused(tmp_path, kw, msg):
    """A thin-lens sensor (Mitsuba's projective integrators refuse it too), a non-box pixel
    filter (Mitsuba's default is gaussian; jaxgfx's boundary term integrates box pixels) and
    curves (jaxgfx does not sample their silhouettes) are refused when the file is read."""
    (tmp_path / "c.txt").write_text("0 0 -5 0.1\n0 0.2 -5 0.1\n")
    with pytest.raises(ValueError, match=msg):
        read_xml(_write(tmp_path, _xml("prb_projective", **kw)))
    read_xml(_write(tmp_path, _xml("prb", **kw), "ok.xml"))  # fine without edge sampling


@pytest.mark.parametrize("kind", ["direct_projective", "prb_projective"])
def test_written_back(tmp_path, kind):
    x = _read(tmp_path, kind, '<integer name="max_depth" value="4"/>')
    w = save_scene(load_scene(x.desc), str(tmp_path / "w.xml"), integrator=kind,
                   max_depth=x.max_depth, rr_depth=x.rr_depth)  # fmt: skip
    with open(w) as f:
        assert f'<integrator type="{kind}"' in f.read()
    y = read_xml(w)
    assert (y.integrator_spec, y.visibility) == (x.integrator_spec, x.visibility)
    w = save_scene(load_scene(x.desc), str(tmp_path / "u.xml"), integrator=kind)
    assert read_xml(w).max_depth == (2 if kind == "direct_projective" else None)


# ------------------------------------------------------------------- gradients (slow)


def _loss(t, key, scene, path, c0, w, spec, vis):
    """Weighted image sum (the columns right of the sphere's projected centre) with the
    sphere moved by ``t`` along x."""
    sc = scene.replace(path, c0 + jnp.asarray([1.0, 0.0, 0.0], c0.dtype) * t)
    img = render(sc, key, spp=16, integrator=spec, visibility=vis)
    return jnp.sum(img.mean(-1) * w) / w.size


@pytest.mark.slow  # slow: ~75 s on 2 cores at load 5 (a float64 program of the value and both
# gradients, and the forward program of the differences)
def test_boundary_gradient_matches_float64_finite_differences(x64, tmp_path):
    """The sphere of the XML scene moving sideways over the lit floor (its silhouette over the
    floor, its shadow on the floor), 8², 16 spp, float64: d(weighted image sum)/dx by AD with the
    loaded integrator and its edge sampling against same-key central differences (h = 0.05;
    32 keys): the paired difference within 4 standard errors. Without the boundary term (plain
    ``direct`` / ``path``, the same integrator) the same comparison fails by more than 4
    standard errors. Also: the primal values are those of the plain integrator. Only
    ``direct_projective`` (``prb_projective`` maps onto ``path`` with the same edge sampling,
    whose first-vertex boundary term is the same code; experiments/projective_mitsuba.py
    compares both with Mitsuba's own gradients). Measured: AD -0.0153, FD -0.0135 +- 0.0011;
    edge - FD -0.0017 +- 0.0015 (1.1 SE), plain - FD +0.0135 +- 0.0015 (9 SE)."""
    kind = "direct_projective"
    x = _read(tmp_path, kind)
    scene = load_scene(x.desc)
    assert scene.dtype == jnp.float64
    si = next(i for i, s in enumerate(scene.shapes) if hasattr(s, "radii"))
    path = f"shapes.{si}.centers"
    c0 = scene.get(path)
    w = jnp.asarray(np.arange(8)[None, :] >= 4, jnp.float64) * jnp.ones((8, 1))
    keys = jax.random.split(jax.random.key(24), 32)
    args = (scene, path, c0, w, x.integrator_spec)

    def grads(t, k):  # one program: the value and both gradients (the forward pass is shared)
        v, ge = jax.value_and_grad(lambda t: _loss(t, k, *args, x.visibility))(t)
        return v, ge, jax.grad(lambda t: _loss(t, k, *args, None))(t)

    vals, ad, pg = (np.asarray(a) for a in jax.jit(jax.vmap(grads, in_axes=(None, 0)))(
        jnp.float64(0.0), keys))  # fmt: skip
    fwd = jax.jit(jax.vmap(lambda t, k: _loss(t, k, *args, None), in_axes=(None, 0)))
    h = 0.05
    fd = (np.asarray(fwd(jnp.float64(h), keys)) - np.asarray(fwd(jnp.float64(-h), keys))) / (2 * h)
    # the same primal as plain direct (another program: float rounding only)
    np.testing.assert_allclose(vals, np.asarray(fwd(jnp.float64(0.0), keys)), rtol=1e-12)
    d, p = ad - fd, pg - fd
    se = d.std(ddof=1) / np.sqrt(d.size)
    sp = p.std(ddof=1) / np.sqrt(p.size)
    print(f"{kind}: AD {ad.mean():.4f} FD {fd.mean():.4f} +- {fd.std(ddof=1) / np.sqrt(32):.4f}, "
          f"edge - FD {d.mean():.4f} +- {se:.4f}, plain - FD {p.mean():.4f} +- {sp:.4f}")
    assert abs(d.mean()) <= 4 * se
    assert abs(p.mean()) > 4 * sp


# ---------------------------------------------------------------- Mitsuba (slow)

LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"


@pytest.mark.mitsuba
@pytest.mark.slow  # slow: ~20-27 s each on 2 cores at load 7 (jaxgfx compile; Mitsuba LLVM)
@pytest.mark.parametrize("kind, body", [
    ("direct_projective", ""), ("prb_projective", '<integer name="max_depth" value="3"/>')])
def test_primal_renders_like_mitsuba(tmp_path, kind, body):
    """The primal image of the XML scene, K = 8 replicates by each renderer at 64 spp, 8²
    (Mitsuba's projective integrators need a JIT variant: ``llvm_ad_rgb``): every 4 x 4 block
    mean within 5 standard errors (Welch). Power: Mitsuba's image of the scene with the sphere
    moved by 0.3 is rejected. Measured: direct_projective max |z| 1.80 (means 0.1344 /
    0.1350), moved 13.1; prb_projective (max_depth 3) 0.80 (0.1362 / 0.1365), moved 12.8."""
    from tests.render._scenes import replicate_block_z
    from tests.render.test_gradients_mitsuba import _llvm_backend_renders

    if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(LLVM19):
        os.environ["DRJIT_LIBLLVM_PATH"] = LLVM19
    mi = pytest.importorskip("mitsuba")
    _llvm_backend_renders()
    mi.set_variant("llvm_ad_rgb")
    text = _xml(kind, body, spp=64)
    x = read_xml(_write(tmp_path, text))
    scene = load_scene(x.desc)
    k = 8
    keys = jax.random.split(jax.random.key(7), k)
    a = np.asarray(jax.jit(jax.vmap(lambda key: render(
        scene, key, spp=x.spp, integrator=x.integrator_spec, visibility=x.visibility)))(keys),
        np.float64)  # fmt: skip

    def theirs(t):
        s = mi.load_string(t)
        return np.stack([np.array(mi.render(s, spp=64, seed=j))[..., :3]
                         for j in range(k)]).astype(np.float64)  # fmt: skip

    try:
        b = theirs(text)
        c = theirs(text.replace('<point name="center" x="0"', '<point name="center" x="0.3"'))
    finally:
        mi.set_variant("scalar_rgb")
    z, ma, mb = replicate_block_z(a, b, n=4)
    zc = replicate_block_z(a, c, n=4)[0].max()
    print(f"{kind}: max |z| {z.max():.2f}, means {ma.mean():.4f} / {mb.mean():.4f}; moved {zc:.1f}")
    assert z.max() < 5
    assert zc > 5
