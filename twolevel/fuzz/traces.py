"""Fuzzing trace CSVs: the same drive written in many ways, and mangled bytes.

The invariant: ``twolevel monitor`` answers every trace with verdicts or diagnostics (never an
exception); reformatting a trace (line endings, quoting, column order, spaces and tabs around
cells, a byte-order mark, blank lines) never changes a verdict or a finding; a verdict agrees
with its robustness (no NaN robustness is given one); mangled bytes (a quote, a NUL, bytes that
are not UTF-8, a line break in the middle of a cell, a truncated file) give diagnostics whose
lines exist in the file.

:func:`generate` draws a :class:`Case` (a table of cells and a rule file over its columns) from a
:class:`random.Random`; :func:`write` renders it in a :class:`Style`; :func:`probe` monitors the
plain rendering, ``variants`` restyled ones and one mangled one, and returns an
:class:`~twolevel.fuzz.rules.Outcome`.
"""

from __future__ import annotations

import os
import random
import tempfile
import traceback
from dataclasses import dataclass

from twolevel.fuzz.rules import ACCEPTED, INCONSISTENT, INTERNAL, REFUSED, Outcome, broken_verdict, outside

__all__ = ["Case", "Style", "PLAIN", "generate", "restyle", "write", "mangle", "probe"]

SIGNALS = ("v", "v_max", "d_stop", "x")
RULES = [
    "speed = v <= v_max;",
    "kept = always[0:{w}] (v <= v_max + 0.5);",
    "stops = eventually[0:{w}] (d_stop - v >= 0);",
    "moves = x until[0:{w}] (v > 3);",
    "calm = historically[0:{w}] not (v > 5);",
    "starts = rise(x > 0);",
    "next_fast = next (v > 1);",
    "huge = x * 1e300 > 0;",
    "same = d_stop - d_stop >= 0;",  # NaN where d_stop is infinite: a finding, never a verdict
    "either = (v > 2) or (x <= 0);",
    "scaled = abs(v - x) / 4 <= v_max;",
]


@dataclass(frozen=True)
class Case:
    """A drive: ``header`` and ``rows`` of cell texts (the time column among them), and a rule
    file over its signals. ``period`` [s] is the time column's spacing."""

    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    rules: str
    period: float


@dataclass(frozen=True)
class Style:
    """How a table is written: line ending, quoting ("none", "all", "some"), the column order (a
    permutation), spaces and tabs around cells, a byte-order mark, blank lines, a final newline."""

    ending: str = "\n"
    quoting: str = "none"
    order: tuple[int, ...] | None = None
    pad: bool = False
    bom: bool = False
    blank_lines: bool = False
    final_newline: bool = True


PLAIN = Style()


def _cell(rnd: random.Random) -> str:
    r = rnd.random()
    if r < 0.04:
        return rnd.choice(["inf", "-inf", "Infinity", "1e308", "-1e308", "5e-324", "-0.0", "1E3", "+2"])
    if r < 0.045:
        return rnd.choice(["", "nan", "n/a", "1,5", "GO"])  # a column that is not a signal
    if r < 0.3:
        return str(rnd.randint(-5, 30))
    return repr(round(rnd.uniform(-5, 30), rnd.randint(0, 6)))


def generate(rnd: random.Random) -> Case:
    """A random drive over some of :data:`SIGNALS` and a rule file over them."""
    period = rnd.choice([0.1, 0.05, 0.2, 1.0, 0.001])
    names = [s for s in SIGNALS if rnd.random() < 0.85] or ["v"]
    time_name = rnd.choice(["t", "time"])
    header = [time_name, *names] + (["decision"] if rnd.random() < 0.2 else [])
    rnd.shuffle(header)
    n = rnd.choice([1, 2, 3, 5, 10, 30])
    start = rnd.choice([0.0, 0.0, 3.5, 100.0])
    rows = []
    for k in range(n):
        row = []
        for name in header:
            if name == time_name:
                row.append(repr(start + k * period))
            elif name == "decision":
                row.append(rnd.choice(["plan", "sample, r=0.3", "brake \"hard\"", ""]))
            else:
                row.append(_cell(rnd))
        rows.append(tuple(row))
    w = repr(rnd.randint(0, 4) * period)
    lines = [f"input float {s}" for s in SIGNALS]
    lines += [rule.replace("{w}", w) for rule in rnd.sample(RULES, rnd.randint(1, 5))]
    return Case(tuple(header), tuple(rows), "\n".join(lines) + "\n", period)


def restyle(case: Case, rnd: random.Random) -> Style:
    """A random way to write ``case``."""
    order = list(range(len(case.header)))
    rnd.shuffle(order)
    return Style(ending=rnd.choice(["\n", "\r\n", "\r"]), quoting=rnd.choice(["none", "all", "some"]),
                 order=tuple(order), pad=rnd.random() < 0.5, bom=rnd.random() < 0.2,
                 blank_lines=rnd.random() < 0.3, final_newline=rnd.random() < 0.8)


def _quote(cell: str) -> str:
    return '"' + cell.replace('"', '""') + '"'


def _render_cell(cell: str, style: Style, rnd: random.Random) -> str:
    needs = any(c in cell for c in ',"\r\n') or cell != cell.strip()
    quoted = needs or style.quoting == "all" or (style.quoting == "some" and rnd.random() < 0.5)
    text = _quote(cell) if quoted else cell
    if style.pad:
        inside = rnd.choice(["", " ", "  ", "\t"]) if quoted and not needs else ""
        if quoted:  # spaces (not tabs) may stand before a quote; anything after it
            text = '"' + inside + text[1:-1] + inside + '"'
            return rnd.choice(["", " ", "  "]) + text + rnd.choice(["", " ", "\t"])
        return rnd.choice(["", " ", "\t"]) + text + rnd.choice(["", " ", "\t"])
    return text


def write(case: Case, style: Style, rnd: random.Random) -> bytes:
    """``case`` as CSV bytes in ``style`` (``rnd`` picks the quoted and padded cells)."""
    order = style.order or tuple(range(len(case.header)))
    lines = []
    for row in (case.header, *case.rows):
        lines.append(",".join(_render_cell(row[j], style, rnd) for j in order))
        if style.blank_lines and rnd.random() < 0.3:
            lines.append(rnd.choice(["", " ", "\t"]))
    text = style.ending.join(lines) + (style.ending if style.final_newline else "")
    return (b"\xef\xbb\xbf" if style.bom else b"") + text.encode("utf-8")


def mangle(data: bytes, rnd: random.Random) -> bytes:
    """``data`` with 1–4 byte-level accidents."""
    for _ in range(rnd.randint(1, 4)):
        at = rnd.randint(0, len(data))
        kind = rnd.randrange(6)
        if kind == 0:
            data = data[:at] + rnd.choice([b'"', b",", b"\r", b"\n", b"\x00", b"\xff", b"\xc3", b"\t", b" "]) + data[at:]
        elif kind == 1:
            data = data[:at] + data[at + rnd.randint(1, 8):]
        elif kind == 2:
            data = data[:at]
        elif kind == 3:
            data = data[:at] + rnd.choice([b"nan", b"inf", b"1e999", b"-", b"1e", b"0x10", b"\xe2\x80\xa8"]) + data[at:]
        elif kind == 4:
            data = data[:at] + b"," * rnd.randint(1, 50) + data[at:]
        else:
            data = data[:at] + b'"' + data[at:at + 20] + b'\n' + data[at + 20:]
    return data


def _verdicts(res: object) -> tuple[object, ...]:
    """What a user acts on: each rule's verdict (exact robustness) and the codes found."""
    report = res.report  # type: ignore[attr-defined]
    rules = () if report is None else tuple((r.name, r.robustness, r.satisfied, r.first_violation_t)
                                             for r in report.rules)
    return rules, tuple(sorted(d.code for d in res.diagnostics)), res.violated  # type: ignore[attr-defined]


def probe(case: Case, *, variants: int = 3, seed: int = 0, folder: str | None = None) -> Outcome:
    """Monitor ``case`` written plainly, in ``variants`` other styles and once mangled (drawn with
    ``seed``), and hold the results to the invariant (module docstring). The files are written
    into ``folder`` (created if needed, files of an earlier probe replaced), else into a
    temporary folder."""
    try:
        if folder is not None:
            os.makedirs(folder, exist_ok=True)
            return _probe(case, variants, random.Random(seed), folder)
        with tempfile.TemporaryDirectory() as d:
            return _probe(case, variants, random.Random(seed), d)
    except Exception:  # noqa: BLE001 - an exception anywhere is what this looks for
        return Outcome(INTERNAL, traceback.format_exc(limit=-3))


def _probe(case: Case, variants: int, rnd: random.Random, d: str) -> Outcome:
    from twolevel import pipeline

    rules = os.path.join(d, "rules.stl")
    with open(rules, "w", encoding="utf-8") as fh:
        fh.write(case.rules)

    def monitor(data: bytes, name: str) -> object:
        path = os.path.join(d, name)
        with open(path, "wb") as fh:
            fh.write(data)
        return pipeline.monitor(rules, path, series=True)

    plain = write(case, PLAIN, rnd)
    first = monitor(plain, "plain.csv")
    where = outside(plain.decode("utf-8"), first.diagnostics, ".csv")  # type: ignore[attr-defined]
    if where:
        return Outcome(INCONSISTENT, where)
    broken = broken_verdict(first.report)  # type: ignore[attr-defined]
    if broken:
        return broken
    expected = _verdicts(first)
    for k in range(variants):
        style = restyle(case, rnd)
        data = write(case, style, rnd)
        other = monitor(data, f"v{k}.csv")
        if _verdicts(other) != expected:
            return Outcome(INCONSISTENT, f"{style} changed the result:\n{_verdicts(other)}\ninstead of\n"
                                         f"{expected}\n{data!r}")
    mangled = mangle(plain, rnd)
    res = monitor(mangled, "mangled.csv")
    where = outside(mangled.decode("utf-8-sig", errors="replace"), res.diagnostics, ".csv")  # type: ignore[attr-defined]
    if where:
        return Outcome(INCONSISTENT, f"{where}: {mangled!r}")
    broken = broken_verdict(res.report)  # type: ignore[attr-defined]
    if broken:
        return broken
    codes = tuple(sorted(d.code for d in first.diagnostics))  # type: ignore[attr-defined]
    return Outcome(REFUSED if any(d.is_error for d in first.diagnostics) else ACCEPTED, "", codes)  # type: ignore[attr-defined]
