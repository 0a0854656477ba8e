"""Hypothesis strategies: random formulas over the signals x, y, z and random signals.

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


def _terms() -> st.SearchStrategy[A.Node]:
    leaf = st.one_of(
        st.sampled_from(SIGNALS).map(A.Var),
        st.sampled_from([-1.0, 0.0, 0.5, 2.0]).map(A.Num),
    )

    def grow(inner: st.SearchStrategy[A.Node]) -> st.SearchStrategy[A.Node]:
        return st.one_of(
            st.builds(A.Arith, st.sampled_from(["+", "-", "*"]), inner, inner),
            st.builds(A.Arith, st.just("/"), inner, st.sampled_from([2.0, -4.0, 0.5]).map(A.Num)),
            st.builds(A.Abs, inner),
            st.builds(A.Neg, inner),
        )

    return st.recursive(leaf, grow, max_leaves=3)


def predicates() -> st.SearchStrategy[A.Node]:
    return st.builds(A.Compare, st.sampled_from(["<", "<=", ">", ">=", "==", "!=="]), _terms(), _terms())


def intervals(scale: float) -> st.SearchStrategy[A.Interval]:
    return st.tuples(st.integers(0, 4), st.integers(0, 5)).map(
        lambda ab: A.Interval(ab[0] * scale, (ab[0] + ab[1]) * scale)
    )


def formulas(*, scale: float = 1.0, bounded: bool = False, rtamt_safe: bool = False, max_leaves: int = 6) -> st.SearchStrategy[A.Node]:
    """Random formulas; intervals are multiples of ``scale`` [s] (use the trace's dt)."""
    atom = predicates()
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
