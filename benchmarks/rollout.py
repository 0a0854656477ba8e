"""Batched rollout of the detailed four-wheel model: time per call for K candidates.

H = 10, dt = 0.1 s (the paper's), numpy vs casadi (SX virtual machine) vs casadi compiled
(JIT, gcc -O2), median of repeated calls after a warm-up (which includes building/compiling).
Also times the bicycle linearisation used by the MPC. Prints figures; not a test.
"""

from __future__ import annotations

import os
import platform
import sys
import time

import numpy as np

from twolevel.models import bicycle, fourwheel as fw
from twolevel.models.params import VehicleParams
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
          f"python {sys.version.split()[0]}, numpy {np.__version__}")
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
    xs = np.c_[rng.normal(size=(H, 3)), rng.uniform(0, 20, H)]
    us = np.c_[rng.uniform(-0.4, 0.4, H), rng.uniform(-5, 3, H)]
    t_lin = _median_ms(lambda: bicycle.linearize(xs, us, DT), 2000)
    print(f"bicycle.linearize, H = {H}: {t_lin * 1e3:.1f} µs")


if __name__ == "__main__":
    main()
