"""Trace CSV files: golden diagnostics for every kind of bad file, defined results for the
edge cases, monitoring rules over a trace, and the JSON report."""

from __future__ import annotations

import json
import math
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from twolevel.diagnostics import Severity, Span
from twolevel.monitor.tracefile import consts_of, monitor_trace, read_trace, to_json
from twolevel.stl import ast as A

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "monitor" / "drive.csv"


def _write(tmp_path: Path, text: str | bytes, name: str = "trace.csv") -> str:
    p = tmp_path / name
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text, encoding="utf-8")
    return str(p)


def _codes(diags: list) -> list[tuple[str, int, int]]:
    return [(d.code, d.span.line, d.span.column) for d in diags]


# ----------------------------------------------------------------------------- golden bad files


@pytest.mark.parametrize(
    ("name", "content", "expected", "words"),
    [
        ("empty", "", [("SIM604", 1, 1)], "empty"),
        ("blank", "\n\n  \n", [("SIM604", 1, 1)], "empty"),
        ("header_only", "t,v\n", [("SIM604", 1, 1)], "no samples"),
        ("binary", b"t,v\n\x00\x01\x02\n", [("SIM605", 1, 1)], "binary"),
        ("latin1", "t,v\n0,1\n".encode() + "0.1,caf\xe9\n".encode("latin-1"), [("SIM605", 3, 1)], "UTF-8"),
        ("no_time", "x,v\n0,1\n1,2\n", [("SIM601", 1, 1)], "no time column"),
        ("backwards", "t,v\n0,1\n0.1,2\n0.05,3\n", [("SIM601", 4, 1)], "increase strictly"),
        ("repeated", "time,v\n0,1\n0.1,2\n0.1,3\n", [("SIM601", 4, 1)], "increase strictly"),
        ("non_uniform", "t,v\n0,1\n0.1,2\n0.2,2\n0.4,3\n0.5,3\n", [("SIM601", 5, 1)], "not uniform"),
        ("text_time", "t,v\n0,1\nlater,2\n", [("SIM603", 3, 1)], "'later' is not a number"),
        ("ragged", "t,v\n0,1\n0.1,2,3\n", [("SIM603", 3, 1)], "3 cells"),
        ("dup_column", "t,v,v\n0,1,2\n", [("SIM606", 1, 5)], "appears twice"),
        ("unnamed_column", "t,,v\n0,1,2\n", [("SIM606", 1, 3)], "no name"),
    ],
)
def test_bad_trace_files(tmp_path: Path, name: str, content: str | bytes, expected: list, words: str) -> None:
    path = _write(tmp_path, content, f"{name}.csv")
    trace, diags = read_trace(path)
    assert trace is None
    assert _codes(diags) == expected
    assert words in diags[0].message
    assert all(d.severity is Severity.ERROR and d.span.file == path for d in diags)


def test_missing_file_and_directory(tmp_path: Path) -> None:
    trace, diags = read_trace(str(tmp_path / "nope.csv"))
    assert trace is None and _codes(diags) == [("SIM605", 1, 1)] and "does not exist" in diags[0].message
    trace, diags = read_trace(str(tmp_path))
    assert trace is None and _codes(diags) == [("SIM605", 1, 1)] and "directory" in diags[0].message


def test_many_ragged_rows_stop_early(tmp_path: Path) -> None:
    rows = "\n".join(f"{k * 0.1:.1f},1,2" for k in range(500))
    trace, diags = read_trace(_write(tmp_path, "t,v\n" + rows + "\n"))
    assert trace is None
    assert len(diags) == 21 and "stopped after 20" in diags[-1].message


@pytest.mark.parametrize(
    ("name", "content", "where", "words"),
    [
        ("text_cell", "t,v,w\n0,1,2\n0.1,fast,2\n", (3, 5), "'fast' is not a number"),
        ("nan_cell", "t,w,v\n0,1,2\n0.1,2,NaN\n", (3, 7), "column 'v' is NaN"),
        ("empty_cell", "t,v,w\n0,,2\n0.1,1,2\n", (2, 3), "is empty"),
    ],
)
def test_bad_cells_matter_only_in_columns_a_rule_reads(tmp_path: Path, name: str, content: str, where: tuple, words: str) -> None:
    """A simulator trace carries text columns (decision, light_state): they are no error unless
    a rule reads them; then the first bad cell is reported at its line and column."""
    trace, diags = read_trace(_write(tmp_path, content, f"{name}.csv"))
    assert trace is not None and diags == [] and "v" in trace.unusable
    other = [c for c in trace.columns if c != "v"]
    reads_v = A.Rule("r", A.Compare(">=", A.Var("v"), A.Num(0.0)))
    reads_other = A.Rule("q", A.Compare(">=", A.Var(other[0]), A.Num(0.0)))
    report, diags = monitor_trace([reads_other, reads_v], {}, trace)
    assert [r.name for r in report.rules] == ["q"]
    assert [(d.code, d.span.line, d.span.column) for d in diags] == [("SIM603", *where)]
    assert words in diags[0].message and "rule 'r'" in diags[0].message


def test_infinite_cells_are_values(tmp_path: Path) -> None:
    trace, diags = read_trace(_write(tmp_path, "t,d_stop\n0,inf\n0.1,-inf\n"))
    assert diags == [] and trace is not None
    assert trace.columns["d_stop"].tolist() == [math.inf, -math.inf]


# ----------------------------------------------------------------------------- defined results


def test_good_trace_with_bom_crlf_and_spaces(tmp_path: Path) -> None:
    text = "\ufefftime, v , w\r\n0.0, 1.5, 2\r\n0.1, 2.5, 3\r\n0.2,3.5,4\r\n"
    trace, diags = read_trace(_write(tmp_path, text))
    assert diags == [] and trace is not None
    assert trace.dt == 0.1 and trace.samples == 3
    assert trace.t.tolist() == [0.0, 0.1, 0.2]
    assert sorted(trace.columns) == ["v", "w"] and trace.columns["v"].tolist() == [1.5, 2.5, 3.5]


def test_one_row_trace_assumes_a_period(tmp_path: Path) -> None:
    trace, diags = read_trace(_write(tmp_path, "t,v\n3.0,7\n"))
    assert trace is not None and trace.samples == 1 and trace.dt == 0.1
    assert _codes(diags) == [("SIM608", 2, 1)] and diags[0].severity is Severity.INFO
    trace, diags = read_trace(_write(tmp_path, "t,v\n3.0,7\n"), dt=0.5)
    assert trace is not None and trace.dt == 0.5 and diags == []
    rule = A.Rule(name="r", formula=A.Temporal("always", A.Interval(0.0, 1.0), A.Compare("<", A.Var("v"), A.Num(10.0))))
    report, diags = monitor_trace([rule], {}, trace)
    assert diags == [] and report.rules[0].robustness == 3.0 and report.rules[0].first_violation_t is None


def test_dt_override(tmp_path: Path) -> None:
    # no time column: rows are samples every dt
    trace, diags = read_trace(_write(tmp_path, "v\n1\n2\n"), dt=0.2)
    assert diags == [] and trace is not None and trace.t.tolist() == [0.0, 0.2]
    # a time column that disagrees with --dt: a warning, rows taken as samples every dt
    trace, diags = read_trace(_write(tmp_path, "t,v\n0,1\n0.1,2\n0.3,3\n"), dt=0.1)
    assert trace is not None and trace.dt == 0.1
    assert _codes(diags) == [("SIM601", 4, 1)] and diags[0].severity is Severity.WARNING
    trace, diags = read_trace(_write(tmp_path, "t,v\n0,1\n"), dt=-1.0)
    assert trace is None and diags[0].code == "SIM601"


def test_large_file_is_streamed(tmp_path: Path) -> None:
    n = 100_000
    t = np.arange(n) * 0.01
    data = np.column_stack([t, np.sin(t), np.cos(t)])
    path = tmp_path / "big.csv"
    np.savetxt(path, data, delimiter=",", header="t,a,b", comments="", fmt="%.6f")
    tracemalloc.start()
    trace, diags = read_trace(str(path))
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert diags == [] and trace is not None and trace.samples == n and trace.dt == 0.01
    numeric = data.nbytes  # 2.4 MB
    assert peak < 4 * numeric, peak  # typed arrays + row line numbers, not Python float lists


# ----------------------------------------------------------------------------- monitoring


def _speed_rules() -> list[A.Rule]:
    slow = A.Compare("<=", A.Var("v"), A.Arith("+", A.Var("v_max"), A.Var("tol")))
    return [
        A.Rule(name="speed_limit", formula=A.Temporal("always", A.Interval(0.0, 1.0), slow)),
        A.Rule(name="never_fast", formula=A.Temporal("always", None, A.Var("speed_limit"))),
    ]


def test_example_drive_violates_the_speed_limit_briefly() -> None:
    trace, diags = read_trace(str(EXAMPLE))
    assert diags == [] and trace is not None and trace.samples == 100 and trace.dt == 0.1
    report, diags = monitor_trace(_speed_rules(), {"tol": 0.5}, trace, series=True)
    assert diags == []
    first = report.rules[0]
    assert first.name == "speed_limit" and first.satisfied and first.robustness == pytest.approx(2.4)
    assert first.first_violation_t == pytest.approx(3.3)
    assert first.series is not None and first.series.shape == (100,)
    assert not np.all(first.series[-10:] < 0)  # the surge is over before the end
    assert report.rules[1].robustness < 0 and not report.rules[1].satisfied
    assert report.violated


def test_missing_column_names_signal_and_rule_with_a_hint(tmp_path: Path) -> None:
    trace, _ = read_trace(_write(tmp_path, "t,v,vmax\n0,1,2\n0.1,1,2\n"))
    assert trace is not None
    v_max = A.Var("v_max", span=Span("speed.stl", 4, 30, 4, 35))
    rules = [
        A.Rule(name="speed_limit", formula=A.Compare("<=", A.Var("v"), v_max)),
        A.Rule(name="uses_it", formula=A.Not(A.Var("speed_limit"))),
        A.Rule(name="ok", formula=A.Compare("<=", A.Var("v"), A.Num(5.0))),
        A.Rule(name="safe", formula=A.Call("collision_free", (A.Num(1.0),))),
    ]
    report, diags = monitor_trace(rules, {}, trace)
    assert [r.name for r in report.rules] == ["ok"]
    assert _codes(diags) == [("SIM602", 4, 30), ("SIM602", 1, 1)]
    assert "'speed_limit'" in diags[0].message and "'v_max'" in diags[0].message
    assert diags[0].hint == "did you mean 'vmax'?"
    assert "'min_gap'" in diags[1].message and "'safe'" in diags[1].message


def test_unknown_builtin_is_a_diagnostic(tmp_path: Path) -> None:
    trace, _ = read_trace(_write(tmp_path, "t,v\n0,1\n"))
    assert trace is not None
    report, diags = monitor_trace([A.Rule(name="r", formula=A.Call("teleport", ()))], {}, trace)
    assert report.rules == () and diags[0].code == "SIM607" and "teleport" in diags[0].message


def test_json_report_is_json_safe(tmp_path: Path) -> None:
    trace, _ = read_trace(_write(tmp_path, "t,v\n0,1\n0.5,-1\n1.0,2\n"))
    assert trace is not None
    rules = [
        A.Rule(name="pos", formula=A.Compare(">", A.Var("v"), A.Num(0.0))),
        A.Rule(name="later", formula=A.Temporal("always", A.Interval(1.0, 1.0), A.Var("v"))),
    ]
    report, diags = monitor_trace(rules, {}, trace, series=True)
    doc = to_json(report)
    assert json.loads(json.dumps(doc, allow_nan=False)) == doc
    assert doc["rules"][0] == {
        "name": "pos",
        "verdict": "violated",
        "robustness": 1.0,
        "satisfied": True,
        "first_violation_t": 0.5,
        "series": [1.0, -1.0, 2.0],
    }
    assert doc["rules"][1]["series"] == [2.0, "inf", "inf"]  # 1 s = 2 samples
    plain = to_json(monitor_trace(rules, {}, trace)[0])
    assert "series" not in plain["rules"][0]


def test_consts_of_a_rule_file() -> None:
    rf = A.RuleFile(
        path="x.stl",
        declarations=(
            A.Declaration(kind="const", type="float", name="a", value=A.Num(2.0)),
            A.Declaration(kind="const", type="float", name="b", value=A.Arith("*", A.Var("a"), A.Neg(A.Num(1.5)))),
            A.Declaration(kind="input", type="float", name="v"),
        ),
    )
    assert consts_of(rf) == {"a": 2.0, "b": -3.0}
    assert math.isfinite(consts_of(rf)["b"])


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="no FIFOs here")
def test_fifo_and_device_are_refused_without_blocking(tmp_path: Path) -> None:
    import os
    import threading

    fifo = tmp_path / "fifo.csv"
    os.mkfifo(fifo)
    box: list = []
    th = threading.Thread(target=lambda: box.append(read_trace(str(fifo))), daemon=True)
    th.start()
    th.join(5.0)
    if th.is_alive():  # release the blocked reader (end of file), then fail
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        th.join(5.0)
        pytest.fail("read_trace blocked on a FIFO")
    trace, diags = box[0]
    assert trace is None and _codes(diags) == [("SIM605", 1, 1)] and "FIFO" in diags[0].message
    if Path("/dev/zero").exists():
        trace, diags = read_trace("/dev/zero")
        assert trace is None and _codes(diags) == [("SIM605", 1, 1)] and "device" in diags[0].message


def test_header_and_cell_positions_cost_linear_work_in_the_number_of_columns(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # 100,000 columns took over a minute: each cell's column was a fresh O(j) sum.
    from twolevel.monitor import tracefile

    work = [0]
    real = tracefile._Record.cell_spans

    def counted(self, path):  # one scan of the record's text
        work[0] += sum(map(len, self.lines))
        return real(self, path)

    monkeypatch.setattr(tracefile._Record, "cell_spans", counted)

    def run(n: int) -> int:
        work[0] = 0
        names = ",".join(f"c{k}" for k in range(n))
        path = _write(tmp_path, f"t,{names}\n0,{','.join(['x'] * n)}\n0.1,{','.join(['1'] * n)}\n", f"w{n}.csv")
        trace, diags = read_trace(path)
        assert trace is not None and diags == []
        unusable = [d for d in tracefile._read_rows(path, [])[3].values()]
        assert len(unusable) == n
        last = unusable[-1].span
        assert last.line == 2 and last.column == 3 + 2 * (n - 1)  # "0," then "x," per column
        assert work[0] > 0
        return work[0]

    small, large = run(1000), run(4000)
    assert large <= 4.5 * small, (small, large)


def test_many_rules_cost_linear_set_up(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # 29,206 rules took over a minute: every rule re-checked and re-converted all earlier ones.
    from twolevel.monitor import robustness as R

    work = [0]
    real = R._trace_length

    def counted(signals, rules):
        work[0] += len(signals) + len(rules)
        return real(signals, rules)

    monkeypatch.setattr(R, "_trace_length", counted)
    trace, diags = read_trace(_write(tmp_path, "t,v\n0,1\n0.1,2\n0.2,3\n"))
    assert trace is not None

    def run(n: int) -> int:
        work[0] = 0
        rules = [A.Rule(name="r0", formula=A.Compare("<=", A.Var("v"), A.Num(2.5)))]
        rules += [A.Rule(name=f"r{k}", formula=A.Not(A.Var(f"r{k - 1}"))) for k in range(1, n)]
        report, diags = monitor_trace(rules, {}, trace)
        assert diags == [] and len(report.rules) == n
        assert report.rules[-1].robustness == (1.5 if n % 2 else -1.5)
        out = R.evaluate_rules(rules, trace.columns, trace.dt)
        assert float(out[f"r{n - 1}"][0]) == report.rules[-1].robustness
        return work[0]

    small, large = run(200), run(800)
    assert large <= 4.5 * small, (small, large)


def test_missing_column_hint_is_computed_once_per_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # 4000 rules reading 'v' from a 100,000-column trace ran difflib 4000 times over every column.
    from twolevel.monitor import tracefile

    calls = [0]
    real = tracefile.difflib.get_close_matches

    def counted(*args, **kw):
        calls[0] += 1
        return real(*args, **kw)

    monkeypatch.setattr(tracefile.difflib, "get_close_matches", counted)
    names = ",".join(f"c{k}" for k in range(100))
    trace, _ = read_trace(_write(tmp_path, f"t,{names}\n0,{','.join(['1'] * 100)}\n0.1,{','.join(['1'] * 100)}\n"))
    assert trace is not None
    rules = [A.Rule(name=f"r{k}", formula=A.Compare("<=", A.Var("v"), A.Num(k))) for k in range(50)]
    report, diags = monitor_trace(rules, {}, trace)
    assert report.rules == () and [d.code for d in diags] == ["SIM602"] * 50
    assert calls[0] == 1
    assert "(80 more)" in (diags[0].hint or "")


def test_undefined_robustness_is_a_finding_not_a_verdict(tmp_path: Path) -> None:
    """Regression: inf - inf (an overflowing term, or an infinite signal) gave NaN robustness with
    satisfied false and no violation time. Such a rule now gets no verdict (SIM607, with the
    first time it is undefined); infinite robustness stays a value with the verdict of its sign."""
    trace, _ = read_trace(_write(tmp_path, "t,v,d\n0,1,5\n0.1,2,inf\n0.2,3,-inf\n"))
    assert trace is not None
    rules = [
        A.Rule(name="nan", formula=A.Compare(">=", A.Arith("-", A.Var("d"), A.Var("d")), A.Num(0.0))),
        A.Rule(name="uses_nan", formula=A.Not(A.Var("nan"))),
        A.Rule(name="huge", formula=A.Compare(">=", A.Arith("*", A.Var("v"), A.Num(1e308)), A.Num(0.0))),
        A.Rule(name="far", formula=A.Compare("<=", A.Var("d"), A.Num(10.0))),
    ]
    report, diags = monitor_trace(rules, {}, trace)
    assert [r.name for r in report.rules] == ["huge", "far"]
    assert [(d.code, "t = 0.1 s" in d.message) for d in diags] == [("SIM607", True)]
    huge, far = report.rules
    assert huge.robustness == 1e308 and huge.satisfied and huge.first_violation_t is None
    assert far.robustness == 5.0 and far.satisfied and far.first_violation_t == pytest.approx(0.1)


@pytest.mark.parametrize("ending", ["\n", "\r\n", "\r"], ids=["LF", "CRLF", "CR"])
def test_cell_positions_are_exact_with_spaces_quotes_and_line_breaks_in_cells(tmp_path: Path, ending: str) -> None:
    """Regression: positions assumed unquoted cells without blanks, and a record holding a quoted
    line break was reported at its last line instead of its first."""
    text = ending.join([
        't, "v", note',
        '0.0, 1.5, "two\nlines"',
        '0.1,  "oops" , ok',
        '0.2, 2.5, x',
    ]) + ending
    path = _write(tmp_path, text)
    report, diags = monitor_trace([A.Rule(name="r", formula=A.Compare(">", A.Var("v"), A.Num(0.0)))], {},
                                  read_trace(path)[0])
    [bad] = diags
    assert (bad.code, bad.span.line, bad.span.column, bad.span.end_column) == ("SIM603", 4, 7, 13)
    ragged = read_trace(_write(tmp_path, text.replace('lines"', 'lines", more'), "ragged.csv"))[1]
    assert _codes(ragged) == [("SIM603", 2, 1)]  # the first line of the record, not its last
    header = read_trace(_write(tmp_path, 't, "v" , "v"' + ending + "0,1,2" + ending, "dup.csv"))[1]
    assert _codes(header) == [("SIM606", 1, 10)]


def test_spaces_before_a_quoted_cell_are_blanks(tmp_path: Path) -> None:
    """Regression: 'a, "1.5"' read the cell as the text ' "1.5"' (not a number), so quoting a
    trace changed its verdicts."""
    trace, diags = read_trace(_write(tmp_path, 't, "v"\n0, "1.5"\n0.1,  "-2" \n'))
    assert diags == [] and trace is not None and trace.columns["v"].tolist() == [1.5, -2.0]


def test_infinite_time_is_refused(tmp_path: Path) -> None:
    trace, diags = read_trace(_write(tmp_path, "t,v\n0,1\n0.1,2\ninf,3\n"))
    assert trace is None and _codes(diags) == [("SIM601", 4, 1)] and "finite" in diags[0].message
