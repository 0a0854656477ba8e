"""The online (incremental) monitor: one sample at a time, O(1) amortised work per operator.

Rules are compiled into a graph of stream nodes (:mod:`twolevel.monitor.stream`): Lemire wedges
for ``always/eventually/historically/once``, a two-stacks window of clamps for ``until/since``
(``until[a,b] = always[0,a-1] l  and  shift_a(l until[0,b-a] r)``), delay lines to align
children of unequal look-ahead. The per-sample code is generated once as one Python function
(stateless operators inlined), so a sample costs a few hundred nanoseconds per operator,
independent of window lengths.

* :meth:`OnlineMonitor.update` returns the robustness values that became final with this
  sample: a rule with look-ahead ``L`` samples (``always[0:1s]`` at dt 0.1: ``L = 10``) is final
  at sample ``k`` once sample ``k + L`` has arrived.
* :meth:`OnlineMonitor.interval_at` / :meth:`OnlineMonitor.pending` give, before that, the
  robustness interval ``[lo, hi]`` (Deshmukh et al. 2017): every continuation of the trace that
  reaches ``k + L`` yields a final value inside it (unseen atomic values range over
  ``[-inf, +inf]``). ``lo >= 0`` already proves satisfaction, ``hi < 0`` violation.
* :meth:`OnlineMonitor.finish` ends the trace with RTAMT's truncation: on every prefix it equals
  the offline :func:`~twolevel.monitor.robustness.robustness` exactly. It does not stop the
  monitor; more samples may follow.

Unbounded future operators (``always`` without a bound, ``until`` without one) cannot run online
and are rejected with :class:`~twolevel.monitor.errors.MonitorError`; past ones are fine.

Quantifiers over participants are expanded over the ``participants`` the monitor is given
(:func:`~twolevel.stl.analysis.expand_quantifiers`): each sample then carries every one's
``present[p]`` (+inf/-inf) and the signals ``name[p]`` the rules read.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from twolevel.monitor import stream as st
from twolevel.monitor.errors import MonitorError
from twolevel.monitor.robustness import DEFAULT_BUILTINS, Builtin
from twolevel.stl import ast
from twolevel.stl.analysis import expand_quantifiers, quantifies

__all__ = ["OnlineMonitor", "Verdict"]

INF = math.inf

Verdict = tuple[str, int, float]
"""``(rule, sample index k, robustness)``: a value that became final (time ``k * dt`` [s])."""


def _div(a: float, b: float) -> float:
    """Division as numpy does it: ``x/0`` is ``±inf`` (``nan`` for ``0/0``), never an exception."""
    try:
        return a / b
    except ZeroDivisionError:
        if a != a or a == 0:
            return math.nan
        return math.copysign(INF, a) * math.copysign(1.0, b)


@dataclass
class _Slot:
    node: st.Node
    children: tuple[int, ...]
    in_lat: int  # absolute look-ahead of its inputs (samples)
    lat: int  # absolute look-ahead of its output


class _Compiler:
    """AST → list of slots in topological order; terms become inlined Python expressions."""

    def __init__(self, dt: float, consts: Mapping[str, float], builtins: Mapping[str, Builtin]) -> None:
        self.dt = dt
        self.consts = consts
        self.builtins = builtins
        self.slots: list[_Slot] = []
        self.namespace: dict[str, Any] = {"inf": INF, "nan": math.nan, "_div": _div}
        self.rules: dict[str, int] = {}
        self.delays: dict[tuple[int, int], int] = {}
        self.consts_ids: dict[float, int] = {}

    def add(self, node: st.Node, children: Sequence[int] = ()) -> int:
        in_lat = max((self.slots[c].lat for c in children), default=0)
        self.slots.append(_Slot(node, tuple(children), in_lat, in_lat + node.lat))
        return len(self.slots) - 1

    def aligned(self, children: Sequence[int]) -> list[int]:
        top = max(self.slots[c].lat for c in children)
        out = []
        for c in children:
            gap = top - self.slots[c].lat
            if gap:
                key = (c, gap)
                if key not in self.delays:
                    self.delays[key] = self.add(st.Delay(gap), (c,))
                c = self.delays[key]
            out.append(c)
        return out

    def op(self, node: st.Node, *children: int) -> int:
        return self.add(node, self.aligned(children) if len(children) > 1 else children)

    def const(self, value: float) -> int:
        if value not in self.consts_ids:
            self.consts_ids[value] = self.add(st.Const(value))
        return self.consts_ids[value]

    # -- terms ----------------------------------------------------------------------------------
    def term(self, t: ast.Node) -> str:
        if isinstance(t, ast.Num):
            return f"({float(t.value)!r})"
        if isinstance(t, ast.Var):
            if t.name in self.rules:
                raise MonitorError(f"rule '{t.name}' used inside arithmetic cannot run online", t.name)
            if t.name in self.consts:
                return f"({float(self.consts[t.name])!r})"
            return f"s[{t.name!r}]"
        if isinstance(t, ast.Neg):
            return f"(-{self.term(t.operand)})"
        if isinstance(t, ast.Abs):
            return f"abs({self.term(t.operand)})"
        if isinstance(t, ast.Arith):
            left, right = self.term(t.left), self.term(t.right)
            return f"_div({left}, {right})" if t.op == "/" else f"({left} {t.op} {right})"
        raise MonitorError(f"a {type(t).__name__} is not a term", type(t).__name__)

    def atom(self, code: str) -> int:
        fn = eval(f"lambda s: {code}", self.namespace)  # noqa: S307 - built from our own AST
        return self.add(st.Atom(fn, code))

    # -- formulas -------------------------------------------------------------------------------
    def formula(self, root: ast.Node) -> int:
        # comparisons and built-in calls are single atoms: their terms are inlined code, not slots
        return ast.fold(root, self.build, leaves=(ast.Compare, ast.Call))

    def steps(self, interval: ast.Interval | None) -> tuple[int, int | None]:
        return (0, None) if interval is None else interval.steps(self.dt)

    def bounded(self, interval: ast.Interval | None, op: str) -> tuple[int, int]:
        a, b = self.steps(interval)
        if b is None:
            raise MonitorError(
                f"'{op}' without an upper time bound looks into the unbounded future and cannot run online; "
                f"give it an interval such as {op}[0:5s]",
                op,
            )
        return a, b

    def build(self, node: ast.Node, kids: list[int]) -> int:  # noqa: C901 - a dispatch table
        if isinstance(node, ast.Compare):
            left, right = self.term(node.left), self.term(node.right)
            code = {
                "<": f"({right} - {left})",
                "<=": f"({right} - {left})",
                ">": f"({left} - {right})",
                ">=": f"({left} - {right})",
                "==": f"(-abs({left} - {right}))",
                "!==": f"abs({left} - {right})",
            }[node.op]
            return self.atom(code)
        if isinstance(node, ast.Call):
            fn = self.builtins.get(node.name)
            if fn is None:
                raise MonitorError(f"unknown built-in predicate '{node.name}'", node.name)
            key = f"_b_{len(self.namespace)}"
            self.namespace[key] = fn
            args = "".join(", " + self.term(a) for a in node.args)
            return self.atom(f"float({key}(s{args}))")
        if isinstance(node, ast.Var):
            if node.name in self.rules:
                return self.rules[node.name]
            if node.name in self.consts:
                return self.const(float(self.consts[node.name]))
            return self.atom(f"s[{node.name!r}]")
        if isinstance(node, ast.BoolConst):
            return self.const(INF if node.value else -INF)
        if isinstance(node, ast.Not):
            return self.op(st.Stateless("not"), kids[0])
        if isinstance(node, ast.Binary):
            return self.op(st.Stateless(node.op), kids[0], kids[1])
        if isinstance(node, ast.Edge):
            return self.op(st.Edge(node.op == "rise"), kids[0])
        if isinstance(node, ast.Temporal):
            return self.temporal(node, kids[0])
        if isinstance(node, ast.BinTemporal):
            return self.bin_temporal(node, kids[0], kids[1])
        raise MonitorError(f"cannot monitor a {type(node).__name__} node", type(node).__name__)

    def temporal(self, node: ast.Temporal, x: int) -> int:
        op = node.op
        if op == "next":
            return self.op(st.Shift(1, INF), x)
        if op == "prev":
            return self.op(st.Lag(1, INF), x)
        if op in ("always", "eventually"):
            a, b = self.bounded(node.interval, op)
            return self.op(st.FutureWindow(a, b, op == "always"), x)
        a, bb = self.steps(node.interval)
        return self.op(st.PastWindow(a, bb, op == "historically"), x)

    def until(self, a: int, b: int, left: int, right: int) -> int:
        core = self.op(st.Until0(b - a), left, right)
        if a == 0:
            return core
        hold = self.op(st.FutureWindow(0, a - 1, True), left)
        return self.op(st.Stateless("and"), hold, self.op(st.Shift(a, -INF), core))

    def bin_temporal(self, node: ast.BinTemporal, left: int, right: int) -> int:
        if node.op == "since":
            a, b = self.steps(node.interval)
            core = self.op(st.Since0(None if b is None else b - a), left, right)
            if a == 0:
                return core
            hold = self.op(st.PastWindow(0, a - 1, True), left)
            return self.op(st.Stateless("and"), hold, self.op(st.Lag(a, -INF), core))
        a, b = self.bounded(node.interval, node.op)
        u = self.until(a, b, left, right)
        if node.op == "until":
            return u
        held = self.op(st.FutureWindow(0, b, True), left)  # unless = always[0,b] l or until
        return self.op(st.Stateless("or"), held, u)


def _generate(slots: list[_Slot], namespace: dict[str, Any], roots: list[tuple[str, int, list]]) -> Callable:
    """Generate ``step(s, i) -> list[Verdict]`` for the graph: one straight-line function."""
    ns = dict(namespace)
    order = sorted(range(len(slots)), key=lambda j: (slots[j].in_lat, j))
    lines = ["def step(s, i):"]
    guard = 0
    indent = "    "
    for j in order:
        slot = slots[j]
        if slot.in_lat != guard:
            guard = slot.in_lat
            lines.append(f"    if i >= {guard}:")
            indent = "        "
        node = slot.node
        args = [f"v{c}" for c in slot.children]
        if isinstance(node, st.Atom):
            expr = node.code
        elif isinstance(node, st.Const):
            ns[f"c{j}"] = node.value
            expr = f"c{j}"
        elif isinstance(node, st.Stateless):
            expr = node.code(args)
        else:
            ns[f"p{j}"] = node.fast_push()
            expr = f"p{j}({', '.join(args)})"
        lines.append(f"{indent}v{j} = {expr}")
    lines.append("    res = []")
    for r, (name, root, series) in enumerate(roots):
        lat = slots[root].lat
        ns[f"ser{r}"] = series
        lines.append(f"    if i >= {lat}:")
        lines.append(f"        ser{r}.append(v{root})")
        lines.append(f"        res.append(({name!r}, i - {lat}, v{root}))")
    lines.append("    return res")
    exec(compile("\n".join(lines), "<twolevel-online-monitor>", "exec"), ns)  # noqa: S102 - our own code
    return ns["step"]


def _as_rules(spec: Sequence[ast.Rule] | ast.RuleFile | ast.Node,
              participants: Sequence[str] | None) -> tuple[ast.Rule, ...]:
    if isinstance(spec, ast.RuleFile):
        rules = spec.rules
    elif isinstance(spec, ast.Rule):
        rules = (spec,)
    elif isinstance(spec, ast.Node):
        rules = (ast.Rule(name="formula", formula=spec),)
    else:
        rules = tuple(spec)
    out = []
    for r in rules:
        if quantifies(r.formula):
            if participants is None:
                raise MonitorError(f"rule '{r.name}' quantifies over participants: give the monitor their ids "
                                   "(participants=...)", r.name)
            r = ast.Rule(r.name, expand_quantifiers(r.formula, participants), name_span=r.name_span, span=r.span)
        out.append(r)
    return tuple(out)


class OnlineMonitor:
    """Monitor rules (or one formula, named ``"formula"``) sample by sample at period ``dt`` [s];
    ``participants``: the ids quantifiers range over (needed when a rule quantifies)."""

    def __init__(
        self,
        rules: Sequence[ast.Rule] | ast.RuleFile | ast.Node,
        dt: float,
        *,
        consts: Mapping[str, float] | None = None,
        builtins: Mapping[str, Builtin] | None = None,
        participants: Sequence[str] | None = None,
    ) -> None:
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise MonitorError(f"the sampling period dt must be a positive number of seconds, got {dt!r}", "dt")
        self.dt = float(dt)
        comp = _Compiler(self.dt, consts or {}, DEFAULT_BUILTINS if builtins is None else builtins)
        roots: list[tuple[str, int]] = []
        try:
            for rule in _as_rules(rules, participants):
                root = comp.formula(rule.formula)
                comp.rules[rule.name] = root
                roots.append((rule.name, root))
        except RecursionError:
            raise MonitorError("formula nested too deeply to monitor online") from None
        self._slots = comp.slots
        self._namespace = comp.namespace
        self._roots = roots
        self._series: list[list[float]] = [[] for _ in roots]
        self._i = 0
        self._build()

    def _build(self) -> None:
        triples = [(n, r, s) for (n, r), s in zip(self._roots, self._series)]
        try:
            self._step = _generate(self._slots, self._namespace, triples)
        except (RecursionError, MemoryError, SyntaxError):
            raise MonitorError("formula nested too deeply to monitor online") from None

    def __deepcopy__(self, memo: dict) -> "OnlineMonitor":
        twin = object.__new__(OnlineMonitor)
        twin.dt = self.dt
        twin._slots = copy.deepcopy(self._slots, memo)
        twin._namespace = self._namespace
        twin._roots = list(self._roots)
        twin._series = [list(s) for s in self._series]
        twin._i = self._i
        twin._build()
        return twin

    # -- facts --------------------------------------------------------------------------------
    @property
    def rule_names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self._roots)

    @property
    def samples(self) -> int:
        """Samples received so far."""
        return self._i

    def latency(self, rule: str) -> int:
        """hor(φ): samples after ``k`` needed before the value at ``k`` is final."""
        return self._slots[self._root(rule)].lat

    def _root(self, rule: str) -> int:
        for name, root in self._roots:
            if name == rule:
                return root
        raise MonitorError(f"no rule named '{rule}'", rule)

    # -- feeding ------------------------------------------------------------------------------
    def update(self, sample: Mapping[str, float]) -> list[Verdict]:
        """Feed the next sample (signal name → value); return the values that became final."""
        try:
            res = self._step(sample, self._i)
        except KeyError as exc:
            name = str(exc.args[0]) if exc.args else ""
            raise MonitorError(f"sample {self._i} has no signal '{name}'", name) from None
        self._i += 1
        return res

    def final(self, rule: str) -> np.ndarray:
        """The robustness values of ``rule`` that are final so far (samples ``0 .. len-1``)."""
        return np.array(self._series[self._index(rule)], dtype=np.float64)

    def _index(self, rule: str) -> int:
        names = self.rule_names
        if rule not in names:
            raise MonitorError(f"no rule named '{rule}'", rule)
        return names.index(rule)

    # -- end of trace -------------------------------------------------------------------------
    def finish(self) -> dict[str, np.ndarray]:
        """The robustness of every rule at every sample received, as if the trace ended now
        (RTAMT's truncated windows). Equal to the offline monitor on the same prefix."""
        slots = copy.deepcopy(self._slots)
        rest: list[list[Any]] = []
        for slot in slots:
            node = slot.node
            if not slot.children:
                rest.append([])
                continue
            feeds = zip(*(rest[c] for c in slot.children))
            out = [v for v in (node.push(*vals) for vals in feeds) if v is not None]
            out.extend(node.flush())
            rest.append(out)
        return {
            name: np.array(series + rest[root], dtype=np.float64)
            for (name, root), series in zip(self._roots, self._series)
        }

    # -- intervals ----------------------------------------------------------------------------
    def _speculate(self, upto: int) -> list[list[tuple[int, Any]]]:
        """Run the graph on unseen samples (atoms ``(-inf, inf)``) until every rule has emitted
        sample ``upto``; return per rule the (k, (lo, hi)) pairs emitted."""
        slots = copy.deepcopy(self._slots)
        nodes = [s.node.interval() for s in slots]
        emitted: list[list[tuple[int, Any]]] = [[] for _ in self._roots]
        top = max((slots[root].lat for _, root in self._roots), default=0)
        order = sorted(range(len(slots)), key=lambda j: (slots[j].in_lat, j))
        for i in range(self._i, max(self._i, upto + top + 1)):
            vals: dict[int, Any] = {}
            for j in order:
                slot = slots[j]
                if i < slot.in_lat:
                    continue
                vals[j] = nodes[j].push(*(vals[c] for c in slot.children)) if slot.children else nodes[j].push(None)
            for r, (_, root) in enumerate(self._roots):
                lat = slots[root].lat
                if i >= lat:
                    emitted[r].append((i - lat, vals[root]))
        return emitted

    def interval_at(self, rule: str, k: int) -> tuple[float, float]:
        """Bounds ``(lo, hi)`` on the robustness of ``rule`` at sample ``k`` (time ``k*dt``),
        given the samples so far; ``lo == hi`` once it is final."""
        r = self._index(rule)
        series = self._series[r]
        if k < 0:
            raise MonitorError(f"sample index {k} is negative", rule)
        if k < len(series):
            return (series[k], series[k])
        for kk, pair in self._speculate(k)[r]:
            if kk == k:
                return (float(pair[0]), float(pair[1]))
        raise AssertionError("speculation did not reach the sample")  # pragma: no cover

    def pending(self) -> dict[str, list[tuple[int, float, float]]]:
        """For every rule, ``(k, lo, hi)`` for each received sample whose value is not final yet."""
        spec = self._speculate(self._i - 1)
        out: dict[str, list[tuple[int, float, float]]] = {}
        for r, (name, _) in enumerate(self._roots):
            done = len(self._series[r])
            out[name] = [(k, float(p[0]), float(p[1])) for k, p in spec[r] if done <= k < self._i]
        return out
