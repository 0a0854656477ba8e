"""STL formulas over an MPC horizon → mixed-integer linear constraints (MILCs).

Signals have two faces (design.md, "World"): at trace step ``k`` a signal is a constant (known at
solve time, including every past sample) or an affine expression of the decision variables.
:class:`AffineSignal` holds the latter as a sparse matrix (one row per step) plus an offset; a
plain array holds the former.

A formula at step ``t`` is first evaluated into a robustness tree (:mod:`twolevel.compiler.tree`):
min/max over affine leaves, with every constant folded, so an inactive rule or a trivially true
disjunct vanishes before a variable is created. Then the tree is *required*:

* satisfaction mode: ``robustness ≥ ε`` (ε = 1e-4, above the solver tolerances);
* robustness mode: ``robustness ≥ ρ`` for one margin variable ρ whose maximum is the robustness
  (ρ ≤ min(a, b) ⇔ ρ ≤ a ∧ ρ ≤ b; ρ ≤ max(a, b) ⇔ ρ ≤ a ∨ ρ ≤ b — exact at the optimum).

A ``min`` needs nothing but its children's rows; a ``max`` over decision variables becomes a
:class:`~twolevel.milp.model.Disjunction` with one binary per disjunct and big-M rows whose M is
the interval bound of the row over the variables' bounds (never a blanket constant). Disjuncts
that can never hold (upper bound below the margin) are removed, a disjunct that always holds
removes its disjunction: this is how vehicle–step pairs out of reach and impossible faces of
``collision_free`` vanish, exactly, once the ego's position bounds are its reachable boxes.
A subtree shared by several parents gets one variable ``z ≤ robustness`` instead of being
encoded once per parent. ``iff``/``xor`` (robustness ∓|a − b|, RTAMT's) need the exact values of
both sides: two-sided encodings ``z = robustness``.

Semantics are those of the offline monitor (RTAMT's discrete-time offline semantics): windows
truncated at the ends of the trace, empty ``always``/``historically`` windows +inf, empty
``eventually``/``once`` windows −inf, ``next`` past the end and ``prev`` before the start +inf.

The code lives in: :mod:`twolevel.compiler.types` (types and codes), :mod:`twolevel.compiler.encoder`
(the :class:`Encoder` object), :mod:`twolevel.compiler.evaluator` (formulas → trees),
:mod:`twolevel.compiler.emitter` (trees → rows); this module is the entry :func:`encode` with rule
recovery, and re-exports the public names.
"""

from __future__ import annotations

import math
from typing import Iterable, Literal, Mapping

import numpy as np

from twolevel.milp.builder import ModelBuilder
from twolevel.compiler.encoder import Encoder
from twolevel.compiler.types import (MIL501, MIL502, MIL503, MIL504, AffineSignal, Builtin, Emission,  # noqa: F401
                                    EncodeError, Encoding, Requirement, Signal, _NOWHERE, _span)
from twolevel.compiler.tree import INF, Lin, Op, Tree, bounds, mk
from twolevel.stl import ast

__all__ = [
    "AffineSignal",
    "Signal",
    "Requirement",
    "Encoding",
    "Emission",
    "EncodeError",
    "Encoder",
    "encode",
    "collision_free_builtin",
    "reachable_box",
    "MIL501",
    "MIL502",
    "MIL503",
    "MIL504",
]


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
) -> Encoding:
    """Encode ``requirements`` into ``builder`` (rows in one block named ``"stl"``).

    Satisfaction: every requirement's robustness ≥ ``eps``. Robustness: a margin variable ρ,
    ρ ≤ every requirement's robustness, cost ``−rho_weight·ρ``; ρ is bounded by the interval
    bounds of the requirements (or ``rho_bounds``). Encoding problems (non-linear predicates,
    unknown names, unbounded big-M) come back as diagnostics, never as exceptions. ``stable``:
    vectorised blocks keep redundant rows (structure independent of the current values; see
    :class:`Emission`) and the result lists the trees and emissions. ``recover`` (satisfaction
    mode): a requirement already false at its step by what is known at solve time is required
    instead from the first later step at which it can hold given the variables' bounds (the
    first step whose value the plan can still change); each such shift is listed in
    ``Encoding.recovered`` as (name, step, new step). ``recover_after`` {name: k}: search from step
    + k + 1 on (after a recovery that the solver found infeasible)."""
    enc = Encoder(builder, signals, dt, consts=consts, rules=rules, builtins=builtins, length=length,
                  stable=stable)
    out = Encoding(mode=mode)
    requirements = list(requirements)
    try:
        trees: list[tuple[str, int, Tree]] = []
        for req in requirements:
            for t in req.times:
                tree = enc.rob(req.formula, t, 1.0)
                if isinstance(tree, Op):
                    enc._refs[id(tree)] = enc._refs.get(id(tree), 0) + 1
                trees.append((req.name, t, tree))
        if mode == "robustness":
            top = mk(False, [tr for _, _, tr in trees]) if trees else INF
            lo, hi = enc.bounds(top)
            if rho_bounds is not None:
                lo, hi = max(lo, rho_bounds[0]), min(hi, rho_bounds[1])
            if not math.isfinite(hi):
                hi = rho_bounds[1] if rho_bounds is not None else 1e3
            if not math.isfinite(lo):
                lo = min(hi, rho_bounds[0] if rho_bounds is not None else -1e3)
            out.rho = enc._new_var("rho", lo, hi)
            builder.add_linear_cost(np.array([out.rho]), -rho_weight)
            margin: Lin | float = Lin((out.rho,), (1.0,), 0.0)
        else:
            margin = float(eps)
        if recover and mode == "satisfaction":
            trees = _recover(enc, trees, list(requirements), float(eps), out, dict(recover_after or {}))
        for name, t, tree in trees:
            enc._label = f"{name}@{t}"
            before = enc.infeasible
            enc.require(tree, margin)
            if enc.infeasible and not before:
                enc.diagnostics.append(MIL503(
                    f"rule '{name}' cannot hold at step {t} given the known signals", _NOWHERE))
        enc.flush("stl")
    except EncodeError as e:
        out.diagnostics.append(e.diagnostic)
        out.infeasible = True
        return out
    out.rows = enc._n
    out.binaries = enc.n_bin
    out.continuous = enc.n_cont
    out.disjunctions = len(enc._disj)
    out.infeasible = enc.infeasible
    out.diagnostics.extend(enc.diagnostics)
    if stable:
        out.trees = trees
        out.emissions = enc.emissions
    return out


def _recover(enc: Encoder, trees: list[tuple[str, int, Tree]], reqs: list[Requirement], eps: float,
             out: Encoding, after: dict[str, int]) -> list[tuple[str, int, Tree]]:
    """Shift each requirement that folds to false (upper bound below ε) to its first later step
    at which it can hold; see :func:`encode`."""
    formulas = [r.formula for r in reqs for _ in r.times]
    res = []
    for (name, t, tree), f in zip(trees, formulas):
        if enc.bounds(tree)[1] >= eps:
            res.append((name, t, tree))
            continue
        for t2 in range(t + 1 + after.get(name, 0), enc.T):
            tree2 = enc.rob(f, t2, 1.0)
            if enc.bounds(tree2)[1] >= eps:
                if isinstance(tree2, Op):
                    enc._refs[id(tree2)] = enc._refs.get(id(tree2), 0) + 1
                out.recovered.append((name, t, t2))
                res.append((name, t2, tree2))
                break
        else:
            res.append((name, t, tree))
    return res


# ---------------------------------------------------------------------------- built-ins
# (in their own module; re-exported here for existing callers)
def __getattr__(name: str) -> object:
    if name in ("collision_free_builtin", "reachable_box"):
        from twolevel.compiler import collision

        return getattr(collision, name)
    raise AttributeError(name)
