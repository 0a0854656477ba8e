"""Write drive.csv: a 10 s recorded drive at dt = 0.1 s (deterministic, no randomness).

The ego cruises at 12 m/s under a 13.9 m/s (50 km/h) limit, surges to 15 m/s around t = 4.5 s
(briefly above the limit plus its 0.5 m/s tolerance, so rules/speed_limit.stl is violated), and
follows a lead car at 12 m/s. A traffic light 150 m ahead is red from 6 s to 8 s; the next stop
line is 200 m ahead, so the red-light and stop-sign rules hold. ``min_gap`` is the bounding-box
separation to the lead car (gap minus a 4.22 m car length).

Run: ``python examples/monitor/make_drive.py`` (rewrites drive.csv next to this file).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

DT = 0.1  # [s]
N = 100


def main() -> None:
    t = np.arange(N) * DT
    v = 12.0 + 3.0 * np.exp(-(((t - 4.5) / 0.5) ** 2))  # ego speed [m/s]
    s = np.concatenate(([0.0], np.cumsum(v[:-1] * DT)))  # distance driven [m]
    v_lead = np.full(N, 12.0)
    d_lead = 30.0 + np.concatenate(([0.0], np.cumsum((v_lead - v)[:-1] * DT)))  # gap [m]
    columns = {
        "t": t,
        "v": v,
        "v_max": np.full(N, 13.9),
        "d_stop": 200.0 - s,
        "light_red": ((t >= 6.0) & (t < 8.0)).astype(float),
        "d_light": 150.0 - s,
        "d_lead": d_lead,
        "v_lead": v_lead,
        "min_gap": d_lead - 4.22,
    }
    lines = [",".join(columns)]
    for k in range(N):
        lines.append(",".join(f"{columns[c][k]:.1f}" if c == "t" else f"{columns[c][k]:.4f}" for c in columns))
    Path(__file__).with_name("drive.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
