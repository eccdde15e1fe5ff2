"""The import structure (docs/architecture.md): no cycle inside ``jaxgfx``, the layers import
only downwards, the leaves (experiments, benchmarks, tests) import only the library, and every
module can be imported while a function is being traced (no array op at import time).

The graph is read from the source (``ast``), function-level imports included, so a cycle
hidden behind a lazy import counts too."""

import ast
import functools
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# which jaxgfx subpackages each layer may import (besides the foundation and itself);
# the data flows of docs/architecture.md: io -> image -> color -> hdr -> tonemap, render uses
# io / image / color, optim never imports render, pipelines compose all, cli calls pipelines
FOUNDATION = {"_checks", "_math", "config", "_jaxcache", "(root)"}
ALLOWED = {
    "_checks": set(),
    "_math": set(),
    "config": set(),
    "_jaxcache": set(),
    "io": set(),
    "image": {"io"},
    "color": {"image"},
    "hdr": {"io", "image", "color", "optim"},
    "tonemap": {"image", "color", "hdr", "optim"},
    "render": {"io", "image", "color"},
    "optim": {"image", "color"},
    "testing": {"io", "image", "color", "hdr", "tonemap", "render", "optim"},
    "pipelines": {"io", "image", "color", "hdr", "tonemap", "render", "optim", "testing"},
    "cli": {"io", "image", "color", "hdr", "tonemap", "render", "optim", "pipelines"},
}


# parsed once per file and graph built once per run: four tests walk the library's modules and
# the leaves' test re-reads it per leaf (the file's CPU time was mostly repeated parsing)
@functools.cache
def _parse(path):
    with open(path, encoding="utf-8") as f:
        return ast.parse(f.read(), path)


def _modules(top):
    out = {}
    for dp, dirs, files in os.walk(os.path.join(ROOT, top)):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        for f in files:
            if f.endswith(".py"):
                p = os.path.join(dp, f)
                rel = os.path.relpath(p, ROOT)[:-3].replace(os.sep, ".")
                out[rel[: -len(".__init__")] if rel.endswith(".__init__") else rel] = p
    return out


def _imports(name, path, known):
    """Modules of ``known`` that ``name`` imports (anywhere in the file). ``from P import m``
    with ``m`` a submodule is an edge to ``P.m`` only (``P`` is then already initialising)."""
    tree = _parse(path)
    pkg = name if path.endswith("__init__.py") else name.rpartition(".")[0]
    out = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            out.update(a.name for a in n.names)
        elif isinstance(n, ast.ImportFrom):
            if n.level:
                base = pkg.split(".")[: len(pkg.split(".")) - (n.level - 1)]
                mod = ".".join(base + ([n.module] if n.module else []))
            else:
                mod = n.module
            subs = [f"{mod}.{a.name}" for a in n.names if f"{mod}.{a.name}" in known]
            out.update(subs)
            if len(subs) < len(n.names):
                out.add(mod)
    return {m for m in out if m in known and m != name}


@functools.cache
def _graph(top="jaxgfx"):
    mods = _modules(top)
    return {m: _imports(m, p, mods) for m, p in mods.items()}


def _cycles(graph):
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, comps = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return comps


def _layer(module):
    parts = module.split(".")
    return "(root)" if len(parts) == 1 else parts[1]


def test_the_library_has_no_import_cycle():
    assert _cycles(_graph()) == []


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_layers_import_only_downwards():
    bad = []
    for m, deps in _graph().items():
        a = _layer(m)
        if a == "(root)":
            continue
        for d in deps:
            b = _layer(d)
            if b != a and b not in FOUNDATION and b not in ALLOWED[a]:
                bad.append(f"{m} -> {d}")
    assert bad == []


def test_the_layer_table_covers_every_subpackage():
    layers = {_layer(m) for m in _modules("jaxgfx")} - {"(root)"}
    assert layers == set(ALLOWED)


@functools.cache
def _absolute_imports(path):
    """Every module name an ``import`` or absolute ``from ... import`` of the file names."""
    names = []
    for n in ast.walk(_parse(path)):
        if isinstance(n, ast.Import):
            names += [a.name for a in n.names]
        elif isinstance(n, ast.ImportFrom) and not n.level and n.module:
            names.append(n.module)
    return tuple(names)


@pytest.mark.parametrize("leaf", ["experiments", "benchmarks", "tests"])
def test_leaves_import_only_the_library(leaf):
    """experiments/, benchmarks/ and tests/ import jaxgfx and their own helpers, never each
    other; jaxgfx imports none of them."""
    others = {"experiments", "benchmarks", "tests"} - {leaf}
    bad = []
    for top in [leaf, "jaxgfx"]:
        mods = _modules(top)
        forbidden = others if top == leaf else {"experiments", "benchmarks", "tests"}
        for name, path in mods.items():
            bad += [f"{name} -> {x}" for x in _absolute_imports(path)
                    if x.split(".")[0] in forbidden]  # fmt: skip
    assert bad == []


def test_every_module_imports_inside_a_trace():
    """Importing a jaxgfx module for the first time while a function is traced (a lazy import
    inside a jitted loss) must work: an array op at import time (``float(jnp.exp(-4.0))``)
    becomes a tracer there and crashed ``jaxgfx fit`` on every photo target. A fresh
    interpreter imports every module inside one trace."""
    names = sorted(m for m in _modules("jaxgfx") if not m.endswith("__main__"))
    code = (
        "import importlib, jax\n"
        f"names = {names!r}\n"
        "def f(x):\n"
        "    for n in names:\n"
        "        importlib.import_module(n)\n"
        "    return x + 1\n"
        "print(float(jax.jit(f)(1.0)))\n"
    )
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "PYTHONPATH": ROOT}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       cwd=ROOT, timeout=300)  # fmt: skip
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.strip() == "2.0"


# a private module imported from outside its package: (importer, module) -> why
PRIVATE_IMPORTS_ALLOWED = {
    ("jaxgfx.cli", "jaxgfx.pipelines._output"): "the CLI installs the jobs' signal handling",
}


def test_private_modules_are_imported_only_inside_their_package():
    """``P._m`` is P's own: other packages use the public names P re-exports (e.g.
    ``render.integrators.replace_grad``, not ``render.integrators._common``)."""
    bad = []
    for m, deps in _graph().items():
        for d in deps:
            parts = d.split(".")
            private = [i for i, p in enumerate(parts) if i > 0 and p.startswith("_")]
            if not private:
                continue
            owner = ".".join(parts[: private[0]])
            inside = m == owner or m.startswith(owner + ".")
            if not inside and (m, d) not in PRIVATE_IMPORTS_ALLOWED:
                bad.append(f"{m} -> {d}")
    assert bad == []
