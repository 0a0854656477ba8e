"""Writes the scripted participants of the everyday suite (the YAML files beside this one are
committed; this script is how their waypoints were made, and ``--check`` tells whether they still
match it).

A scripted participant follows waypoints {t [s], x [m], y [m]}, linear in between (constant
velocity per piece, :mod:`twolevel.world.traffic`). To stay within the declared assumptions
about others (``twolevel/world/assumptions.py``) a manoeuvre is written as phases of constant
acceleration sampled at the control period (0.1 s) — a change of speed between two waypoints
is then one step's worth of the phase's acceleration — and every track is checked against the
bounds here: vehicles ≤ 1.2 × the limit, |a| ≤ 8 m/s² (driving power-limited above 7.319 m/s:
a ≤ 8 · 7.319 / v), no reversing; pedestrians ≤ 2 m/s, |a| ≤ 0.6 m/s². Pieces of constant
velocity keep only their ends.

    python scenarios/everyday/generate.py [--check]
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
DT = 0.1  # [s] the control period: waypoints of accelerating phases are this far apart


@dataclass(frozen=True)
class Phase:
    """``duration`` [s] at acceleration ``accel`` [m/s²] along the path (speed clamped at 0);
    ``lateral`` [m]: the sideways offset reached at the end of the phase (a smooth lane change,
    None: keep it)."""

    duration: float
    accel: float = 0.0
    lateral: float | None = None


def track(x0: float, y0: float, heading_deg: float, v0: float, phases: list[Phase], until: float, *,
          v_cap: float, a_max: float, v_switch: float = math.inf) -> list[tuple[float, float, float]]:
    """Waypoints (t, x, y) of a straight path from (x0, y0) along ``heading_deg`` at speed ``v0``
    [m/s] through ``phases`` and on at the last speed until ``until`` [s] (a script that ended
    would stop dead), checked against the bounds ``v_cap`` [m/s], ``a_max`` [m/s²] and the power
    limit above ``v_switch`` [m/s]; the lateral offset is to the left of the heading."""
    h = math.radians(heading_deg)
    done = sum(max(1, int(round(ph.duration / DT))) * DT for ph in phases)
    phases = phases + [Phase(max(until + 1.0 - done, DT))]
    ux, uy, nx, ny = math.cos(h), math.sin(h), -math.sin(h), math.cos(h)
    t, s, v, lat = 0.0, 0.0, v0, 0.0
    pts = [(0.0, 0.0, 0.0)]  # (t, s, lateral)
    for ph in phases:
        n = max(1, int(round(ph.duration / DT)))
        lat0, lat1 = lat, lat if ph.lateral is None else ph.lateral
        for k in range(1, n + 1):
            a = ph.accel
            v_new = max(v + a * DT, 0.0)
            a_real = (v_new - v) / DT
            if abs(a_real) > a_max + 1e-9 or (a_real > 0 and a_real > a_max * v_switch / max(v_new, 1e-9) + 1e-9):
                raise ValueError(f"acceleration {a_real:.2f} m/s² at {v_new:.2f} m/s breaks the bounds")
            if v_new > v_cap + 1e-9:
                raise ValueError(f"speed {v_new:.2f} m/s over the bound {v_cap:.2f} m/s")
            s += v * DT  # the simulator holds each piece's velocity over the step
            v = v_new
            t += DT
            lat = lat0 + (lat1 - lat0) * 0.5 * (1 - math.cos(math.pi * k / n))
            pts.append((t, s, lat))
    # keep the ends of pieces of constant velocity only
    keep = [pts[0]]
    for prev, cur, nxt in zip(pts, pts[1:], pts[2:]):
        d1 = (cur[1] - prev[1], cur[2] - prev[2])
        d2 = (nxt[1] - cur[1], nxt[2] - cur[2])
        if abs(d1[0] - d2[0]) > 1e-9 or abs(d1[1] - d2[1]) > 1e-9:
            keep.append(cur)
    keep.append(pts[-1])
    return [(round(tk, 3), round(x0 + sk * ux + lk * nx, 3), round(y0 + sk * uy + lk * ny, 3)) for tk, sk, lk in keep]


def vehicle(x0: float, y0: float, heading_deg: float, v0: float, phases: list[Phase], limit: float, until: float
            ) -> list[tuple[float, float, float]]:
    """A vehicle's waypoints within the default vehicle bounds where the limit is ``limit`` [m/s]."""
    return track(x0, y0, heading_deg, v0, phases, until, v_cap=1.2 * limit, a_max=8.0, v_switch=7.319)


def pedestrian(x0: float, y0: float, heading_deg: float, v0: float, phases: list[Phase], until: float
               ) -> list[tuple[float, float, float]]:
    """A pedestrian's waypoints within the default pedestrian bounds."""
    return track(x0, y0, heading_deg, v0, phases, until, v_cap=2.0, a_max=0.6)


def waypoints_yaml(points: list[tuple[float, float, float]], indent: int = 6) -> str:
    pad = " " * indent
    return "\n".join(f"{pad}- {{t: {t:g}, x: {x:g}, y: {y:g}}}" for t, x, y in points)


def scripted(pid: str, points: list[tuple[float, float, float]], v0: float, box: str = "") -> str:
    """A scripted participant's YAML entry (``v0``: its speed at t = 0, as the prediction reads it;
    ``box``: a flow-style box, or the default)."""
    lines = [f"  - id: {pid}", "    behaviour: scripted", f"    speed: {v0:g}"]
    if box:
        lines.append(f"    box: {box}")
    return "\n".join(lines + ["    waypoints:", waypoints_yaml(points)])


# ------------------------------------------------------------------------------- the scenarios

def cut_in_brake(until: float) -> str:
    # arterial (limit 16.67): the cutter starts 30 m ahead on the left lane at 15 m/s
    wp = vehicle(80.0, 1.75, 0.0, 15.0, [Phase(3.0), Phase(2.5, 0.0, -3.5), Phase(2.0), Phase(2.6, -6.0),
                                          Phase(3.0), Phase(6.0, 2.5)], 16.67, until)
    return scripted("cutter", wp, 15.0)


def cut_in_fast(until: float) -> str:
    # highway (limit 30): 35 m ahead of the ego (25 m/s) on the left lane, cuts in, brakes to 9.6 m/s,
    # drives on at that speed for 4 s, then back up to 24 m/s
    wp = vehicle(75.0, 3.5, 0.0, 25.0, [Phase(2.0), Phase(2.0, 0.0, -3.5), Phase(1.0), Phase(2.2, -7.0), Phase(4.0),
                                         Phase(8.0, 1.8)], 30.0, until)
    return scripted("cutter", wp, 25.0)


def braking_leader_fast(until: float) -> str:
    # highway: 45 m ahead of the ego at 25 m/s, brakes at 7 m/s² to standstill at 3 s, waits, drives off
    wp = vehicle(85.0, 0.0, 0.0, 25.0, [Phase(3.0), Phase(3.6, -7.0), Phase(4.0), Phase(10.0, 2.0)], 30.0, until)
    return scripted("leader", wp, 25.0)


def stop_and_go(until: float) -> str:
    # one lane (limit 12): 30 m ahead at 10 m/s; three times: brake to standstill, wait, drive off
    cycle = [Phase(2.0, -5.0), Phase(2.0), Phase(5.0, 2.0)]
    wp = vehicle(40.0, 0.0, 0.0, 10.0, [Phase(3.0)] + cycle + [Phase(3.0)] + cycle + [Phase(2.0)] + cycle, 12.0, until)
    return scripted("leader", wp, 10.0)


def pedestrian_parked(until: float) -> str:
    # urban street: stands between two parked cars at the kerb (y = -6.0), steps out at 3 s,
    # crosses at up to 1.5 m/s
    wp = pedestrian(92.0, -6.0, 90.0, 0.0, [Phase(3.0), Phase(2.5, 0.6), Phase(6.0), Phase(2.5, -0.6)], until)
    return scripted("walker", wp, 0.0, "{length: 0.5, width: 0.5}")


def pedestrian_crossing(until: float) -> str:
    # urban street: walks up to the kerb 43 m ahead of the ego and across at 1.4 m/s
    wp = pedestrian(53.0, -8.0, 90.0, 1.4, [Phase(14.0), Phase(2.4, -0.58)], until)
    return scripted("walker", wp, 1.4, "{length: 0.5, width: 0.5}")


def tailgater(until: float) -> str:
    # one lane (limit 12): 8 m behind the ego at 11 m/s, never brakes harder than 2 m/s² (it
    # breaks RSS's duty of a follower): when the ego stops for the stalled car it runs into it
    wp = vehicle(2.0, 0.0, 0.0, 11.0, [Phase(4.0), Phase(5.5, -2.0)], 12.0, until)
    return scripted("tailgater", wp, 11.0)


GENERATED = {
    "cut_in_brake": cut_in_brake, "cut_in_fast": cut_in_fast, "braking_leader_fast": braking_leader_fast,
    "stop_and_go": stop_and_go, "pedestrian_parked": pedestrian_parked, "pedestrian_crossing": pedestrian_crossing,
    "tailgater": tailgater,
}
MARK = "# --- scripted participants (scenarios/everyday/generate.py) ---"


def render(name: str) -> str:
    """The scenario file ``name`` with its generated block replaced by the generator's output
    (tracks last the run's duration, read from its ``run: {duration: …}`` line)."""
    text = (HERE / f"{name}.yaml").read_text(encoding="utf-8")
    until = float(re.search(r"^run: \{duration: ([0-9.]+)", text, re.M).group(1))  # type: ignore[union-attr]
    head, mark, rest = text.partition(MARK + "\n")
    _, end, tail = rest.partition("# --- end ---\n")
    if not (mark and end):
        raise SystemExit(f"{name}.yaml needs the lines '{MARK}' and '# --- end ---'")
    return f"{head}{MARK}\n{GENERATED[name](until)}\n# --- end ---\n{tail}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="only tell whether the files match")
    args = ap.parse_args(argv)
    stale = []
    for name in GENERATED:
        new = render(name)
        path = HERE / f"{name}.yaml"
        if path.read_text(encoding="utf-8") != new:
            stale.append(name)
            if not args.check:
                path.write_text(new, encoding="utf-8")
    if args.check and stale:
        print("out of date: " + ", ".join(stale))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
