"""Batched rollout of the detailed four-wheel model: time per call for K candidates.

H = 10, dt = 0.1 s (the paper's), numpy vs casadi (SX virtual machine) vs casadi compiled
(JIT, gcc -O2), median of repeated calls after a warm-up (which includes building/compiling).
Then the compiled path before and after compiling a whole control step (its substeps looped in C)
and calling it through a buffer, side by side: the reference (casadi's virtual machine calling
the compiled substep per substep, the arrays converted to casadi matrices) against the path
``rollout`` takes, on the shapes the fail-safes (few candidates, half-second to few-second
segments) and the low level's sampling (32–64 candidates, H = 10) use; the two give the same
states bit for bit (checked here too). Also times the bicycle linearisation used by the MPC.
Prints figures; not a test.
"""

from __future__ import annotations

import os
import platform
import sys
import time

import numpy as np

from twolevel.models import bicycle, fourwheel as fw
from twolevel.models.params import VehicleParams
from twolevel.models import rollout as ro
from twolevel.models.rollout import compiled_available, rollout

H, DT = 10, 0.1


def _median_ms(fn, repeat: int) -> float:
    fn()  # warm-up: builds and compiles the casadi functions for this K
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def main() -> None:
    p = VehicleParams()
    n = fw.substeps_per_step(DT, p)
    print(f"machine: {os.cpu_count()} cpus, {platform.processor() or platform.machine()}, "
          f"python {sys.version.split()[0]}, numpy {np.__version__}, load {os.getloadavg()[0]:.2f}")
    import casadi

    print(f"casadi {casadi.__version__}, compiled backend available: {compiled_available()}")
    print(f"H = {H}, dt = {DT} s, internal step h = {DT / n * 1e3:.2f} ms ({n} per step, "
          f"{n * H} per rollout), state size {fw.NX}")
    rng = np.random.default_rng(0)
    x0 = fw.initial_state(v=12.0)
    print(f"{'K':>5} {'numpy ms':>10} {'casadi-vm ms':>13} {'compiled ms':>12} {'numpy/compiled':>15} {'vm/compiled':>12}")
    for K in (1, 16, 64, 256):
        u = np.stack([rng.uniform(-0.3, 0.3, (K, H)), rng.uniform(-1, 1, (K, H))], axis=-1)
        rep = 5 if K >= 64 else 15
        t_np = _median_ms(lambda: rollout(x0, u, DT, p, backend="numpy"), max(3, rep // 3))
        t_vm = _median_ms(lambda: rollout(x0, u, DT, p, backend="casadi-vm"), rep)
        t_c = _median_ms(lambda: rollout(x0, u, DT, p, backend="casadi"), rep)
        print(f"{K:>5} {t_np:>10.2f} {t_vm:>13.2f} {t_c:>12.2f} {t_np / t_c:>15.1f} {t_vm / t_c:>12.1f}")
    if compiled_available():
        _fused(p, rng)
    xs = np.c_[rng.normal(size=(H, 3)), rng.uniform(0, 20, H)]
    us = np.c_[rng.uniform(-0.4, 0.4, H), rng.uniform(-5, 3, H)]
    t_lin = _median_ms(lambda: bicycle.linearize(xs, us, DT), 2000)
    print(f"bicycle.linearize, H = {H}: {t_lin * 1e3:.1f} µs")


def _reference(x0: np.ndarray, u: np.ndarray, p: VehicleParams) -> np.ndarray:
    """The compiled rollout before: the per-substep batch function called on casadi matrices."""
    x = np.array(np.broadcast_to(x0, (u.shape[0], fw.NX)))
    K, Hk, _ = u.shape
    f = ro._batch_function(p, DT, Hk, K, False, True, False)
    out = np.asarray(f(x.T, u.reshape(K * Hk, 2).T).full())
    return np.concatenate([x[:, None, :], out.reshape(fw.NX, K, Hk).transpose(1, 2, 0)], axis=1)


def _fused(p: VehicleParams, rng: np.random.Generator) -> None:
    print("compiled rollout, before (per-substep calls, casadi matrices) and after (one compiled step, buffer):")
    print(f"{'K':>5} {'H':>4} {'before ms':>10} {'after ms':>9} {'before/after':>13}  same bits")
    x0 = fw.initial_state(v=20.0)
    for K, Hk in ((1, 5), (3, 5), (1, 10), (3, 20), (2, 60), (32, 10), (64, 10)):
        u = np.stack([rng.uniform(-0.2, 0.2, (K, Hk)), rng.uniform(-1, 0.5, (K, Hk))], axis=-1)
        rep = 7 if K * Hk >= 300 else 41
        same = np.array_equal(_reference(x0, u, p), rollout(x0, u, DT, p).states)
        t_b = _median_ms(lambda: _reference(x0, u, p), rep)
        t_a = _median_ms(lambda: rollout(x0, u, DT, p), rep)
        print(f"{K:>5} {Hk:>4} {t_b:>10.3f} {t_a:>9.3f} {t_b / t_a:>13.2f}  {same}")


if __name__ == "__main__":
    main()
