"""The compiler's driver: STL requirements over an MPC horizon → mixed-integer linear constraints.

:func:`encode` runs the stages of :mod:`twolevel.compiler` over every requirement at every step
it is required at:

1. stage 1, :class:`~twolevel.compiler.evaluator.Evaluator`: the formula at the step → its
   robustness tree (:mod:`twolevel.compiler.tree`), every constant folded, so an inactive rule
   or a trivially true disjunct vanishes before a variable is created;
2. stage 2, :class:`~twolevel.compiler.emitter.RowEmitter`: the tree *required* above a margin
   → rows of the model:

   * satisfaction mode: ``robustness ≥ ε`` (ε = 1e-4, above the solver tolerances);
   * robustness mode: ``robustness ≥ ρ`` for one margin variable ρ whose maximum is the
     robustness (ρ ≤ min(a, b) ⇔ ρ ≤ a ∧ ρ ≤ b; ρ ≤ max(a, b) ⇔ ρ ≤ a ∨ ρ ≤ b — exact at the
     optimum).

The stages share the column bounds (:class:`~twolevel.compiler.tree.IntervalBounds`: big-M and
pruning come from them; pairs of ``collision_free`` out of reach vanish exactly once the ego's
position bounds are its reachable boxes) and the parent counts of the tree
(:class:`~twolevel.compiler.tree.Parents`: a subtree shared by several parents is encoded once).
``iff``/``xor`` (robustness ∓|a − b|, RTAMT's) need the exact values of both sides: stage 1
asks stage 2 for a variable ``z = robustness`` (:meth:`~twolevel.compiler.emitter.RowEmitter.value`).

Quantifiers over participants are expanded first over the participants in range at solve
time, those whose presence ``present[p]`` the signals hold
(:func:`~twolevel.stl.analysis.expand_quantifiers`): ``forall`` becomes a conjunction of
``present[p] -> body(p)``, ``exists`` a disjunction of ``present[p] and body(p)``, the body
reading ``name[p]`` for ``name(o)``. A presence known at solve time folds away (an absent
participant's conjunct vanishes before any binary is created); a participant signal affine in the
decision variables (``d_lon``: its route position less the ego's) encodes as any affine signal,
and a product of two decision-dependent terms is MIL501 as elsewhere.

Semantics are those of the offline monitor (:mod:`twolevel.monitor.robustness`, RTAMT's
discrete-time offline semantics); the tests hold the encoding to it.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Iterable, Literal, Mapping

import numpy as np

from twolevel.compiler.codes import MIL503, NOWHERE, EncodeError
from twolevel.compiler.emitter import RowEmitter
from twolevel.compiler.evaluator import Evaluator
from twolevel.compiler.signals import Signal, TraceSignals
from twolevel.compiler.tree import INF, IntervalBounds, Lin, Parents, Tree, mk
from twolevel.compiler.types import Builtin, Encoding, Requirement
from twolevel.diagnostics import Diagnostic
from twolevel.milp.builder import ModelBuilder
from twolevel.stl import ast
from twolevel.stl.analysis import expand_quantifiers, participants_in

__all__ = ["encode", "margin_at"]


def encode(
    builder: ModelBuilder,
    requirements: Iterable[Requirement],
    signals: Mapping[str, Signal],
    dt: float,
    *,
    mode: Literal["satisfaction", "robustness"] = "satisfaction",
    eps: float = 1e-4,
    consts: Mapping[str, float] | None = None,
    rules: Mapping[str, ast.Node] | None = None,
    builtins: Mapping[str, Builtin] | None = None,
    length: int | None = None,
    rho_weight: float = 1.0,
    rho_bounds: tuple[float, float] | None = None,
    stable: bool = False,
    recover: bool = False,
    recover_after: Mapping[str, int] | None = None,
    margins: Mapping[str, float] | None = None,
) -> Encoding:
    """Encode ``requirements`` into ``builder`` (rows in one block named ``"stl"``).

    Satisfaction: every requirement's robustness ≥ ``eps``. Robustness: a margin variable ρ,
    ρ ≤ every requirement's robustness, cost ``−rho_weight·ρ``; ρ is bounded by the interval
    bounds of the requirements (or ``rho_bounds``). Encoding problems (non-linear predicates,
    unknown names, unbounded big-M) come back as diagnostics, never as exceptions. ``stable``:
    vectorised blocks keep redundant rows (structure independent of the current values; see
    :class:`~twolevel.compiler.types.Emission`) and the result lists the trees and emissions. ``recover`` (satisfaction
    mode): a requirement already false at its step by what is known at solve time is required
    instead from the first later step at which it can hold given the variables' bounds (the
    first step whose value the plan can still change); each such shift is listed in
    ``Encoding.recovered`` as (name, step, new step). ``recover_after`` {name: k}: search from step
    + k + 1 on (after a recovery that the solver found infeasible). ``margins`` {name: m}: that
    requirement is required with robustness ≥ ``eps`` + m (≥ ρ + m in robustness mode) — in
    satisfaction mode at each step where it can be, given the variables' bounds: at a step
    whose value what is known already fixes (the speed and acceleration now, say) below
    ``eps`` + m but not below ``eps``, it is required with plain ``eps`` (listed in
    ``Encoding.unmargined`` as (name, step)), so what is known alone never makes a margin
    infeasible (where the dynamics do, the high level plans the step without margins)."""
    pids = participants_in(signals)
    requirements = [replace(r, formula=expand_quantifiers(r.formula, pids)) for r in requirements]
    rules = {k: expand_quantifiers(v, pids) for k, v in (rules or {}).items()}
    table = TraceSignals(signals, length, consts)
    bounds = IntervalBounds(builder)
    parents = Parents()
    emitter = RowEmitter(builder, bounds, parents, stable=stable)
    ev = Evaluator(table, dt, bounds, rules=rules, builtins=builtins, parents=parents, exact=emitter.value,
                   stable=stable)
    out = Encoding(mode=mode)
    diagnostics: list[Diagnostic] = []
    try:
        trees: list[tuple[str, int, Tree]] = []
        for req in requirements:
            for t in req.times:
                tree = ev.rob(req.formula, t, 1.0)
                parents.add(tree)
                trees.append((req.name, t, tree))
        if mode == "robustness":
            top = mk(False, [tr for _, _, tr in trees]) if trees else INF
            lo, hi = bounds(top)
            if rho_bounds is not None:
                lo, hi = max(lo, rho_bounds[0]), min(hi, rho_bounds[1])
            if not math.isfinite(hi):
                hi = rho_bounds[1] if rho_bounds is not None else 1e3
            if not math.isfinite(lo):
                lo = min(hi, rho_bounds[0] if rho_bounds is not None else -1e3)
            out.rho = emitter.add_continuous("rho", lo, hi)
            builder.add_linear_cost(np.array([out.rho]), -rho_weight)
            margin: Lin | float = Lin((out.rho,), (1.0,), 0.0)
        else:
            margin = float(eps)
        if recover and mode == "satisfaction":
            trees = _recover(ev, trees, requirements, float(eps), out, dict(recover_after or {}))
        for name, t, tree in trees:
            emitter.label = f"{name}@{t}"
            before = emitter.infeasible
            m = float(margins.get(name, 0.0)) if margins else 0.0
            if m and mode == "satisfaction" and not margin_at(ev, tree, m, float(eps)):
                out.unmargined.append((name, t))
                m = 0.0
            emitter.require(tree, margin if m == 0.0 else
                            Lin(margin.idx, margin.val, margin.c + m) if isinstance(margin, Lin) else margin + m)
            if emitter.infeasible and not before:
                diagnostics.append(MIL503(f"rule '{name}' cannot hold at step {t} given the known signals", NOWHERE))
        emitter.flush("stl")
    except EncodeError as e:
        out.diagnostics.append(e.diagnostic)
        out.infeasible = True
        return out
    out.rows = emitter.rows
    out.binaries = emitter.binaries
    out.continuous = emitter.continuous
    out.disjunctions = emitter.disjunctions
    out.infeasible = emitter.infeasible
    out.diagnostics.extend(diagnostics)
    if stable:
        out.trees = trees
        out.emissions = emitter.emissions
    return out


def margin_at(ev: Evaluator, tree: Tree, margin: float, eps: float) -> float:
    """The margin [the rule's units] a requirement's folded ``tree`` is required with above
    ``eps`` in satisfaction mode: ``margin``, or 0 where the tree's upper bound (what is known,
    the variables' bounds) cannot reach ``eps`` + ``margin`` (see :func:`encode`)."""
    return margin if margin == 0.0 or ev.bounds(tree)[1] >= eps + margin else 0.0


def _recover(ev: Evaluator, trees: list[tuple[str, int, Tree]], reqs: list[Requirement], eps: float,
             out: Encoding, after: dict[str, int]) -> list[tuple[str, int, Tree]]:
    """Shift each requirement that folds to false (upper bound below ε) to its first later step
    at which it can hold; see :func:`encode`."""
    formulas = [r.formula for r in reqs for _ in r.times]
    res = []
    for (name, t, tree), f in zip(trees, formulas):
        if ev.bounds(tree)[1] >= eps:
            res.append((name, t, tree))
            continue
        for t2 in range(t + 1 + after.get(name, 0), ev.length):
            tree2 = ev.rob(f, t2, 1.0)
            if ev.bounds(tree2)[1] >= eps:
                ev.parents.add(tree2)
                out.recovered.append((name, t, t2))
                res.append((name, t2, tree2))
                break
        else:
            res.append((name, t, tree))
    return res
