"""One spelling per concept (docs/architecture.md, "Who owns which concept"): the names that
must survive in two places are the same object as their owner's, and the owner's constants are
not retyped anywhere else in the library (a scan of the source)."""

import os
import re

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_aliases_are_their_owners_objects():
    from jaxgfx import color, hdr, io
    from jaxgfx.hdr import raw_calibration
    from jaxgfx.image import bayer
    from jaxgfx.pipelines import fit
    from jaxgfx.render.bsdf import textured
    from jaxgfx.tonemap import _global

    assert raw_calibration.CFA_PATTERNS is bayer.BAYER_PATTERNS
    assert _global._ACES is color.ACES_NARKOWICZ2015
    assert textured._LUMA is color.LUMINANCE_WEIGHTS["rec709"]
    assert set(hdr.SYNTHETIC_RESPONSES) - {"gamma2.2"} == set(hdr.ANALYTIC_RESPONSES) - {"linear"}
    assert fit.RESPONSE_MODELS == ("gamma", "table", *hdr.ANALYTIC_RESPONSES)
    assert set(hdr.RESPONSE_KINDS) == {"table", "gamma", "polynomial", *hdr.ANALYTIC_RESPONSES}
    assert io.kind_of("a.NRW") == "raw" and io.kind_of("x.exr") == "hdr"
    assert io.kind_of("y.jpeg") == "ldr" and io.kind_of("z.npy") == "npy"
    assert io.kind_of("w.txt") is None


def test_the_jobs_extension_lists_are_ios():
    """The jobs' output (and input) extensions are jaxgfx.io's tables, not copies."""
    from jaxgfx import io
    from jaxgfx.pipelines import _output, filter_ops, fuse, render, tonemap

    assert _output.WRITABLE_EXTENSIONS is io.WRITE_EXTENSIONS
    assert render._LINEAR_EXT is io.LINEAR_WRITE_EXTENSIONS
    assert render._DISPLAY_EXT is io.DISPLAY_WRITE_EXTENSIONS
    for m in (fuse, filter_ops, tonemap):
        assert m._DISPLAY_EXT is io.LDR_WRITE_EXTENSIONS
    assert set(tonemap._INPUT_EXT) == io.HDR_EXTENSIONS
    assert set(io.WRITE_EXTENSIONS) == set(io.LINEAR_WRITE_EXTENSIONS) | set(
        io.DISPLAY_WRITE_EXTENSIONS
    )
    assert {io.kind_of("a" + e) for e in io.HDR_WRITE_EXTENSIONS} == {"hdr"}
    assert {io.kind_of("a" + e) for e in io.LDR_WRITE_EXTENSIONS} == {"ldr"}


def test_the_filmic_response_is_the_aces_fit():
    """hdr's "filmic" camera curve is the colour module's ACES fit, f(4x) / f(4)."""
    import jax.numpy as jnp
    import numpy as np

    from jaxgfx import color, hdr

    x = jnp.linspace(0.0, 1.0, 11)
    r = hdr.CameraResponse.analytic("filmic", anchor="unit")
    want = color.aces_narkowicz2015(4.0 * x) / color.aces_narkowicz2015(4.0)
    np.testing.assert_allclose(np.asarray(r.from_linear_normalized(x[:, None]))[:, 0], want,
                               rtol=1e-6, atol=1e-7)  # fmt: skip


_IMG = r"\"\.(?:exr|hdr|pic|rgbe|png|jpe?g|tiff?|bmp)\""  # a quoted image file extension
# (constant, where it may be written): retyping it elsewhere is a second spelling
OWNED = [
    (r"0\.2126\b", ("jaxgfx/color/",)),  # Rec. 709 luminance weights
    (r"0\.0031308\b|0\.04045\b", ("jaxgfx/color/",)),  # sRGB knees
    (r"\b2\.51\b", ("jaxgfx/color/",)),  # the ACES fit's coefficients
    (r"\"BGGR\"", ("jaxgfx/image/bayer.py",)),  # Bayer tiles
    (r"\"\.nef\"|\"\.cr2\"", ("jaxgfx/io/_dispatch.py",)),  # camera raw extensions
    (rf"{_IMG}\s*,\s*\"\.\w+\"|\"\.\w+\"\s*,\s*{_IMG}", ("jaxgfx/io/",)),  # image extension lists
]


@pytest.mark.parametrize(("pattern", "owners"), OWNED)
def test_owned_constants_are_not_retyped(pattern, owners):
    rx = re.compile(pattern)
    bad = []
    for dp, dirs, files in os.walk(os.path.join(ROOT, "jaxgfx")):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        for f in files:
            if not f.endswith(".py"):
                continue
            path = os.path.join(dp, f)
            rel = os.path.relpath(path, ROOT).replace(os.sep, "/")
            if rel.startswith(owners):
                continue
            with open(path, encoding="utf-8") as fh:
                for n, line in enumerate(fh, 1):
                    code = line.split("#")[0]
                    if rx.search(code) and '``' not in code and not code.strip().startswith(
                        ('"', "'", "f(x)")
                    ):
                        bad.append(f"{rel}:{n}: {line.strip()}")
    assert bad == []


# hand-written "expected one of" messages that check_choice (a string among fixed names)
# cannot give: file -> why. Every other choice error goes through jaxgfx._checks.check_choice.
CHOICE_MESSAGES_ALLOWED = {
    "jaxgfx/_checks.py": "check_choice itself",
    "jaxgfx/config.py": "typing.Literal values of any type",
    "jaxgfx/render/scene/mitsuba_xml.py": "the XML file and line come first (self.err)",
    "jaxgfx/render/bsdf/__init__.py": "an unknown parameter key of a BSDF type",
    "jaxgfx/hdr/camera.py": "integer bit depths",
    "jaxgfx/color/spaces.py": "a white point name or an xy / XYZ array",
}


def test_choice_errors_go_through_check_choice():
    found = set()
    for dp, dirs, files in os.walk(os.path.join(ROOT, "jaxgfx")):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        for f in files:
            if f.endswith(".py"):
                path = os.path.join(dp, f)
                with open(path, encoding="utf-8") as fh:
                    if "expected one of" in fh.read():
                        found.add(os.path.relpath(path, ROOT).replace(os.sep, "/"))
    assert sorted(found - set(CHOICE_MESSAGES_ALLOWED)) == []  # use check_choice there
    assert sorted(set(CHOICE_MESSAGES_ALLOWED) - found) == []  # stale entries
