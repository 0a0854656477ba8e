"""One MPC step as a :class:`~twolevel.milp.model.MilpModel`: dynamics, the paper's cost, rules.

Columns: ``x`` — the states X, Y, ψ, v for k = 1..N (row-major, 4 per step; N steps of the
look-ahead, the first H of one period); ``u`` — the inputs δ, a for k = 0..N−1; then the
encoder's variables (binaries of disjunctions, auxiliaries).
Rows: ``dyn`` — x_{k+1} − A_k x_k − B_k u_k = c_k (A_0 x_0 moved to the right-hand side; each
step discretised for its length h_k); ``guard`` (:mod:`twolevel.control.high_level.guards`) — the
lateral offset e_k ≈ n̄_kᵀ(p_k − p̄_k) within the drivable band for k = 1..N, the terminal
can-still-stop row v_N ≤ κ·(s_line − margin − s_0 − Σ_k h_k·(v_k + v_{k+1})/2) + offset on the
distance travelled (which no sideways motion shortens, and which bounds the route progress from
above; ``0·x ≤ 1`` when no line applies, so the pattern never changes), and, when the settings
keep RSS's distance, K plain rows *behind the vehicle ahead by RSS's distance* (in force when the
ego may not pass it, so the mode search's lower bound keeps them), then the disjunction *behind
(the same K rows) | passing on the left | on the right (a lateral-offset row per step)* with its
cover row (binaries ``rss``; in force when a side is free; rows not in force are zero rows that
always hold, so the pattern never changes); then the rules' rows (``stl``, and ``cf*`` for the
vectorised collision_free blocks), over the fine part only.

Cost (paper): Σ_k w_u‖u_k‖² + w_du‖u_k − u_{k−1}‖² + Σ_i w_i (ζ_{k,i} − ω_{k,i})², as residuals,
over every step of the look-ahead, each step's terms weighed by its length in periods (a coarse
step of 0.5 s counts as five of the paper's: the sum stays a time integral, and a plan gains
nothing by putting a manoeuvre off into the coarse part). With ``settings.lateral_weight`` the
steering's terms are δ_k − δ_ref,k (the steering that follows the route) and δ_k − δ_{k−1},
weighed by the lateral acceleration they cause at the step's speed, and while the ego passes over
the oncoming lane the heading's tracking terms by the lateral velocity they cause
(:mod:`twolevel.control.high_level.steering`).

Signals of the trace (past samples from ``history``, then now, then k = 1..H: the rules see the
fine part, in steps of dt): constants for what is known at solve time,
:class:`~twolevel.compiler.signals.AffineSignal` for v, X, Y, ψ, δ, a, the route progress
s_k ≈ s̄_k + t̄_kᵀ(p_k − p̄_k), the lateral offset e_k ≈ n̄_kᵀ(p_k − p̄_k), d_stop,k = s_stop − s_k,
d_light,k = s_light − s_k, d_xwalk,k = s_xwalk − s_k, d_lead,k = s_lead,k − s_k − offset and
rss_gap,k = s_ahead,k − s_k − offset − (c0_k + c1_k·v_k), the chord of RSS's distance over the
speeds step k can reach (above it: conservative).

Every model of the same *shape* (same triplet structure, same finiteness of bounds, same
disjunctions) shares one CSC pattern (:class:`~twolevel.milp.model.PatternCache`), so the
backend can be reused and updated in place (:func:`shape_key`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Mapping

import numpy as np
import scipy.sparse as sp

from twolevel.compiler.collision import collision_free_builtin
from twolevel.compiler.driver import encode
from twolevel.compiler.signals import AffineSignal
from twolevel.compiler.types import Encoding, Requirement
from twolevel.control.codes import MIL517
from twolevel.control.high_level.linearisation import StepData
from twolevel.control.high_level.neighbours import neighbour_signals_over
from twolevel.control.high_level.right_of_way import zone_signals_over
from twolevel.control.high_level.settings import MPCSettings, Weights
from twolevel.diagnostics import Diagnostic, Span
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.model import Disjunction, MilpModel, PatternCache, Residuals
from twolevel.models.params import BicycleParams

__all__ = ["StepRules", "Layout", "Assembled", "assemble", "trace_signals", "shape_key", "dynamics_values",
           "guard_values", "rss_bounds", "others_of", "set_cost", "input_bounds"]

FAR_INSIDE = 1e3
"""[m] ``over_centre`` where no oncoming lane lies left of the route at some steps of a horizon
that has one at others (the monitor's −inf there): far inside, finite for the encoding."""


@dataclass(frozen=True, eq=False)
class StepRules:
    """What the rules ask of one step: the ``requirements``, the signal ``names`` they read,
    the recorded ``past`` samples of those signals (oldest first, now excluded), how many of
    them the trace holds (``P``), and, for a rule being recovered, the trace index after which
    it is required (``recover_after``)."""

    requirements: tuple[Requirement, ...]
    names: frozenset[str]
    past: Mapping[str, np.ndarray]
    P: int
    recover_after: Mapping[str, int] | None = None


@dataclass(frozen=True, eq=False)
class Layout:
    """Column indices: ``x`` (N, 4) states k = 1..N, ``u`` (N, 2) inputs k = 0..N−1; ``P`` past
    samples in the trace (the current step is trace index P); ``H`` steps of the fine part (the
    rules' trace holds now and k = 1..H); ``rss`` (3,): the binaries of the RSS terminal
    disjunction (behind, left, right; none when the settings do not keep RSS's distance)."""

    x: np.ndarray
    u: np.ndarray
    P: int
    H: int
    rss: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))


@dataclass(eq=False)
class Assembled:
    """A built step model and what the encoder said (``signals``: the rules' signals over the
    trace, :func:`trace_signals`)."""

    model: MilpModel
    layout: Layout
    encoding: Encoding
    signals: dict[str, object]
    diagnostics: list[Diagnostic] = field(default_factory=list)


class RowMatrix:
    """A minimal CSR matrix (``indptr``, ``indices``, ``data``, ``shape``, ``@ x``) — what the
    encoder reads of an :class:`AffineSignal`, without scipy's per-construction checks."""

    __slots__ = ("indptr", "indices", "data", "shape")

    def __init__(self, data: np.ndarray, indices: np.ndarray, indptr: np.ndarray, shape: tuple[int, int]) -> None:
        self.data, self.indices, self.indptr, self.shape = data, indices, indptr, shape

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        out = np.zeros(self.shape[0])
        rows = np.repeat(np.arange(self.shape[0]), np.diff(self.indptr))
        np.add.at(out, rows, self.data * np.asarray(x)[self.indices])
        return out


def _affine(cols: np.ndarray, coefs: np.ndarray, offset: np.ndarray, past: np.ndarray, n: int) -> AffineSignal:
    """Signal with ``len(past)`` constant samples then one row per row of ``cols``:
    ``coefs[k] @ x[cols[k]] + offset[k]``."""
    H, m = cols.shape
    P = past.size
    indptr = np.concatenate([np.zeros(P + 1, np.int64), m * np.arange(1, H + 1)])
    C = RowMatrix(coefs.ravel().astype(float), cols.ravel(), indptr, (P + H, n))
    return AffineSignal(C, np.concatenate([past, offset]))  # type: ignore[arg-type]


def trace_signals(step: StepData, lay: Layout, n: int, past: Mapping[str, np.ndarray], names: Iterable[str]
                  ) -> dict[str, object]:
    """The signals the rules read, over the trace (P past samples, now, k = 1..H of the fine part)."""
    H = lay.H
    P = lay.P
    hc = step.hc
    x0 = step.x0
    full, lay = lay, Layout(lay.x[:H], lay.u[:H], P, H)
    f = slice(0, H + 1)  # the fine part of the look-ahead's constants

    def hist(name: str, now: float) -> np.ndarray:
        h = past.get(name)
        h = np.zeros(0) if h is None or P == 0 else np.asarray(h, float)[-P:]
        return np.concatenate([h, [now]])

    one = np.ones((H, 1))
    s_now = float(step.s_bar[0])
    h_bar, p_bar = step.h_bar[1:H + 1], step.p_bar[1:H + 1]
    t_hat = np.stack([np.cos(h_bar), np.sin(h_bar)], axis=1)
    n_hat = np.stack([-np.sin(h_bar), np.cos(h_bar)], axis=1)
    xy = lay.x[:, :2]
    s_off = step.s_bar[1:H + 1] - np.einsum("kj,kj->k", t_hat, p_bar)
    e_off = -np.einsum("kj,kj->k", n_hat, p_bar)
    e_now = float(n_hat[0] @ (x0[:2] - step.p_bar[0])) if H else 0.0
    out: dict[str, object] = {}
    for name in names:
        if name in ("x", "y", "psi", "v"):
            i = ("x", "y", "psi", "v").index(name)
            out[name] = _affine(lay.x[:, i:i + 1], one, np.zeros(H), hist(name, float(x0[i])), n)
        elif name in ("delta", "a"):
            j = 0 if name == "delta" else 1
            # sample k carries the control applied from k on (twolevel.world.provided): now is u_0,
            # the last recorded sample u_{-1}; sample H the first coarse step's control, or u_{H-1}
            # held when the look-ahead ends there
            cols = np.concatenate([full.u[:, j], full.u[-1:, j]])[:H + 1, None]
            out[name] = _affine(cols, np.ones((H + 1, 1)), np.zeros(H + 1), hist(name, 0.0)[:-1], n)
        elif name == "s":
            out[name] = _affine(xy, t_hat, s_off, hist("s", s_now), n)
        elif name == "e":
            out[name] = _affine(xy, n_hat, e_off, hist("e", e_now), n)
        elif name in ("d_stop", "d_light", "d_xwalk", "d_lead"):
            if name == "d_stop":
                tgt, extra = np.full(H + 1, hc.s_stop), 0.0
            elif name == "d_light":
                tgt, extra = np.full(H + 1, hc.s_light), 0.0
            elif name == "d_xwalk":
                tgt, extra = np.full(H + 1, hc.s_xwalk), 0.0
            else:
                tgt, extra = hc.s_lead[f], hc.lead_offset
            if not np.all(np.isfinite(tgt)):
                out[name] = np.concatenate([hist(name, np.inf)[:-1], np.full(H + 1, np.inf)])
            else:
                now = float(tgt[0] - s_now - extra)
                out[name] = _affine(xy, -t_hat, tgt[1:] - extra - s_off, hist(name, now), n)
        elif name == "rss_gap":
            rss = step.rss
            if rss is None or not np.all(np.isfinite(rss.rule)):  # no vehicle ahead in the ego's lane
                out[name] = np.concatenate([hist(name, np.inf)[:-1], np.full(H + 1, np.inf)])
            else:  # s_ahead,k − s_k − offset − (c0 + c1·v_k): three coefficients per sample
                cols = np.concatenate([xy, lay.x[:, 3:4]], axis=1)
                coefs = np.concatenate([-t_hat, -rss.rule[:, :1]], axis=1)
                off = hc.s_ahead[1:H + 1] - hc.ahead_offset - s_off - rss.rule[:, 1]
                out[name] = _affine(cols, coefs, off, hist(name, rss.gap0), n)
        elif name == "v_max":
            out[name] = np.concatenate([hist(name, float(hc.v_max[0]))[:-1], hc.v_max[f]])
        elif name in ("light_red", "xwalk_busy"):
            c = getattr(hc, name)
            out[name] = np.concatenate([hist(name, float(c[0]))[:-1], c[f]])
        elif name == "v_lead":
            v_lead = float(hc.v[hc.lead]) if hc.lead >= 0 else np.nan
            if hc.lead < 0:
                out[name] = _affine(lay.x[:, 3:4], one, np.zeros(H), hist(name, float(x0[3])), n)
            else:
                out[name] = np.concatenate([hist(name, v_lead)[:-1], np.full(H + 1, v_lead)])
        elif name == "over_centre":  # e_k + W/2 − the centre line's offset at s̄_k (twolevel.world.area)
            c = hc.over_offset[f]
            if not np.any(np.isfinite(c)):  # no oncoming lane to the left anywhere along the horizon
                out[name] = np.concatenate([hist(name, -np.inf)[:-1], np.full(H + 1, -np.inf)])
            else:  # where one begins or ends within the horizon: far inside, finite for the encoding
                c = np.maximum(c, -FAR_INSIDE)
                out[name] = _affine(xy, n_hat, e_off + c[1:], hist(name, e_now + float(c[0])), n)
        elif name in ("solid_left", "no_overtaking"):
            c = getattr(hc, name)[f]
            out[name] = np.concatenate([hist(name, float(c[0]))[:-1], c])
        elif name == "n_near":
            out[name] = np.concatenate([hist(name, float(len(hc.index)))[:-1], np.full(H + 1, float(len(hc.index)))])
    out.update(zone_signals_over(step.zones, names, H, P,
                                 lambda pst, c: _affine(xy, -t_hat, c - s_off, np.append(pst, c - s_now), n), hist))
    out.update(neighbour_signals_over(
        step.neighbours, names, H, P,
        lambda pst, c: _affine(xy, -t_hat, c[1:] - s_off, np.append(pst, c[0] - s_now), n),  # c − s_k
        lambda pst, c: _affine(xy, t_hat, s_off - c[1:], np.append(pst, s_now - c[0]), n),  # s_k − c
        lambda pst, c: _affine(xy, -n_hat, c[1:] - e_off, np.append(pst, c[0] - e_now), n),  # c − e_k
        hist))
    return out


def dynamics_values(step: StepData) -> tuple[np.ndarray, np.ndarray]:
    """The ``dyn`` block's triplet values (in :func:`_dynamics`' order) and right-hand side."""
    H = step.A.shape[0]
    rhs = step.c.copy()
    rhs[0] += step.A[0] @ step.x0
    return np.concatenate([np.ones(4 * H), -step.A[1:].ravel(), -step.B.ravel()]), rhs.ravel()


def _dynamics(b: ModelBuilder, step: StepData, lay: Layout) -> None:
    H = lay.x.shape[0]
    k = np.arange(H)
    # x_{k+1}: identity
    r_id = 4 * k[:, None] + np.arange(4)[None]
    c_id = lay.x
    v_id = np.ones((H, 4))
    # −A_k x_k for k ≥ 1 (dense 4×4, explicit zeros kept)
    kk = k[1:]
    r_a = np.broadcast_to((4 * kk[:, None, None] + np.arange(4)[None, :, None]), (H - 1, 4, 4))
    c_a = np.broadcast_to(lay.x[kk - 1][:, None, :], (H - 1, 4, 4))
    v_a = -step.A[1:]
    # −B_k u_k
    r_b = np.broadcast_to((4 * k[:, None, None] + np.arange(4)[None, :, None]), (H, 4, 2))
    c_b = np.broadcast_to(lay.u[:, None, :], (H, 4, 2))
    v_b = -step.B
    rhs = step.c.copy()
    rhs[0] += step.A[0] @ step.x0
    b.add_rows("dyn", 4 * H, np.concatenate([r_id.ravel(), r_a.ravel(), r_b.ravel()]),
               np.concatenate([c_id.ravel(), c_a.ravel(), c_b.ravel()]),
               np.concatenate([v_id.ravel(), v_a.ravel(), v_b.ravel()]), rhs.ravel(), rhs.ravel())


def _travelled(steps: np.ndarray) -> np.ndarray:
    """(N,) [s]: the weights of v_1..v_N in the distance travelled from now to step N,
    Σ_k h_k (v_k + v_{k+1})/2 (v_0's share aside)."""
    return 0.5 * (steps + np.concatenate([steps[1:], [0.0]]))


def rss_bounds(step: StepData) -> np.ndarray:
    """Upper bounds (3,) of the RSS terminal disjunction's binaries (behind, left, right): a side
    the ego may not be beside the vehicle ahead on is switched off (every disjunct holds when
    the disjunction is not in use: :func:`_rss_mode`)."""
    rss = step.rss
    if rss is None:
        return np.zeros(0)
    if _rss_mode(step) != "choice":
        return np.ones(3)
    return np.array([1.0, float(rss.sides[0]), float(rss.sides[1])])


def _rss_mode(step: StepData) -> str:
    """How the RSS terminal is written this step: ``"none"`` (no vehicle ahead: every RSS row
    holds), ``"behind"`` (no side free: the behind rows as plain rows, the disjunction idle, so
    the mode search's lower bound keeps them) or ``"choice"`` (the disjunction)."""
    rss = step.rss
    if rss is None or not rss.active:
        return "none"
    return "choice" if any(rss.sides) else "behind"


def guard_values(step: StepData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The ``guard`` block's triplet values (in :func:`_guards`' order) and row bounds (lo, hi)."""
    N = step.A.shape[0]
    h = step.h_bar[1:]
    n_hat = np.stack([-np.sin(h), np.cos(h)], axis=1)
    base = np.einsum("kj,kj->k", n_hat, step.p_bar[1:])
    tm = step.term
    trav = _travelled(step.steps)
    if tm.active:  # v_N + κ·(distance travelled) ≤ κ·(s_line − margin − s_0) + offset
        w = tm.slope * trav
        w[-1] += 1.0
        term_hi = tm.slope * (tm.s_line - tm.margin - float(step.s_bar[0]) - 0.5 * step.steps[0] * float(step.x0[3])) \
            + tm.offset
    else:
        w, term_hi = np.zeros(N), 1.0
    vals = [n_hat.ravel(), w]
    lo = [step.e_lo + base, [-np.inf]]
    hi = [step.e_hi + base, [term_hi]]
    rss = step.rss
    if rss is not None:  # RSS at step N: K plain behind rows, then the disjunction behind | left | right
        K = len(rss.slope)
        mode = _rss_mode(step)
        coef = np.broadcast_to(-trav, (K, N)).copy()  # behind: bound − slope·v_N − Σ w v ≥ 0
        coef[:, -1] -= rss.slope
        if mode == "behind":
            vals.append(coef.ravel())
            lo.append(-rss.bound)
        else:
            vals.append(np.zeros(K * N))
            lo.append(np.full(K, -1.0))
        if mode == "choice":  # each disjunct's rows relaxed by its M when its binary is 0
            v_hi = step.hi[:, 3]
            m_b = np.maximum(0.0, rss.slope * v_hi[-1] + trav @ v_hi - rss.bound) + 1.0
            a, c = n_hat * step.lo[:, :2], n_hat * step.hi[:, :2]
            e_min, e_max = np.minimum(a, c).sum(axis=1), np.maximum(a, c).sum(axis=1)  # n̂ᵀp over the box
            left, right = np.nan_to_num(rss.left), np.nan_to_num(rss.right)  # NaN: free (0 ≥ −1)
            m_l = np.maximum(0.0, left + base - e_min) + 1.0
            m_r = np.maximum(0.0, e_max - right - base) + 1.0
            side = [np.where(np.isfinite(at)[:, None], np.column_stack([sign * n_hat, -m]), 0.0).ravel()
                    for at, sign, m in ((rss.left, 1.0, m_l), (rss.right, -1.0, m_r))]
            vals += [np.column_stack([coef, -m_b]).ravel(), *side, np.ones(3)]
            lo += [-rss.bound - m_b, np.where(np.isfinite(rss.left), left + base - m_l, -1.0),
                   np.where(np.isfinite(rss.right), -(right + base) - m_r, -1.0), [1.0]]
        else:  # every disjunct holds
            vals += [np.zeros(K * (N + 1) + 6 * N), np.ones(3)]
            lo += [np.full(K + 2 * N, -1.0), [1.0]]
        hi += [np.full(2 * K + 2 * N + 1, np.inf)]
    return np.concatenate(vals), np.concatenate(lo), np.concatenate(hi)


def _guards(b: ModelBuilder, step: StepData, lay: Layout) -> None:
    N = lay.x.shape[0]
    rows = [np.repeat(np.arange(N), 2), np.full(N, N)]
    cols = [lay.x[:, :2].ravel(), lay.x[:, 3]]
    n_rows = N + 1
    rss = step.rss
    if rss is not None:
        K = len(rss.slope)
        r0 = N + 1 + K  # the disjunction's first row, after the plain behind rows
        rl, rr, rc = r0 + K, r0 + K + N, r0 + K + 2 * N  # its left rows, right rows (one per step), cover row
        side_cols = np.column_stack([lay.x[:, :2], np.zeros(N, np.int64)])
        left, right = side_cols.copy(), side_cols
        left[:, 2], right[:, 2] = lay.rss[1], lay.rss[2]
        rows += [np.repeat(N + 1 + np.arange(K), N), np.repeat(r0 + np.arange(K), N + 1),
                 np.repeat(rl + np.arange(N), 3), np.repeat(rr + np.arange(N), 3), np.full(3, rc)]
        cols += [np.tile(lay.x[:, 3], K), np.tile(np.append(lay.x[:, 3], lay.rss[0]), K), left.ravel(), right.ravel(),
                 lay.rss]
        n_rows += 2 * K + 2 * N + 1
    vals, lo, hi = guard_values(step)
    g = b.add_rows("guard", n_rows, np.concatenate(rows), np.concatenate(cols), vals, lo, hi)
    if rss is not None:
        b.add_disjunction(Disjunction(len(b.disjunctions), lay.rss.copy(), (g[r0:rl], g[rl:rr], g[rr:rc]), int(g[rc]),
                                      label="rss terminal: behind | left | right"))


@dataclass(frozen=True, eq=False)
class _CostShape:
    """The parts of the cost that depend only on (H, weights, n): residual matrix, weights, Hessian."""

    F: sp.csr_matrix
    w: np.ndarray
    P: sp.csc_matrix
    FtW: sp.csr_matrix  # Fᵀ diag(w)
    Ft: sp.csr_matrix  # Fᵀ: FtW's pattern, for other row weights
    to_P: sp.csr_matrix  # (nnz P, rows of F): P.data = 2·(to_P @ row weights), for other row weights

    def weighed(self, w_rows: np.ndarray) -> tuple[sp.csc_matrix, sp.csr_matrix]:
        """P and Fᵀ diag(``w_rows``) for other positive row weights (same patterns as ``P`` and
        ``FtW``), from whole arrays: no sparse product per step."""
        P = sp.csc_matrix(((self.to_P @ w_rows) * 2.0, self.P.indices, self.P.indptr), shape=self.P.shape)
        FtW = sp.csr_matrix((self.Ft.data * w_rows[self.Ft.indices], self.Ft.indices, self.Ft.indptr),
                            shape=self.Ft.shape)
        return P, FtW


_COST_CACHE: dict[tuple, _CostShape] = {}


def _widen(cs: _CostShape, n: int) -> _CostShape:
    """The same cost over ``n`` columns (the extra columns — binaries, auxiliaries — cost nothing)."""
    m, n0 = cs.F.shape
    F = sp.csr_matrix((cs.F.data, cs.F.indices, cs.F.indptr), shape=(m, n))
    P = sp.csc_matrix((cs.P.data, cs.P.indices, np.concatenate([cs.P.indptr, np.full(n - n0, cs.P.indptr[-1])])),
                      shape=(n, n))
    FtW, Ft = (sp.csr_matrix((a.data, a.indices, np.concatenate([a.indptr, np.full(n - n0, a.indptr[-1])])),
                             shape=(n, m)) for a in (cs.FtW, cs.Ft))
    return _CostShape(F, cs.w, P, FtW, Ft, cs.to_P)


def _cost_shape(lay: Layout, w: Weights, n: int, span: tuple[float, ...]) -> _CostShape:
    """The cost's matrices over ``n`` columns; built once over the state and input columns (which
    come first) and widened per column count, so a new number of binaries costs no rebuild.
    ``span`` (N,): each step's length in periods, which weighs its terms."""
    H = lay.x.shape[0]
    key = (H, w, n, int(lay.x[0, 0]), int(lay.u[0, 0]), span)
    hit = _COST_CACHE.get(key)
    if hit is not None:
        return hit
    n0 = int(max(lay.x.max(), lay.u.max())) + 1
    base_key = (H, w, n0, int(lay.x[0, 0]), int(lay.u[0, 0]), span)
    base = _COST_CACHE.get(base_key)
    if base is None:
        base = _base_cost_shape(lay, w, n0, np.asarray(span))
        _COST_CACHE[base_key] = base
    out = base if n == n0 else _widen(base, n)
    if len(_COST_CACHE) > 64:
        _COST_CACHE.clear()
        _COST_CACHE[base_key] = base
    _COST_CACHE[key] = out
    return out


def _base_cost_shape(lay: Layout, w: Weights, n: int, span: np.ndarray) -> _CostShape:
    H = lay.x.shape[0]
    nu = 2 * H
    ucols = lay.u.ravel()
    r = np.arange(nu)
    F_u = sp.csr_matrix((np.ones(nu), (r, ucols)), shape=(nu, n))
    rd = np.concatenate([r, r[2:]])
    cd = np.concatenate([ucols, ucols[:-2]])
    vd = np.concatenate([np.ones(nu), -np.ones(nu - 2)])
    F_du = sp.csr_matrix((vd, (rd, cd)), shape=(nu, n))
    nx = 4 * H
    F_x = sp.csr_matrix((np.ones(nx), (np.arange(nx), lay.x.ravel())), shape=(nx, n))
    F = sp.vstack([F_u, F_du, F_x]).tocsr()
    wt = np.concatenate([np.full(nu, w.u), np.full(nu, w.du), np.tile(np.asarray(w.track, float), H)])
    wt *= np.concatenate([np.repeat(span, 2), np.repeat(span, 2), np.repeat(span, 4)])  # a coarse step lasts longer
    Hs = (F.T @ sp.diags(2.0 * wt) @ F).tocsc()
    P = sp.triu(Hs).tocsc()
    P.sum_duplicates()
    Ft = F.T.tocsr()
    Ft.sort_indices()
    i = np.repeat(np.arange(n), np.diff(P.indptr))  # P's entries (row P.indices, column i)
    to_P = Ft[P.indices].multiply(Ft[i]).tocsr()  # F_ri·F_rj for entry (i, j), over the rows r of F
    to_P.sort_indices()
    return _CostShape(F, wt, P, (F.T @ sp.diags(wt)).tocsr(), Ft, to_P)


def others_of(step: StepData, P: int) -> np.ndarray:
    """Other vehicles' predicted positions over the trace (n, P+1+H, 2), NaN before now [m]
    (H: the fine part)."""
    hc = step.hc
    H = step.H
    others = np.full((len(hc.index), P + 1 + H, 2), np.nan)
    others[:, P:, :] = hc.xy[:, :H + 1]
    return others


def _cost(model: MilpModel, step: StepData, lay: Layout, w: Weights) -> None:
    """Put the paper's cost into ``model`` (P shared between models of the same shape)."""
    H = lay.x.shape[0]
    cs = _cost_shape(lay, w, model.n_cols, tuple(step.steps / step.steps[0]))
    nu = 2 * H
    g = np.zeros(2 * nu + 4 * H)
    g[nu:nu + 2] = step.u_prev
    g[2 * nu:] = step.omega.ravel()
    w_rows, P, FtW = cs.w, cs.P, cs.FtW
    scale = np.ones_like(cs.w)
    if step.steer_weight is not None:  # the steering in the lateral acceleration it causes
        g[0:nu:2] = step.steer_ref
        scale[0:nu:2] = scale[nu:2 * nu:2] = step.steer_weight
    if step.head_weight is not None:  # passing over the oncoming lane: the heading in the lateral velocity it causes
        scale[2 * nu + 2::4] = step.head_weight
    if step.steer_weight is not None or step.head_weight is not None:
        w_rows = cs.w * scale
        P, FtW = cs.weighed(w_rows)
    model.P = P
    model.q = model.q - 2.0 * (FtW @ g)
    model.c0 = model.c0 + float(w_rows @ (g * g))
    model.residuals = Residuals(cs.F, g, w_rows)


def set_cost(model: MilpModel, step: StepData, lay: Layout, w: Weights) -> None:
    """Replace the cost of ``model`` (built by :func:`assemble`) by this step's, in place."""
    model.q = np.zeros(model.n_cols)
    model.c0 = 0.0
    _cost(model, step, lay, w)


def assemble(
    step: StepData, rules: StepRules, settings: MPCSettings, params: BicycleParams, *,
    cache: PatternCache | None = None, stable: bool = False, keep: np.ndarray | None = None, recover: bool = True,
) -> Assembled:
    """Build the step's model (dynamics, cost, guards over the look-ahead of ``step``; every
    requirement's MILCs over its fine part) with the weights and margin ``eps`` of ``settings``. ``stable``: the encoder's stable
    mode (a structure that :mod:`twolevel.control.high_level.template` can refresh), with
    vehicle–step pairs kept within d + ``settings.pad`` [m] (or the pair codes ``keep``).
    ``recover``: a rule already false now by known signals is required from the first step the
    plan can change (``MIL517`` warning) instead of making the step infeasible."""
    N, H, P = step.N, step.H, rules.P
    b = ModelBuilder()
    xb = b.add_vars("x", 4 * N, step.lo.ravel(), step.hi.ravel())
    u_lo, u_hi = input_bounds(step, params)
    ub = b.add_vars("u", 2 * N, u_lo.ravel(), u_hi.ravel())
    rb = b.add_vars("rss", 3, 0.0, rss_bounds(step), integer=True).idx if step.rss is not None else np.zeros(0, np.int64)
    lay = Layout(xb.idx.reshape(N, 4), ub.idx.reshape(N, 2), P, H, rb)
    _dynamics(b, step, lay)
    _guards(b, step, lay)
    sigs = trace_signals(step, lay, b.n_cols, rules.past, rules.names | {"x", "y"})
    hc = step.hc
    T = P + 1 + H
    others = others_of(step, P)
    cf = collision_free_builtin("x", "y", others, ids=np.asarray(hc.index, np.int64), pad=settings.pad, keep=keep)
    enc = encode(b, rules.requirements, sigs, settings.dt, eps=settings.eps, length=T,
                 builtins={"collision_free": cf}, stable=stable, recover=recover, recover_after=rules.recover_after,
                 margins=dict(settings.margins))
    model = b.build(cache)
    _cost(model, step, lay, settings.weights)
    diags = list(enc.diagnostics)
    for name, t, t2 in enc.recovered:
        diags.append(MIL517(f"t = {step.t:.2f} s: rule '{name}' is already violated by known signals; "
                            f"required from step k = {t2 - P} of the horizon on (recovering)", Span("<mpc>"),
                            hint="the plan restores the rule as fast as the dynamics allow"))
    return Assembled(model, lay, enc, sigs, diags)


def input_bounds(step: StepData, params: BicycleParams) -> tuple[np.ndarray, np.ndarray]:
    """Bounds (H, 2) of the inputs [δ rad, a m/s²]: the steering bound of the step (the lateral
    acceleration limit at speed, :func:`twolevel.control.high_level.linearisation.steering_bound`) and the
    acceleration limits."""
    H = step.A.shape[0]
    d = np.full(H, params.delta_max) if step.delta_hi is None else step.delta_hi
    return (np.stack([-d, np.full(H, params.a_min)], axis=1), np.stack([d, np.full(H, params.a_max)], axis=1))


def shape_key(m: MilpModel) -> tuple:
    """What must match for a backend built on one model to be reused for another (values aside)."""
    return (id(m.pattern), m.n_rows, m.n_cols,
            (m.row_lo == m.row_hi).tobytes(), np.isfinite(m.row_lo).tobytes(), np.isfinite(m.row_hi).tobytes(),
            np.isfinite(m.lb).tobytes(), np.isfinite(m.ub).tobytes(), m.integrality.tobytes(),
            tuple((d.cover_row, d.guard, d.binaries.tobytes()) for d in m.disjunctions))
