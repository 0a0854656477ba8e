"""Quantifiers in the MILC encoding: expanded over the participants in range at solve time, and
equal to the offline monitor (the oracle) on random quantified formulas.

The participants a, b, c have a signal ``d`` affine in the decision variables, as ``d_lon`` is in
the MPC: d[i] = c_i − p (a known route position less the ego's), and a presence that is known
(constant) in the past and, for the ones in range, over the horizon."""

from __future__ import annotations

import numpy as np
import pytest

from twolevel.compiler.driver import encode
from twolevel.compiler.signals import AffineSignal
from twolevel.compiler.types import Requirement
from twolevel.milp.builder import ModelBuilder
from twolevel.monitor.robustness import robustness
from twolevel.stl import ast
from twolevel.stl.parser import parse
from twolevel.stl.typecheck import map_vars

from helpers.milp_oracle import check_optimal_robustness, check_satisfaction_of_a_fixed_trajectory
from helpers.milp_systems import DT, H, PAST, T, double_integrator, random_formula

NOW = PAST
PIDS = ("a", "b", "c")
SEEDS = range(60)


def _quantified(rng: np.random.Generator) -> ast.Node:
    body = map_vars(random_formula(rng, depth=int(rng.integers(1, 3))),
                    lambda v: ast.ParticipantSignal("d", "o") if v.name == "c" else v)
    q = ast.Quantifier("forall" if rng.random() < 0.5 else "exists", "o", "vehicles", body)
    k = int(rng.integers(0, 3))
    if k == 0:
        return q
    iv = ast.Interval(0.0, float(rng.integers(0, 3)) * DT)
    return ast.Temporal("always" if k == 1 else "once", iv, q)


def _case(seed: int):
    rng = np.random.default_rng(1000 + seed)
    f = _quantified(rng)
    p_past = rng.uniform(-2, 2, PAST + 1)
    v_past = rng.uniform(-1, 1, PAST + 1)
    anchor = {pid: rng.uniform(-1, 4, T) for pid in PIDS}  # c_i: known at solve time
    in_range = {pid: bool(rng.random() < 0.7) for pid in PIDS}
    present = {pid: np.concatenate([np.where(rng.random(PAST) < 0.6, np.inf, -np.inf),
                                    np.full(H + 1, np.inf if in_range[pid] else -np.inf)]) for pid in PIDS}
    return rng, f, p_past, v_past, anchor, present


def _signals(b: ModelBuilder, p_past, v_past, anchor, present):
    pb, vb, ab, sig = double_integrator(b, p_past, v_past)
    n = b.n_cols
    for pid in PIDS:
        c = anchor[pid]
        sig[f"d[{pid}]"] = AffineSignal.of_columns(pb.idx, n, past=c[: PAST + 1] - p_past, scale=-1.0,
                                                   offset=c[PAST + 1:])
        sig[f"present[{pid}]"] = present[pid]
    return pb, vb, ab, sig


def _monitor(f, p, v, anchor, present):
    sig = {"p": p, "v": v}
    for pid in PIDS:
        sig[f"d[{pid}]"] = anchor[pid] - p
        sig[f"present[{pid}]"] = present[pid]
    return float(robustness(f, sig, DT)[NOW])


@pytest.mark.parametrize("seed", SEEDS)
def test_satisfaction_of_a_fixed_trajectory_matches_the_monitor(seed: int) -> None:
    rng, f, p_past, v_past, anchor, present = _case(seed)
    check_satisfaction_of_a_fixed_trajectory(rng, f, (NOW,), p_past, v_past,
                                             lambda b: _signals(b, p_past, v_past, anchor, present),
                                             lambda p, v: _monitor(f, p, v, anchor, present))


@pytest.mark.parametrize("seed", SEEDS)
def test_optimal_robustness_equals_the_monitor_of_the_plan(seed: int) -> None:
    _, f, p_past, v_past, anchor, present = _case(seed)
    check_optimal_robustness(f, (NOW,), p_past, v_past, lambda b: _signals(b, p_past, v_past, anchor, present),
                             lambda p, v: _monitor(f, p, v, anchor, present))


def test_an_absent_participant_costs_no_binary() -> None:
    """A participant out of range at solve time folds away before any binary is created; one in
    range adds its conjunct."""
    rf, _ = parse("r = forall o in vehicles: (d(o) >= 1 or d(o) <= -1);", "q.stl")
    f = rf.rules[0].formula
    rng = np.random.default_rng(3)
    p_past, v_past = np.zeros(PAST + 1), np.zeros(PAST + 1)
    anchor = {pid: rng.uniform(-1, 4, T) for pid in PIDS}
    counts = []
    for present_now in ((), ("a",), ("a", "b", "c")):
        present = {pid: np.full(T, np.inf if pid in present_now else -np.inf) for pid in PIDS}
        b = ModelBuilder()
        sig = _signals(b, p_past, v_past, anchor, present)[3]
        enc = encode(b, [Requirement("r", f, (NOW + 1,))], sig, DT)
        counts.append(enc.binaries)
    assert counts[0] == 0 and 0 < counts[1] < counts[2]


def test_a_product_of_decision_dependent_participant_terms_is_mil501() -> None:
    rf, _ = parse("r = forall o in vehicles: (d(o) * p >= 1);", "q.stl")
    b = ModelBuilder()
    present = {pid: np.full(T, np.inf) for pid in PIDS}
    sig = _signals(b, np.zeros(PAST + 1), np.zeros(PAST + 1), {pid: np.ones(T) for pid in PIDS}, present)[3]
    enc = encode(b, [Requirement("r", rf.rules[0].formula, (NOW + 1,))], sig, DT)
    assert [d.code for d in enc.diagnostics] == ["MIL501"]
