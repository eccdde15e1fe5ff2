"""``python -m benchmarks.fitloop`` (issue 22's targets as ratios from one command): the verdict
and table logic on synthetic numbers, and its command line. No timing: the benchmark is run by
hand (docs/performance.md). Imported by name: tests do not import benchmarks statically."""

import importlib

import pytest

F = importlib.import_module("benchmarks.fitloop")


def _row(target, **kw):
    return {"target": target, "case": "synthetic", "jaxgfx": None, "mitsuba": None,
            "ratio": None, **kw}  # fmt: skip


def test_verdict_is_exact_at_the_bound_and_fails_just_past_it():
    # <= targets: the bound itself is met, a hair over it is not
    t = F.TARGET["grad_time_ratio"]  # <= 2x
    assert F.verdict(t, _row(t.id, ratio=2.0)) == "met"
    assert F.verdict(t, _row(t.id, ratio=2.0 + 1e-9)) == "not met"
    assert F.verdict(t, _row(t.id, ratio=3.9)) == "not met"
    # >= targets: jaxgfx ÷ Mitsuba samples/s
    t = F.TARGET["path_analytic"]  # >= 0.33x
    assert F.verdict(t, _row(t.id, ratio=0.33)) == "met"
    assert F.verdict(t, _row(t.id, ratio=0.3299)) == "not met"
    assert F.verdict(t, _row(t.id, ratio=0.2, jaxgfx=99.0)) == "not met"  # the ratio decides
    # absolute targets compare jaxgfx's figure, not a ratio
    t = F.TARGET["fit_step_compile"]  # <= 6 s
    assert F.verdict(t, _row(t.id, jaxgfx=6.0001, ratio=0.5)) == "not met"
    assert F.verdict(t, _row(t.id, jaxgfx=5.9)) == "met"
    # no figure: not measured, unless the row says a missing figure is a failure
    t = F.TARGET["time_to_2pct"]
    assert F.verdict(t, _row(t.id, jaxgfx=None, mitsuba=3.9)) == "not measured"
    assert F.verdict(t, _row(t.id, missing_is_unmet=True)) == "not met"
    assert F.verdict(t, _row(t.id, ratio=float("nan"))) == "not measured"


def test_target_thresholds_are_the_issues():
    want = {"path_analytic": (">=", 0.33), "direct_analytic": (">=", 0.5),
            "path_mesh": (">=", 0.33), "fit_step_compile": ("<=", 6.0),
            "fit_cold_wall": ("<=", 15.0), "grad_compile_ratio": ("<=", 2.0),
            "forward_compile": ("<=", 3.0), "grad_time_ratio": ("<=", 2.0),
            "time_to_2pct": ("<=", 2.0)}  # fmt: skip
    for tid, (op, thr) in want.items():
        assert (F.TARGET[tid].op, F.TARGET[tid].threshold) == (op, thr), tid
    assert len(F.TARGET) == len(F.TARGETS)  # ids unique


def test_table_has_one_line_per_row_with_its_verdict():
    rows = [
        _row("path_analytic", ratio=0.2, jaxgfx=1.5, mitsuba=7.5, other_cores=0.1,
             load_avg=[0.3, 0.2, 0.1]),
        _row("grad_time_ratio", ratio=2.01, jaxgfx=0.2, mitsuba=3.3, notes=["n1"]),
        _row("fit_step_compile", jaxgfx=5.5, jaxgfx_text="5.5 s (trace 2 + ...)"),
        _row("time_to_2pct", missing_is_unmet=True, mitsuba=3.9),
        _row("path_mesh", ratio=0.5, unreliable_because="Mitsuba starved"),
    ]  # fmt: skip
    F.finish_rows(rows, loaded=True)
    assert [r["verdict"] for r in rows] == ["not met", "not met", "met", "not met", "met"]
    assert [r["reliable"] for r in rows] == [True] * 4 + [False]
    assert all(r["loaded"] for r in rows)
    table = F.table_markdown(rows).splitlines()
    assert len(table) == 2 + len(rows)
    header = [c.strip() for c in table[0].strip("|").split("|")]
    assert header == ["target (issue 22)", "case", "jaxgfx", "Mitsuba 3 (same run)", "ratio",
                      "target", "verdict", "conditions"]  # fmt: skip
    cells = [[c.strip() for c in ln.strip("|").split(" | ")] for ln in table[2:]]
    assert all(len(c) == 8 for c in cells)
    assert cells[0][4] == "0.2×" and cells[0][6] == "**not met**"
    assert cells[0][5].startswith("≥ 0.33×") and "load 0.30" in cells[0][7]
    assert "**loaded**" in cells[0][7]
    assert cells[1][6] == "**not met** (n1)" and cells[1][4] == "2.01×"
    assert cells[2][4] == "—" and cells[2][5] == "≤ 6 s" and cells[2][6] == "**met**"
    assert cells[2][2] == "5.5 s (trace 2 + ...)"
    assert cells[4][6] == "**met?** (not reliable: Mitsuba starved)"  # flagged, not hidden
    with pytest.raises(KeyError, match="unknown target"):
        F.finish_rows([_row("no_such_target")], loaded=False)


def test_command_line_and_sections_are_consistent():
    assert set(F.SECTION_FUNCS) == set(F.SECTIONS)
    assert {t.section for t in F.TARGETS} == set(F.SECTIONS)  # every section has a target
    ap = F.build_parser()
    a = ap.parse_args([])
    assert F.parse_sections(a.sections) == list(F.SECTIONS) and a.max_load == 1.0
    a = ap.parse_args(["--quick", "--sections", "fit,compile", "--allow-load", "--no-mitsuba"])
    assert a.quick and a.allow_load and a.no_mitsuba
    assert F.parse_sections(a.sections) == ["compile", "fit"]  # the module's order
    assert F.parse_sections(["gradient", "throughput,fit"]) == ["throughput", "gradient", "fit"]
    with pytest.raises(ValueError, match="unknown \\['speed'\\]"):
        F.parse_sections(["compile,speed"])
    with pytest.raises(SystemExit):  # one or the other
        ap.parse_args(["--max-load", "2", "--allow-load"])
    with pytest.raises(SystemExit):  # main refuses an unknown section before measuring
        F.main(["--sections", "nope"])
