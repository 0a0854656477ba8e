"""Hypothesis strategies: random formulas over the signals x, y, z and random signals; random
quantified formulas (``forall``/``exists o in vehicles``) whose bodies also read the participant
signals p(o), q(o), and traces of the participants a, b, c present at random samples.

Values come from a small grid so that ties (the corner cases of min/max windows) are common.
``rtamt_safe`` keeps to what RTAMT 0.4.10 computes and parses correctly: no true/false literal,
no bare signal as a formula (its offline ``always``/``eventually`` pad the dataset list in place),
``iff``/``xor`` only between predicates (no ``inf - inf``), division by non-zero numbers only.
``bounded`` leaves out unbounded future operators (the online monitor rejects them).
"""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

from twolevel.stl import ast as A

SIGNALS = ("x", "y", "z")
VALUES = st.sampled_from([-3.0, -2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0, 3.0])


def signals(n: int) -> st.SearchStrategy[dict[str, np.ndarray]]:
    col = st.lists(VALUES, min_size=n, max_size=n).map(lambda v: np.array(v, dtype=np.float64))
    return st.fixed_dictionaries({name: col for name in SIGNALS})


def traces(min_size: int = 0, max_size: int = 14) -> st.SearchStrategy[dict[str, np.ndarray]]:
    return st.integers(min_size, max_size).flatmap(signals)


PARTICIPANTS = ("a", "b", "c")
PARTICIPANT_SIGNALS = ("p", "q")


def participant_traces(min_size: int = 0, max_size: int = 14) -> st.SearchStrategy[dict[str, np.ndarray]]:
    """x, y, z and, for each of a, b, c, ``present[·]`` (+inf/-inf) and ``p[·]``, ``q[·]``; a
    participant may be present nowhere (``none`` leaves every one out)."""
    def of(n: int) -> st.SearchStrategy[dict[str, np.ndarray]]:
        col = st.lists(VALUES, min_size=n, max_size=n).map(lambda v: np.array(v, dtype=np.float64))
        pres = st.lists(st.booleans(), min_size=n, max_size=n).map(
            lambda b: np.where(np.array(b, dtype=bool), np.inf, -np.inf).astype(np.float64))
        names = {k: col for k in SIGNALS}
        for pid in PARTICIPANTS:
            names[f"present[{pid}]"] = pres
            names.update({f"{s}[{pid}]": col for s in PARTICIPANT_SIGNALS})
        every = st.fixed_dictionaries(names)
        return st.one_of(every, every.map(lambda d: {k: v for k, v in d.items() if k in SIGNALS}))
    return st.integers(min_size, max_size).flatmap(of)


def _terms(participant: bool = False) -> st.SearchStrategy[A.Node]:
    leaves = [st.sampled_from(SIGNALS).map(A.Var), st.sampled_from([-1.0, 0.0, 0.5, 2.0]).map(A.Num)]
    if participant:
        leaves.append(st.sampled_from(PARTICIPANT_SIGNALS).map(lambda n: A.ParticipantSignal(n, "o")))
    leaf = st.one_of(*leaves)

    def grow(inner: st.SearchStrategy[A.Node]) -> st.SearchStrategy[A.Node]:
        return st.one_of(
            st.builds(A.Arith, st.sampled_from(["+", "-", "*"]), inner, inner),
            st.builds(A.Arith, st.just("/"), inner, st.sampled_from([2.0, -4.0, 0.5]).map(A.Num)),
            st.builds(A.Abs, inner),
            st.builds(A.Neg, inner),
        )

    return st.recursive(leaf, grow, max_leaves=3)


def predicates(participant: bool = False) -> st.SearchStrategy[A.Node]:
    return st.builds(A.Compare, st.sampled_from(["<", "<=", ">", ">=", "==", "!=="]), _terms(participant),
                     _terms(participant))


def intervals(scale: float) -> st.SearchStrategy[A.Interval]:
    return st.tuples(st.integers(0, 4), st.integers(0, 5)).map(
        lambda ab: A.Interval(ab[0] * scale, (ab[0] + ab[1]) * scale)
    )


def formulas(*, scale: float = 1.0, bounded: bool = False, rtamt_safe: bool = False, max_leaves: int = 6,
             participant: bool = False) -> st.SearchStrategy[A.Node]:
    """Random formulas; intervals are multiples of ``scale`` [s] (use the trace's dt).
    ``participant``: predicates may read p(o), q(o) (a quantifier's body)."""
    atom = predicates(participant)
    leaves = [atom, atom]
    if not rtamt_safe:
        leaves.append(st.sampled_from(SIGNALS).map(A.Var))
        leaves.append(st.booleans().map(A.BoolConst))
    base = st.one_of(*leaves)
    ivals = intervals(scale)
    opt_ival = st.one_of(st.none(), ivals)
    future_ival = ivals if bounded else opt_ival
    finite_pair = st.builds(A.Binary, st.sampled_from(["iff", "xor"]), atom, atom)
    unless_ival = ivals if (bounded or rtamt_safe) else opt_ival  # RTAMT fails on a bare 'unless'

    def grow(inner: st.SearchStrategy[A.Node]) -> st.SearchStrategy[A.Node]:
        return st.one_of(
            st.builds(A.Not, inner),
            st.builds(A.Binary, st.sampled_from(["and", "or", "implies"]), inner, inner),
            finite_pair,
            st.builds(A.Temporal, st.sampled_from(["always", "eventually"]), future_ival, inner),
            st.builds(A.Temporal, st.sampled_from(["historically", "once"]), opt_ival, inner),
            st.builds(A.Temporal, st.sampled_from(["next", "prev"]), st.none(), inner),
            st.builds(A.BinTemporal, st.just("until"), future_ival, inner, inner),
            st.builds(A.BinTemporal, st.just("unless"), unless_ival, inner, inner),
            st.builds(A.BinTemporal, st.just("since"), opt_ival, inner, inner),
            st.builds(A.Edge, st.sampled_from(["rise", "fall"]), inner),
        )

    return st.recursive(base, grow, max_leaves=max_leaves)


def quantified_formulas(*, scale: float = 1.0, bounded: bool = False, rtamt_safe: bool = False,
                        max_leaves: int = 4) -> st.SearchStrategy[A.Node]:
    """Random formulas with quantifiers over the participants (one level: no quantifier inside
    another), under and around temporal operators."""
    body = formulas(scale=scale, bounded=bounded, rtamt_safe=rtamt_safe, max_leaves=max_leaves, participant=True)
    quant = st.builds(A.Quantifier, st.sampled_from(["forall", "exists"]), st.just("o"), st.just("vehicles"), body)
    outer = formulas(scale=scale, bounded=bounded, rtamt_safe=rtamt_safe, max_leaves=2)
    ivals = intervals(scale)

    def grow(inner: st.SearchStrategy[A.Node]) -> st.SearchStrategy[A.Node]:
        return st.one_of(
            st.builds(A.Not, inner),
            st.builds(A.Binary, st.sampled_from(["and", "or", "implies"]), inner, st.one_of(inner, outer)),
            st.builds(A.Temporal, st.sampled_from(["always", "eventually", "historically", "once"]), ivals, inner),
            st.builds(A.BinTemporal, st.sampled_from(["until", "since"]), ivals, inner, outer),
        )

    return st.recursive(quant, grow, max_leaves=3)
