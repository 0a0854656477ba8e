"""Line breaks: a rule file reads the same under LF, CRLF and bare-CR endings, with the
positions an editor shows, and the ``full`` renderer shows the line the position names (also
after characters such as a form feed that :meth:`str.splitlines` would break at)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from twolevel import diagnostics
from twolevel.diagnostics import render, source_lines
from twolevel.stl.lint import check_file, check_source

ROOT = Path(__file__).resolve().parents[2]

TEXT = """// speed rules
input float v
/* a block
   comment */ input float v_max
const float tol = 0.5   // m/s
speed = always[0:1] (v <= v_max + tol);
bad = always[0:1] (vx <= v_max);
"""

ENDINGS = {"LF": "\n", "CRLF": "\r\n", "CR": "\r"}


def _positions(text: str) -> list[tuple[str, int, int, int, int]]:
    result = check_source(text, "r.stl")
    return [(d.code, d.span.line, d.span.column, d.span.end_line, d.span.end_column) for d in result.diagnostics]


@pytest.mark.parametrize("ending", list(ENDINGS), ids=list(ENDINGS))
def test_every_line_ending_reads_the_same_with_the_same_positions(ending: str) -> None:
    text = TEXT.replace("\n", ENDINGS[ending])
    result = check_source(text, "r.stl")
    assert result.rulefile is not None and [r.name for r in result.rulefile.rules] == ["speed", "bad"]
    assert _positions(text) == _positions(TEXT) == [("STL201", 7, 20, 7, 22)]
    rule = result.rulefile.rules[0]
    assert (rule.span.line, rule.span.column) == (6, 1)


def test_mixed_line_endings_count_each_break_once() -> None:
    text = "input float v\r\ninput float w\rr = v > 0;\nq = zz > 0;\r\n"
    assert _positions(text) == [("STL202", 2, 1, 2, 14), ("STL201", 4, 5, 4, 7)]


def test_bare_cr_rule_file_is_monitored(tmp_path: Path) -> None:
    """Regression: with bare-CR endings the first '//' comment swallowed the rest of the file,
    and monitor reported no rules and exited 0 on a drive breaking the speed limit."""
    rules = tmp_path / "speed.stl"
    rules.write_bytes(b"// the limit\rinput float v\rinput float v_max\rspeed = v <= v_max;\r")
    trace = tmp_path / "drive.csv"
    trace.write_text("t,v,v_max\n0,10,13.9\n0.1,15,13.9\n")
    res = subprocess.run([sys.executable, "-m", "twolevel", "monitor", str(rules), str(trace), "--format", "json"],
                         capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert res.returncode == 1, res.stderr
    assert '"name": "speed"' in res.stdout and '"first_violation_t": 0.1' in res.stdout


def test_byte_positions_of_unreadable_content_count_cr_lines(tmp_path: Path) -> None:
    p = tmp_path / "r.stl"
    p.write_bytes(b"input float v\r// caf\xe9\rr = v > 0;\r")
    [d] = check_file(str(p)).diagnostics
    assert (d.code, d.span.line, d.span.column) == ("STL106", 2, 7)
    p.write_bytes(b"input float v\r\nr = v\x00 > 0;\r\n")
    [d] = check_file(str(p)).diagnostics
    assert (d.code, d.span.line, d.span.column) == ("STL105", 2, 6)


@pytest.mark.parametrize("odd", ["\f", "\v", "\x1c", "\x1d", "\x1e", "\x85", "\u2028", "\u2029"])
def test_full_shows_the_line_the_position_names_after_splitlines_breaks(odd: str) -> None:
    """Regression: after a form feed (or another character splitlines breaks at) the ``full``
    format showed a line other than the one the finding is on."""
    text = f"input float v\n// page{odd}two\nr = always[0:1] (vx <= 1);\n"
    result = check_source(text, "r.stl")
    [undeclared] = [d for d in result.diagnostics if d.code == "STL201"]
    assert (undeclared.span.line, undeclared.span.column) == (3, 18)
    out = render("full", [undeclared], sources={"r.stl": text}).splitlines()
    assert out[1] == "    3 | r = always[0:1] (vx <= 1);"
    assert out[2].index("^") == out[1].index("vx") and out[2].count("^") == 2


def test_full_shows_control_characters_as_visible_stand_ins() -> None:
    text = "input float v\nr = v\x1b[2J > 0;\n"
    [d] = check_source(text, "r.stl").diagnostics[:1]
    assert (d.code, d.span.line, d.span.column) == ("STL102", 2, 6)
    out = render("full", [d], sources={"r.stl": text}).splitlines()
    assert "\x1b" not in out[1] and out[1].endswith("r = v\u241b[2J > 0;")
    assert out[2].index("^") == out[1].index("\u241b")


def test_full_keeps_tabs_under_the_caret() -> None:
    text = "input float v\n\tr =\tvx > 0;\n"
    [d] = [d for d in check_source(text, "r.stl").diagnostics if d.code == "STL201"]
    out = render("full", [d], sources={"r.stl": text}).splitlines()
    assert out[2].split("| ", 1)[1] == "\t   \t^^"


def test_full_shows_a_window_of_a_long_line_around_the_finding() -> None:
    line = "r = " + " and ".join(f"v > {k}" for k in range(150)) + " and vx > 0;"
    text = "input float v\n" + line + "\n"
    [d] = [d for d in check_source(text, "r.stl").diagnostics if d.code == "STL201"]
    out = render("full", [d], sources={"r.stl": text}).splitlines()
    shown = out[1].split("| ", 1)[1]
    assert shown.startswith("…") and "vx > 0;" in shown and len(shown) <= 302
    assert out[2].index("^") == out[1].index("vx")


def test_yaml_sources_are_split_where_pyyaml_counts_lines() -> None:
    text = "a: 1\u2028b: [\n"
    assert source_lines(text, "m.yaml") == ["a: 1", "b: [", ""]
    assert source_lines(text, "r.stl") == ["a: 1\u2028b: [", ""]


def test_full_splits_each_source_once(monkeypatch: pytest.MonkeyPatch) -> None:
    """Regression: every finding split its whole file into lines again (a 1 MB file with
    74,000 findings took over 5 minutes)."""
    split: list[int] = []
    real = diagnostics.source_lines
    monkeypatch.setattr(diagnostics, "source_lines", lambda text, file="": split.append(len(text)) or real(text, file))
    text = "input float v\n" + "".join(f"r{k} = x{k} > 0;\n" for k in range(2000))
    found = check_source(text, "big.stl").diagnostics
    assert len(found) == 2001  # 2000 undeclared names, an unused input
    out = render("full", found, sources={"big.stl": text})
    assert split == [len(text)]
    assert out.count("error[STL201]") == 2000

