"""The diagnostics core: one serialised form feeding every output format."""

from __future__ import annotations

import ast
import importlib
import json
from pathlib import Path

import pytest

from twolevel.diagnostics import REGISTRY, Code, Diagnostic, Severity, Span, render, sort_key

TST901 = Code("TST901", "test-error", Severity.ERROR, "An error used by the renderer tests.")
TST902 = Code("TST902", "test-warning", Severity.WARNING, "A warning used by the renderer tests.")

SOURCE = "input float v\nspeed = always[0:1] (v <= 30);\n"


def _diags() -> list[Diagnostic]:
    return [
        TST902("odd, with a comma, and: colon", Span("b.stl", 2, 9, 2, 20)),
        TST901("undeclared signal 'vx'", Span("a.stl", 2, 22, 2, 24), hint="did you mean 'v'?"),
    ]


def test_code_call_makes_a_diagnostic_with_default_severity() -> None:
    d = TST901("m", Span("f", 3, 4, 3, 9))
    assert (d.code, d.severity, d.message, d.span.line, d.span.column) == ("TST901", Severity.ERROR, "m", 3, 4)
    assert REGISTRY["TST901"] is TST901


def test_redeclaring_a_code_differently_is_refused() -> None:
    with pytest.raises(ValueError):
        Code("TST901", "other-name", Severity.INFO, "different")


def test_bad_input_is_a_property_of_the_code_and_only_of_errors() -> None:
    bad = Code("TST903", "test-bad-input", Severity.ERROR, "A bad input used by this test.", bad_input=True)
    assert bad("m", Span("f")).bad_input
    assert not bad("m", Span("f"), severity=Severity.WARNING).bad_input  # demoted: a finding
    assert not TST901("m", Span("f")).bad_input
    assert not Diagnostic("XXX999", Severity.ERROR, "never declared", Span("f")).bad_input


ROOT = Path(__file__).resolve().parents[1] / "twolevel"
STAGE_PREFIXES = {  # the codes.py of each stage and the codes it may declare
    "stl": ("STL",), "world": ("YML",), "compiler": ("MIL50",), "control": ("MIL51", "MIL52", "MIL53"),
    "monitor": ("SIM60",), "sim": ("SIM61", "SIM63"), "verdict": ("SIM62",), "pipeline": ("CLI",),
    "interop": ("IMP",),
}


def test_every_code_is_declared_in_its_stage_codes_module() -> None:
    """Codes are declared only in ``twolevel/<stage>/codes.py``, each with its stage's prefix, and
    the CLI's and pipeline's exit decisions read ``bad_input`` instead of code prefixes."""
    outside = []
    for path in sorted(ROOT.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)
                 and n.func.id == "Code"]
        if calls and path.name != "codes.py":
            outside.append(f"{path.relative_to(ROOT)}:{calls[0].lineno}")
        prefixes = [n for n in ast.walk(tree) if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
                    and n.func.attr == "startswith" and isinstance(n.func.value, ast.Attribute)
                    and n.func.value.attr == "code"]
        assert not prefixes, f"{path}: a decision by code prefix (declare bad_input on the Code)"
    assert not outside, outside
    for stage, allowed in STAGE_PREFIXES.items():
        module = importlib.import_module(f"twolevel.{stage}.codes")
        ids = [v.id for v in vars(module).values() if isinstance(v, Code)]
        assert ids, stage
        assert all(i.startswith(allowed) for i in ids), (stage, ids)
    found = {p.parent.name for p in ROOT.rglob("codes.py")}
    assert found == set(STAGE_PREFIXES), found


def test_span_end_never_precedes_start() -> None:
    s = Span("f", 5, 7)
    assert (s.end_line, s.end_column) == (5, 7)
    assert Span("f", 1, 1, 2, 3).to(Span("f", 4, 1, 4, 9)) == Span("f", 1, 1, 4, 9)


def test_json_has_the_documented_shape_sorted_by_file() -> None:
    payload = json.loads(render("json", _diags(), files_checked=2))
    assert payload["files_checked"] == 2
    first = payload["diagnostics"][0]
    assert set(first) == {"file", "line", "column", "end_line", "end_column", "code", "severity", "message", "hint"}
    assert [d["file"] for d in payload["diagnostics"]] == ["a.stl", "b.stl"]
    assert first["line"] == 2 and first["column"] == 22 and first["hint"] == "did you mean 'v'?"


def test_concise_is_one_line_per_finding() -> None:
    lines = render("concise", _diags()).splitlines()
    assert lines == [
        "a.stl:2:22: TST901 [error] undeclared signal 'vx'",
        "b.stl:2:9: TST902 [warning] odd, with a comma, and: colon",
    ]


def test_full_shows_the_source_line_and_a_caret_under_the_span() -> None:
    text = render("full", _diags()[1:], sources={"a.stl": SOURCE})
    lines = text.splitlines()
    assert lines[0] == "a.stl:2:22: error[TST901]: undeclared signal 'vx'"
    assert lines[1].endswith(SOURCE.splitlines()[1])
    caret = lines[2]
    # the caret sits under columns 22..23 of the source line
    offset = lines[1].index("speed")
    assert caret.index("^") - offset == 21 and caret.count("^") == 2
    assert "hint: did you mean 'v'?" in lines[3]


def test_github_escapes_property_separators_and_newlines() -> None:
    d = TST902("line1\nline2, 100%", Span("dir:x,y.stl", 1, 2, 1, 3))
    out = render("github", [d]).strip()
    assert out.startswith("::warning file=dir%3Ax%2Cy.stl,line=1,col=2,")
    assert out.endswith("::TST902 line1%0Aline2, 100%25")


def test_sarif_lists_each_used_rule_once_with_regions() -> None:
    doc = json.loads(render("sarif", _diags() + _diags()))
    run = doc["runs"][0]
    assert doc["version"] == "2.1.0"
    assert sorted(r["id"] for r in run["tool"]["driver"]["rules"]) == ["TST901", "TST902"]
    assert len(run["results"]) == 4
    region = run["results"][0]["locations"][0]["physicalLocation"]["region"]
    assert region == {"startLine": 2, "startColumn": 22, "endLine": 2, "endColumn": 24}
    assert {r["level"] for r in run["results"]} == {"error", "warning"}


def test_unknown_format_is_refused() -> None:
    with pytest.raises(ValueError):
        render("xml", [])


def test_sort_key_orders_by_file_then_position() -> None:
    ds = sorted(_diags(), key=sort_key)
    assert [d.span.file for d in ds] == ["a.stl", "b.stl"]


def test_sarif_uris_are_percent_encoded() -> None:
    """A path with reserved characters must stay a valid URI reference (review finding)."""
    doc = json.loads(render("sarif", [TST901("m", Span("./we,ird::na%me x.stl", 1, 1))]))
    uri = doc["runs"][0]["results"][0]["locations"][0]["physicalLocation"]["artifactLocation"]["uri"]
    assert uri == "./we%2Cird%3A%3Ana%25me%20x.stl"


def test_github_annotations_leave_out_columns_for_spans_across_lines() -> None:
    """Regression: GitHub rejects an annotation with columns whose endLine differs from its line."""
    one = TST901("one line", Span("r.stl", 3, 5, 3, 9))
    many = TST902("across lines", Span("r.stl", 3, 5, 6, 2))
    lines = render("github", [one, many]).splitlines()
    assert lines[0].startswith("::error file=r.stl,line=3,col=5,endLine=3,endColumn=9,title=TST901::")
    assert lines[1].startswith("::warning file=r.stl,line=3,endLine=6,title=TST902::")
    assert "col=" not in lines[1] and "endColumn=" not in lines[1]
