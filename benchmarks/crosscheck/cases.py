"""twolevel's side of the cross-check with CommonRoad's monitor: interstate drives, their signals
by twolevel's world, and the rule pack's robustness on them.

Each case is a straight two-lane interstate (lanes 3.5 m wide along x, right lane at y = 0, the
limit 27.78 m/s) with an ego (id 100) and other cars (ids 101, …), every one a 4.5 m × 1.8 m box
given by its centre, heading, speed and acceleration at every step (dt = 0.1 s). twolevel computes
the signals from a world of the same geometry (:func:`twolevel.world.signals.signals_along`,
:func:`~twolevel.world.signals.participant_signals_along`) and evaluates
``rules/commonroad/R_G1…R_G4`` on them; :func:`export` writes the same drives for
``crmonitor_side.py`` (the accelerations exported are the trace's: the ego's commanded ``a``, the
others' ``a(o)``).
"""

from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path
import numpy as np

from twolevel.monitor.robustness import evaluate_rules
from twolevel.stl.lint import load_ruleset
from twolevel.world.loader import load_scenario
from twolevel.world.provided import PROVIDED_PARTICIPANT_SIGNALS
from twolevel.world.signals import TrafficLog, participant_signals_along, signals_along
from twolevel.world.world import World, build_world

ROOT = Path(__file__).resolve().parents[2]
PACK = ROOT / "rules" / "commonroad"
RULES = ("R_G1", "R_G2", "R_G3", "R_G4")
DT, LANE, LENGTH, LIMIT, BOX = 0.1, 3.5, 1000.0, 27.78, (4.5, 1.8)
START = 200.0  # [m] where the ego starts: every car of every drive starts and stays on the road
EGO = 100

Track = dict[str, np.ndarray]  # x, y, psi, v, a per step


def straight(x0: float, y: float, v0: float, T: int, *, accel: float = 0.0, from_t: float = 0.0) -> Track:
    """A car along x starting ``x0`` [m] ahead of the ego's start (``START``) at lateral position
    ``y`` [m]: speed ``v0`` [m/s], accelerating at ``accel`` [m/s²] from ``from_t`` [s] on (never
    below standstill)."""
    t = DT * np.arange(T)
    v = np.maximum(v0 + accel * np.maximum(t - from_t, 0.0), 0.0)
    a = np.where((t >= from_t) & (v > 0), accel, 0.0)
    x = START + x0 + np.concatenate([[0.0], np.cumsum(v[:-1] * DT)])
    return {"x": x, "y": np.full(T, y), "psi": np.zeros(T), "v": v, "a": a}


def lane_change(track: Track, y_to: float, start: float, duration: float) -> Track:
    """``track`` moving laterally to ``y_to`` [m] between ``start`` and ``start + duration`` [s]
    (a smooth step), its heading along its path and its speed along it."""
    t = DT * np.arange(len(track["x"]))
    u = np.clip((t - start) / duration, 0.0, 1.0)
    y = track["y"] + (y_to - track["y"]) * (3 * u ** 2 - 2 * u ** 3)
    dx = np.gradient(track["x"], DT)
    dy = np.gradient(y, DT)
    return {**track, "y": y, "psi": np.arctan2(dy, dx), "v": np.hypot(dx, dy)}


def _cases(T: int) -> dict[str, dict[int, Track]]:
    left = LANE
    rng = np.random.default_rng(7)
    dense = {EGO: straight(0.0, 0.0, 22.0, T), 101: straight(45.0, 0.0, 22.0, T)}
    for i in range(18):  # 18 more cars on both lanes, 25 m apart, none closer than the leader ahead
        lane = left if i % 2 == 0 else 0.0
        x0 = -140.0 + 25.0 * i if lane else 75.0 + 25.0 * i
        dense[102 + i] = straight(x0, lane, float(rng.uniform(20.0, 24.0)), T)
    return {
        "safe": {EGO: straight(0.0, 0.0, 22.0, T), 101: straight(60.0, 0.0, 22.0, T),
                 102: straight(20.0, left, 24.0, T), 103: straight(-30.0, left, 26.0, T)},
        "tailgate": {EGO: straight(0.0, 0.0, 24.0, T, accel=-0.5), 101: straight(16.5, 0.0, 22.0, T),
                     102: straight(-10.0, left, 24.0, T)},
        "speeding": {EGO: straight(0.0, 0.0, 31.0, T), 101: straight(80.0, 0.0, 22.0, T),
                     102: straight(10.0, left, 27.0, T)},
        "brake": {EGO: straight(0.0, 0.0, 22.0, T, accel=-4.0, from_t=0.5), 101: straight(80.0, 0.0, 22.0, T),
                  102: straight(10.0, left, 22.0, T)},
        "brake_with_leader": {EGO: straight(0.0, 0.0, 22.0, T, accel=-4.0, from_t=0.5),
                              101: straight(35.0, 0.0, 22.0, T, accel=-4.0, from_t=0.5),
                              102: straight(-20.0, left, 22.0, T)},
        "cut_in": {EGO: straight(0.0, 0.0, 20.0, T),
                   101: lane_change(straight(10.0, left, 20.0, T), 0.0, start=0.5, duration=1.5),
                   102: straight(70.0, 0.0, 20.0, T), 103: straight(-25.0, left, 22.0, T)},
        "slow_traffic": {EGO: straight(0.0, 0.0, 10.0, T), 101: straight(40.0, 0.0, 10.0, T),
                         102: straight(5.0, left, 25.0, T)},
        "slow_free": {EGO: straight(0.0, 0.0, 10.0, T), 101: straight(30.0, left, 25.0, T),
                      102: straight(-20.0, left, 25.0, T)},
        "dense": dense,
    }


CASES: tuple[str, ...] = tuple(_cases(2))
"""The drives, by name (``dense``: 20 vehicles, the benchmark's)."""


def case(name: str, T: int = 100) -> dict[int, Track]:
    """Drive ``name`` over ``T`` steps: vehicle id → its track."""
    return _cases(T)[name]


def world(n_others: int) -> World:
    """twolevel's world of the interstate with ``n_others`` other cars (ids 101, …)."""
    with tempfile.TemporaryDirectory(prefix="twolevel-crosscheck-") as name:
        return _world_in(Path(name), n_others)


def _world_in(tmp: Path, n_others: int) -> World:
    (tmp / "map.yaml").write_text(
        "kind: map\nname: interstate\n"
        f"default_speed_limit: {LIMIT}\n"
        "roads:\n  - id: road\n    start: {x: 0, y: 0, heading: 0}\n"
        f"    segments: [{{line: {LENGTH}}}]\n"
        f"    lanes:\n      - {{id: right, offset: 0.0, width: {LANE}}}\n"
        f"      - {{id: left, offset: {LANE}, width: {LANE}}}\n")
    parts = ", ".join(f"{{id: '{101 + i}', behaviour: constant_velocity, start: {{lane: right, s: {10 + 10 * i}}}, "
                      f"box: {{length: {BOX[0]}, width: {BOX[1]}}}}}" for i in range(n_others))
    (tmp / "s.yaml").write_text(
        "kind: scenario\nname: crosscheck\nmap: map.yaml\n"
        f"ego: {{start: {{lane: right, s: 1}}, speed: 20, box: {{length: {BOX[0]}, width: {BOX[1]}}}}}\n"
        f"route: {{start: {{lane: right, s: 1}}, goal: {{lane: right, s: {LENGTH - 5}}}}}\n"
        f"participants: [{parts}]\ncontroller: {{r_near: 200}}\nrun: {{duration: 10, seed: 0}}\n")
    scn, diags = load_scenario(str(tmp / "s.yaml"))
    if scn is None:
        raise RuntimeError("; ".join(d.message for d in diags))
    return build_world(scn)


def signals(w: World, tracks: dict[int, Track]) -> dict[str, np.ndarray]:
    """Every signal the pack reads, as twolevel's world defines it."""
    others = [vid for vid in tracks if vid != EGO]
    col = lambda k: np.stack([tracks[vid][k] for vid in others], axis=1)  # noqa: E731
    T = len(tracks[EGO]["x"])
    n = len(others)
    log = TrafficLog(col("x"), col("y"), col("psi"), col("v"), np.ones((T, n), bool), np.full(n, BOX[0]),
                     np.full(n, BOX[1]))
    ego = {k: tracks[EGO][k] for k in ("x", "y", "psi", "v", "a")}
    out = signals_along(w, log, ego, dt=DT)
    out.update(participant_signals_along(w, log, ego, dt=DT, ids=[str(vid) for vid in others]))
    return out


def rulesets() -> list:
    out = []
    for rule in RULES:
        path = next(PACK.glob(rule + "_*.stl"))
        rs, diags = load_ruleset(str(path), dt=DT, participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
        if rs is None:
            raise RuntimeError(f"{path}: " + "; ".join(d.message for d in diags))
        out.append(rs)
    return out


AS_CRMONITOR = {"a_ego": 10.5}
"""Constants bound as crmonitor has them here: it judges a scenario's obstacle as the ego (as the
drives are exported) with the parameters of *other* vehicles (config.yaml's
``other_vehicles_param``: a_min = −10.5 m/s², not the ego's −10), so the safe distance of R_G1 and
R_G2 brakes the ego at 10.5 m/s² too."""


def robustness(sig: dict[str, np.ndarray], sets: list) -> tuple[dict[str, np.ndarray], float]:
    """The pack's robustness at every step (rule → series), with ``AS_CRMONITOR`` bound, and the
    CPU time it took [s]."""
    c0 = time.process_time()
    out: dict[str, np.ndarray] = {}
    for rs in sets:
        consts = dict(rs.consts)
        consts.update({k: v for k, v in AS_CRMONITOR.items() if k in consts})
        out.update(evaluate_rules(rs.rules, sig, DT, consts=consts))
    return out, time.process_time() - c0


def export(tracks: dict[int, Track], sig: dict[str, np.ndarray]) -> dict:
    """The drive as ``crmonitor_side.py`` reads it (others' accelerations as twolevel's a(o))."""
    vehicles = []
    for vid, tr in tracks.items():
        a = tr["a"] if vid == EGO else sig[f"a[{vid}]"]
        vehicles.append({"id": vid, "length": BOX[0], "width": BOX[1],
                         **{k: [float(x) for x in (a if k == "a" else tr[k])] for k in ("x", "y", "psi", "v", "a")}})
    return {"dt": DT, "length": LENGTH, "lane_width": LANE, "lanes": [{"id": "right", "y": 0.0}, {"id": "left", "y": LANE}],
            "speed_limit": LIMIT, "ego": EGO, "rules": list(RULES), "vehicles": vehicles}


def sign_agreement(ours: np.ndarray, theirs: np.ndarray) -> tuple[int, int]:
    """Steps on which both say the same (robustness ≥ 0: satisfied), and steps compared."""
    n = min(len(ours), len(theirs))
    return int(np.sum((np.asarray(ours[:n]) >= 0) == (np.asarray(theirs[:n]) >= 0))), n


def spearman(a: np.ndarray, b: np.ndarray) -> float:
    """Spearman's rank correlation of two series over their common finite steps (NaN when one
    of them is constant there)."""
    from scipy.stats import spearmanr

    n = min(len(a), len(b))
    a, b = np.asarray(a[:n], dtype=float), np.asarray(b[:n], dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.ptp(a[ok]) == 0 or np.ptp(b[ok]) == 0:
        return math.nan
    return float(spearmanr(a[ok], b[ok]).statistic)
