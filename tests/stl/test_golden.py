"""Golden diagnostics: every code of twolevel.stl.codes, with its position, never a traceback.

Each ``golden/*.stl`` starts with ``// expect: CODE@line:col, ...`` (the exact multiset of
findings) and may say ``// options: dt=0.1 horizon=10 provided=v,x participants=d_lon``. Inputs that cannot live
in the repository (binary, invalid UTF-8, 10 MB, 10,000 nested parentheses, FIFOs) are generated
into ``tmp_path``.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path

import pytest

from twolevel.diagnostics import Severity
from twolevel.stl import codes
from twolevel.stl.lint import check_file, check_source, load_ruleset

GOLDEN = Path(__file__).with_name("golden")
CASES = sorted(GOLDEN.glob("*.stl"))


def _expectations(text: str) -> tuple[list[str], dict]:
    m = re.search(r"//\s*expect:(.*)", text)
    assert m, "golden file without an '// expect:' line"
    expected = sorted(x.strip() for x in m.group(1).split(",") if x.strip())
    kw: dict = {}
    o = re.search(r"//\s*options:(.*)", text)
    if o:
        opts = dict(kv.split("=") for kv in o.group(1).split())
        if "dt" in opts:
            kw["dt"] = float(opts["dt"])
        if "horizon" in opts:
            kw["horizon"] = int(opts["horizon"])
        if "provided" in opts:
            kw["provided_signals"] = frozenset(opts["provided"].split(","))
        if "participants" in opts:
            kw["participant_signals"] = frozenset(opts["participants"].split(","))
    return expected, kw


def _found(result) -> list[str]:
    return sorted(f"{d.code}@{d.span.line}:{d.span.column}" for d in result.diagnostics)


@pytest.mark.parametrize("path", CASES, ids=[p.stem for p in CASES])
def test_golden(path: Path) -> None:
    expected, kw = _expectations(path.read_text(encoding="utf-8"))
    result = check_file(str(path), **kw)
    assert _found(result) == expected
    for d in result.diagnostics:
        assert d.message and d.span.file == str(path)
        assert d.severity is codes.__dict__[d.code].severity or d.code == "STL217"


# ----------------------------------------------------------------------------- generated inputs

#: A hang guard, not a speed claim (speed is measured in benchmarks/, never asserted): a hostile
#: input that made check quadratic or recursive would blow far past it on any machine.
HANG_GUARD_S = 15.0


def _timed_check(path: Path):
    t0 = time.perf_counter()
    result = check_file(str(path))
    elapsed = time.perf_counter() - t0
    assert elapsed < HANG_GUARD_S, f"took {elapsed:.2f} s: check hangs on this input"
    return result


def _codes(result) -> set[str]:
    return {d.code for d in result.diagnostics}


def test_missing_file(tmp_path: Path) -> None:
    r = _timed_check(tmp_path / "nope.stl")
    assert _codes(r) == {"STL100"} and "no such file" in r.diagnostics[0].message


def test_directory(tmp_path: Path) -> None:
    r = _timed_check(tmp_path)
    assert _codes(r) == {"STL100"} and "directory" in r.diagnostics[0].message


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.stl"
    os.mkfifo(fifo)
    assert _codes(_timed_check(fifo)) == {"STL100"}


def test_empty_file(tmp_path: Path) -> None:
    p = tmp_path / "empty.stl"
    p.write_bytes(b"")
    r = _timed_check(p)
    assert _codes(r) == {"STL104"} and r.rulefile is not None and r.ruleset is not None
    assert r.diagnostics[0].severity is Severity.WARNING


def test_binary_file(tmp_path: Path) -> None:
    p = tmp_path / "bin.stl"
    p.write_bytes(b"input float v\nr = v\x00\x01\x02 > 0;")
    r = _timed_check(p)
    assert _codes(r) == {"STL105"}
    assert (r.diagnostics[0].span.line, r.diagnostics[0].span.column) == (2, 6)


def test_invalid_utf8(tmp_path: Path) -> None:
    p = tmp_path / "latin1.stl"
    p.write_bytes("input float v\n// vitesse en km/h: é\nr = v > 0;".encode("latin-1"))
    r = _timed_check(p)
    assert _codes(r) == {"STL106"}
    d = r.diagnostics[0]
    assert (d.span.line, d.span.column) == (2, 21) and "line 2, column 21" in d.message


def test_utf8_bom_and_non_ascii_comments_are_fine(tmp_path: Path) -> None:
    p = tmp_path / "bom.stl"
    p.write_bytes("\ufeff// vitesse — ≤ limite\ninput float v\nr = always[0:1] (v >= 0);".encode("utf-8"))
    r = _timed_check(p)
    assert r.diagnostics == ()


def test_ten_megabytes(tmp_path: Path) -> None:
    p = tmp_path / "huge.stl"
    line = b"r = always[0:1] (v <= 3);\n"
    p.write_bytes(line * (10 * 2**20 // len(line) + 1))
    r = _timed_check(p)
    assert _codes(r) == {"STL107"}


def test_ten_thousand_nested_parentheses(tmp_path: Path) -> None:
    p = tmp_path / "deep.stl"
    p.write_text("input float v\nr = " + "(" * 10_000 + "v > 0" + ")" * 10_000 + ";\n")
    r = _timed_check(p)
    assert _codes(r) == {"STL108"}
    d = r.diagnostics[0]
    assert (d.span.line, d.span.column) == (2, 5 + 64)  # where the 65th '(' opens


def test_long_prefix_chain(tmp_path: Path) -> None:
    p = tmp_path / "nots.stl"
    p.write_text("input float v\nr = " + "not " * 10_000 + "v > 0;\n")
    r = _timed_check(p)
    assert _codes(r) == {"STL108"}


def test_long_operator_chain(tmp_path: Path) -> None:
    """A chain of binary operators is a deep tree too: refused before any recursion."""
    p = tmp_path / "ands.stl"
    p.write_text("input float v\nr = v > 0" + " and v > 0" * 5_000 + ";\n")
    r = _timed_check(p)
    assert _codes(r) == {"STL108"}


def test_many_bad_characters_are_capped() -> None:
    r = check_source("input float v\nr = v > 0 " + "$" * 5000 + ";", "x.stl")
    assert {d.code for d in r.diagnostics} == {"STL102"} and len(r.diagnostics) <= 20


def test_load_ruleset_binds_constants(tmp_path: Path) -> None:
    p = tmp_path / "r.stl"
    p.write_text("input float v\nconst float lim\nconst float tol = 0.5\nr = always[0:1] (v <= lim + tol);\n")
    rs, diags = load_ruleset(str(p), {"lim": 13.9})
    assert rs is not None and not any(d.is_error for d in diags)
    assert rs.consts == {"lim": 13.9, "tol": 0.5}
    rs2, _ = load_ruleset(str(p), {"lim": 10.0, "tol": 0.0})
    assert rs2 is not None and rs2.consts["tol"] == 0.0


def test_load_ruleset_unknown_binding(tmp_path: Path) -> None:
    p = tmp_path / "r.stl"
    p.write_text("input float v\nconst float lim = 3\nr = always[0:1] (v <= lim);\n")
    rs, diags = load_ruleset(str(p), {"limit": 13.9})
    assert rs is None and [d.code for d in diags] == ["STL219"]
    assert "lim" in (diags[0].hint or "")


def test_load_ruleset_unbound_constant_is_an_error(tmp_path: Path) -> None:
    p = tmp_path / "r.stl"
    p.write_text("input float v\nconst float lim\nr = always[0:1] (v <= lim);\n")
    rs, diags = load_ruleset(str(p))
    assert rs is None
    assert [(d.code, d.severity, d.span.line) for d in diags] == [("STL217", Severity.ERROR, 2)]


GENERATED = {"STL100", "STL104", "STL105", "STL106", "STL107", "STL108", "STL219"}


def test_every_code_is_covered() -> None:
    covered = set(GENERATED)
    for path in CASES:
        expected, _ = _expectations(path.read_text(encoding="utf-8"))
        covered |= {e.split("@")[0] for e in expected}
    assert covered == {c.id for c in codes.ALL}


@pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
def test_binding_a_non_finite_constant_is_refused(tmp_path: Path, value: float) -> None:
    p = tmp_path / "r.stl"
    p.write_text("input float v\nconst float tol\nr = always[0:1] (v <= tol);\n")
    rs, diags = load_ruleset(str(p), {"tol": value})
    assert rs is None and [d.code for d in diags] == ["STL222"] and "tol" in diags[0].message
    ok, _ = load_ruleset(str(p), {"tol": 1.0})
    assert ok is not None
    with pytest.raises(ValueError, match="finite"):
        ok.bind({"tol": value})


def test_binding_a_constant_that_makes_a_term_overflow_is_refused(tmp_path: Path) -> None:
    """A finite binding can still make arithmetic on constants overflow (STL223 at the term)."""
    p = tmp_path / "r.stl"
    p.write_text("input float v\nconst float k = 1\nr = always[0:1] (v <= k * 1e300);\n")
    rs, diags = load_ruleset(str(p), {"k": 1e10})
    assert rs is None and [(d.code, d.span.line, d.span.column) for d in diags] == [("STL223", 3, 23)]
    ok, diags = load_ruleset(str(p), {"k": 1e8})
    assert ok is not None and diags == []


def test_did_you_mean_hints_cost_linear_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """Regression: each undeclared name was compared with every name defined before it, so a
    file with 4,000 undeclared names took 30 s (74,000: hours)."""
    from twolevel.stl import typecheck as T

    compared = [0]
    real = T.difflib.get_close_matches

    def counted(word, possibilities, *args, **kw):
        possibilities = list(possibilities)
        compared[0] += len(possibilities)
        return real(word, possibilities, *args, **kw)

    monkeypatch.setattr(T.difflib, "get_close_matches", counted)

    def work(n: int) -> int:
        compared[0] = 0
        text = "input float speed\n" + "".join(f"r{k} = x{k} > 0;\n" for k in range(n)) + "q = sped > 0;\n"
        found = check_source(text, "many.stl").diagnostics
        assert sum(d.code == "STL201" for d in found) == n + 1
        return compared[0]

    assert work(100) > 0
    assert work(3000) <= T.SUGGESTION_BUDGET
    small = check_source("input float speed\nq = sped > 0;\n", "one.stl").diagnostics
    assert [d.hint for d in small if d.code == "STL201"] == ["did you mean 'speed'?"]
