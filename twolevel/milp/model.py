"""The solver-neutral mixed-integer model: variables, a sparse constraint matrix, costs, disjunctions.

A :class:`MilpModel` is

    minimise    ½ xᵀ P x + qᵀ x + c0
    subject to  row_lo ≤ A x ≤ row_hi,   lb ≤ x ≤ ub,   x_j integral where ``integrality[j]``

* ``A`` is a :class:`scipy.sparse.csc_matrix` whose explicit zeros are *kept*: the sparsity
  pattern is structural and never depends on current values, so a backend can update values in
  place (Clarabel's ``update``) between solves.
* ``P`` is the **upper triangle** (diagonal included) of the symmetric Hessian, CSC — Clarabel's
  convention. When the quadratic cost comes from weighted residuals (the MPC's least squares)
  they are kept too, in :class:`Residuals` ``Σ_i w_i (F_i x − g_i)²``, so the cost can be turned
  into its L1 counterpart (:func:`twolevel.milp.l1_surrogate.l1_surrogate`).
* every binary belongs to exactly one :class:`Disjunction`: one binary per disjunct, the rows
  that the binary switches on (big-M rows ``expr + M·(1 − b) ≥ 0``) and the enclosing guard. A
  *mode* picks one disjunct per disjunction; with the mode fixed the problem is convex.

Models are assembled by :class:`~twolevel.milp.builder.ModelBuilder` from whole COO arrays
concatenated once; :class:`PatternCache` keeps the CSC pattern of a shape so later builds only
scatter values (``A.data[perm] = values``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

__all__ = [
    "Disjunction",
    "Residuals",
    "MilpModel",
    "Pattern",
    "PatternCache",
    "build_pattern",
    "csc_from_coo",
]


@dataclass(frozen=True)
class Disjunction:
    """One disjunction of the model: pick (at least) one disjunct.

    ``binaries[i]`` is the column of disjunct ``i``'s binary; ``rows[i]`` the big-M rows it
    enables (written ``expr − M·b ≥ −M``: relaxed when ``b = 0``); ``cover_row`` the row
    ``Σ b_i − guard ≥ 0``; ``guard`` the binary of the enclosing disjunct (−1 at top level).
    ``label`` says where it comes from (rule, step, formula); ``sources[i]`` describes disjunct
    ``i`` for its producer (the compiler puts its robustness tree there), empty when none."""

    id: int
    binaries: np.ndarray
    rows: tuple[np.ndarray, ...]
    cover_row: int
    guard: int = -1
    label: str = ""
    sources: tuple[object, ...] = ()

    @property
    def size(self) -> int:
        return int(self.binaries.size)


@dataclass(frozen=True)
class Residuals:
    """A quadratic cost in residual form ``Σ_i w_i (F_i x − g_i)²`` (F: CSR, m × n)."""

    F: sp.csr_matrix
    g: np.ndarray
    w: np.ndarray


@dataclass(frozen=True)
class Pattern:
    """The CSC pattern of one COO triplet list: ``perm[k]`` is the data position of triplet k."""

    shape: tuple[int, int]
    indptr: np.ndarray
    indices: np.ndarray
    perm: np.ndarray
    duplicates: bool

    def matrix(self, values: np.ndarray) -> sp.csc_matrix:
        """A CSC matrix with this pattern holding ``values`` (triplet order), explicit zeros kept."""
        data = self.scatter(values)
        m = sp.csc_matrix((data, self.indices, self.indptr), shape=self.shape)
        return m

    def scatter(self, values: np.ndarray) -> np.ndarray:
        """The CSC data array for triplet ``values`` (duplicates summed)."""
        nnz = self.indices.size
        if self.duplicates:
            return np.bincount(self.perm, weights=values, minlength=nnz).astype(float)
        data = np.empty(nnz)
        data[self.perm] = values
        return data


def build_pattern(rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> Pattern:
    """The CSC pattern of the COO positions (``rows``, ``cols``) in a matrix of ``shape``
    (duplicate positions share one entry)."""
    order = np.lexsort((rows, cols))
    r, c = rows[order], cols[order]
    if r.size:
        new = np.empty(r.size, dtype=bool)
        new[0] = True
        new[1:] = (r[1:] != r[:-1]) | (c[1:] != c[:-1])
    else:
        new = np.zeros(0, dtype=bool)
    uid = np.cumsum(new) - 1
    perm = np.empty(rows.size, dtype=np.int64)
    perm[order] = uid
    indices = r[new].astype(np.int32)
    counts = np.bincount(c[new], minlength=shape[1])
    indptr = np.zeros(shape[1] + 1, dtype=np.int32)
    np.cumsum(counts, out=indptr[1:])
    return Pattern(shape, indptr, indices, perm, bool(r.size and not new.all()))


def csc_from_coo(
    rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, shape: tuple[int, int],
    cache: "PatternCache | None" = None,
) -> tuple[sp.csc_matrix, Pattern]:
    """CSC matrix from COO triplets keeping explicit zeros; the pattern comes from ``cache`` when
    the same (rows, cols, shape) was seen before."""
    pat = cache.get(rows, cols, shape) if cache is not None else build_pattern(rows, cols, shape)
    return pat.matrix(vals), pat


class PatternCache:
    """A few CSC patterns keyed by their triplet structure (least recently used dropped).

    The key is a hash of the row and column arrays; a hit is confirmed by comparing the arrays,
    so a collision can never return a wrong pattern. ``hits``/``misses`` count lookups."""

    def __init__(self, capacity: int = 8) -> None:
        self.capacity = capacity
        self._store: dict[tuple, tuple[np.ndarray, np.ndarray, Pattern]] = {}
        self.hits = 0
        self.misses = 0

    def get(self, rows: np.ndarray, cols: np.ndarray, shape: tuple[int, int]) -> Pattern:
        key = (shape, rows.size, hash(rows.tobytes()), hash(cols.tobytes()))
        found = self._store.pop(key, None)
        if found is not None and np.array_equal(found[0], rows) and np.array_equal(found[1], cols):
            self._store[key] = found
            self.hits += 1
            return found[2]
        self.misses += 1
        pat = build_pattern(rows, cols, shape)
        self._store[key] = (rows.copy(), cols.copy(), pat)
        while len(self._store) > self.capacity:
            self._store.pop(next(iter(self._store)))
        return pat


@dataclass
class MilpModel:
    """A mixed-integer (quadratic) program in solver-neutral arrays; see the module docstring.

    Mutable on purpose: between solves of the same shape, values change in place
    (:meth:`set_block_values`, :meth:`set_row_bounds`, ``q``, ``lb``/``ub``)."""

    A: sp.csc_matrix
    row_lo: np.ndarray
    row_hi: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    integrality: np.ndarray  # bool per column
    q: np.ndarray
    P: sp.csc_matrix | None = None
    c0: float = 0.0
    residuals: Residuals | None = None
    col_names: tuple[str, ...] = ()
    row_names: tuple[str, ...] = ()
    disjunctions: tuple[Disjunction, ...] = ()
    pattern: Pattern | None = None
    # name → (triplet slice, row range) of each constraint block; name → column range of each
    # variable block
    row_blocks: dict[str, tuple[slice, slice]] = field(default_factory=dict)
    col_blocks: dict[str, slice] = field(default_factory=dict)
    triplet_values: np.ndarray | None = None

    @property
    def n_cols(self) -> int:
        return int(self.lb.size)

    @property
    def n_rows(self) -> int:
        return int(self.row_lo.size)

    @property
    def n_binaries(self) -> int:
        return int(np.count_nonzero(self.integrality & (self.lb >= 0) & (self.ub <= 1)))

    def cols(self, name: str) -> np.ndarray:
        """Column indices of the variable block ``name``."""
        s = self.col_blocks[name]
        return np.arange(s.start, s.stop)

    def rows(self, name: str) -> np.ndarray:
        """Row indices of the constraint block ``name``."""
        s = self.row_blocks[name][1]
        return np.arange(s.start, s.stop)

    def set_block_values(self, name: str, values: np.ndarray) -> None:
        """Replace the coefficient values of block ``name`` (same triplet order as when it was
        added), in place in ``A.data``."""
        tri, _ = self.row_blocks[name]
        assert self.pattern is not None and self.triplet_values is not None
        self.triplet_values[tri] = values
        if self.pattern.duplicates:
            self.A.data[:] = self.pattern.scatter(self.triplet_values)
        else:
            self.A.data[self.pattern.perm[tri]] = values

    def set_row_bounds(self, name: str, lo: np.ndarray | float, hi: np.ndarray | float) -> None:
        """Replace the row bounds of block ``name`` in place."""
        rs = self.row_blocks[name][1]
        self.row_lo[rs] = lo
        self.row_hi[rs] = hi

    def objective(self, x: np.ndarray) -> float:
        """The model's cost at ``x``."""
        val = float(self.q @ x) + self.c0
        if self.P is not None:
            Px = self.P @ x
            diag = self.P.diagonal()
            # P holds the upper triangle: xᵀ(U + Uᵀ − D)x / 2
            val += float(x @ Px) - 0.5 * float(diag @ (x * x))
        return val

    def violation(self, x: np.ndarray) -> float:
        """The largest bound or row violation of ``x`` (0 when feasible)."""
        ax = self.A @ x
        v = [0.0]
        if ax.size:
            v.append(float(np.max(np.maximum(self.row_lo - ax, ax - self.row_hi))))
        if x.size:
            v.append(float(np.max(np.maximum(self.lb - x, x - self.ub))))
        return max(v)
