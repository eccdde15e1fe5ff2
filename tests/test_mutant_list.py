"""The curated mutants of ``tools/mutants.py`` must still apply to the current source.

``make mutate`` (CI, after the slow tests) stops with "mutant list is stale" when a patch's old
text no longer occurs exactly once; this default-run check finds that within seconds of the
refactor that moved the code instead of half an hour into CI.
"""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _mutate_module():
    spec = importlib.util.spec_from_file_location("jaxgfx_tools_mutate", ROOT / "tools/mutate.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_every_mutant_applies_once_and_names_existing_tests():
    mod = _mutate_module()
    assert len(mod.MUTANTS) >= 20
    assert mod._check_list(mod.MUTANTS) == []


def test_stale_patch_is_reported():
    mod = _mutate_module()
    m = dict(mod.MUTANTS[0], old="this text is in no source file", name="stale")
    errors = mod._check_list([m])
    assert len(errors) == 1 and "old text found 0 times" in errors[0]
