"""Mitsuba 3 <-> jaxgfx: the one table of names and conventions.

Read by the XML loader (:mod:`jaxgfx.render.scene.mitsuba_xml`), the dict exporter
(:func:`jaxgfx.render.scene.mitsuba.to_mitsuba_dict`) and the XML writer
(:func:`jaxgfx.render.scene.mitsuba_xml.save_scene`), so that reading and writing cannot
drift apart. Pure NumPy (imports nothing from Mitsuba). Each convention is checked against
Mitsuba 3.9.1 by tests/render/test_mitsuba*.py.

* :data:`PLUGINS`: every Mitsuba plugin the loader knows, by ``(tag, type)``, with its status
  (``"supported"`` plus notes, or ``"refused: why"``); docs/render_scenes.md's plugin table is
  tested to list exactly these rows. A plugin not listed is refused as unknown.
* :data:`BSDF_TO_MITSUBA`: jaxgfx BSDF class name -> Mitsuba plugin; :data:`ONE_SIDED_BSDFS`:
  Mitsuba's BSDFs that are black from behind (jaxgfx shades them on both sides; the writer
  wraps them in ``twosided``); :data:`DEFAULTS`: Mitsuba's default parameter values that
  differ from jaxgfx's.
* :data:`IOR_TABLE`: Mitsuba's named dielectric IORs; :data:`CONDUCTOR_IOR`: its named
  conductors (``material="Au"``) as the RGB ``(eta, k)`` its RGB variants use.
* :func:`look_at_matrix`: Mitsuba's ``Transform4f.look_at`` (camera looks along local +z,
  +y up); :func:`orthographic_view_proj_inverse` / :func:`orthographic_to_world`: Mitsuba's
  ``orthographic`` sensor as a jaxgfx :class:`~jaxgfx.render.camera.MatrixCamera` and back;
  :func:`rectangle_to_world`: a jaxgfx parallelogram as Mitsuba's ``[-1, 1]^2``
  rectangle; :func:`spectrum_to_rgb`: spectra -> RGB as the RGB variants convert them;
  :func:`envmap_for_mitsuba` / :func:`envmap_from_mitsuba`: the two lat-long grids.
"""

from __future__ import annotations

import os

import numpy as np

__all__ = [
    "PLUGINS",
    "plugin_status",
    "BSDF_TO_MITSUBA",
    "ONE_SIDED_BSDFS",
    "DEFAULTS",
    "IOR_TABLE",
    "CONDUCTOR_IOR",
    "conductor_ior_from_spd",
    "read_spd",
    "look_at_matrix",
    "orthographic_view_proj_inverse",
    "orthographic_to_world",
    "rectangle_to_world",
    "spectrum_to_rgb",
    "envmap_for_mitsuba",
    "envmap_from_mitsuba",
    "ENVMAP_ROW_FACTOR",
]

S = "supported"
PLUGINS: dict[tuple[str, str], str] = {
    # shapes
    ("shape", "obj"): S,
    ("shape", "ply"): S,
    ("shape", "serialized"): S + " (shape_index; vertex colours ignored)",
    ("shape", "sphere"): S,
    ("shape", "rectangle"): S,
    ("shape", "cube"): S + " (Mitsuba's 24-vertex mesh and uvs)",
    ("shape", "disk"): S + " (256-triangle fan, uv (r, φ/2π))",
    ("shape", "cylinder"): S + " (512-triangle tube, no caps, uv (φ/2π, z))",
    ("shape", "shapegroup"): S + " (meshes and analytic shapes; no emitters, no nesting)",
    ("shape", "instance"): S + " (any invertible affine to_world)",
    ("shape", "sdfgrid"): S + " (`filename`, `normals`; exact per-voxel intersection)",
    ("shape", "bsplinecurve"): S + " (`filename`, `to_world`; circle sweep, Newton-refined)",
    ("shape", "linearcurve"): S + " (`filename`, `to_world`; exact round cones, culled backs)",
    ("shape", "ellipsoids"): S + " (`filename` PLY, `extent`, `scale_factor`, `to_world`; exact, "
                                 "culled backs; attributes and emitters refused)",
    # BSDFs
    ("bsdf", "diffuse"): S,
    ("bsdf", "twosided"): S + " (one nested BSDF)",
    ("bsdf", "conductor"): S,
    ("bsdf", "roughconductor"): S + " (anisotropic in the dp/du frame, not nested)",
    ("bsdf", "dielectric"): S,
    ("bsdf", "roughplastic"): S,
    ("bsdf", "plastic"): S,
    ("bsdf", "roughdielectric"): S + " (isotropic)",
    ("bsdf", "thindielectric"): S,
    ("bsdf", "principled"): S + " (anisotropic in the dp/du frame, not nested)",
    ("bsdf", "principledthin"): S + " (anisotropic in the dp/du frame, not nested)",
    ("bsdf", "mask"): S + " (`opacity` a number or texture, one untextured nested BSDF)",
    ("bsdf", "bumpmap"): S + " (one nested bitmap texture, `scale`; not inside a blendbsdf)",
    ("bsdf", "normalmap"): S + " (texture `normalmap`, one nested BSDF; not inside a blendbsdf)",
    ("bsdf", "blendbsdf"): S + " (two nested BSDFs; a texture weight at the top level only)",
    ("bsdf", "pplastic"): S + " (unpolarised, as Mitsuba's RGB variants: rough specular plus "
    "Fresnel-weighted diffuse lobe; anisotropic in the dp/du frame)",
    ("bsdf", "polarizer"): S + " (unpolarised, as Mitsuba's RGB variants: a pass-through of "
    "0.5 x `transmittance`; `theta`, `polarizing` have no effect; not nested)",
    ("bsdf", "circular"): S + " (unpolarised, as Mitsuba's RGB variants: a pass-through of "
    "0.5 x `transmittance`; `left_handed` has no effect; not nested)",
    ("bsdf", "retarder"): S + " (unpolarised, as Mitsuba's RGB variants: a pass-through of "
    "`transmittance`; `theta`, `delta` have no effect; not nested)",
    ("bsdf", "measured"): S + " (RGB `.bsdf` files, not spectral ones; anisotropic ones not "
                              "nested)",
    ("bsdf", "null"): S + " (`Null`: a mask of opacity 0; not nested)",
    ("bsdf", "hair"): S + " (`sigma_a` an RGB or a number, not a texture; not nested)",
    # textures
    ("texture", "bitmap"): S + " (`to_uv` an affine uv map)",
    ("texture", "checkerboard"): S + " (`to_uv` a uniform scale)",
    ("texture", "rawconstant"): S + " (`value` a float or a vector)",
    ("texture", "mesh_attribute"): S + " (vertex_* / face_* of PLY files; not in shapegroups)",
    ("texture", "volume"): "refused: jaxgfx renders surfaces only",
    # emitters
    ("emitter", "area"): S + " (inside a shape; `radiance` an RGB or a bitmap / checkerboard)",
    ("emitter", "point"): S,
    ("emitter", "constant"): S,
    ("emitter", "envmap"): S + " (rotating `to_world`; no scale or shear)",
    ("emitter", "directional"): S,
    ("emitter", "spot"): S + " (a projected `texture` a bitmap)",
    ("emitter", "projector"): S + " (`irradiance` a colour or a bitmap; rigid `to_world`)",
    ("emitter", "directionalarea"): S + " (RGB `radiance`; lit only by the ptracer, as in Mitsuba)",
    ("emitter", "sunsky"): S + " (RGB; `sun_direction` or location / time; `complex_sun`; "
    "rotating `to_world`; `albedo` a colour)",
    # sensors, films, filters, samplers
    ("sensor", "perspective"): S + " (rigid `to_world`)",
    ("sensor", "thinlens"): S + " (rigid `to_world`; `aperture_radius` required)",
    ("sensor", "orthographic"): S + " (as a matrix camera)",
    ("sensor", "radiancemeter"): S + " (a 1 x 1 film; `origin` + `direction` or `to_world`)",
    ("sensor", "irradiancemeter"): S + " (a 1 x 1 film; on a sphere, rectangle or mesh)",
    ("sensor", "distant"): S + " (a 1 x 1 film; `target` a point, a shape or none)",
    ("sensor", "batch"): S + " (perspective, thin-lens and orthographic sensors side by side; "
    "film width divisible by their number)",
    ("film", "hdrfilm"): S,
    ("film", "specfilm"): "refused: spectral variants only, as in Mitsuba, whose RGB variants "
    "refuse it too; jaxgfx renders RGB",
    ("rfilter", "box"): S,
    ("rfilter", "gaussian"): S,
    ("rfilter", "tent"): S,
    ("rfilter", "mitchell"): S + " (`B`, `C`; signed sample weights)",
    ("rfilter", "catmullrom"): S + " (signed sample weights)",
    ("rfilter", "lanczos"): S + " (`lobes`; signed sample weights)",
    ("sampler", "independent"): S,
    ("sampler", "stratified"): S + " (sampled independently)",
    ("sampler", "multijitter"): S + " (sampled independently)",
    ("sampler", "orthogonal"): S + " (sampled independently)",
    ("sampler", "ldsampler"): S + " (sampled independently)",
    # integrators
    ("integrator", "path"): S,
    ("integrator", "direct"): S + " (one sample per strategy)",
    ("integrator", "moment"): S + " (reads the nested integrator)",
    ("integrator", "prb"): S + " (a `PathIntegrator` with adjoint replay; default max_depth 6)",
    ("integrator", "prb_basic"): S + " (as prb with strategy bsdf, no Russian roulette)",
    ("integrator", "direct_projective"): S + " (`direct` with visibility='edge': edge-sampled "
    "boundary gradients; `sppc`/`sppp`/`sppi`, guiding options read and unused; perspective "
    "sensor, box rfilter, no curves)",
    ("integrator", "prb_projective"): S + " (`path` with visibility='edge' and adjoint 'ad'; "
    "default max_depth 6; `sppc`/`sppp`/`sppi`, guiding options read and unused; perspective "
    "sensor, box rfilter, no curves)",
    ("integrator", "volpath"): "refused: jaxgfx renders surfaces only",
    ("integrator", "volpathmis"): "refused: jaxgfx renders surfaces only",
    ("integrator", "ptracer"): S + " (point, spot, directional, area, directionalarea, "
    "constant and envmap emitters; hide_emitters)",
    ("integrator", "aov"): S + " (`aovs` of types albedo, depth, position, geo_normal, "
    "sh_normal; no nested integrator)",
    ("integrator", "stokes"): "refused: polarized variants only, as in Mitsuba, whose RGB "
    "variants refuse it too; jaxgfx renders unpolarized RGB",
}
"""``(tag, type)`` -> status of every Mitsuba 3 plugin the loader knows (tested against the
table in docs/render_scenes.md)."""


def plugin_status(tag: str, type_: str, where: str) -> None:
    """``None`` for a supported plugin, else one ``ValueError`` naming it, ``where``
    (``file:line: <tag type id>``) and why (or the supported ones of that tag)."""
    status = PLUGINS.get((tag, type_))
    if status is not None and status.startswith(S):
        return
    ok = [t for (g, t), s in PLUGINS.items() if g == tag and s.startswith(S)]
    why = status.split(": ", 1)[1] if status else f"unknown plugin; supported: {', '.join(ok)}"
    raise ValueError(f"{where}: {tag} plugin {type_!r} is not supported ({why})")


BSDF_TO_MITSUBA = {
    "Diffuse": "diffuse",
    "Mirror": "conductor",
    "RoughConductor": "roughconductor",
    "SmoothDielectric": "dielectric",
    "RoughDielectric": "roughdielectric",
    "SmoothPlastic": "plastic",
    "RoughPlastic": "roughplastic",
    "PolarizedPlastic": "pplastic",
    "Polarizer": "polarizer",
    "CircularPolarizer": "circular",
    "Retarder": "retarder",
    "ThinDielectric": "thindielectric",
    "BlendBSDF": "blendbsdf",
    "Mask": "mask",
    "Null": "null",
    "Principled": "principled",
    "PrincipledThin": "principledthin",
    "Hair": "hair",
    "Measured": "measured",
}
"""jaxgfx BSDF class -> Mitsuba plugin (``Phong`` has none)."""

ONE_SIDED_BSDFS = (
    "diffuse", "conductor", "roughconductor", "plastic", "roughplastic", "principled", "pplastic",
    "measured",
)  # fmt: skip
"""Mitsuba BSDFs that are black from behind (``principled`` only without ``spec_trans``). The
XML reader loads them ``one_sided: true`` unless a ``twosided`` encloses them; the writer wraps
a two-sided jaxgfx material of these plugins in ``twosided`` and writes a one-sided one bare."""

DEFAULTS = {
    "diffuse.reflectance": 0.5,
    "mask.opacity": 0.5,
    "distribution": "beckmann",
    "alpha": 0.1,
    "sample_visible": True,
    "dielectric.int_ior": "bk7",
    "dielectric.ext_ior": "air",
    "roughplastic.int_ior": "polypropylene",
    "roughplastic.ext_ior": "air",
    "roughplastic.diffuse_reflectance": 0.5,
    "pplastic.int_ior": "polypropylene",
    "pplastic.ext_ior": "air",
    "pplastic.diffuse_reflectance": 0.5,
    "principled.base_color": 0.5,
    "principled.roughness": 0.5,
    "principled.specular": 0.5,
    "principledthin.eta": 1.5,
    "conductor.material": "none",
    "blendbsdf.weight": 0.5,
    "hair.roughness": 0.3,
    "hair.scale_tilt": 2.0,
    "hair.int_ior": "amber",
    "hair.ext_ior": "air",
    "hair.eumelanin": 1.3,
    "hair.pheomelanin": 0.2,
    "spot.cutoff_angle": 20.0,
    "spot.beam_width_fraction": 0.75,
    "directional.direction": (0.0, 0.0, 1.0),
    "film.width": 768,
    "film.height": 576,
    "rfilter": "gaussian",
    "gaussian.stddev": 0.5,
    "tent.radius": 1.0,
    "mitchell.B": 1.0 / 3.0,
    "mitchell.C": 1.0 / 3.0,
    "lanczos.lobes": 3,
    "fov_axis": "x",
    "near_clip": 1e-2,
    "far_clip": 1e4,
    "focal_length": "50mm",
    "sample_count": 4,
    "path.max_depth": -1,
    "path.rr_depth": 5,
    "default_bsdf": "diffuse",
}
"""Mitsuba 3's defaults where a parameter is omitted (its plugin docs; checked in tests)."""

# Mitsuba 3's named indices of refraction (src/render/ior.h, checked against Mitsuba 3.9.1)
IOR_TABLE = {
    "vacuum": 1.0,
    "helium": 1.000036,
    "hydrogen": 1.000132,
    "air": 1.000277,
    "carbon dioxide": 1.00045,
    "water": 1.3330,
    "acetone": 1.36,
    "ethanol": 1.361,
    "carbon tetrachloride": 1.461,
    "glycerol": 1.4729,
    "benzene": 1.501,
    "silicone oil": 1.52045,
    "bromine": 1.661,
    "water ice": 1.31,
    "fused quartz": 1.458,
    "pyrex": 1.470,
    "acrylic glass": 1.49,
    "polypropylene": 1.49,
    "bk7": 1.5046,
    "sodium chloride": 1.544,
    "amber": 1.55,
    "pet": 1.5750,
    "diamond": 2.419,
}

# Mitsuba 3's named conductors: RGB (eta, k) of its measured spectra (``data/ior/NAME.eta.spd``
# and ``NAME.k.spd`` of the mitsuba 3.9.1 wheel, luxpop.com / Palik data; BSD-3-Clause
# repository), reduced by :func:`conductor_ior_from_spd` (= spectrum_to_rgb, emission
# normalisation, as Mitsuba's RGB variants reduce them; agrees with Mitsuba 3.9.1 to the
# tolerance tests/render/test_mitsuba_xml_vs_mitsuba.py states). Regenerate with
# ``conductor_ior_from_spd(os.path.join(os.path.dirname(mitsuba.__file__), "data/ior"), name)``.
CONDUCTOR_IOR = {
    "Ag": ((0.155264, 0.116723, 0.138381), (4.82835, 3.12224, 2.14696)),
    "Al": ((1.65746, 0.880367, 0.521229), (9.22388, 6.26952, 4.83701)),
    "AlAs": ((3.60512, 3.23291, 2.21782), (0.000666607, 0, 0.00742299)),
    "AlAs_palik": ((3.60512, 3.23291, 2.21782), (0.000666607, 0, 0.00742299)),
    "AlSb": ((0, 4.14153, 4.67013), (0, 0.093754, 1.30075)),
    "AlSb_palik": ((0, 4.14153, 4.67013), (0, 0.093754, 1.30075)),
    "Au": ((0.143124, 0.374942, 1.4425), (3.98317, 2.38573, 1.60321)),
    "Be": ((4.18507, 3.18506, 2.7841), (3.83544, 3.01012, 2.86902)),
    "Be_palik": ((4.18507, 3.18506, 2.7841), (3.83544, 3.01012, 2.86902)),
    "Cr": ((4.36969, 2.91671, 1.6547), (5.20644, 4.23136, 3.75497)),
    "CsI": ((2.14491, 1.70231, 1.66242), (0, 0, 0)),
    "CsI_palik": ((2.14491, 1.70231, 1.66242), (0, 0, 0)),
    "Cu": ((0.200417, 0.924044, 1.10221), (3.91294, 2.45284, 2.1422)),
    "Cu2O": ((3.5518, 2.94991, 2.75203), (0.114193, 0.193827, 0.60603)),
    "Cu2O_palik": ((3.5518, 2.94991, 2.75203), (0.114193, 0.193827, 0.60603)),
    "CuO": ((3.24752, 2.4478, 2.21024), (0.521098, 0.570032, 0.722171)),
    "CuO_palik": ((3.24752, 2.4478, 2.21024), (0.521098, 0.570032, 0.722171)),
    "Cu_palik": ((0.212664, 0.919998, 1.10241), (3.92156, 2.45714, 2.13666)),
    "Hg": ((2.39893, 1.44002, 0.909552), (6.32764, 4.37194, 3.4218)),
    "HgTe": ((4.77955, 3.23099, 2.66004), (1.632, 1.58082, 1.72959)),
    "HgTe_palik": ((4.77955, 3.23099, 2.66004), (1.632, 1.58082, 1.72959)),
    "Hg_palik": ((2.39893, 1.44002, 0.909552), (6.32764, 4.37194, 3.4218)),
    "Ir": ((3.08642, 2.08219, 1.61789), (5.59216, 4.06718, 3.26727)),
    "Ir_palik": ((3.08642, 2.08219, 1.61789), (5.59216, 4.06718, 3.26727)),
    "K": ((0.0640497, 0.04641, 0.0381842), (2.10422, 1.34894, 0.913216)),
    "K_palik": ((0.0640497, 0.04641, 0.0381842), (2.10422, 1.34894, 0.913216)),
    "Li": ((0.265787, 0.19561, 0.220919), (3.54017, 2.31113, 1.6686)),
    "Li_palik": ((0.265787, 0.19561, 0.220919), (3.54017, 2.31113, 1.6686)),
    "MgO": ((2.08959, 1.65072, 1.59488), (4.21297e-12, 0, 2.42715e-11)),
    "MgO_palik": ((2.08959, 1.65072, 1.59488), (4.21297e-12, 0, 2.42715e-11)),
    "Mo": ((4.4837, 3.52547, 2.77607), (4.11112, 3.42087, 3.15061)),
    "Mo_palik": ((4.4837, 3.52547, 2.77607), (4.11112, 3.42087, 3.15061)),
    "Na_palik": ((0.0602665, 0.0561412, 0.0619912), (3.1793, 2.11248, 1.5791)),
    "Nb": ((3.42014, 2.79019, 2.39559), (3.44139, 2.73764, 2.57993)),
    "Nb_palik": ((3.42014, 2.79019, 2.39559), (3.44139, 2.73764, 2.57993)),
    "Ni_palik": ((2.36728, 1.66336, 1.46706), (4.49884, 3.05016, 2.34543)),
    "Rh": ((2.5858, 1.86018, 1.55444), (6.7823, 4.70294, 3.9761)),
    "Rh_palik": ((2.5858, 1.86018, 1.55444), (6.7823, 4.70294, 3.9761)),
    "Se": ((4.05897, 2.84272, 2.82076), (0.754382, 0.638518, 0.52158)),
    "Se-e": ((5.72391, 4.16541, 4.08178), (0.871402, 1.10527, 1.56487)),
    "Se-e_palik": ((5.72391, 4.16541, 4.08178), (0.871402, 1.10527, 1.56487)),
    "Se_palik": ((4.05897, 2.84272, 2.82076), (0.754382, 0.638518, 0.52158)),
    "SiC": ((3.17235, 2.52597, 2.47937), (7.27763e-07, 0, 1.00107e-05)),
    "SiC_palik": ((3.17235, 2.52597, 2.47937), (7.27763e-07, 0, 1.00107e-05)),
    "SnTe": ((4.52523, 1.98113, 1.28169), (0, 0, 0)),
    "SnTe_palik": ((4.52523, 1.98113, 1.28169), (0, 0, 0)),
    "Ta": ((2.06258, 2.3931, 2.62808), (2.40804, 1.74136, 1.94704)),
    "Ta_palik": ((2.06258, 2.3931, 2.62808), (2.40804, 1.74136, 1.94704)),
    "Te": ((7.39087, 4.4821, 2.63709), (3.25615, 3.5274, 3.2922)),
    "Te-e": ((7.50905, 4.29646, 2.36987), (5.58423, 4.94764, 3.99752)),
    "Te-e_palik": ((7.50905, 4.29646, 2.36987), (5.58423, 4.94764, 3.99752)),
    "Te_palik": ((7.39087, 4.4821, 2.63709), (3.25615, 3.5274, 3.2922)),
    "ThF4": ((1.83072, 1.44223, 1.38765), (0, 0, 0)),
    "ThF4_palik": ((1.83072, 1.44223, 1.38765), (0, 0, 0)),
    "TiC": ((3.70047, 2.83743, 2.58231), (3.2657, 2.35156, 2.17279)),
    "TiC_palik": ((3.70047, 2.83743, 2.58231), (3.2657, 2.35156, 2.17279)),
    "TiN": ((1.64847, 1.15044, 1.37978), (3.36847, 1.94349, 1.10201)),
    "TiN_palik": ((1.64847, 1.15044, 1.37978), (3.36847, 1.94349, 1.10201)),
    "TiO2": ((3.45663, 2.8017, 2.90515), (0.000102635, 0, 0.000635436)),
    "TiO2-e": ((3.10656, 2.51315, 2.58239), (2.89479e-05, 0, 0.000177501)),
    "TiO2-e_palik": ((3.10656, 2.51315, 2.58239), (2.89479e-05, 0, 0.000177501)),
    "TiO2_palik": ((3.45663, 2.8017, 2.90515), (0.000102635, 0, 0.000635436)),
    "VC": ((3.65757, 2.75273, 2.53269), (3.06836, 2.19867, 1.96319)),
    "VC_palik": ((3.65757, 2.75273, 2.53269), (3.06836, 2.19867, 1.96319)),
    "VN": ((2.86561, 2.11918, 1.94008), (3.03233, 2.05611, 1.6163)),
    "VN_palik": ((2.86561, 2.11918, 1.94008), (3.03233, 2.05611, 1.6163)),
    "V_palik": ((4.27752, 3.51316, 2.76113), (3.49119, 2.88935, 3.11171)),
    "W": ((4.3707, 3.3003, 2.99827), (3.50068, 2.60486, 2.2732)),
    "a-C": ((2.94411, 2.22715, 1.96817), (0.887433, 0.799322, 0.815288)),
    "d-C": ((2.71016, 2.31869, 2.22889), (0, 0, 0)),
    "d-C_palik": ((2.71016, 2.31869, 2.22889), (0, 0, 0)),
}


def read_spd(path) -> tuple[np.ndarray, np.ndarray]:
    """Wavelengths (nm) and values of a Mitsuba ``.spd`` file (``lambda value`` rows, ``#``
    comments)."""
    rows = []
    with open(path) as f:
        for line in f:
            line = line.split("#", 1)[0].strip()
            if line:
                rows.append([float(x) for x in line.split()[:2]])
    a = np.asarray(rows, np.float64)
    if a.ndim != 2 or a.shape[0] < 2:
        raise ValueError(f"{path}: expected at least two 'wavelength value' rows")
    return a[:, 0], a[:, 1]


def conductor_ior_from_spd(folder, name) -> tuple[np.ndarray, np.ndarray]:
    """RGB ``(eta, k)`` of the conductor ``name`` from ``folder/NAME.eta.spd`` and
    ``NAME.k.spd``, reduced as Mitsuba 3's RGB variants do (:func:`spectrum_to_rgb`, not
    weighted by an illuminant, negative components clamped to 0 as Mitsuba clamps them)."""
    eta = spectrum_to_rgb(*read_spd(os.path.join(folder, f"{name}.eta.spd")), emission=True)
    k = spectrum_to_rgb(*read_spd(os.path.join(folder, f"{name}.k.spd")), emission=True)
    return np.maximum(eta, 0.0), np.maximum(k, 0.0)  # Mitsuba clamps out-of-gamut colours


def spectrum_to_rgb(wavelengths, values, *, emission: bool) -> np.ndarray:
    """Linear sRGB of a piecewise-linear spectrum as Mitsuba 3's RGB variants compute it.

    The spectrum is zero outside ``[wavelengths[0], wavelengths[-1]]`` (nm). ``emission``:
    integrate against the CIE 1931 2 degree CMFs and divide by the integral of y-bar (radiance,
    intensity, conductor IORs); else weight by illuminant D65 and divide by the luminance of
    D65 (reflectances). 1000 samples over 360-830 nm, XYZ -> linear sRGB.

    Example: a constant reflectance 0.5 from 360 to 830 nm gives about (0.5, 0.5, 0.5).
    """
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour

        cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
        lam = np.linspace(360.0, 830.0, 1000)
        xyz = np.asarray(cmfs[lam], np.float64)
        w = np.ones_like(lam) if emission else np.asarray(colour.SDS_ILLUMINANTS["D65"][lam])
    wl, v = np.asarray(wavelengths, np.float64), np.asarray(values, np.float64)
    s = np.interp(lam, wl, v)
    s[(lam < wl[0]) | (lam > wl[-1])] = 0.0
    total = (xyz * (s * w)[:, None]).sum(0) / (xyz[:, 1] * w).sum()
    to_srgb = np.array(
        [
            [3.240479, -1.537150, -0.498535],
            [-0.969256, 1.875991, 0.041556],
            [0.055648, -0.204043, 1.057311],
        ]
    )
    return to_srgb @ total


def swap_scalar_checkerboard(tex):
    """A ``checkerboard`` texture description with ``color0`` and ``color1`` exchanged (any
    other texture unchanged), for a checkerboard that sets a *scalar* parameter (roughness
    ``alpha``, a ``blendbsdf`` ``weight``, the ``principled`` weights).

    Mitsuba 3 (3.9.1, ``src/textures/checkerboard.cpp``) evaluates one checkerboard two ways:
    ``eval`` (RGB parameters) gives ``color0`` where ``frac(u) > 1/2`` equals
    ``frac(v) > 1/2``, ``eval_1`` (scalar parameters) gives ``color0`` where they differ. jaxgfx
    has the one pattern of ``eval`` for both, so the loader swaps the colours of a scalar
    parameter's checkerboard and the writer swaps them back: the same scene in both renderers
    (``tests/render/test_mitsuba_xml_textured_write.py``)."""
    if isinstance(tex, dict) and tex.get("type") == "checkerboard":
        return {**tex, "color0": tex["color1"], "color1": tex["color0"]}
    return tex


def look_at_matrix(origin, target, up) -> np.ndarray:
    """Mitsuba's ``Transform4f.look_at``: columns ``(left, up', dir, origin)``; ``ValueError``
    when origin and target coincide or up is parallel to the viewing direction."""
    o, t, u = (np.asarray(x, np.float64) for x in (origin, target, up))
    d = t - o
    if not np.linalg.norm(d) > 0:
        raise ValueError("origin and target coincide")
    d = d / np.linalg.norm(d)
    left = np.cross(u, d)
    if not np.linalg.norm(left) > 0:
        raise ValueError("up is parallel to the viewing direction")
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(d, left), d, o
    return m


def _ortho_ndc_to_camera(near_clip, width, height) -> np.ndarray:
    a = width / height
    c = np.eye(4)
    c[0, 0], c[1, 1], c[2, 3] = -1.0, 1.0 / a, near_clip + 1.0
    return c


def orthographic_view_proj_inverse(to_world, near_clip, width, height) -> np.ndarray:
    """Mitsuba 3's ``orthographic`` sensor as the ``view_proj_inverse`` (OpenGL NDC -> world)
    of a jaxgfx :class:`~jaxgfx.render.camera.MatrixCamera` with the same rays.

    Mitsuba (``orthographic_projection``, ``sensors/orthographic.cpp``) maps the film position
    ``(s_x, s_y)`` in ``[0, 1]^2`` (from the top left) to the camera-space point
    ``(1 - 2 s_x, (1 - 2 s_y) / a, near_clip)``, ``a = width / height`` (the film width spans
    ``[-1, 1]``; image left is camera +x, the ``left`` of its ``look_at``), starts the ray at
    ``to_world`` of that point and sends it along ``normalize(to_world (0, 0, 1))``. With jaxgfx's
    NDC ``x = 2 s_x - 1``, ``y = 1 - 2 s_y``: NDC ``(x, y, z)`` -> camera
    ``(-x, y / a, near_clip + 1 + z)``, so the near point (``z = -1``) is Mitsuba's ray origin
    and the far one (``z = 1``) lies 2 camera units further along +z (jaxgfx does not clip at
    ``far_clip``; the loader checks that nothing lies beyond it). Returns ``to_world @ C``.

    Example: the identity ``to_world`` with ``near_clip = 0``, a square film: the centre ray
    starts at the origin and points along +z.
    """
    m = np.asarray(to_world, np.float64)
    return m @ _ortho_ndc_to_camera(float(near_clip), width, height)


def orthographic_to_world(view_proj_inverse, width, height, near_clip=1e-2):
    """The ``to_world`` of a Mitsuba ``orthographic`` sensor (with ``near_clip``) whose rays
    are those of a :class:`~jaxgfx.render.camera.MatrixCamera` with this affine
    ``view_proj_inverse`` (the inverse of :func:`orthographic_view_proj_inverse`), or ``None``
    when the matrix is projective (last row not ``(0, 0, 0, 1)``: no orthographic sensor)."""
    m = np.asarray(view_proj_inverse, np.float64)
    if not np.allclose(m[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=1e-7 * np.abs(m).max()):
        return None
    m = m.copy()
    m[3] = [0.0, 0.0, 0.0, 1.0]
    return m @ np.linalg.inv(_ortho_ndc_to_camera(float(near_clip), width, height))


def rectangle_to_world(center, edge_u, edge_v) -> np.ndarray:
    """Mitsuba ``rectangle`` (``[-1, 1]^2`` in its local xy plane, normal +z) ``to_world``
    of jaxgfx's parallelogram ``center +- edge_u / 2 +- edge_v / 2``: columns
    ``(edge_u / 2, edge_v / 2, n, center)``, ``n = normalize(edge_u x edge_v)`` (same corners,
    uv and normal; the loader reads ``edge_u = 2 to_world[:, 0]`` back)."""
    eu, ev, c = (np.asarray(x, np.float64) for x in (edge_u, edge_v, center))
    n = np.cross(eu, ev)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = eu / 2, ev / 2, n / np.linalg.norm(n), c
    return m


ENVMAP_ROW_FACTOR = 4


def envmap_for_mitsuba(image) -> np.ndarray:
    """Re-grid a jaxgfx lat-long map ``(H, W, 3)`` so Mitsuba 3's lookup reproduces jaxgfx's.

    jaxgfx interpolates bilinearly between texel centres ``v_j = (j + 0.5) / H`` and clamps
    beyond the first/last centre; Mitsuba 3 interpolates between rows at ``v_j = j / (H' - 1)``.
    The returned ``(2H + 1, W, 3)`` map holds, at ``v = k / 2H``: the clamped first row
    (``k = 0``), the texel rows (odd ``k``), the averages of neighbouring rows (even ``k``) and
    the clamped last row (``k = 2H``). jaxgfx's lookup is linear in v between these knots, so
    Mitsuba's piecewise-linear interpolation equals it exactly. Columns (u) already agree.
    Negative values are clamped to 0 as in :class:`jaxgfx.render.emitters.EnvironmentMap`.

    Example: a 2-row map with rows 0 and 1 becomes rows ``[0, 0, 0.5, 1, 1]``.
    """
    img = np.asarray(image, np.float32)
    if img.ndim != 3 or img.shape[-1] < 3 or min(img.shape[:2]) < 2:
        raise ValueError(f"envmap.image: expected (H>=2, W>=2, 3), got shape {img.shape}")
    img = np.maximum(img[..., :3], 0.0)
    h, w = img.shape[:2]
    out = np.empty((2 * h + 1, w, 3), np.float32)
    out[0] = img[0]
    out[1::2] = img
    out[2:-1:2] = 0.5 * (img[:-1] + img[1:])
    out[-1] = img[-1]
    return out


def envmap_from_mitsuba(image, factor: int = ENVMAP_ROW_FACTOR) -> np.ndarray:
    """Resample a Mitsuba 3 lat-long map ``(H, W, 3)`` (rows at ``v = j / (H - 1)``) for
    jaxgfx's lookup (texel centres at ``v = (i + 1/2) / H'``): ``H' = factor * H`` rows, row
    ``i`` = Mitsuba's linear interpolation at ``(i + 1/2) / H'``. Columns are unchanged (both
    place them at ``(k + 1/2) / W``). jaxgfx then interpolates linearly between these samples
    of Mitsuba's piecewise-linear profile; the two differ only in the sub-rows around each of
    Mitsuba's rows (the resampled profile cuts the corner) and in the half sub-row next to each
    pole (clamped).

    Example: a 2-row map with rows 0 and 1 and ``factor=1`` gives rows 0.25 and 0.75.
    """
    img = np.asarray(image, np.float64)[..., :3]
    h = img.shape[0]
    n = factor * h
    v = (np.arange(n) + 0.5) / n * (h - 1)
    j0 = np.clip(np.floor(v).astype(int), 0, h - 2)
    f = (v - j0)[:, None, None]
    return ((1 - f) * img[j0] + f * img[j0 + 1]).astype(np.float32)
