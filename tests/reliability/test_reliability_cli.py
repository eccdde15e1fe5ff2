# ruff: noqa: E501  (a table of cases: one case per line reads best)
"""The ``jaxgfx`` command over a table of bad inputs, in-process (``jaxgfx.cli.main``).

Every case asserts the exact class of outcome: exit status 1 (2 for usage errors), exactly one
line on stderr naming the argument or path, no traceback — and that the case's folder is
unchanged afterwards (no partial file, no created ``--out``, no staging leftovers).
The true subprocess runs are in ``test_reliability_subprocess.py``.
"""

from __future__ import annotations

import os

import pytest

from ._util import assert_one_line_error, no_partial_files, read_only_sys, run_cli, snapshot

RO = "/sys/jaxgfx-reliability"  # sysfs is not writable, even by root

# (id, files to create in the case folder, argv builder (files, tmp) -> argv, status, needles)
CASES: list[tuple] = []


def add(name, argv, needles=(), *, status=1, setup=None):
    CASES.append((name, setup or {}, argv, status, tuple(needles)))


# ----------------------------------------------------------------------------- usage

add("no-args-subcommand-unknown", lambda f, t: ["paint"], ["invalid choice"], status=2)
add(
    "filter-missing-output",
    lambda f, t: ["filter", f["png"]],
    ["INPUT and OUTPUT are required"],
    status=2,
)
add("render-missing-args", lambda f, t: ["render"], ["required"], status=2)
add(
    "render-spp-text",
    lambda f, t: ["render", f["scene"], t / "o.exr", "--spp", "many"],
    ["--spp"],
    status=2,
)
add(
    "filter-sigma-text",
    lambda f, t: ["filter", f["png"], t / "o.png", "--sigma", "wide"],
    ["--sigma"],
    status=2,
)
add(
    "calibrate-unknown-option",
    lambda f, t: ["calibrate", "--smoothness", "3"],
    ["unrecognized"],
    status=2,
)

# ----------------------------------------------------------------------------- calibrate: --times

for times, needle in [
    ("1/0,1,4", "--times [0]"), ("0,1,4", "--times [0]"), ("a,b,c", "--times [0]"),
    ("", "--times [0]"), ("1,,4", "--times [1]"), ("-1,2,4", "--times [0]"),
    ("1;2;4", "--times [0]"), ("nan,1,2", "--times [0]"), ("1,2,inf", "--times [2]"),
    ("1/2/3,1,2", "--times [0]"), ("1e999,1,2", "--times [0]"),
]:  # fmt: skip
    add(
        f"times-{times!r}",
        lambda f, t, x=times: ["calibrate", f"--times={x}", "--out", t / "out"],
        [needle],
    )
add("times-count", lambda f, t: ["calibrate", f["stack"], "--times", "1,2", "--out", t / "out", "--quiet"],
    ["exposure_times: expected 3 positive values"])  # fmt: skip

# ----------------------------------------------------------------------------- calibrate: config

CONFIGS = {
    "yaml-syntax": ("synthetic: {height: 16\n", "not valid YAML"),
    "yaml-list": ("- 1\n", "expected a mapping"),
    "unknown-top": ("bogus: 1\n", "unknown config key(s) bogus"),
    "unknown-synthetic": ("synthetic: {heigth: 16}\n", "synthetic.heigth"),
    "unknown-response": ("response: {smoothness: 50}\n", "response.smoothness"),
    "unknown-merge": ("merge: {weights: hat}\n", "merge.weights"),
    "unknown-align": ("align: {enable: true}\n", "align.enable"),
    "demosaic-fancy": ("demosaic: fancy\n", "demosaic: expected one of"),
    "preview-key-neg": ("preview_key: -1\n", "preview_key"),
    "preview-key-text": ("preview_key: bright\n", "preview_key"),
    "n-samples-0": ("response: {options: {n_samples: 0}}\n", "n_samples"),
    "smoothness-option": ("response: {options: {smoothness: 50.0}}\n", "no option 'smoothness'"),
    "align-method": ("align: {enabled: true, method: sift}\n", "align.method"),
    "method-bad": ("response: {method: magic}\n", "response.method"),
    "compare-bad": ("response: {compare: [debevec, magic]}\n", "response.compare[1]"),
    "weighting-noise": ("merge: {weighting: noise}\n", "merge.weighting"),
    "height-small": ("synthetic: {height: 2}\n", "synthetic.height"),
    "bits-12": ("synthetic: {bits: 12}\n", "synthetic.bits"),
    "times-one": ("synthetic: {exposure_times: [1.0]}\n", "synthetic.exposure_times"),
    "synthetic-response": ("synthetic: {response: linear}\n", "synthetic.response"),
    "enabled-text": ("align: {enabled: maybe}\n", "align.enabled"),
    "exposure-zero": ("exposure_times: [0, 1, 2]\n", "exposure_times[0]"),
    "section-scalar": ("response: 3\n", "response"),
}
for name, (text, needle) in CONFIGS.items():
    add(f"config-{name}", lambda f, t: ["calibrate", "--config", t / "c.yaml", "--out", t / "out"],
        [needle], setup={"c.yaml": text})  # fmt: skip
add(
    "config-missing",
    lambda f, t: ["calibrate", "--config", t / "nope.yaml", "--out", t / "out"],
    ["nope.yaml"],
)
add(
    "config-folder",
    lambda f, t: ["calibrate", "--config", t, "--out", t / "out"],
    ["config: is a folder"],
)
add("config-binary", lambda f, t: ["calibrate", "--config", t / "c.yaml", "--out", t / "out"],
    ["not a UTF-8"], setup={"c.yaml": b"\xff\xfe\x00\x81"})  # fmt: skip
add(
    "method-flag-bad",
    lambda f, t: ["calibrate", "--method", "magic", "--out", t / "out"],
    ["response.method"],
)

# ----------------------------------------------------------------------------- calibrate: --out

add("out-is-file", lambda f, t: ["calibrate", "--out", f["a_file"]], ["--out: is a file", "a_file"])
add("out-parent-is-file", lambda f, t: ["calibrate", "--out", f["a_file"] / "out"], ["a_file"])
add("out-read-only", lambda f, t: ["calibrate", "--out", f"{RO}/out"], [RO])
add("out-holds-results", lambda f, t: ["calibrate", "--out", t / "out"], ["holds the results of a previous run", "--overwrite"],
    setup={"out/report.json": "{}", "out/radiance.exr": "old"})  # fmt: skip
add("out-holds-one-result", lambda f, t: ["calibrate", "--out", t / "out"], ["preview.png"],
    setup={"out/preview.png": "old", "out/notes.txt": "mine"})  # fmt: skip

# ----------------------------------------------------------------------------- calibrate: inputs

for key, needle in [
    ("saturated", "too few usable pixels"), ("black", "too few usable pixels"),
    ("sizes", "different sizes"), ("single", "at least 2 images"),
    ("no_times", "no EXIF ExposureTime"), ("short_sidecar", "expected a list of 3"),
    ("exif_zero", "EXIF ExposureTime is 0"),
]:  # fmt: skip
    add(
        f"inputs-{key}",
        lambda f, t, k=key: ["calibrate", f[k], "--out", t / "out", "--quiet"],
        [needle],
    )
add(
    "inputs-missing",
    lambda f, t: ["calibrate", t / "nothing", "--out", t / "out"],
    ["input not found"],
)
add(
    "inputs-empty-dir",
    lambda f, t: ["calibrate", t / "empty", "--out", t / "out"],
    ["no image files"],
    setup={"empty/": None},
)
add(
    "inputs-mixed",
    lambda f, t: ["calibrate", f["png"], f["garbage.dng"], "--out", t / "out"],
    ["mix of RAW and LDR"],
)
for ext in (".png", ".jpg", ".tif"):
    add(f"inputs-garbage{ext}", lambda f, t, e=ext: ["calibrate", f[f"garbage{e}"], f[f"empty{e}"], "--times", "1,2", "--out", t / "out", "--quiet"],
        [f"garbage{ext}"])  # fmt: skip
add(
    "inputs-garbage-dng",
    lambda f, t: ["calibrate", f["garbage.dng"], f["empty.dng"], "--out", t / "out", "--quiet"],
    ["garbage.dng"],
)
add(
    "inputs-trunc-png",
    lambda f, t: [
        "calibrate",
        f["png"],
        f["trunc_png"],
        "--times",
        "1,2",
        "--out",
        t / "out",
        "--quiet",
    ],
    ["trunc.png"],
)

# ----------------------------------------------------------------------------- filter

for op, args, needle in [
    ("blurr", [], "op: expected one of"), ("box", ["--radius", "-3"], "--radius: expected an integer >= 0"),
    ("gaussian", ["--sigma", "-1"], "--sigma"), ("gaussian", ["--sigma", "0"], "--sigma"),
    ("gaussian", ["--sigma", "nan"], "--sigma"), ("gaussian", ["--sigma", "inf"], "--sigma"),
    ("gaussian", ["--radius", "2"], "--radius"), ("sobel", ["--sigma", "2"], "--sigma"),
    ("bilateral", ["--sigma-range", "0"], "--sigma-range"), ("bilateral", ["--sigma-spatial", "-1"], "--sigma-spatial"),
    ("lowpass", ["--cutoff", "0"], "--cutoff"), ("highpass", ["--cutoff", "-0.1"], "--cutoff"),
    ("gamma", ["--gamma", "0"], "--gamma"), ("gamma", ["--gamma", "-2"], "--gamma"),
    ("unsharp", ["--amount", "nan"], "--amount"), ("canny", ["--low", "inf"], "--low"),
    ("median", ["--size", "4"], "size"), ("median", ["--size", "0"], "size"),
    ("gaussian", ["--padding", "mirror"], "padding"), ("demosaic", ["--pattern", "XXXX"], "pattern"),
    ("stretch", ["--low", "0.9", "--high", "0.1"], "low"), ("canny", ["--low", "0.5", "--high", "0.1"], "low"),
]:  # fmt: skip
    add(
        f"filter-{op}-{'-'.join(args) or 'unknown'}",
        lambda f, t, o=op, a=args: ["filter", f["png"], t / "o.png", "--op", o, *a],
        [needle],
    )
for ext in (".bmp", ".gif", ".xyz", ".dng", ""):
    add(
        f"filter-out-ext{ext or '-none'}",
        lambda f, t, e=ext: ["filter", f["png"], t / "sub" / f"o{e}"],
        ["unsupported extension"],
    )
add("filter-out-is-dir", lambda f, t: ["filter", f["png"], f["dir_png"]], ["folder.png"])
add("filter-out-parent-file", lambda f, t: ["filter", f["png"], f["a_file"] / "o.png"], ["a_file"])
add("filter-out-read-only", lambda f, t: ["filter", f["png"], f"{RO}/o.png"], [RO])
add(
    "filter-out-exists",
    lambda f, t: ["filter", f["png"], t / "o.png"],
    ["already exists", "--overwrite"],
    setup={"o.png": "mine"},
)
add("filter-in-missing", lambda f, t: ["filter", t / "nope.png", t / "o.png"], ["nope.png"])
add("filter-in-dir", lambda f, t: ["filter", f["dir_png"], t / "o.png"], ["folder.png"])
add(
    "filter-in-same-as-out",
    lambda f, t: ["filter", t / "o.png", t / "o.png"],
    ["already exists"],
    setup={"o.png": "mine"},
)
for kind in ("garbage", "empty"):
    for ext in (".png", ".jpg", ".tif", ".exr", ".hdr", ".bmp", ".dng"):
        add(
            f"filter-in-{kind}{ext}",
            lambda f, t, k=f"{kind}{ext}": ["filter", f[k], t / "o.exr"],
            [f"{kind}{ext}"],
        )
add("filter-in-trunc-png", lambda f, t: ["filter", f["trunc_png"], t / "o.exr"], ["trunc.png"])
add(
    "filter-in-unknown-ext",
    lambda f, t: ["filter", f["a_file"], t / "o.exr"],
    ["a_file", "unsupported extension"],
)

# ----------------------------------------------------------------------------- render

add(
    "render-ext-bmp",
    lambda f, t: ["render", f["scene"], t / "o.bmp"],
    ["unsupported extension '.bmp'"],
)
add("render-ext-none", lambda f, t: ["render", f["scene"], t / "out"], ["unsupported extension"])
add(
    "render-ext-dng",
    lambda f, t: ["render", f["scene"], t / "o.dng"],
    ["unsupported extension '.dng'"],
)
add(
    "render-aov-png",
    lambda f, t: ["render", f["scene"], t / "o.png", "--integrator", "aov"],
    ["7 channels", "use .exr"],
)
add(
    "render-aov-hdr",
    lambda f, t: ["render", f["scene"], t / "o.hdr", "--integrator", "aov"],
    ["7 channels"],
)
add(
    "render-preview-ext",
    lambda f, t: ["render", f["scene"], t / "o.exr", "--preview", t / "p.exr"],
    ["preview", "unsupported extension"],
)
add(
    "render-preview-same",
    lambda f, t: ["render", f["scene"], t / "o.png", "--preview", t / "o.png"],
    ["same file"],
)
add(
    "render-preview-collides-default",
    lambda f, t: ["render", f["scene"], t / "o.exr", "--preview", t / "o.exr"],
    ["unsupported extension"],
)
for opt, val in [
    ("--spp", "0"),
    ("--spp", "-4"),
    ("--max-depth", "0"),
    ("--seed", "-1"),
    ("--integrator", "bdpt"),
]:
    add(
        f"render-{opt}={val}",
        lambda f, t, o=opt, v=val: ["render", f["scene"], t / "o.exr", o, v],
        [opt.lstrip("-").replace("-", "_")],
    )
add(
    "render-scene-missing",
    lambda f, t: ["render", t / "nope.yaml", t / "o.exr"],
    ["scene", "nope.yaml"],
)
add("render-scene-dir", lambda f, t: ["render", t, t / "o.exr"], ["scene: is a directory"])
add(
    "render-out-exists",
    lambda f, t: ["render", f["scene"], t / "o.exr"],
    ["already exists", "--overwrite"],
    setup={"o.exr": "mine"},
)
add(
    "render-preview-exists",
    lambda f, t: ["render", f["scene"], t / "o.exr"],
    ["preview", "already exists"],
    setup={"o.png": "mine"},
)
add(
    "render-out-is-dir",
    lambda f, t: ["render", f["scene"], t / "d.exr"],
    ["d.exr"],
    setup={"d.exr/": None},
)
add(
    "render-out-parent-file", lambda f, t: ["render", f["scene"], f["a_file"] / "o.exr"], ["a_file"]
)
add("render-out-read-only", lambda f, t: ["render", f["scene"], f"{RO}/o.exr"], [RO])
SCENES = {
    "yaml-syntax": ("camera: {fov: 45\n", "YAML"),
    "unknown-top": ("cameras: {}\n", "cameras"),
    "radius-neg": ("camera: {origin: [0, 0, 3], target: [0, 0, 0], fov: 45, width: 8, height: 6}\nshapes:\n  - {type: sphere, center: [0, 0, 0], radius: -1}\n", "radius"),
    "width-zero": ("camera: {origin: [0, 0, 3], target: [0, 0, 0], fov: 45, width: 0, height: 6}\nshapes: []\n", "width"),
    "fov-180": ("camera: {origin: [0, 0, 3], target: [0, 0, 0], fov: 180, width: 8, height: 6}\nshapes: []\n", "fov"),
    "nan-mesh": ("camera: {origin: [0, 0, 3], target: [0, 0, 0], fov: 45, width: 8, height: 6}\nshapes:\n  - {type: mesh, file: bad.obj}\n", "bad.obj"),
}  # fmt: skip
for name, (text, needle) in SCENES.items():
    add(f"render-scene-{name}", lambda f, t: ["render", t / "s.yaml", t / "o.exr"], [needle],
        setup={"s.yaml": text, "bad.obj": "v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n"})  # fmt: skip

# ----------------------------------------------------------------------------- tonemap

add(
    "tonemap-op-unknown",
    lambda f, t: ["tonemap", f["exr"], t / "o.png", "--op", "magic"],
    ["op: expected one of"],
)
add(
    "tonemap-param-other-op",
    lambda f, t: ["tonemap", f["exr"], t / "o.png", "--op", "exposure", "--bias", "0.8"],
    ["--bias"],
)
add(
    "tonemap-param-nan",
    lambda f, t: ["tonemap", f["exr"], t / "o.png", "--bias", "nan"],
    ["--bias"],
)
add(
    "tonemap-param-text",
    lambda f, t: ["tonemap", f["exr"], t / "o.png", "--bias", "strong"],
    ["--bias"],
    status=2,
)
add(
    "tonemap-in-missing",
    lambda f, t: ["tonemap", t / "nope.exr", t / "o.png"],
    ["input", "nope.exr"],
)
add(
    "tonemap-in-ldr",
    lambda f, t: ["tonemap", f["png"], t / "o.png"],
    ["input: cannot read", "in.png", "as linear radiance"],
)
add(
    "tonemap-in-nonfinite",
    lambda f, t: ["tonemap", f["inf_exr"], t / "o.png"],
    ["inf.exr", "2 of 256 pixels hold NaN or Inf"],
)
add(
    "tonemap-intensity-range",
    lambda f, t: ["tonemap", f["exr"], t / "o.png", "--op", "reinhard_devlin", "--intensity", "100"],
    ["--intensity", "<= 8.0"],
)
add("tonemap-in-dir", lambda f, t: ["tonemap", t, t / "o.png"], ["input: is a directory"])
add("tonemap-in-garbage", lambda f, t: ["tonemap", f["garbage.exr"], t / "o.png"], ["garbage.exr"])
add("tonemap-in-empty-hdr", lambda f, t: ["tonemap", f["empty.hdr"], t / "o.png"], ["empty.hdr"])
add(
    "tonemap-out-exr",
    lambda f, t: ["tonemap", f["exr"], t / "o.exr"],
    ["output", "unsupported extension"],
)
add(
    "tonemap-out-exists",
    lambda f, t: ["tonemap", f["exr"], t / "o.png"],
    ["already exists"],
    setup={"o.png": "mine"},
)
add(
    "tonemap-out-parent-file", lambda f, t: ["tonemap", f["exr"], f["a_file"] / "o.png"], ["a_file"]
)
add("tonemap-out-read-only", lambda f, t: ["tonemap", f["exr"], f"{RO}/o.png"], [RO])
add(
    "tonemap-missing-args",
    lambda f, t: ["tonemap", f["exr"]],
    ["INPUT and OUTPUT are required"],
    status=2,
)


def _setup(tmp, spec):
    for rel, content in spec.items():
        p = tmp / rel
        if rel.endswith("/"):
            p.mkdir(parents=True, exist_ok=True)
            continue
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(content if isinstance(content, bytes) else content.encode())


@pytest.mark.parametrize("name, setup, argv, status, needles", CASES, ids=[c[0] for c in CASES])
def test_cli_case(name, setup, argv, status, needles, files, tmp_path, monkeypatch):
    if any(RO in os.fspath(a) for a in argv(files, tmp_path)) and not read_only_sys():
        pytest.skip("no read-only file system at /sys here")
    import jaxgfx.render

    def no_render(*a, **k):  # every render case must fail before rendering
        raise AssertionError("rendered before the arguments were checked")

    monkeypatch.setattr(jaxgfx.render, "render", no_render)
    _setup(tmp_path, setup)
    before = snapshot(tmp_path)
    code, _, err = run_cli(argv(files, tmp_path))
    assert_one_line_error(code, err, *needles, status=status)
    assert snapshot(tmp_path) == before
    assert no_partial_files(tmp_path) and no_partial_files(files["a_file"].parent)


def test_cli_spp_over_the_key_limit_names_the_option(files, tmp_path):
    # the library's message names `spp` (test_reliability_scene.py); the CLI names the option
    # as the user typed it. 8x6 pixels: at most 2**32 // (8 * 6 * 2) = 44739242 spp per key
    before = snapshot(tmp_path)
    code, _, err = run_cli(["render", files["scene"], tmp_path / "o.exr", "--spp", "100000000"])
    assert_one_line_error(
        code,
        err,
        "jaxgfx render: error: --spp: 100000000 samples per pixel at 8x6 pixels need 9600000000 "
        "random numbers, more than the 2**32 of one key; use spp <= 44739242 (and average "
        "renders made with split keys for more)",
    )
    assert snapshot(tmp_path) == before
    assert no_partial_files(tmp_path)
