"""Start-up cost of `twolevel check` (the aim: well under 0.5 s for one file), printed, not asserted.

Each figure is the best of 5 fresh processes (lark's parse tables cached on disk by a first run):
importing the parser and parsing one rule file; `twolevel check` on one rule file; on the whole
shipped tree (rules, maps, scenarios).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def best_of(cmd: list[str], n: int = 5) -> float:
    subprocess.run(cmd, cwd=ROOT, capture_output=True)  # warm the disk caches and lark's table cache
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        subprocess.run(cmd, cwd=ROOT, capture_output=True)
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    py = sys.executable
    parse = "from twolevel.stl.parser import parse; parse(open('rules/speed_limit.stl').read(), 'x')"
    rows = [
        ("python start-up alone", best_of([py, "-c", "pass"])),
        ("import parser + parse one file", best_of([py, "-c", parse])),
        ("twolevel check rules/speed_limit.stl", best_of([py, "-m", "twolevel", "check", "rules/speed_limit.stl"])),
        ("twolevel check rules/ maps/ scenarios/", best_of([py, "-m", "twolevel", "check", "rules/", "maps/", "scenarios/"])),
    ]
    print(f"machine: {os.cpu_count()} cpus, {platform.processor() or platform.machine()}, "
          f"load {os.getloadavg()[0]:.2f}, python {platform.python_version()}")
    base = rows[0][1]
    for label, t in rows:
        print(f"{label:42s} {t * 1000:7.1f} ms   ({t / base:4.1f}x python start-up)")


if __name__ == "__main__":
    main()
