"""Value-only refresh of an MPC step model whose structure repeats: build the pattern once per
shape and update values in place.

A step model built in the encoder's *stable* mode (:func:`twolevel.control.high_level.problem.assemble`
with ``stable=True``) has a structure that depends only on the rule set after folding, on which
signals are affine, and on the kept vehicle–step pairs: every vectorised block keeps its
redundant rows, every kept pair is a disjunction of its four faces (impossible faces are
switched off by their binary's upper bound, a value), and pairs are kept within d + ``pad`` of
the ego's reachable boxes, so the same structure serves the next steps while the vehicles that
can come within reach stay among the kept pairs.

:class:`StepTemplate` keeps such a model with where each block's values live. On the next step
:func:`refresh` evaluates the rules' folded trees on the new signals (vectorised blocks, no row
by row work), checks that the structure is the same (same blocks, same structural patterns, the
new reachable pairs among the kept ones, not too many stale pairs) and writes the new numbers —
dynamics, bounds, big-M, constants, row bounds, binaries' upper bounds, cost — into the model's
arrays in place; the Clarabel solver and the mode search built on it are kept (values go in by
``update``). Anything else (a generic rule such as ``until``, a rule false by constants, a new
pair within reach) is a miss: the caller builds afresh and keeps the new template (a small LRU).
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Mapping

import numpy as np

from twolevel.compiler.affine_block import AffineBlock
from twolevel.compiler.collision import CollisionBlock, collision_free_builtin
from twolevel.compiler.codes import EncodeError
from twolevel.compiler.driver import margin_at
from twolevel.compiler.evaluator import Evaluator
from twolevel.compiler.signals import AffineSignal, TraceSignals
from twolevel.compiler.tree import Block, Box, IntervalBounds, Op
from twolevel.compiler.types import Emission
from twolevel.stl.analysis import expand_quantifiers, participants_in
from twolevel.control.high_level.backend import Backend
from twolevel.control.high_level.linearisation import StepData
from twolevel.control.high_level.problem import (Assembled, StepRules, dynamics_values, guard_values, input_bounds,
                                                 others_of, rss_bounds, set_cost, trace_signals)
from twolevel.control.high_level.settings import MPCSettings
from twolevel.models.params import BicycleParams

__all__ = ["StepTemplate", "TemplateCache", "template_of", "refresh", "signal_kinds"]

STALE = (2.0, 8)  # a template whose kept pairs exceed 2·(pairs within d + pad) + 8 is rebuilt


@dataclass(eq=False)
class StepTemplate:
    """A stable-mode step model (mutated in place by :func:`refresh`) and its emissions;
    ``backend``: the solver objects built on it (kept by the controller); ``hits``: refreshes."""

    asm: Assembled
    emissions: tuple[Emission, ...]
    kinds: tuple[tuple[str, ...], ...]  # per requirement: the kinds of its emitted blocks
    tri0: int
    row0: int
    backend: Backend | None = None
    hits: int = 0
    codes: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


def _parts(tree: object) -> tuple[list[Block], float] | None:
    """A top-level folded tree as (blocks, constant), or None when it has other structure."""
    if isinstance(tree, float):
        return [], tree
    if isinstance(tree, Block):
        return [tree], float("inf")
    if isinstance(tree, Op) and not tree.is_max:
        blocks = [k for k in tree.kids if isinstance(k, Block)]
        consts = [k for k in tree.kids if isinstance(k, float)]
        if len(blocks) + len(consts) == len(tree.kids) and len(consts) <= 1:
            return blocks, consts[0] if consts else float("inf")
    return None


def _kind(b: Block) -> str:
    return "affine" if isinstance(b, AffineBlock) else "collision" if isinstance(b, CollisionBlock) else "?"


def signal_kinds(sigs: Mapping[str, object]) -> tuple:
    """Which signals are affine in the decision variables (part of a template's key)."""
    return tuple(sorted((k, isinstance(v, AffineSignal)) for k, v in sigs.items()))


def template_of(asm: Assembled, eps: float) -> StepTemplate | None:
    """The template of a model built in stable mode, or None when it cannot be refreshed (a rule
    outside the vectorised blocks, an infeasible or robustness-mode encoding)."""
    enc = asm.encoding
    if enc.infeasible or enc.recovered or enc.mode != "satisfaction" or enc.rho >= 0 or "stl" not in asm.model.row_blocks:
        return None
    kinds = []
    for _, _, tree in enc.trees:
        p = _parts(tree)
        if p is None or p[1] < eps:
            return None
        kinds.append(tuple(_kind(b) for b in p[0]))
    if "?" in {k for ks in kinds for k in ks} or sum(len(k) for k in kinds) != len(enc.emissions):
        return None
    if any(e.kind == "none" for e in enc.emissions) or asm.model.pattern is None:
        return None
    tri, rows = asm.model.row_blocks["stl"]
    codes = [e.struct[0] for e in enc.emissions if e.kind == "collision"]
    return StepTemplate(asm, tuple(enc.emissions), tuple(kinds), tri.start, rows.start,
                        codes=np.concatenate(codes) if codes else np.zeros(0, np.int64))


def refresh(tpl: StepTemplate, step: StepData, rules: StepRules, settings: MPCSettings,
            params: BicycleParams) -> Assembled | None:
    """Write this step's values into ``tpl``'s model in place; None (model untouched) when the
    structure differs. See the module docstring."""
    requirements, past = rules.requirements, rules.past
    dt, eps = settings.dt, settings.eps
    asm = tpl.asm
    m, lay = asm.model, asm.layout
    n_sig = lay.x.size + lay.u.size + lay.rss.size  # the columns before the encoder's
    sigs = trace_signals(step, lay, n_sig, past, rules.names | {"x", "y"})
    if signal_kinds(sigs) != signal_kinds(asm.signals):
        return None
    lb, ub = m.lb.copy(), m.ub.copy()
    lb[lay.x.ravel()] = step.lo.ravel()
    ub[lay.x.ravel()] = step.hi.ravel()
    u_lo, u_hi = input_bounds(step, params)
    lb[lay.u.ravel()], ub[lay.u.ravel()] = u_lo.ravel(), u_hi.ravel()
    ub[lay.rss] = rss_bounds(step)
    P = lay.P
    cf = collision_free_builtin("x", "y", others_of(step, P), ids=np.asarray(step.hc.index, np.int64),
                                pad=settings.pad)
    ev = Evaluator(TraceSignals(sigs, P + 1 + lay.H), dt, IntervalBounds(Box(lb, ub)), builtins={"collision_free": cf},
                   stable=True)
    writes: list[tuple[Emission, np.ndarray, np.ndarray, np.ndarray | None]] = []
    it = iter(tpl.emissions)
    pids = participants_in(sigs)  # quantifiers over the participants in range, as the encoder expands them
    margins = dict(settings.margins)
    for req, kinds in zip(requirements, tpl.kinds):
        try:
            tree = ev.rob(expand_quantifiers(req.formula, pids), P, 1.0)
        except EncodeError:  # e.g. undefined now (MIL505): the whole encoding reports it
            return None
        eps = settings.eps + margin_at(ev, tree, margins.get(req.name, 0.0), settings.eps)  # as the encoder
        p = _parts(tree)
        if p is None or p[1] < eps or tuple(_kind(b) for b in p[0]) != kinds:
            return None
        for b in p[0]:
            e = next(it)
            if isinstance(b, AffineBlock):
                out = b.layout(lb, ub, eps)
                if out is None or not np.array_equal(b.S, e.struct[0]):
                    return None
                writes.append((e, out[2], out[3], None))
            else:
                lay_c = b.stable_layout(lb, ub, eps, keep=e.struct[0])  # type: ignore[attr-defined]
                if lay_c is None or lay_c.failed or not np.array_equal(lay_c.codes, e.struct[0]):
                    return None
                if lay_c.n > STALE[0] * lay_c.n_padded + STALE[1]:
                    return None
                writes.append((e, lay_c.tvals, lay_c.lo, lay_c.bin_ub))
    if len(requirements) != len(tpl.kinds):
        return None
    # the structure matches: write every value in place
    vals, rhs = dynamics_values(step)
    m.set_block_values("dyn", vals)
    m.set_row_bounds("dyn", rhs, rhs)
    gv, glo, ghi = guard_values(step)
    m.set_block_values("guard", gv)
    m.set_row_bounds("guard", glo, ghi)
    pat, tv = m.pattern, m.triplet_values
    assert pat is not None and tv is not None
    for e, tvals, lo, bub in writes:
        t = slice(tpl.tri0 + e.tri.start, tpl.tri0 + e.tri.stop)
        tv[t] = tvals
        if not pat.duplicates:
            m.A.data[pat.perm[t]] = tvals
        m.row_lo[tpl.row0 + e.rows.start:tpl.row0 + e.rows.stop] = lo
        if bub is not None:
            ub[e.bins] = bub
    if pat.duplicates:
        m.A.data[:] = pat.scatter(tv)
    m.lb[:], m.ub[:] = lb, ub
    set_cost(m, step, lay, settings.weights)
    asm.signals = sigs
    tpl.hits += 1
    return asm


class TemplateCache:
    """A few templates per key (rule set, history length, affine signals), most recent first."""

    def __init__(self, capacity: int = 4) -> None:
        self.capacity = capacity
        self._store: OrderedDict[tuple, StepTemplate] = OrderedDict()
        self.hits = 0
        self.misses = 0

    def candidates(self, key: tuple) -> list[StepTemplate]:
        return [t for k, t in reversed(self._store.items()) if k[0] == key][:2]

    def add(self, key: tuple, tpl: StepTemplate) -> None:
        self._store[(key, id(tpl))] = tpl
        while len(self._store) > self.capacity:
            self._store.popitem(last=False)

    def touch(self, key: tuple, tpl: StepTemplate) -> None:
        self._store.move_to_end((key, id(tpl)))

    def holding(self, asm: Assembled) -> StepTemplate | None:
        """The template whose model ``asm`` is, if any."""
        for tpl in self._store.values():
            if tpl.asm is asm:
                return tpl
        return None
