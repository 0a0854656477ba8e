"""The fixed-mode QP's Hessian parts for a new step's Hessian on the same pattern (its values
moved into place) are those of the sparse algebra, bit for bit."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from twolevel.milp.clarabel import _hessian_parts, _HessianMoves


def _same(a: sp.spmatrix | None, b: sp.spmatrix | None) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return (type(a) is type(b) and a.shape == b.shape and np.array_equal(a.indptr, b.indptr)
            and np.array_equal(a.indices, b.indices) and np.array_equal(a.data.view(np.int64), b.data.view(np.int64)))


@settings(max_examples=150, deadline=None)
@given(n=st.integers(1, 12), density=st.floats(0.05, 1.0), seed=st.integers(0, 2**16), steps=st.integers(1, 4))
def test_moved_hessian_parts_are_the_sparse_algebra(n, density, seed, steps):
    """Over random upper-triangular patterns and integer/continuous splits, each later Hessian
    (new nonzero values on the same pattern, as the cost's weighed Hessian of each step) gets
    the coupling block and the continuous upper triangle exactly as the sparse algebra gives them;
    a zero value or another pattern is refused (the algebra would drop or move entries)."""
    rng = np.random.default_rng(seed)
    dense = np.triu(rng.uniform(0.5, 2.0, (n, n)) * (rng.uniform(size=(n, n)) < density))
    np.fill_diagonal(dense, rng.uniform(0.5, 2.0, n))
    P0 = sp.csc_matrix(dense)
    is_int = rng.uniform(size=n) < 0.4
    cont, ints = np.flatnonzero(~is_int), np.flatnonzero(is_int)
    moves = _HessianMoves.of(P0, cont, ints)
    assert moves is not None
    for _ in range(steps):
        P = sp.csc_matrix((rng.uniform(-3.0, 3.0, P0.nnz) + 5.0, P0.indices, P0.indptr), shape=P0.shape)
        got = moves.parts(P)
        assert got is not None
        want = _hessian_parts(P, cont, ints)
        assert _same(got[0], want[0]) and _same(got[1], want[1])
    zero = sp.csc_matrix((np.where(np.arange(P0.nnz) == 0, 0.0, 1.0), P0.indices, P0.indptr), shape=P0.shape)
    assert moves.parts(zero) is None
    if P0.nnz > 1:  # another pattern of as many entries: the last entry's row changed
        other = P0.indices.copy()
        other[-1] = 0 if other[-1] else 1
        assert moves.parts(sp.csc_matrix((P0.data, other, P0.indptr), shape=P0.shape)) is None


def test_a_hessian_with_lower_entries_has_no_moves():
    """Both triangles stored: the symmetric sum adds entries, so the values are not moved."""
    P = sp.csc_matrix(np.array([[2.0, 1.0], [1.0, 3.0]]))
    assert _HessianMoves.of(P, np.array([0, 1]), np.zeros(0, np.int64)) is None
