"""Static analysis: horizons, linearity, partial evaluation, RuleSet binding and inlining."""

from __future__ import annotations

import math
import typing
from pathlib import Path

import numpy as np
import pytest

from twolevel.stl.analysis import (
    fold_constants, future_horizon, is_linear, nonlinear_nodes, past_depth, signals_read, substitute,
)
from twolevel.stl.ast import (
    FUTURE_OPS, PAST_OPS, BinaryTemporalOp, BoolConst, Compare, Num, Temporal, UnaryTemporalOp, Var,
)
from twolevel.stl.lint import check_source, load_ruleset
from twolevel.stl.parser import parse
from twolevel.stl.printer import format_formula

RULES = Path(__file__).resolve().parents[2] / "rules"


def f(src: str):
    rf, diags = parse(f"r = {src};", "t.stl")
    assert rf is not None, [d.message for d in diags]
    return rf.rules[0].formula


@pytest.mark.parametrize(
    "src, future, past",
    [
        ("a > 0", 0.0, 0.0),
        ("always[0:1] a", 1.0, 0.0),
        ("always[0:1] eventually[0.5:2] a", 3.0, 0.0),
        ("a until[0:1.5] always[0:0.5] b", 2.0, 0.0),
        ("historically[0:2] a", 0.0, 2.0),
        ("once[1:3] eventually[0:2] a", 1.0, 3.0),
        ("eventually[2:4] historically[0:1] a", 4.0, 0.0),
        ("next next a", 0.2, 0.0),
        ("prev a and rise(b)", 0.0, 0.1),
        ("always a", math.inf, 0.0),
        ("a since b", 0.0, math.inf),
        ("(historically[0:2] prev a) since[1:3] eventually[0:0.4] next b", 0.0, 5.1),
    ],
)
def test_horizons(src: str, future: float, past: float) -> None:
    assert future_horizon(f(src), dt=0.1) == pytest.approx(future)
    assert past_depth(f(src), dt=0.1) == pytest.approx(past)


def test_horizon_through_rule_references() -> None:
    res = check_source("input float v\np = eventually[0:0.6] (v > 0);\nq = always[0:0.6] p;\n",
                       "t.stl", dt=0.1, horizon=10)
    assert [(d.code, d.span.line) for d in res.diagnostics] == [("STL211", 3)]


def test_signals_read() -> None:
    assert signals_read(f("always[0:1] (v <= v_max + tol) and collision_free(D)")) == {"v", "v_max", "tol", "D"}


@pytest.mark.parametrize(
    "src, bad",
    [
        ("x * y > 0", ["x * y"]),
        ("2 * x + y / 3 > 0", []),
        ("k * x > 0", []),          # k is a constant
        ("x / y > 0", ["x / y"]),
        ("x / k > 0", []),
        ("abs(x - y) <= 1", []),    # piecewise linear: encodable
        ("abs(x * y) <= 1", ["x * y"]),
        ("(x + 1) * (k - 2) > 0", []),
    ],
)
def test_nonlinear_nodes(src: str, bad: list[str]) -> None:
    formula = f(src)
    assert [format_formula(n) for n in nonlinear_nodes(formula, {"k"})] == bad
    assert is_linear(formula, {"k"}) == (not bad)


def test_fold_constants() -> None:
    assert fold_constants(f("always[0:1] (v <= 2 * 3 + 1)")) == f("always[0:1] (v <= 7)")
    assert fold_constants(f("1 < 2 and v > 0")) == f("v > 0")
    assert fold_constants(f("1 > 2 or not (3 >= 3)")) == BoolConst(False)
    assert fold_constants(f("v / 0 > 1")) == f("v / 0 > 1")  # no division by zero


def test_activation_is_partial_evaluation() -> None:
    """Known signals fold the rule away before the encoder sees it (activation is partial
    evaluation: docs/architecture.md, "The rule language")."""
    red = f("always[0:1] ((light_red > 0.5) -> (d_light > 0))")
    assert substitute(red, {"light_red": 0.0}) == BoolConst(True)
    assert substitute(red, {"light_red": 1.0}) == f("always[0:1] (d_light > 0)")
    assert substitute(red, {"light_red": 1.0, "d_light": -2.0}) == BoolConst(False)
    speed = f("always[0:1] (v <= v_max + tol)")
    assert substitute(speed, {"v_max": 13.9, "tol": 0.5}) == f("always[0:1] (v <= 14.4)")
    stop = f("always[0:1] ((d_stop <= 0) -> once[0:10] ((v <= eps) and (d_stop <= d_near)))")
    assert substitute(stop, {"d_stop": 50.0, "eps": 0.1, "d_near": 3.0}) == BoolConst(True)
    # a signal read as a formula keeps its robustness sign; until with a true left side
    assert substitute(f("x and y"), {"x": -1.0}) == BoolConst(False)
    assert substitute(f("x until[0:1] y"), {"x": 2.0}) == f("eventually[0:1] y")
    assert substitute(f("x until[0:1] y"), {"y": -2.0}) == BoolConst(False)
    kept = substitute(f("x > 0 and y"), {"x": 2.0}, fold_predicates=False)
    assert kept == f("2 > 0 and y")


def test_ruleset_bind_and_inline(tmp_path: Path) -> None:
    p = tmp_path / "r.stl"
    p.write_text("input float v\nconst float lim\nfast = v > lim;\nr = always[0:1] (not fast);\n")
    rs, diags = load_ruleset(str(p), {"lim": 10.0})
    assert rs is not None
    assert rs.formula("r") == f("always[0:1] (not (v > 10))")
    assert rs.formula("r", inline=False) == f("always[0:1] (not fast)")
    with pytest.raises(KeyError):
        rs.bind({"nope": 1.0})
    assert rs.bind({"lim": 5.0}).formula("fast") == f("v > 5")


def test_library_rules_fold_when_inactive() -> None:
    rs, _ = load_ruleset(str(RULES / "red_light.stl"))
    assert substitute(rs.formula("red_light"), {"light_red": 0.0}) == BoolConst(True)


def test_every_temporal_operator_looks_one_way() -> None:
    """FUTURE_OPS and PAST_OPS split the temporal operators of the grammar, as the offline monitor
    (the oracle) evaluates them: a future operator's value at a sample changes with later samples
    only, a past one's with earlier samples only. Every module that asks which way an operator
    looks reads these two sets."""
    from twolevel.monitor.robustness import robustness

    ops = set(typing.get_args(UnaryTemporalOp)) | set(typing.get_args(BinaryTemporalOp))
    assert FUTURE_OPS | PAST_OPS == ops and not FUTURE_OPS & PAST_OPS
    base = {"a": np.linspace(1.0, -1.0, 11), "b": np.full(11, 0.5)}
    k = np.arange(11)

    def moves(node, where) -> bool:
        """Whether the value at sample 5 changes when the samples ``where`` are raised or lowered."""
        rho = robustness(node, base, 1.0)[5]
        return any(robustness(node, {n: np.where(where, v, x) for n, x in base.items()}, 1.0)[5] != rho
                   for v in (-5.0, 5.0))

    for op in sorted(ops):
        src = (f"{op}(a > 0)" if op in ("next", "prev") else f"(b > 0) {op}[0:2] (a > 0)"
               if op in typing.get_args(BinaryTemporalOp) else f"{op}[0:2] (a > 0)")
        node = f(src)
        assert moves(node, k > 5) == (op in FUTURE_OPS), op
        assert moves(node, k < 5) == (op in PAST_OPS), op
        assert (future_horizon(node, 1.0) > 0) == (op in FUTURE_OPS), op
