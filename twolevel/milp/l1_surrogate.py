"""The L1 surrogate of a least-squares cost: the linear model HiGHS solves on the exact path.

``Σ_i w_i (F_i x − g_i)²`` becomes ``Σ_i √w_i · t_i`` with auxiliary ``t_i ≥ ±(F_i x − g_i)``:
a MILP that HiGHS solves for the mode (the binaries); Clarabel then restores the exact quadratic
cost with those binaries fixed (:class:`twolevel.milp.clarabel.FixedModeQP` on the *original*
model, whose columns are the first ``n`` of the surrogate's).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from twolevel.milp.model import MilpModel, csc_from_coo

__all__ = ["l1_surrogate"]


def l1_surrogate(model: MilpModel, weight: str = "sqrt") -> MilpModel:
    """The model with its quadratic cost replaced by the L1 norm of its weighted residuals.

    Columns ``0..n-1`` are the original ones; ``t`` columns follow; the original rows come first,
    then ``2m`` rows ``t_i − (F_i x − g_i) ≥ 0`` and ``t_i + (F_i x − g_i) ≥ 0``. ``weight``:
    ``"sqrt"`` (cost ``√w_i·t_i``, the L1 norm of the same scaled residuals) or ``"linear"``
    (``w_i·t_i``)."""
    if model.residuals is None:
        if model.P is None or model.P.nnz == 0:
            return model
        raise ValueError("the quadratic cost has no residual form; add it with add_residuals()")
    R = model.residuals
    n, m0 = model.n_cols, model.n_rows
    mres = R.g.size
    F = sp.coo_matrix(R.F)
    A = model.A.tocoo()
    tcols = n + np.arange(mres)
    r_new = np.concatenate([
        A.row, m0 + F.row, m0 + np.arange(mres), m0 + mres + F.row, m0 + mres + np.arange(mres)])
    c_new = np.concatenate([A.col, F.col, tcols, F.col, tcols])
    v_new = np.concatenate([A.data, -F.data, np.ones(mres), F.data, np.ones(mres)])
    shape = (m0 + 2 * mres, n + mres)
    A2, pat = csc_from_coo(r_new, c_new, v_new, shape)
    w = np.sqrt(R.w) if weight == "sqrt" else R.w
    q = np.concatenate([model.q * 0.0, w])
    # keep the linear cost terms that are not part of the residual expansion
    q[:n] += model.q + 2.0 * (R.F.T @ (R.w * R.g))
    return replace(
        model, A=A2,
        row_lo=np.concatenate([model.row_lo, -R.g, R.g]),
        row_hi=np.concatenate([model.row_hi, np.full(2 * mres, np.inf)]),
        lb=np.concatenate([model.lb, np.zeros(mres)]),
        ub=np.concatenate([model.ub, np.full(mres, np.inf)]),
        integrality=np.concatenate([model.integrality, np.zeros(mres, bool)]),
        q=q, P=None, c0=model.c0 - float(R.w @ (R.g * R.g)), residuals=None,
        col_names=model.col_names + tuple(f"t[{i}]" for i in range(mres)),
        row_names=model.row_names + tuple(f"l1p[{i}]" for i in range(mres))
        + tuple(f"l1n[{i}]" for i in range(mres)),
        pattern=pat, triplet_values=v_new, row_blocks=dict(model.row_blocks),
        col_blocks=dict(model.col_blocks),
    )
