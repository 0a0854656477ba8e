"""HiGHS backend (highspy): MILP and LP from whole arrays, status mapping, time limit, MIP start.

highspy is imported lazily, on first solve. The model goes in through one ``passModel`` call
with the CSC arrays of :class:`~twolevel.milp.model.MilpModel`; a quadratic cost is not passed
(HiGHS's QP solver failed on most of the MPC's polish QPs when it was tried): turn it into its L1
counterpart first (:func:`twolevel.milp.l1_surrogate.l1_surrogate`) or use
:mod:`twolevel.milp.clarabel`.
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
import threading
import time
from pathlib import Path
from typing import Iterator

import numpy as np

from twolevel.milp.model import MilpModel
from twolevel.milp.solution import Capabilities, Solution, Status

__all__ = ["CAPABILITIES", "solve_highs", "write_model"]

CAPABILITIES = Capabilities("highs", integer=True, quadratic=False, mip_start=True, export=True)


def _highs():
    import highspy  # lazy: heavy

    return highspy


_FD_LOCK = threading.Lock()


@contextlib.contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """Send what C code writes to file descriptor 1 (stdout) to descriptor 2 (stderr) meanwhile.

    highspy (1.16) prints its banner to stdout when a ``Highs`` object is built, before any
    option can silence it; stdout carries the commands' JSON. A lock serialises the swap between
    threads of this process (output of other threads meanwhile goes to stderr too)."""
    with _FD_LOCK:
        try:
            if sys.stdout is not None:
                sys.stdout.flush()
            saved = os.dup(1)
        except (OSError, ValueError):  # no stdout to protect (closed)
            yield
            return
        try:
            os.dup2(2, 1)
        except OSError:  # no stderr either: drop the output
            null = os.open(os.devnull, os.O_WRONLY)
            os.dup2(null, 1)
            os.close(null)
        try:
            yield
        finally:
            _flush_c_stdio()
            os.dup2(saved, 1)
            os.close(saved)


@functools.cache
def _libc():  # type: ignore[no-untyped-def]
    """The C library of this process (``None`` where it cannot be reached, e.g. on Windows)."""
    try:
        import ctypes

        return ctypes.CDLL(None)
    except (OSError, TypeError):
        return None


def _flush_c_stdio() -> None:
    """Flush the C library's ``stdout`` buffer (what was written while fd 1 pointed elsewhere
    must go there, not to the restored stdout)."""
    libc = _libc()
    if libc is not None:
        libc.fflush(None)


def _new_highs(highspy):  # type: ignore[no-untyped-def]
    """A ``highspy.Highs`` with logging off, its banner kept off stdout."""
    with _stdout_to_stderr():
        h = highspy.Highs()
        h.setOptionValue("output_flag", False)
    return h


def _status(h, highspy) -> Status:  # type: ignore[no-untyped-def]
    ms = h.getModelStatus()
    S = highspy.HighsModelStatus
    if ms == S.kOptimal:
        return Status.OPTIMAL
    if ms == S.kInfeasible:
        return Status.INFEASIBLE
    if ms in (S.kUnbounded, S.kUnboundedOrInfeasible):
        return Status.UNBOUNDED
    if ms in (S.kTimeLimit, S.kIterationLimit, S.kSolutionLimit, S.kInterrupt):
        return Status.TIME_LIMIT
    if ms == S.kModelEmpty:
        return Status.OPTIMAL
    return Status.ERROR


def _pass(h, model: MilpModel, highspy, relax: bool = False) -> None:  # type: ignore[no-untyped-def]
    A = model.A
    inf = highspy.kHighsInf
    integrality = (np.zeros(model.n_cols, np.int32) if relax
                   else model.integrality.astype(np.int32))
    st = h.passModel(
        int(model.n_cols), int(model.n_rows), int(A.nnz), 1, 1, float(model.c0),
        np.ascontiguousarray(model.q, float),
        np.clip(model.lb, -inf, inf), np.clip(model.ub, -inf, inf),
        np.clip(model.row_lo, -inf, inf), np.clip(model.row_hi, -inf, inf),
        A.indptr.astype(np.int32), A.indices.astype(np.int32), np.ascontiguousarray(A.data, float),
        integrality,
    )
    if st == highspy.HighsStatus.kError:
        raise RuntimeError("HiGHS rejected the model")


def solve_highs(
    model: MilpModel, *, time_limit: float | None = None, mip_start: np.ndarray | None = None,
    mip_gap: float = 1e-6, threads: int = 1, relax: bool = False,
    options: dict[str, object] | None = None,
) -> Solution:
    """Solve the linear part of ``model`` (the quadratic cost, if any, is ignored — see the module
    docstring) with HiGHS. ``time_limit`` [s]; ``mip_start`` a full point (its integer part is
    what matters); ``relax`` drops integrality (the LP relaxation)."""
    highspy = _highs()
    t0 = time.perf_counter()
    h = _new_highs(highspy)
    h.setOptionValue("threads", threads)
    h.setOptionValue("mip_rel_gap", mip_gap)
    h.setOptionValue("random_seed", 0)
    if time_limit is not None:
        h.setOptionValue("time_limit", float(time_limit))
    for k, v in (options or {}).items():
        h.setOptionValue(k, v)
    try:
        _pass(h, model, highspy, relax)
    except RuntimeError as e:
        return Solution(Status.ERROR, None, float("nan"), 0.0, info={"error": str(e)})
    if mip_start is not None:
        idx = np.arange(model.n_cols, dtype=np.int32)
        h.setSolution(int(model.n_cols), idx, np.asarray(mip_start, float))
    t1 = time.perf_counter()
    h.run()
    t2 = time.perf_counter()
    status = _status(h, highspy)
    x = None
    obj = float("nan")
    info = h.getInfo()
    has_point = info.primal_solution_status == highspy.kSolutionStatusFeasible
    if has_point and status in (Status.OPTIMAL, Status.TIME_LIMIT):
        x = np.asarray(h.getSolution().col_value, float)
        obj = float(info.objective_function_value)
    gap = float(getattr(info, "mip_gap", float("nan"))) if model.integrality.any() else 0.0
    return Solution(status, x, obj, (t2 - t1) * 1e3, (t1 - t0) * 1e3, gap,
                    {"nodes": int(getattr(info, "mip_node_count", 0) or 0)})


def write_model(model: MilpModel, path: str | Path) -> None:
    """Write the model's linear part as ``.mps`` or ``.lp`` (by the suffix) via HiGHS, with the
    model's column and row names."""
    highspy = _highs()
    h = _new_highs(highspy)
    _pass(h, model, highspy)
    for j, name in enumerate(model.col_names):
        h.passColName(j, _safe(name))
    for i, name in enumerate(model.row_names):
        h.passRowName(i, _safe(name))
    st = h.writeModel(str(path))
    if st == highspy.HighsStatus.kError:
        raise OSError(f"HiGHS could not write {path}")


def _safe(name: str) -> str:
    return name.replace(" ", "_").replace("[", "(").replace("]", ")")
