"""Batched rollouts of the detailed four-wheel model: the low-level controller's hot path.

``rollout(x0, controls (K, H, 2) of [δ, γ], dt, params)`` simulates K candidate control
sequences over H steps at once and returns their states and oriented bounding boxes;
:func:`rollout_accel` takes [δ, a] (the MPC's outputs) and turns each a into γ through
:func:`twolevel.models.actuation.gamma_from_accel` at the speed the car has at that step.

Backends (same equations, :mod:`twolevel.models.fourwheel`, agree to 1e-12):

- ``"casadi"``: one control step (its internal steps, the commands held) as a casadi function,
  compiled to machine code with the system C compiler (casadi's code generator, gcc -O2 in a
  subprocess) once per parameter set and step length, then ``mapaccum`` over the horizon and
  ``map`` over the K candidates, called through a casadi buffer on the arrays' memory (no
  conversion to casadi matrices). The loop over the internal steps runs in the compiled code, not
  in casadi's virtual machine: the same arithmetic in the same order, so the states are those of
  compiling one internal step and letting casadi call it per substep, bit for bit
  (``-ffp-contract=off``: no fused multiply-adds on any platform), at about half the time for the
  few-candidate, short-horizon rollouts of the fail-safes (``benchmarks/rollout.py``). Without a
  working compiler it falls back to casadi's SX virtual machine (≈ 3× slower).
- ``"numpy"``: the substep vectorised over K, looping over H × substeps in Python.

``"auto"`` (the default) is casadi, compiled when possible. Measured on this 2-core machine
(H = 10, dt = 0.1 s, h = 5 ms, i.e. 200 substeps; ``benchmarks/rollout.py``; ranges over runs
with other jobs sharing the cores), compiled / VM / numpy: K = 1: 0.18–0.35 / 0.44–0.8 /
53–126 ms; K = 64: 7.4–16.5 / 26–37 / 60–170 ms; K = 256: 28–57 / 102–224 / 82–223 ms.
The first call per (parameters, dt, H, K) builds the functions (≈ 0.3 s with the compile).
"""

from __future__ import annotations

import contextlib
import functools
import os
import secrets
import subprocess
import tempfile
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twolevel.models import fourwheel as fw
from twolevel.models.actuation import gamma_from_accel
from twolevel.models.obb import box_corners
from twolevel.models.ops import NP, casadi_ops
from twolevel.models.params import VehicleParams

__all__ = ["Rollout", "rollout", "rollout_accel", "Backend", "compiled_available"]

Backend = Literal["auto", "casadi", "casadi-vm", "numpy"]
_DEFAULT = VehicleParams()


@dataclass(frozen=True)
class Rollout:
    """K simulated trajectories of H steps of a car ``length`` × ``width`` [m].

    states: (K, H+1, 12) detailed-model states (see :mod:`twolevel.models.fourwheel`), states[:, 0] = x0.
    """

    states: NDArray[np.float64]
    length: float
    width: float

    @functools.cached_property
    def boxes(self) -> NDArray[np.float64]:
        """(K, H+1, 4, 2) oriented bounding-box corners [m], counter-clockwise from the rear right
        (computed when first asked for: most callers read the states only)."""
        s = self.states
        return box_corners(s[..., 0], s[..., 1], s[..., 2], self.length, self.width)


@functools.lru_cache(maxsize=8)
def _substep_function(p: VehicleParams, h: float, jit: bool) -> Any:
    """casadi Function (x (12), δ, γ) → x after one internal step h [s]; compiled if jit."""
    import casadi as ca

    x = ca.SX.sym("x", fw.NX)
    delta = ca.SX.sym("delta")
    gamma = ca.SX.sym("gamma")
    cols = fw.substep([x[i] for i in range(fw.NX)], delta, gamma, h, p, casadi_ops())
    f = ca.Function("fourwheel_substep", [x, delta, gamma], [ca.vertcat(*cols)])
    return _compiled(f) if jit else f


def _compiled(fn: Any) -> Any:
    """``fn`` as C (casadi's code generator) compiled by the system C compiler (gcc -O2) into a
    shared object and loaded back (``casadi.external``). The compiler runs as a subprocess in
    its own session, not through casadi's JIT: that runs it with ``system()``, which ignores
    SIGINT meanwhile and so discards a Ctrl-C, and a terminal's Ctrl-C would kill the compiler
    (the run stops at its next checkpoint instead, :mod:`twolevel.interruption`). The files are
    written in this user's private build directory (never the working directory) and removed
    once loaded."""
    import casadi as ca

    build = _jit_dir()
    stem = f"{fn.name()}_{os.getpid()}_{secrets.token_hex(4)}"
    c_file, so_file = os.path.join(build, stem + ".c"), os.path.join(build, stem + ".so")
    try:
        gen = ca.CodeGenerator(stem + ".c")
        gen.add(fn)
        gen.generate(build + os.sep)
        subprocess.run(["gcc", "-O2", "-ffp-contract=off", "-fPIC", "-shared", c_file, "-o", so_file, "-lm"],
                       check=True, capture_output=True, start_new_session=True, timeout=600)
        return ca.external(fn.name(), so_file)
    finally:
        for path in (c_file, so_file):
            with contextlib.suppress(OSError):
                os.unlink(path)


@functools.lru_cache(maxsize=1)
def _jit_dir() -> str:
    """This user's private directory for casadi's JIT files (file names are unique per build)."""
    path = os.path.join(tempfile.gettempdir(), f"twolevel-jit-{os.getuid()}")
    os.makedirs(path, mode=0o700, exist_ok=True)
    st = os.stat(path)
    if st.st_uid != os.getuid() or st.st_mode & 0o077:  # not ours, or open to others: use a fresh one
        path = tempfile.mkdtemp(prefix="twolevel-jit-")
    return path


@functools.lru_cache(maxsize=1)
def compiled_available() -> bool:
    """Whether casadi can JIT-compile with the system C compiler here (tried once)."""
    try:
        f = _substep_function(_DEFAULT, 0.005, True)
        out = np.asarray(f(fw.initial_state(v=5.0), 0.0, 0.0)).ravel()
        return bool(np.all(np.isfinite(out)))
    except Exception:  # no compiler, or it failed: use the virtual machine
        return False


def _substeps(sub: Any, n: int, x: Any, delta: Any, gamma: Any) -> Any:
    """The state (MX) after ``n`` calls of the substep function ``sub`` from ``x``, the commands held."""
    import casadi as ca

    ones = ca.DM.ones(1, n)
    return sub.mapaccum("substeps", n)(x, delta @ ones, gamma @ ones)[:, -1]


@functools.lru_cache(maxsize=8)
def _step_function(p: VehicleParams, dt: float, jit: bool) -> Any:
    """casadi Function (x (12), δ, γ) → x after one control step ``dt`` [s], i.e. its internal
    steps with the commands held; compiled as one C function (the loop over the internal steps
    inside it) if jit."""
    import casadi as ca

    n = fw.substeps_per_step(dt, p)
    x, delta, gamma = ca.MX.sym("x", fw.NX), ca.MX.sym("delta"), ca.MX.sym("gamma")
    x_next = _substeps(_substep_function(p, dt / n, False), n, x, delta, gamma)
    f = ca.Function("fourwheel_step", [x, delta, gamma], [x_next])
    return _compiled(f) if jit else f


@functools.lru_cache(maxsize=128)  # the fail-safes roll the manoeuvres still moving: K varies
def _batch_function(p: VehicleParams, dt: float, H: int, K: int, accel: bool, jit: bool, fused: bool = True) -> Any:
    """casadi Function (x0 (12×K), U (2×HK)) → states (12×HK), columns k-major per candidate.
    ``fused``: each control step is one call of :func:`_step_function`; else (the reference the
    benchmark and the tests compare with) casadi's virtual machine calls the one-substep function
    (compiled if jit) for every internal step."""
    import casadi as ca

    x = ca.MX.sym("x", fw.NX)
    u = ca.MX.sym("u", 2)
    gamma = gamma_from_accel(u[1], x[3], p, casadi_ops()) if accel else u[1]
    if fused:
        x_next = _step_function(p, dt, jit)(x, u[0], gamma)
    else:
        n = fw.substeps_per_step(dt, p)
        x_next = _substeps(_substep_function(p, dt / n, jit), n, x, u[0], gamma)
    step = ca.Function("fourwheel_step", [x, u], [x_next])
    horizon = step.mapaccum("horizon", H)
    return horizon.map(K) if K > 1 else horizon


def _prepare(x0: ArrayLike, controls: ArrayLike) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    u = np.asarray(controls, dtype=float)
    if u.ndim == 2:
        u = u[None]
    if u.ndim != 3 or u.shape[-1] != 2:
        raise ValueError(f"controls must be (K, H, 2), got {np.shape(controls)}")
    x = np.asarray(x0, dtype=float)
    if x.shape[-1] != fw.NX:
        raise ValueError(f"x0 must have {fw.NX} components (see fourwheel.py), got {x.shape}")
    return np.array(np.broadcast_to(x, (u.shape[0], fw.NX))), u


def _simulate(x0: ArrayLike, controls: ArrayLike, dt: float, p: VehicleParams, backend: Backend,
              accel: bool, fused: bool = True) -> Rollout:
    x, u = _prepare(x0, controls)
    K, H, _ = u.shape
    if backend == "numpy":
        states = _simulate_numpy(x, u, dt, p, accel)
    elif backend in ("auto", "casadi") and compiled_available():
        states = _simulate_buffered(_batch_function(p, float(dt), H, K, accel, True, fused), x, u)
    elif backend in ("auto", "casadi", "casadi-vm"):
        f = _batch_function(p, float(dt), H, K, accel, False, fused)
        res = f(x.T, u.reshape(K * H, 2).T)
        if not hasattr(res, "full"):  # symbolic: casadi's overload dispatch swallowed a signal raised in
            from twolevel import interruption  # the numeric call and tried the symbolic overloads

            interruption.checkpoint()  # the signal, as the interruption it is
            raise RuntimeError("the compiled rollout returned a symbolic result")
        out = np.asarray(res.full())  # (12, K·H)
        states = np.concatenate([x[:, None, :], out.reshape(fw.NX, K, H).transpose(1, 2, 0)], axis=1)
    else:
        raise ValueError(f"unknown backend {backend!r}")
    return Rollout(states, p.length, p.width)


def _simulate_buffered(f: Any, x: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """The states (K, H+1, 12) of the batch function ``f`` (:func:`_batch_function`'s) from ``x``
    (K, 12) under ``u`` (K, H, 2), called through a casadi buffer on the arrays' memory: a (K, 12)
    array in C order is the 12×K matrix in casadi's column-major order, and so on (no casadi
    matrices built, no symbolic overloads tried: a signal is raised by Python once the call
    returns)."""
    K, H, _ = u.shape
    xin = np.ascontiguousarray(x)
    uin = np.ascontiguousarray(u.reshape(K * H, 2))
    states = np.empty((K, H + 1, fw.NX))
    states[:, 0] = x
    out = np.empty((K * H, fw.NX))
    buf, call = f.buffer()
    buf.set_arg(0, memoryview(xin))
    buf.set_arg(1, memoryview(uin))
    buf.set_res(0, memoryview(out))
    call()
    states[:, 1:] = out.reshape(K, H, fw.NX)
    return states


def _simulate_numpy(x: NDArray[np.float64], u: NDArray[np.float64], dt: float, p: VehicleParams,
                    accel: bool) -> NDArray[np.float64]:
    n = fw.substeps_per_step(dt, p)
    h = dt / n
    cols = [x[:, i] for i in range(fw.NX)]
    out = [x]
    for k in range(u.shape[1]):
        delta = u[:, k, 0]
        gamma = gamma_from_accel(u[:, k, 1], cols[3], p, NP) if accel else u[:, k, 1]
        for _ in range(n):
            cols = fw.substep(cols, delta, gamma, h, p, NP)
        out.append(np.stack(cols, axis=-1))
    return np.stack(out, axis=1)


def rollout(x0: ArrayLike, controls: ArrayLike, dt: float, params: VehicleParams = _DEFAULT,
            backend: Backend = "auto") -> Rollout:
    """Simulate controls (K, H, 2) of [δ [rad], γ [-]] each held for dt [s] from x0 (12,) or (K, 12)."""
    return _simulate(x0, controls, dt, params, backend, accel=False)


def rollout_accel(x0: ArrayLike, controls: ArrayLike, dt: float, params: VehicleParams = _DEFAULT,
                  backend: Backend = "auto") -> Rollout:
    """As :func:`rollout` with controls of [δ [rad], a [m/s²]]; a → γ by the quasi-static
    inverse actuation map at the start of each step (the speed the car has then)."""
    return _simulate(x0, controls, dt, params, backend, accel=True)
