"""Shape derivative through Mitsuba's projective integrators: jaxgfx (the XML read as ``direct``
/ ``path`` with edge sampling) against Mitsuba 3's own ``direct_projective`` /
``prb_projective`` (issue 24).

    python -m experiments.projective_mitsuba [--kind direct_projective] [--max-depth 3]
                                             [--keys 32] [--spp 16] [--out FILE]

Scene (one XML file, read by both renderers): a diffuse sphere over a diffuse floor, lit by a
tilted area light and a dim constant environment, 8², box filter. Parameter: the sphere's x
(Mitsuba: a translation prepended to its ``to_world``). Loss: the mean over the image columns
right of the sphere's projected centre (the image mean would nearly cancel the two moving
edges). Per key / seed: jaxgfx's reverse-mode gradient with ``visibility="edge"`` (what the
loader maps the projective integrators to) and without it, and Mitsuba's reverse-mode gradient
through its projective integrator (``llvm_ad_rgb``; needs ``DRJIT_LIBLLVM_PATH``, set to
Debian's libLLVM 19 when present). Prints JSON: means and standard errors over the keys.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

from experiments._common import emit_json, log

SCENE = """<scene version="3.0.0">
  <integrator type="{kind}">{body}</integrator>
  <sensor type="{sensor}"><float name="fov" value="40"/>{extra}
    <transform name="to_world"><lookat origin="0, 1.2, 4" target="0, 0.5, 0" up="0, 1, 0"/>
    </transform>
    <sampler type="independent"><integer name="sample_count" value="{spp}"/></sampler>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
      {rfilter}</film>
  </sensor>
  <shape type="sphere" id="ball"><point name="center" x="0" y="0.6" z="0"/>
    <float name="radius" value="0.4"/>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.6, 0.6"/></bsdf></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/>
      <scale value="3"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf></shape>
  <shape type="rectangle"><transform name="to_world"><scale x="0.7" y="0.45"/>
      <rotate x="1" angle="150"/><translate y="1.3" z="-1.5"/></transform>
    <emitter type="area"><rgb name="radiance" value="5, 5, 5"/></emitter></shape>
  <emitter type="constant"><rgb name="radiance" value="0.2, 0.2, 0.2"/></emitter>
  {more}
</scene>
"""


def scene_xml(kind, body="", *, spp=16, sensor="perspective", extra="",
              rfilter='<rfilter type="box"/>', more=""):  # fmt: skip
    """The scene as XML text: integrator ``kind`` with the XML ``body`` inside its element,
    ``spp`` samples per pixel, the ``sensor`` type with ``extra`` XML inside it, the film's
    ``rfilter`` element and ``more`` XML at the end of the scene (the sphere's id is ``ball``).
    Also the scene of tests/render/test_mitsuba_xml_projective.py (imported by name there)."""
    return SCENE.format(kind=kind, body=body, spp=spp, sensor=sensor, extra=extra,
                        rfilter=rfilter, more=more)  # fmt: skip


LLVM19 = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"


def _stats(v):
    v = np.asarray(v, np.float64)
    return {"mean": float(v.mean()), "stderr": float(v.std(ddof=1) / np.sqrt(v.size))}


def _weights():
    w = np.zeros((8, 8))
    w[:, 4:] = 1.0  # the sphere's centre projects to the middle of the image
    return w / w.size


def jaxgfx_gradients(path, keys, spp):
    import jax
    import jax.numpy as jnp

    from jaxgfx.render import load_scene, render
    from jaxgfx.render.scene.mitsuba_xml import read_xml

    x = read_xml(path)
    scene = load_scene(x.desc)
    si = next(i for i, s in enumerate(scene.shapes) if hasattr(s, "radii"))
    c0 = scene.get(f"shapes.{si}.centers")
    w = jnp.asarray(_weights(), c0.dtype)

    def loss(t, key, vis):
        sc = scene.replace(f"shapes.{si}.centers", c0 + jnp.asarray([1.0, 0, 0], c0.dtype) * t)
        img = render(sc, key, spp=spp, integrator=x.integrator_spec, visibility=vis)
        return jnp.sum(img.mean(-1) * w)

    out = {}
    ks = jax.random.split(jax.random.key(2024), keys)
    for name, vis in (("edge", x.visibility), ("plain", None)):
        t = time.perf_counter()
        g = jax.jit(jax.vmap(jax.grad(lambda t, k, vis=vis: loss(t, k, vis)), in_axes=(None, 0)))
        out[name] = _stats(np.asarray(g(jnp.float32(0.0), ks)))
        log(name, out[name], f"{time.perf_counter() - t:.0f} s")
    return x.visibility, out


def mitsuba_gradients(path, keys, spp):
    if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(LLVM19):
        os.environ["DRJIT_LIBLLVM_PATH"] = LLVM19
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    scene = mi.load_file(path)
    params = mi.traverse(scene)
    t0 = mi.Transform4f(params["ball.to_world"])
    w = mi.TensorXf(np.repeat(_weights()[..., None], 3, -1) / 3)
    gs = []
    t = time.perf_counter()
    for seed in range(keys):
        x = mi.Float(0.0)
        dr.enable_grad(x)
        params["ball.to_world"] = mi.Transform4f().translate([x, 0.0, 0.0]) @ t0
        params.update()
        img = mi.render(scene, params, spp=spp, seed=seed)
        dr.backward(dr.sum(img * w, axis=None))
        gs.append(float(np.asarray(dr.grad(x)).ravel()[0]))
    log("mitsuba", _stats(gs), f"{time.perf_counter() - t:.0f} s")
    return _stats(gs)


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--kind", default="direct_projective",
                   choices=("direct_projective", "prb_projective"))  # fmt: skip
    p.add_argument("--max-depth", type=int, default=3, help="prb_projective only")
    p.add_argument("--keys", type=int, default=32)
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    prb = a.kind == "prb_projective"
    body = f'<integer name="max_depth" value="{a.max_depth}"/>' if prb else ""
    with tempfile.TemporaryDirectory() as d:
        path = os.path.join(d, "scene.xml")
        with open(path, "w", encoding="utf-8") as f:
            f.write(scene_xml(a.kind, body, spp=a.spp))
        vis, ours = jaxgfx_gradients(path, a.keys, a.spp)
        theirs = mitsuba_gradients(path, a.keys, a.spp)
    out = {"kind": a.kind, "max_depth": a.max_depth if prb else 2,
           "keys": a.keys, "spp": a.spp, "visibility": vis, "jaxgfx_edge": ours["edge"],
           "jaxgfx_plain": ours["plain"], "mitsuba": theirs,
           "edge_minus_mitsuba_z": (ours["edge"]["mean"] - theirs["mean"])
           / float(np.hypot(ours["edge"]["stderr"], theirs["stderr"]))}  # fmt: skip
    emit_json(out, a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
