"""How long `twolevel report` takes on a long synthetic run (6000 steps = 10 min at dt 0.1 s,
4 rules, up to 18 nearby vehicles), and how big its outputs are. Prints figures; not a test."""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from twolevel.report.build import build_report
from twolevel.report.metrics import compute_metrics
from twolevel.sim.trace import BASE_COLUMNS, TraceWriter, read_run

RULES = ("speed_limit", "stop_sign", "red_light", "collision")


def make_run(run_dir: Path, n: int, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.1
    v = 8 + 3 * np.sin(t / 20)
    x = np.cumsum(v * 0.1)
    near = (9 + 9 * np.sin(t / 50)).round()
    gap = 3 + 2 * np.sin(t / 7)
    high, low = rng.gamma(4, 1.0, n), rng.gamma(3, 0.5, n)
    states = np.array(["none", "green", "yellow", "red"])[(t // 15).astype(int) % 4]
    meta = {"scenario": {"name": "bench"}, "settings": {"dt": 0.1}, "seed": seed,
            "map_lines": [[[-50.0, y], [float(x[-1]) + 50, y]] for y in (-1.75, 1.75, 5.25)]}
    with TraceWriter(run_dir, BASE_COLUMNS + tuple(f"rob_{r}" for r in RULES), meta, flush_every=1000) as w:
        for k in range(n):
            w.write({"t": t[k], "x": x[k], "y": 0.0, "v": v[k], "decision": "mpc" if k % 50 else "sampled",
                     "t_high_ms": high[k], "t_low_ms": low[k], "t_step_ms": high[k] + low[k] + 0.2, "n_near": near[k],
                     "min_dist": gap[k] + 4.22, "min_gap": gap[k], "tracking_error": 0.1 * abs(np.sin(t[k])),
                     "v_max": 10.0, "light_state": states[k], **{f"rob_{r}": np.sin(t[k] / (j + 3)) for j, r in enumerate(RULES)}})
    with open(run_dir / "frames.jsonl", "w", encoding="utf-8") as fh:
        for k in range(n):
            others = [[x[k] + 8 * (i - 9), 3.5 * (i % 2), 0.0, 4.22, 1.8] for i in range(int(near[k]))]
            fh.write(json.dumps({"t": t[k], "ego": [x[k], 0.0, 0.0, 4.22, 1.8], "plan": [[x[k] + j, 0.0] for j in range(10)],
                                 "others": others, "lights": [{"x": 100.0, "y": 3.0, "state": str(states[k])}]}) + "\n")


def main(n: int = 6000) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        run_dir = Path(tmp) / "run"
        make_run(run_dir, n)
        t0 = time.perf_counter()
        run = read_run(run_dir)
        t1 = time.perf_counter()
        compute_metrics(run)
        t2 = time.perf_counter()
        build_report(run_dir, gif=False)
        t3 = time.perf_counter()
        figs = sum(p.stat().st_size for p in (run_dir / "figures").iterdir())
        build_report(run_dir, gif=True, formats=())
        t4 = time.perf_counter()
        size = {p.name: p.stat().st_size for p in run_dir.iterdir() if p.is_file()}
        print(f"steps {n}")
        print(f"read_run          {1000 * (t1 - t0):8.1f} ms")
        print(f"compute_metrics   {1000 * (t2 - t1):8.1f} ms")
        print(f"report, no GIF    {1000 * (t3 - t2):8.1f} ms  (9 figures × png+svg, html, summaries)")
        print(f"report with GIF   {1000 * (t4 - t3):8.1f} ms  (figures embedded only, 200-frame GIF)")
        print(f"report.html {size['report.html'] / 1e6:.2f} MB, animation.gif {size['animation.gif'] / 1e6:.2f} MB, figures {figs / 1e6:.2f} MB")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 6000)
