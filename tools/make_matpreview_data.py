# ruff: noqa: E501  (the scene XML keeps the original long matrix lines)
"""Reduced copy of Mitsuba's material-preview scene for tests/data/mitsuba/scenes/matpreview/.

Usage: ``python tools/make_matpreview_data.py SRC_DIR OUT_DIR [CELL]`` with ``SRC_DIR`` holding
``matpreview.xml``, ``matpreview.serialized`` and ``envmap.exr`` from mitsuba-data's
``scenes/matpreview/`` (commit fdb2739 added them). Needs Mitsuba 3 (``scalar_rgb``) for the
environment map. Writes into ``OUT_DIR``:

* ``plane.ply``, ``interior.ply``: shapes 0 and 1 of ``matpreview.serialized`` unchanged
  (vertices, normals, uvs as stored; float32).
* ``exterior.ply``: shape 2 (57152 triangles) reduced by vertex clustering: vertices snapped to
  a cubic grid of cell ``CELL`` (default 0.1, in the shape's local units, whose extent is
  2.4 x 2.4 x 2.2), each cluster's position the mean of its vertices, its normal the normalised mean of
  their normals (a member's own normal where they cancel), triangles whose corners fall in fewer than three clusters dropped, uvs dropped
  (the material on it is not textured).
* ``envmap.exr``: 64 x 32 (Mitsuba's lat-long grid: columns at ``u = (k + 1/2) / W``, rows at
  ``v = j / (H - 1)``) with the XML's envmap ``to_world`` rotation baked in: each texel is the
  mean of Mitsuba's own ``envmap.eval`` (the original 512 x 256 map, ``scale`` 1, the XML's
  ``to_world``) over 8 x 8 directions spread over the texel, so the reduced scene's envmap
  needs no ``to_world`` (jaxgfx refuses a rotated envmap).
* ``matpreview.xml``: the original with these files, no envmap ``to_world``, ``ply`` shapes,
  ``$`` parameters for the sizes, spp and depth (``max_depth`` default 8 instead of -1); the
  preview material ``bsdf-matpreview`` is the original plastic (tests replace that element).
"""

from __future__ import annotations

import os
import sys

import numpy as np

from jaxgfx.io import write_exr
from jaxgfx.render.geometry.mesh import TriangleMesh
from jaxgfx.render.geometry.mesh_io import save_ply
from jaxgfx.render.geometry.serialized import read_serialized

ENV_TO_WORLD = (
    '<rotate y="1" angle="-180"/><matrix value="-0.224951 -0.000001 -0.974370 0.000000 '
    "-0.974370 0.000000 0.224951 0.000000 0.000000 1.000000 -0.000001 8.870000 0.000000 "
    '0.000000 0.000000 1.000000"/>'
)


def cluster(mesh, cell):
    v, f, n = (np.asarray(x, np.float64) for x in (mesh.vertices, mesh.faces, mesh.normals))
    key = np.floor(v / cell).astype(np.int64)
    _, inv = np.unique(key, axis=0, return_inverse=True)
    inv = inv.ravel()
    m = inv.max() + 1
    cnt = np.bincount(inv, minlength=m)[:, None]
    pos = np.stack([np.bincount(inv, v[:, i], m) for i in range(3)], 1) / cnt
    nor = np.stack([np.bincount(inv, n[:, i], m) for i in range(3)], 1)
    bad = np.linalg.norm(nor, axis=1) < 1e-6 * cnt[:, 0]  # opposite normals cancel (thin walls)
    nor[inv[::-1]] = np.where(bad[inv[::-1], None], n[::-1], nor[inv[::-1]])  # a member's own
    nor /= np.linalg.norm(nor, axis=1, keepdims=True)
    ff = inv[f.astype(np.int64)]
    keep = (ff[:, 0] != ff[:, 1]) & (ff[:, 1] != ff[:, 2]) & (ff[:, 0] != ff[:, 2])
    ff = ff[keep]
    used = np.unique(ff)
    remap = np.full(m, -1)
    remap[used] = np.arange(len(used))
    return TriangleMesh(pos[used], remap[ff].astype(np.int32), normals=nor[used])


def bake_envmap(src, w=64, h=32, sub=8):
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    xml = (
        '<emitter version="3.0.0" type="envmap"><string name="filename" value="'
        + os.path.join(src, "envmap.exr")
        + '"/><transform name="to_world">'
        + ENV_TO_WORLD
        + "</transform></emitter>"
    )
    env = mi.load_string(xml)
    out = np.zeros((h, w, 3))
    s = (np.arange(sub) + 0.5) / sub - 0.5
    for j in range(h):
        for k in range(w):
            acc = np.zeros(3)
            for a in s:
                for b in s:
                    u = (k + 0.5 + a) / w
                    v = np.clip((j + b) / (h - 1), 0.0, 1.0)
                    th, ph = np.pi * v, 2 * np.pi * u
                    d = [np.sin(th) * np.sin(ph), np.cos(th), -np.sin(th) * np.cos(ph)]
                    si = mi.SurfaceInteraction3f()
                    si.wi = mi.Vector3f(-np.asarray(d))
                    acc += np.array(env.eval(si))
            out[j, k] = acc / sub**2
    return out.astype(np.float32)


XML = """<scene version="3.0.0">
    <!-- mitsuba-data scenes/matpreview/matpreview.xml (commit fdb2739), reduced:
         tools/make_matpreview_data.py; ORIGIN.md -->
    <default name="spp" value="64"/>
    <default name="width" value="683"/>
    <default name="height" value="512"/>
    <default name="max_depth" value="8"/>

    <integrator type="path">
        <integer name="max_depth" value="$max_depth"/>
    </integrator>

    <sensor type="perspective" id="camera">
        <string name="fov_axis" value="smaller"/>
        <float name="fov" value="28.8415"/>
        <transform name="to_world">
            <lookat target="3.04072, -2.85176, 2.80939"
                    origin="3.69558, -3.46243, 3.25463"
                    up="-0.317366, 0.312466, 0.895346"/>
        </transform>
        <sampler type="independent">
            <integer name="sample_count" value="$spp"/>
        </sampler>
        <film type="hdrfilm" id="film">
            <integer name="width" value="$width"/>
            <integer name="height" value="$height"/>
            <string name="pixel_format" value="rgb"/>
            <rfilter type="gaussian"/>
        </film>
    </sensor>

    <emitter type="envmap" id="envmap">
        <string name="filename" value="envmap.exr"/>
        <float name="scale" value="3"/>
    </emitter>

    <bsdf type="diffuse" id="bsdf-diffuse">
        <rgb name="reflectance" value="0.18 0.18 0.18"/>
    </bsdf>

    <texture type="checkerboard" id="texture-checkerboard">
        <rgb name="color0" value="0.4"/>
        <rgb name="color1" value="0.2"/>
        <transform name="to_uv">
            <scale x="8.000000" y="8.000000"/>
        </transform>
    </texture>

    <bsdf type="diffuse" id="bsdf-plane">
        <ref name="reflectance" id="texture-checkerboard"/>
    </bsdf>

    <bsdf type="plastic" id="bsdf-matpreview">
        <rgb name="diffuse_reflectance" value="0.940, 0.271, 0.361"/>
        <float name="int_ior" value="1.9"/>
    </bsdf>

    <shape type="ply" id="plane">
        <string name="filename" value="plane.ply"/>
        <transform name="to_world">
            <rotate z="1" angle="-4.3"/>
            <matrix value="3.38818 -4.06354 0 -1.74958 4.06354 3.38818 0 1.43683 0 0 5.29076 -0.0120714 0 0 0 1"/>
        </transform>
        <ref name="bsdf" id="bsdf-plane"/>
    </shape>

    <shape type="ply" id="interior">
        <string name="filename" value="interior.ply"/>
        <transform name="to_world">
            <matrix value="1 0 0 0 0 1 0 0 0 0 1 0.0252155 0 0 0 1"/>
        </transform>
        <ref name="bsdf" id="bsdf-diffuse"/>
    </shape>

    <shape type="ply" id="exterior">
        <string name="filename" value="exterior.ply"/>
        <transform name="to_world">
            <matrix value="0.614046 0.614047 0 -1.78814e-07 -0.614047 0.614046 0 2.08616e-07 0 0 0.868393 1.02569 0 0 0 1"/>
            <translate z="0.01"/>
        </transform>
        <ref name="bsdf" id="bsdf-matpreview"/>
    </shape>
</scene>
"""


def main(src, out, cell=0.1):
    os.makedirs(out, exist_ok=True)
    ser = os.path.join(src, "matpreview.serialized")
    for i, name in ((0, "plane"), (1, "interior")):
        m = read_serialized(ser, i)
        save_ply(os.path.join(out, name + ".ply"), TriangleMesh(m.vertices, m.faces, m.normals,
                                                                m.uvs))  # fmt: skip
    ext = read_serialized(ser, 2)
    red = cluster(TriangleMesh(ext.vertices, ext.faces, ext.normals), cell)
    save_ply(os.path.join(out, "exterior.ply"), red)
    print("exterior", ext.faces.shape[0], "->", red.faces.shape[0], "triangles")
    write_exr(os.path.join(out, "envmap.exr"), bake_envmap(src))
    with open(os.path.join(out, "matpreview.xml"), "w") as fh:
        fh.write(XML)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], *(float(x) for x in sys.argv[3:]))
