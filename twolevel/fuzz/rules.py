"""Fuzzing rule files: generate rule-language text, mangle it, and hold ``check`` to its promises.

The invariant: whatever the text, ``check`` answers with diagnostics whose positions lie inside
the text (never an exception); the same text under other line endings gets the same findings at
the same places; every renderer renders them; what parses prints back to text that parses to the
same file; and what ``check`` accepts is monitored over a small trace without an exception and
without a NaN robustness given a verdict.

:func:`generate` draws a text from a :class:`random.Random` (a file written from the grammar,
then 0–3 mutations: other line endings, odd characters, deleted or repeated pieces, long operator
chains, numbers at the edge of the floats); :func:`probe` runs the stages and returns an
:class:`Outcome`.
"""

from __future__ import annotations

import json
import math
import random
import traceback
from dataclasses import dataclass, field

__all__ = ["Outcome", "generate", "probe", "outside", "broken_verdict", "REFUSED", "ACCEPTED", "INTERNAL", "INCONSISTENT", "NAN_STATE"]

#: Verdicts of :func:`probe`: "refused" (an error diagnostic) and "accepted" keep the invariant,
#: the others break it.
REFUSED, ACCEPTED = "refused", "accepted"
INTERNAL, INCONSISTENT, NAN_STATE = "internal-error", "inconsistent", "nan-verdict"

SIGNALS = ("v", "v_max", "d_stop", "x", "a_1")
CONSTS = ("tol", "lim")

ODD = ["\f", "\v", "\x1c", "\x1d", "\x1e", "\x85", "\u2028", "\u2029", "\r", "\r\n", "\n", "\t", "\x00",
       "\x1b", "\ufeff", "\u200b", "\u0661", "\uff11", "\u0967", "é", "$", "#", "'", '"', "%", "^", "~", "\\"]
PIECES = ["input", "output", "const", "float", "int", "specification s", "import x", "=", "==", "!==", "!=",
          "<", "<=", ">", ">=", "+", "-", "*", "/", "(", ")", "[", "]", ":", ",", ";", "always", "G", "eventually",
          "F", "until", "U", "unless", "W", "since", "S", "historically", "H", "once", "O", "next", "X", "prev",
          "Y", "not", "!", "and", "&", "&&", "or", "|", "||", "->", "implies", "<->", "iff", "xor", "rise", "fall",
          "abs", "true", "false", "collision_free", "foo", "//c\n", "/*", "*/", "1e999", "2ms", "3s", "0.5"]
EDGE_NUMBERS = ["1e308", "1.7976931348623157e308", "1e309", "9e999", "5e-324", "1e-400", "0", "0.0", "1e-9",
                "123456789012345678901234567890", ".5", "5.", "1e308 * 10", "1e300 * 1e300", "1e308 + 1e308"]


@dataclass
class Outcome:
    """What happened to one input: ``verdict`` and, when it breaks the invariant, ``detail``."""

    verdict: str
    detail: str = ""
    codes: tuple[str, ...] = field(default_factory=tuple)

    @property
    def broken(self) -> bool:
        """The invariant does not hold for this input."""
        return self.verdict not in (REFUSED, ACCEPTED)


# ----------------------------------------------------------------------------- generation


def _number(rnd: random.Random) -> str:
    r = rnd.random()
    if r < 0.1:
        return rnd.choice(EDGE_NUMBERS)
    if r < 0.5:
        return str(rnd.randint(0, 100))
    return repr(round(rnd.uniform(0, 50), rnd.randint(0, 4)))


def _interval(rnd: random.Random) -> str:
    lo = rnd.randint(0, 5)
    hi = lo + rnd.randint(0, 10)
    unit = rnd.choice(["", "", "s", "ms"])
    scale = 100 if unit == "ms" else 1
    sep = rnd.choice([":", ","])
    return f"[{lo * scale / 10:g}{unit}{sep}{hi * scale / 10:g}{unit}]"


def _term(rnd: random.Random, depth: int) -> str:
    if depth <= 0 or rnd.random() < 0.4:
        return rnd.choice([*SIGNALS, *CONSTS]) if rnd.random() < 0.6 else _number(rnd)
    kind = rnd.randrange(4)
    if kind == 0:
        return f"{_term(rnd, depth - 1)} {rnd.choice('+-*/')} {_term(rnd, depth - 1)}"
    if kind == 1:
        return f"-{_term(rnd, depth - 1)}"
    if kind == 2:
        return f"abs({_term(rnd, depth - 1)})"
    return f"({_term(rnd, depth - 1)})"


def _formula(rnd: random.Random, depth: int, rules: list[str]) -> str:
    if depth <= 0 or rnd.random() < 0.25:
        r = rnd.random()
        if r < 0.1:
            return rnd.choice(["true", "false"])
        if r < 0.2 and rules:
            return rnd.choice(rules)
        if r < 0.25:
            return f"collision_free({_term(rnd, 1)})"
        op = rnd.choice(["<", "<=", ">", ">=", "==", "!=="])
        return f"{_term(rnd, 2)} {op} {_term(rnd, 2)}"
    kind = rnd.randrange(6)
    sub = lambda: _formula(rnd, depth - 1, rules)  # noqa: E731
    if kind == 0:
        op = rnd.choice(["and", "&", "&&", "or", "|", "||", "->", "implies", "<->", "iff", "xor"])
        return f"({sub()}) {op} ({sub()})"
    if kind == 1:
        op = rnd.choice(["always", "G", "eventually", "F", "historically", "H", "once", "O"])
        iv = _interval(rnd) if rnd.random() < 0.8 else ""
        return f"{op}{iv} ({sub()})"
    if kind == 2:
        return f"{rnd.choice(['next', 'X', 'prev', 'Y', 'not', '!'])} ({sub()})"
    if kind == 3:
        op = rnd.choice(["until", "U", "unless", "W", "since", "S"])
        iv = _interval(rnd) if rnd.random() < 0.8 else ""
        return f"({sub()}) {op}{iv} ({sub()})"
    if kind == 4:
        return f"{rnd.choice(['rise', 'fall'])}({sub()})"
    return f"({sub()})"


def _file(rnd: random.Random) -> str:
    lines = []
    for name in SIGNALS:
        if rnd.random() < 0.85:
            lines.append(f"input {rnd.choice(['float', 'float', 'int'])} {name}" + rnd.choice(["", ";", "  // [m/s]"]))
    for k, name in enumerate(CONSTS):
        if rnd.random() < 0.7:
            earlier = [*CONSTS[:k], _number(rnd)]
            value = rnd.choice(["", f" = {_number(rnd)}", f" = {rnd.choice(earlier)} {rnd.choice('+-*/')} {_number(rnd)}"])
            lines.append(f"const float {name}{value}")
    rules: list[str] = []
    for k in range(rnd.randint(0, 4)):
        name = f"r{k}"
        body = _formula(rnd, rnd.randint(0, 4), rules)
        lines.append(rnd.choice(["", "// a rule\n", "/* a\n rule */ "]) + f"{name} = {body}" + rnd.choice([";", ";", ""]))
        rules.append(name)
    return "\n".join(lines) + rnd.choice(["\n", "", "\n\n"])


def _chain(rnd: random.Random) -> str:
    n = rnd.choice([10, 63, 64, 65, 67, 70, 150, 199, 200, 201, 300])
    kind = rnd.randrange(6)
    if kind == 0:
        return " -> ".join(["v > 0"] * n)
    if kind == 1:
        return " - ".join(["v"] * n) + " > 0"
    if kind == 2:
        return "(" * n + "v > 0" + ")" * n
    if kind == 3:
        return "not " * n + "v > 0"
    if kind == 4:
        return " and ".join(["v > 0"] * n)
    return "- " * n + "v > 0"


def _mutate(text: str, rnd: random.Random) -> str:
    kind = rnd.randrange(8)
    at = rnd.randint(0, len(text))
    if kind == 0:  # another line-ending convention, or a mix
        ending = rnd.choice(["\r\n", "\r"])
        return "".join(c if c != "\n" or rnd.random() < 0.3 else ending for c in text)
    if kind == 1:
        return text[:at] + rnd.choice(ODD) + text[at:]
    if kind == 2 and text:
        end = min(len(text), at + rnd.randint(1, 12))
        return text[:at] + text[end:]
    if kind == 3 and text:
        end = min(len(text), at + rnd.randint(1, 30))
        return text[:end] + text[at:end] * rnd.randint(1, 3) + text[end:]
    if kind == 4:
        return text[:at] + " " + rnd.choice(PIECES) + " " + text[at:]
    if kind == 5:
        return text + f"\ndeep = {_chain(rnd)};\n"
    if kind == 6:
        return text + f"\nedge = v <= {rnd.choice(EDGE_NUMBERS)} {rnd.choice(['', '* 10', '- v * 1e308'])};\n"
    return text[:at] + rnd.choice(["//", "/*", "*/", "/* x */"]) + text[at:]


def generate(rnd: random.Random) -> str:
    """A rule-file text: a file from the grammar, then 0–3 mutations (none for a third)."""
    text = _file(rnd)
    for _ in range(rnd.choice([0, 0, 1, 1, 2, 3])):
        text = _mutate(text, rnd)
    return text


# ----------------------------------------------------------------------------- probing


def _positions(diags: object) -> list[tuple[str, int, int, int, int]]:
    return [(d.code, d.span.line, d.span.column, d.span.end_line, d.span.end_column) for d in diags]  # type: ignore[attr-defined]


def outside(text: str, diags: object, suffix: str = "") -> str | None:
    """The first diagnostic (about a file ending in ``suffix``) whose span does not lie inside
    ``text``, lines counted as the parser and the trace reader count them; ``None`` if none."""
    from twolevel.diagnostics import source_lines

    lines = source_lines(text)
    for d in diags:  # type: ignore[attr-defined]
        sp = d.span
        if not sp.file.endswith(suffix):
            continue
        for line, col in ((sp.line, sp.column), (sp.end_line, sp.end_column)):
            if not (1 <= line <= len(lines) and 1 <= col <= len(lines[line - 1]) + 1):
                return f"{d.code} at {sp.line}:{sp.column}-{sp.end_line}:{sp.end_column} lies outside the text"
    return None


def broken_verdict(report: object) -> Outcome | None:
    """The first rule of a monitor report (with series) whose verdict contradicts its robustness
    (NaN given a verdict, ``satisfied`` not ``robustness >= 0``, a violation time without a
    negative sample or the reverse); ``None`` if none."""
    import numpy as np

    for r in () if report is None else report.rules:  # type: ignore[attr-defined]
        if math.isnan(r.robustness) or r.series is None or np.isnan(r.series).any():
            return Outcome(NAN_STATE, f"rule {r.name}: NaN robustness with a verdict")
        first = np.flatnonzero(r.series < 0)
        if r.satisfied != (r.robustness >= 0) or (r.first_violation_t is None) != (first.size == 0):
            return Outcome(INCONSISTENT, f"rule {r.name}: verdict {r.satisfied}/{r.first_violation_t} "
                                         f"against robustness {r.robustness}")
    return None


def probe(text: str, *, dt: float | None = 0.1, horizon: int | None = 10, seed: int = 0) -> Outcome:
    """Check ``text`` as a rule file and hold every stage to the invariant (module docstring);
    ``seed`` draws the trace an accepted file is monitored over."""
    try:
        return _probe(text, dt, horizon, seed)
    except Exception:  # noqa: BLE001 - an exception anywhere is what this looks for
        return Outcome(INTERNAL, traceback.format_exc(limit=-3))


def _probe(text: str, dt: float | None, horizon: int | None, seed: int) -> Outcome:
    from twolevel.diagnostics import FORMATS, LINE_BREAK, render
    from twolevel.stl.lint import check_source
    from twolevel.stl.parser import parse
    from twolevel.stl.printer import format_file

    result = check_source(text, "fuzz.stl", dt=dt, horizon=horizon)
    diags = result.diagnostics
    codes = tuple(d.code for d in diags)
    verdict = REFUSED if any(d.is_error for d in diags) else ACCEPTED
    if result.rulefile is None and verdict == ACCEPTED:
        return Outcome(INCONSISTENT, "no rule file and no error", codes)
    where = outside(text, diags)
    if where:
        return Outcome(INCONSISTENT, where, codes)
    for fmt in FORMATS:
        out = render(fmt, diags, sources={"fuzz.stl": text}, files_checked=1)
        if fmt in ("json", "sarif"):
            json.loads(out, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
    for ending in ("\r\n", "\r"):
        other = check_source(LINE_BREAK.sub(ending, text), "fuzz.stl", dt=dt, horizon=horizon)
        if _positions(other.diagnostics) != _positions(diags):
            return Outcome(INCONSISTENT, f"other findings with {ending!r} line endings", codes)
    if result.rulefile is not None:
        printed = format_file(result.rulefile)
        back, back_diags = parse(printed, "fuzz.stl")
        if back != result.rulefile:
            why = "; ".join(d.message for d in back_diags[:2]) or "a different file"
            return Outcome(INCONSISTENT, f"printed text parses back to {why}:\n{printed}", codes)
    if verdict == ACCEPTED and result.ruleset is not None and not result.ruleset.unbound:
        broken = _monitor(result.ruleset, dt or 0.1, random.Random(seed))
        if broken is not None:
            return broken
    return Outcome(verdict, "", codes)


def _monitor(ruleset: object, dt: float, rnd: random.Random) -> Outcome | None:
    """Monitor an accepted rule set over a short random trace: verdicts agree with robustness."""
    import numpy as np

    from twolevel.monitor.tracefile import Trace, monitor_trace

    n = rnd.randint(1, 8)
    pool = [0.0, 1.0, -1.0, 13.9, 1e308, -1e308, math.inf, -math.inf, 5e-324]
    columns = {name: np.array([rnd.choice(pool) if rnd.random() < 0.3 else rnd.uniform(-50, 50) for _ in range(n)])
               for name in (*SIGNALS, "min_gap")}
    trace = Trace("fuzz.csv", np.arange(n) * dt, columns, dt)
    report, _ = monitor_trace(ruleset.rules, dict(ruleset.consts), trace, series=True)  # type: ignore[attr-defined]
    return broken_verdict(report)
