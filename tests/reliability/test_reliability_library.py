# ruff: noqa: E501, B008  (a table of cases: one case per line reads best)
"""The library over a table of bad inputs: each case is a clear error naming the argument
(exception class and a substring of the message) or a correct result.

Cases run before any tracing (the checks are at the Python boundary), so hundreds cost
seconds; the few that compute use tiny arrays.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np
import pytest

from jaxgfx import hdr, image, io
from jaxgfx.config import load_config, read_yaml
from jaxgfx.pipelines.calibrate import CalibrateConfig


@dataclasses.dataclass(frozen=True)
class Err:
    """The call raises ``exc`` and its message contains ``needle``."""

    exc: type
    needle: str


@dataclasses.dataclass(frozen=True)
class Ok:
    """The call returns a value for which ``check(value)`` is true."""

    check: Callable


CASES: list[tuple[str, Callable, object]] = []


def case(name, outcome):
    def deco(fn):
        CASES.append((name, fn, outcome))
        return fn

    return deco


def add(name, fn, outcome):
    CASES.append((name, fn, outcome))


# ----------------------------------------------------------------------------- exposure times

for text, want in [("1/250", 0.004), ("0.5", 0.5), (" 1/8 ", 0.125), ("2", 2.0), (30, 30.0)]:
    add(f"time-ok-{text!r}", lambda t=text: io.parse_exposure_time(t), Ok(lambda v, w=want: v == w))
for bad in ["1/0", "0", "-1", "abc", "", "nan", "inf", "1/", "/2", "1e400", "0/5", "-1/4", "1,5"]:
    add(f"time-bad-{bad!r}", lambda t=bad: io.parse_exposure_time(t, "--times [0]"),
        Err(ValueError, "--times [0]"))  # fmt: skip
for bad in [None, True, [1.0], {"t": 1}, float("nan"), -0.0, 0]:
    add(
        f"time-bad-type-{bad!r}",
        lambda t=bad: io.parse_exposure_time(t, "t"),
        Err(ValueError, "t:"),
    )
add(
    "order-stable",
    lambda: io.exposure_order([2.0, 1.0, 2.0]).tolist(),
    Ok(lambda v: v == [1, 0, 2]),
)

# ----------------------------------------------------------------------------- config

SECTIONS = {"": None, "synthetic": None, "response": None, "merge": None, "align": None}
for section in SECTIONS:
    for key in ("bogus", "Method", "weighting_", "smoothness"):
        data = {key: 1} if not section else {section: {key: 1}}
        where = f"{section}.{key}" if section else key
        add(f"config-unknown-{where}", lambda d=data: load_config(CalibrateConfig, d),
            Err(ValueError, f"unknown config key(s) {where}"))  # fmt: skip

WRONG = {
    int: ["abc", 1.5, True, None, [1]],
    float: ["abc", True, None, [1.0], {"a": 1}],
    str: [3, None, [1], True],
    bool: ["yes", 1, None],
    "times": ["abc", 3, {"a": 1}, [1.0, "x"]],
    "strs": ["debevec", 3, [1]],
    dict: [[1], "x", 3],
}
FIELDS = {
    "synthetic.seed": int,
    "synthetic.height": int,
    "synthetic.width": int,
    "synthetic.dynamic_range": float,
    "synthetic.response": str,
    "synthetic.exposure_times": "times",
    "synthetic.bits": int,
    "synthetic.gain": float,
    "synthetic.read_sigma": float,
    "response.method": str,
    "response.options": dict,
    "response.compare": "strs",
    "merge.weighting": str,
    "align.enabled": bool,
    "align.method": str,
    "demosaic": str,
    "preview_key": float,
    "exposure_times": "times",
}


def _nested(path, value):
    d: dict = {}
    cur = d
    *heads, last = path.split(".")
    for h in heads:
        cur[h] = {}
        cur = cur[h]
    cur[last] = value
    return d


for path, kind in FIELDS.items():
    for v in WRONG[kind]:
        if path == "exposure_times" and v is None:
            continue  # null = read the times from the files
        add(f"config-type-{path}={v!r}", lambda d=_nested(path, v): load_config(CalibrateConfig, d),
            Err(ValueError, path))  # fmt: skip

for path, v in [
    ("synthetic.height", 4), ("synthetic.width", 0), ("synthetic.bits", 12),
    ("synthetic.exposure_times", [1.0]), ("synthetic.exposure_times", [1.0, -2.0]),
    ("synthetic.dynamic_range", 0.5), ("synthetic.gain", -1.0), ("synthetic.read_sigma", -0.1),
    ("synthetic.response", "linear"), ("synthetic.seed", -1), ("response.method", "Debevec"),
    ("merge.weighting", "noise"), ("merge.weighting", "median"), ("align.method", "orb"),
    ("demosaic", "AHD"), ("preview_key", -1.0), ("preview_key", float("nan")),
    ("preview_key", float("inf")), ("exposure_times", [0.0, 1.0]), ("exposure_times", [-1.0]),
    ("response.options", {"n_samples": 0}), ("response.options", {"n_samples": 1.5}),
    ("response.options", {"n_samples": "many"}), ("response.options", {"lambda": 1.0}),
]:  # fmt: skip
    add(f"config-value-{path}={v!r}", lambda d=_nested(path, v): load_config(CalibrateConfig, d),
        Err(ValueError, path.split(".")[-1] if path.startswith("response.options") else path))  # fmt: skip

for section in ("synthetic", "response", "merge", "align"):
    for v in (3, "x", [1]):
        add(f"config-section-{section}={v!r}", lambda d={section: v}: load_config(CalibrateConfig, d),
            Err(ValueError, section))  # fmt: skip

add("config-ok-lam", lambda: load_config(CalibrateConfig, {"response": {"options": {"lam": 5.0}}}),
    Ok(lambda c: c.response.options == {"lam": 5.0}))  # fmt: skip
for m, opt in [("robertson", "n_iter"), ("gamma", "max_steps"), ("polynomial", "degree"),
               ("spline", "n_knots"), ("debevec", "n_levels")]:  # fmt: skip
    add(f"config-ok-{m}-{opt}",
        lambda m=m, o=opt: load_config(CalibrateConfig, {"response": {"method": m, "options": {o: 8}}}),
        Ok(lambda c: True))  # fmt: skip
    add(f"config-option-of-other-method-{m}",
        lambda m=m: load_config(CalibrateConfig, {"response": {"method": m, "options": {"bogus": 1}}}),
        Err(ValueError, "response.options: method"))  # fmt: skip


@pytest.fixture(scope="module")
def yaml_files(tmp_path_factory):
    root = tmp_path_factory.mktemp("yaml")
    texts = {
        "syntax": "synthetic: {height: 16\n",
        "tabs": "synthetic:\n\theight: 16\n",
        "list": "- 1\n- 2\n",
        "scalar": "42\n",
        "binary": b"\xff\xfe\x00garbage\x80",
        "empty": "",
    }
    out = {}
    for k, t in texts.items():
        p = root / f"{k}.yaml"
        p.write_bytes(t if isinstance(t, bytes) else t.encode())
        out[k] = p
    out["missing"] = root / "missing.yaml"
    out["folder"] = root
    return out


YAML_CASES = [
    ("syntax", Err(ValueError, "syntax.yaml: not valid YAML")),
    ("tabs", Err(ValueError, "tabs.yaml: not valid YAML")),
    ("list", Err(ValueError, "list.yaml: expected a mapping")),
    ("scalar", Err(ValueError, "scalar.yaml: expected a mapping")),
    ("binary", Err(ValueError, "binary.yaml: not a UTF-8")),
    ("empty", Ok(lambda d: d == {})),
    ("missing", Err(FileNotFoundError, "missing.yaml")),
    ("folder", Err(IsADirectoryError, "config: is a folder")),
]

# ----------------------------------------------------------------------------- image functions

IMAGE_FUNCS = {
    "gaussian_blur": lambda x: image.gaussian_blur(x, 1.0),
    "box_blur": lambda x: image.box_blur(x, 3),
    "median_filter": lambda x: image.median_filter(x, 3),
    "bilateral_filter": lambda x: image.bilateral_filter(x, 2.0, 0.1),
    "unsharp_mask": lambda x: image.unsharp_mask(x, 1.0, 1.0),
    "laplacian_of_gaussian": lambda x: image.laplacian_of_gaussian(x, 1.0),
    "sharpen": lambda x: image.sharpen(x),
    "canny": lambda x: image.canny(x, 1.0),
    "sobel": lambda x: image.sobel(x),
    "stretch_contrast": lambda x: image.stretch_contrast(x),
    "gamma_correct": lambda x: image.gamma_correct(x, 0.5),
    "equalize_histogram": lambda x: image.equalize_histogram(x),
    "fourier_lowpass": lambda x: image.fourier_lowpass(x, 0.1),
}
BAD_IMAGES = [
    ("empty-0x5", np.zeros((0, 5), np.float32), Err(ValueError, "image")),
    ("empty-0x0x3", np.zeros((0, 0, 3), np.float32), Err(ValueError, "image")),
    ("nan", np.full((4, 4), np.nan, np.float32), Err(ValueError, "image: expected finite")),
    ("inf", np.full((4, 4, 3), np.inf, np.float32), Err(ValueError, "image: expected finite")),
    ("1-d", np.zeros(5, np.float32), Err(ValueError, "image: expected at least 2 dimensions")),
    ("0-d", np.float32(1.0), Err(ValueError, "image: expected at least 2 dimensions")),
    ("string", "image.png", Err(TypeError, "image")),
    ("none", None, Err(TypeError, "image")),
    ("bool", np.ones((4, 4), bool), Err(TypeError, "image")),
]
ELEMENTWISE = {"gamma_correct"}  # any shape is an image of values: the result keeps it
for fname, fn in IMAGE_FUNCS.items():
    for iname, arr, outcome in BAD_IMAGES:
        if fname in ELEMENTWISE and iname in ("empty-0x5", "empty-0x0x3", "1-d", "0-d"):
            outcome = Ok(lambda y, a=arr: np.shape(y) == np.shape(a))
        add(f"image-{fname}-{iname}", lambda fn=fn, a=arr: fn(a), outcome)

BAD_PARAMS = [
    ("gaussian-sigma-neg", lambda x: image.gaussian_blur(x, -1.0), Err(ValueError, "sigma")),
    ("gaussian-sigma-nan", lambda x: image.gaussian_blur(x, float("nan")), Err(ValueError, "sigma")),
    ("gaussian-padding", lambda x: image.gaussian_blur(x, 1.0, padding="mirror"), Err(ValueError, "padding")),
    ("box-size-0", lambda x: image.box_blur(x, 0), Err(ValueError, "size")),
    ("box-size-float", lambda x: image.box_blur(x, 2.5), Err((ValueError, TypeError), "size")),
    ("median-size-even", lambda x: image.median_filter(x, 4), Err(ValueError, "size")),
    ("median-size-0", lambda x: image.median_filter(x, 0), Err(ValueError, "size")),
    ("bilateral-sigma-range-0", lambda x: image.bilateral_filter(x, 2.0, 0.0), Err(ValueError, "sigma_range")),
    ("bilateral-sigma-spatial-neg", lambda x: image.bilateral_filter(x, -2.0, 0.1), Err(ValueError, "sigma_spatial")),
    ("unsharp-threshold-neg", lambda x: image.unsharp_mask(x, 1.0, 1.0, threshold=-1.0), Err(ValueError, "threshold")),
    ("log-sigma-0", lambda x: image.laplacian_of_gaussian(x, 0.0), Err(ValueError, "sigma")),
    ("log-sigma-tiny", lambda x: image.laplacian_of_gaussian(x, 1e-30), Err(ValueError, "sigma")),
    ("canny-low-gt-high", lambda x: image.canny(x, 1.0, 0.5, 0.1), Err(ValueError, "low")),
    ("canny-quantile-gt-1", lambda x: image.canny(x, 1.0, 0.1, 2.0, use_quantiles=True), Err(ValueError, "high")),
    ("canny-sigma-neg", lambda x: image.canny(x, -1.0), Err(ValueError, "sigma")),
    ("stretch-low-gt-high", lambda x: image.stretch_contrast(x, low=0.9, high=0.1), Err(ValueError, "low")),
    ("equalize-bins-0", lambda x: image.equalize_histogram(x, bins=0), Err(ValueError, "bins")),
    ("lowpass-cutoff-neg", lambda x: image.fourier_lowpass(x, -0.1), Err(ValueError, "cutoff")),
    ("sobel-padding", lambda x: image.sobel(x, padding="nope"), Err(ValueError, "padding")),
    ("demosaic-pattern", lambda x: image.demosaic(x, "RGBX"), Err(ValueError, "pattern")),
]  # fmt: skip
for name, fn, outcome in BAD_PARAMS:
    add(f"param-{name}", lambda fn=fn: fn(np.zeros((8, 8), np.float32)), outcome)

# ----------------------------------------------------------------------------- HDR

_rng = np.random.default_rng(0)
STACK = (_rng.random((3, 8, 8, 3)) * 200 + 20).astype(np.uint8)
T3 = [1.0, 2.0, 4.0]
RESP = hdr.CameraResponse.gamma(2.2)
HDR_BAD = [
    ("times-short", STACK, [1.0, 2.0], Err(ValueError, "exposure_times: expected shape (3,)")),
    ("times-2d", STACK, [[1.0, 2.0, 4.0]], Err(ValueError, "exposure_times")),
    ("times-zero", STACK, [0.0, 2.0, 4.0], Err(ValueError, "exposure_times: expected finite values > 0")),
    ("times-neg", STACK, [-1.0, 2.0, 4.0], Err(ValueError, "exposure_times")),
    ("times-nan", STACK, [np.nan, 2.0, 4.0], Err(ValueError, "exposure_times")),
    ("times-inf", STACK, [np.inf, 2.0, 4.0], Err(ValueError, "exposure_times")),
    ("times-none", STACK, None, Err(TypeError, "exposure_times")),
    ("times-str", STACK, "1,2,4", Err(TypeError, "exposure_times")),
    ("images-2d", STACK[0, ..., 0], T3, Err(ValueError, "images: expected shape")),
    ("images-5d", STACK[None], T3, Err(ValueError, "images: expected shape")),
    ("images-bool", STACK > 100, T3, Err(TypeError, "images")),
    ("images-int32", STACK.astype(np.int32), T3, Err(TypeError, "images")),
    ("images-float-range", STACK.astype(np.float32), T3, Err(ValueError, "images: float pixels must be normalised")),
    ("images-nan", np.full((3, 8, 8, 3), np.nan, np.float32), T3, Err(ValueError, "images")),
    ("images-empty", np.zeros((3, 0, 8, 3), np.uint8), T3, Err(ValueError, "images: expected a non-empty")),
    ("images-str", "stack", T3, Err(TypeError, "images")),
    ("images-ragged", [STACK[0], STACK[1, :4], STACK[2]], T3, Err(ValueError, "same shape")),
    ("images-mixed-dtype", [STACK[0], STACK[1].astype(np.uint16), STACK[2]], T3, Err(TypeError, "dtype")),
]  # fmt: skip
for name, ims, t, outcome in HDR_BAD:
    add(f"recover-{name}", lambda i=ims, t=t: hdr.recover_response(i, t), outcome)
    add(f"merge-{name}", lambda i=ims, t=t: hdr.merge_radiance(i, t, RESP), outcome)
add(
    "recover-one-frame",
    lambda: hdr.recover_response(STACK[:1], [1.0]),
    Err(ValueError, "at least 2"),
)
add("recover-equal-times", lambda: hdr.recover_response(STACK, [2.0, 2.0, 2.0]),
    Err(ValueError, "2 distinct exposure times"))  # fmt: skip
add(
    "recover-method",
    lambda: hdr.recover_response(STACK, T3, method="Debevec"),
    Err(ValueError, "method"),
)
for m in sorted(hdr.RESPONSE_METHODS):
    add(f"recover-{m}-unknown-option", lambda m=m: hdr.recover_response(STACK, T3, method=m, bogus=1),
        Err(ValueError, f"method {m!r} has no option 'bogus'"))  # fmt: skip
    for n in (0, 31, 1.5, "many", True):
        add(f"recover-{m}-n_samples={n!r}",
            lambda m=m, n=n: hdr.recover_response(STACK, T3, method=m, n_samples=n),
            Err(ValueError, "n_samples: expected an integer >= 32"))  # fmt: skip
    for level in (255, 0):
        add(f"recover-{m}-all-{level}",
            lambda m=m, v=level: hdr.recover_response(np.full((3, 8, 8, 3), v, np.uint8), T3, method=m),
            Err(ValueError, "too few usable pixels"))  # fmt: skip
    add(f"recover-{m}-15-usable",
        lambda m=m: hdr.recover_response(np.where(np.arange(64).reshape(1, 8, 8, 1) < 15, STACK, 255).astype(np.uint8), T3, method=m),
        Err(ValueError, "15 per channel"))  # fmt: skip
add(
    "merge-weighting",
    lambda: hdr.merge_radiance(STACK, T3, RESP, weighting="box"),
    Err(ValueError, "weighting"),
)
add(
    "merge-domain",
    lambda: hdr.merge_radiance(STACK, T3, RESP, domain="exp"),
    Err(ValueError, "domain"),
)
add(
    "merge-response-type",
    lambda: hdr.merge_radiance(STACK, T3, "gamma"),
    Err(TypeError, "response"),
)
add(
    "merge-noise-missing",
    lambda: hdr.merge_radiance(STACK, T3, RESP, weighting="noise"),
    Err(ValueError, "noise"),
)
add("merge-channels", lambda: hdr.merge_radiance(STACK, T3, hdr.CameraResponse.gamma(2.2, channels=2)),
    Err(ValueError, "response: has 2 channels"))  # fmt: skip

# ----------------------------------------------------------------------------- writers (data)

for ext, fn in [
    (".png", io.write_png),
    (".exr", io.write_exr),
    (".hdr", io.write_hdr),
    (".any.png", io.write_any),
]:
    for name, arr, exc in [
        ("empty", np.zeros((0, 4, 3), np.float32), ValueError),
        ("1d", np.zeros(4, np.float32), ValueError),
        ("4d", np.zeros((1, 2, 2, 3), np.float32), ValueError),
        ("string", "pixels", TypeError),
        ("bool", np.ones((2, 2, 3), bool), TypeError),
    ]:  # fmt: skip
        add(
            f"write{ext}-{name}",
            lambda fn=fn, a=arr, e=ext: fn(f"/tmp/never-written{e}", a),
            Err(exc, "image"),
        )
add(
    "write-png-nan",
    lambda: io.write_png("/tmp/never.png", np.full((2, 2), np.nan)),
    Err(ValueError, "NaN"),
)
add(
    "write-png-bits",
    lambda: io.write_png("/tmp/never.png", np.zeros((2, 2)), bits=12),
    Err(ValueError, "bits"),
)
add(
    "write-png-2ch",
    lambda: io.write_png("/tmp/never.png", np.zeros((2, 2, 2))),
    Err(ValueError, "channels"),
)
add(
    "write-png-int-range",
    lambda: io.write_png("/tmp/never.png", np.full((2, 2), 300)),
    Err(ValueError, "[0, 255]"),
)
add(
    "write-hdr-4ch",
    lambda: io.write_hdr("/tmp/never.hdr", np.zeros((2, 2, 4), np.float32)),
    Err(ValueError, "image"),
)
for ext in (".bmp", ".gif", ".xyz", "", ".dng"):
    add(f"write-any-ext{ext or '-none'}", lambda e=ext: io.write_any(f"/tmp/never{e}", np.zeros((2, 2, 3))),
        Err(ValueError, "cannot write"))  # fmt: skip
for ext in (".png", ".exr", ".hdr", ".jpg", ".tif"):
    add(f"write-any-missing-folder{ext}", lambda e=ext: io.write_any(f"/nonexistent-folder/x{e}", np.zeros((2, 2, 3), np.float32)),
        Err(FileNotFoundError, "/nonexistent-folder"))  # fmt: skip

# ----------------------------------------------------------------------------- parametrised runs


@pytest.mark.parametrize("name, fn, outcome", CASES, ids=[c[0] for c in CASES])
def test_library_case(name, fn, outcome):
    check_outcome(fn, outcome)


def check_outcome(fn, outcome):
    if isinstance(outcome, Err):
        with pytest.raises(outcome.exc) as e:
            fn()
        assert outcome.needle in str(e.value), f"{outcome.needle!r} not in {str(e.value)!r}"
    else:
        assert outcome.check(fn())


@pytest.mark.parametrize("name, outcome", YAML_CASES, ids=[c[0] for c in YAML_CASES])
def test_yaml_case(name, outcome, yaml_files):
    check_outcome(lambda: read_yaml(yaml_files[name]), outcome)


# ----------------------------------------------------------------------------- files on disk

CORRUPT = [(f"{kind}{ext}", ext) for kind in ("garbage", "empty")
           for ext in (".png", ".jpg", ".tif", ".exr", ".hdr", ".dng")]  # fmt: skip


@pytest.mark.parametrize("name, ext", CORRUPT, ids=[c[0] for c in CORRUPT])
def test_corrupt_file_read_any(name, ext, files):
    with pytest.raises(ValueError, match=name.replace(".", r"\.")):
        io.read_any(str(files[name]))


@pytest.mark.parametrize("reader", ["read_any", "read_image", "read_exr", "read_hdr", "read_raw"])
def test_reader_on_missing_file_and_folder(reader, files, tmp_path):
    fn = getattr(io, reader)
    with pytest.raises(FileNotFoundError, match="missing"):
        fn(str(tmp_path / "missing.png"))
    with pytest.raises(IsADirectoryError, match="folder.png"):
        fn(str(files["dir_png"]))


@pytest.fixture(scope="module")
def truncations(files, tmp_path_factory):
    """Every file cut at several points: PNG, JPEG, EXR, Radiance HDR."""
    root = tmp_path_factory.mktemp("cuts")
    src = {".png": files["png"], ".exr": files["exr"]}
    hdr_path = root / "full.hdr"
    io.write_hdr(str(hdr_path), np.ones((8, 8, 3), np.float32))
    src[".hdr"] = hdr_path
    jpg = root / "full.jpg"
    io.write_any(str(jpg), np.full((16, 16, 3), 0.5, np.float32))
    src[".jpg"] = jpg
    out = []
    for ext, p in src.items():
        data = p.read_bytes()
        for frac in (0.05, 0.2, 0.5, 0.8, 0.95):
            q = root / f"cut{int(frac * 100):02d}{ext}"
            q.write_bytes(data[: max(1, int(len(data) * frac))])
            out.append(q)
    return out


def test_truncated_files_every_cut(truncations):
    ok = []
    for p in truncations:  # 20 cases: a clear error naming the file, or (JPEG) a full image
        try:
            img = io.read_any(str(p))
        except ValueError as e:
            assert p.name in str(e), str(e)
        else:
            ok.append(p.name)
            assert img.shape[:2] == (16, 16) and p.suffix == ".jpg"
    assert len(ok) <= 2, ok  # only JPEG tolerates a missing tail (its decoder pads it)


# ----------------------------------------------------------------------------- stacks and sidecars


def _stack_paths(d):
    return sorted(str(p) for p in d.iterdir() if p.suffix in (".png", ".jpg"))


STACK_CASES = [
    ("sizes", {"sidecar": True}, Err(ValueError, "different sizes")),
    ("no_times", {}, Err(ValueError, "no EXIF ExposureTime")),
    ("exif_zero", {}, Err(ValueError, "EXIF ExposureTime is 0 s")),
    ("short_sidecar", {"sidecar": True}, Err(ValueError, "expected a list of 3 exposure times")),
    ("stack", {"exposure_times": [1.0, 2.0]}, Err(ValueError, "exposure_times: expected 3")),
    ("stack", {"exposure_times": [1.0, 0.0, 2.0]}, Err(ValueError, "exposure_times")),
    ("stack", {"sidecar": True}, Ok(lambda r: r[1].tolist() == [1.0, 4.0, 16.0])),
]


@pytest.mark.parametrize(
    "name, kw, outcome", STACK_CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(STACK_CASES)]
)
def test_ldr_stack_case(name, kw, outcome, files):
    d = files[name]
    kw = dict(kw)
    if kw.pop("sidecar", False):
        kw["sidecar"] = str(d / "exposure_times.txt")
    check_outcome(lambda: io.read_ldr_stack(_stack_paths(d), **kw), outcome)


SIDECAR_BAD = ["1/0 1 2", "0 1 2", "a b c", "1 2", "1 2 3 4", "-1 2 3", "nan 1 2", "1/ 2 3"]


@pytest.mark.parametrize("text", SIDECAR_BAD)
def test_bad_sidecar(text, files, tmp_path):
    s = tmp_path / "exposure_times.txt"
    s.write_text(text)
    with pytest.raises(ValueError, match="exposure_times.txt"):
        io.read_ldr_stack(_stack_paths(files["stack"]), sidecar=str(s))


@pytest.mark.parametrize(
    "name, text",
    [
        ("yaml-mapping-missing", "{f0.png: 1, f1.png: 2}"),
        ("yaml-syntax", "[1, 2"),
        ("json-syntax", "{"),
        ("json-strings", '["x", "y", "z"]'),
        ("yaml-nested", "exposure_times: {a: 1}"),
    ],
)
def test_bad_structured_sidecar(name, text, files, tmp_path):
    s = tmp_path / ("times.json" if name.startswith("json") else "times.yaml")
    s.write_text(text)
    with pytest.raises(ValueError, match=s.name):
        io.read_ldr_stack(_stack_paths(files["stack"]), sidecar=str(s))


# ----------------------------------------------------------------------------- meshes

OBJ_BAD = {
    "nan-vertex": ("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n", "NaN/Inf"),
    "inf-vertex": ("v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n", "NaN/Inf"),
    "index-range": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "out of range"),
    "index-zero": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "out of range"),
    "no-faces": ("v 0 0 0\nv 1 0 0\n", "no faces"),
    "two-coords": ("v 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "expected 3 coordinates"),
    "text-coord": ("v 0 0 x\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "malformed"),
    "short-face": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", "at least 3"),
    "bad-corner": ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 a\n", "malformed"),
    "binary": (b"\x00\xff\xfe\x81garbage", "obj"),
    "empty": ("", "no faces"),
}
PLY_HEAD = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
PLY_BAD = {
    "nan-vertex": (PLY_HEAD + "0 0 0\n1 0 nan\n0 1 0\n3 0 1 2\n", "NaN/Inf"),
    "index-range": (PLY_HEAD + "0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n", "out of range"),
    "truncated-body": (PLY_HEAD + "0 0 0\n1 0 0\n", "truncated"),
    "no-magic": ("format ascii 1.0\nend_header\n", "not a PLY"),
    "no-end-header": ("ply\nformat ascii 1.0\n", "not a PLY"),
    "bad-format": ("ply\nformat ebcdic 1.0\nend_header\n", "unsupported PLY format"),
    "short-face": (PLY_HEAD.replace("element face 1", "element face 1") + "0 0 0\n1 0 0\n0 1 0\n2 0 1\n", "< 3"),
    "no-vertex": ("ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n", "no vertex"),
    "binary-trunc": (PLY_HEAD.replace("ascii", "binary_little_endian") + "\x00\x00", "truncated"),
}  # fmt: skip


@pytest.mark.parametrize("name", sorted(OBJ_BAD))
def test_bad_obj(name, tmp_path):
    from jaxgfx.render import load_obj

    text, needle = OBJ_BAD[name]
    p = tmp_path / f"{name}.obj"
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ValueError) as e:
        load_obj(str(p))
    assert p.name in str(e.value) and needle in str(e.value), str(e.value)


@pytest.mark.parametrize("name", sorted(PLY_BAD))
def test_bad_ply(name, tmp_path):
    from jaxgfx.render import load_ply

    text, needle = PLY_BAD[name]
    p = tmp_path / f"{name}.ply"
    p.write_bytes(text.encode("latin-1"))
    with pytest.raises(ValueError) as e:
        load_ply(str(p))
    assert p.name in str(e.value) and needle in str(e.value), str(e.value)


# ----------------------------------------------------------------------------- 1x1 images: results


def test_one_pixel_images_give_correct_results():
    # a 1x1 image under any padding is a constant image: blurs return it unchanged
    x = np.full((1, 1, 3), 0.25, np.float32)
    np.testing.assert_allclose(np.asarray(image.box_blur(x, 3)), x, rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(image.equalize_histogram(x)), 0.5)  # flat
