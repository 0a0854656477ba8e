"""The CommonRoad rule pack (rules/commonroad/): check accepts it, it round-trips, and each rule
has drives that satisfy and drives that violate it — the signals computed by the world from ego
and traffic trajectories on the highway map (participant_signals_along, signals_along), or given
directly for the ego-only rules, then monitored offline as `twolevel monitor` does."""

from __future__ import annotations

import functools
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from helpers.world_files import load_world
from twolevel.cli import app
from twolevel.monitor.tracefile import Trace, monitor_trace
from twolevel.stl.lint import check_file, load_ruleset
from twolevel.stl.parser import parse
from twolevel.stl.printer import format_file
from twolevel.world.provided import PROVIDED_PARTICIPANT_SIGNALS, PROVIDED_SIGNALS
from twolevel.world.signals import TrafficLog, participant_signals_along, signals_along

ROOT = Path(__file__).resolve().parents[2]
PACK = ROOT / "rules" / "commonroad"
FILES = sorted(PACK.glob("*.stl"))
DT = 0.1
NONLINEAR = {"R_G1_safe_distance.stl", "R_G2_no_abrupt_braking.stl"}  # quadratic braking distances


def test_the_pack_is_there() -> None:
    assert [p.name for p in FILES] == [
        "R_G1_safe_distance.stl", "R_G2_no_abrupt_braking.stl", "R_G3_speed_limits.stl", "R_G4_traffic_flow.stl",
        "R_IN1_stop_sign.stl", "R_IN2_red_light.stl"]


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_check_accepts_every_rule(path: Path) -> None:
    """No error and no style finding; the only warnings are the braking distances' products
    (STL212: the MPC cannot encode R_G1 and R_G2), two per file."""
    r = check_file(str(path), dt=DT, horizon=10, provided_signals=PROVIDED_SIGNALS,
                   participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
    codes = [d.code for d in r.diagnostics]
    assert codes == (["STL212", "STL212"] if path.name in NONLINEAR else []), [d.message for d in r.diagnostics]
    assert r.source is not None and r.source.startswith("// R_")
    assert "Maierhofer" in r.source and "Parameters:" in r.source
    rf, _ = parse(r.source, str(path))
    back, diags = parse(format_file(rf), str(path))
    assert diags == [] and back == rf


def test_twolevel_check_on_the_pack_exits_zero() -> None:
    res = CliRunner().invoke(app, ["check", str(PACK), "--dt", "0.1", "--horizon", "10", "-f", "concise"])
    assert res.exit_code == 0, res.output
    assert res.output.count("STL212") == 4 and "error" not in res.output


# --------------------------------------------------------------------------- monitoring drives


@functools.lru_cache(maxsize=1)
def _world():
    tmp = Path(tempfile.mkdtemp())
    (tmp / "s.yaml").write_text(
        f"kind: scenario\nname: pack\nmap: {ROOT / 'maps' / 'highway.yaml'}\n"
        "ego: {start: {lane: middle, s: 20}, speed: 20}\n"
        "route: {start: {lane: middle, s: 20}, goal: {lane: middle, s: 1400}}\n"
        "participants: [{id: lead, behaviour: constant_velocity, start: {lane: middle, s: 100}},\n"
        "  {id: side, behaviour: constant_velocity, start: {lane: left, s: 100}}]\n"
        "controller: {r_near: 200}\nrun: {duration: 10, seed: 0}\n")
    return load_world(tmp / "s.yaml")


def _drive(v: np.ndarray, a: np.ndarray, others: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
           s0: float = 100.0, lat: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The world's signals for an ego at speeds ``v`` [m/s] from route position ``s0`` on the
    middle lane, and others given as (route s, lateral offset, speed) per sample."""
    w = _world()
    T = len(v)
    s = s0 + np.concatenate([[0.0], np.cumsum(v[:-1] * DT)])
    lat = np.zeros(T) if lat is None else lat
    pts = w.route.position(s, lat)
    psi = w.route.heading_at(s) + np.concatenate([np.diff(lat) / np.maximum(v[:-1] * DT, 1e-9), [0.0]])
    ids = list(others)
    xs, ys, hs, vs = [], [], [], []
    for pid in ids:
        so, eo, vo = others[pid]
        p = w.route.position(so, eo)
        xs.append(p[:, 0])
        ys.append(p[:, 1])
        hs.append(w.route.heading_at(so) + np.concatenate([np.diff(eo) / np.maximum(vo[:-1] * DT, 1e-9), [0.0]]))
        vs.append(vo)
    n = len(ids)
    log = TrafficLog(np.stack(xs, 1), np.stack(ys, 1), np.stack(hs, 1), np.stack(vs, 1), np.ones((T, n), bool),
                     np.full(n, 4.22), np.full(n, 1.8))
    ego = {"x": pts[:, 0], "y": pts[:, 1], "psi": psi, "v": v, "a": a}
    sig = signals_along(w, log, ego, dt=DT)
    sig.update(participant_signals_along(w, log, ego, dt=DT, ids=ids))
    return sig


def _cruise(s0: float, v: float, T: int, lane: float = 0.0, accel: float = 0.0) -> tuple[np.ndarray, ...]:
    t = DT * np.arange(T)
    speed = np.maximum(v + accel * t, 0.0)
    return s0 + np.concatenate([[0.0], np.cumsum(speed[:-1] * DT)]), np.full(T, lane), speed


def _monitor(name: str, sig: dict[str, np.ndarray]) -> np.ndarray:
    path = next(p for p in FILES if p.name.startswith(name + "_"))
    rs, diags = load_ruleset(str(path), dt=DT, participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
    assert rs is not None, diags
    n = len(next(iter(sig.values())))
    trace = Trace(str(path), DT * np.arange(n), sig, DT)
    report, diags = monitor_trace(rs.rules, dict(rs.consts), trace, series=True)
    assert not diags, [d.message for d in diags]
    return report.rules[0].series


T = 60


def test_r_g1_holds_at_a_safe_gap_and_fails_when_tailgating() -> None:
    v = np.full(T, 22.0)
    safe = _monitor("R_G1", _drive(v, np.zeros(T), {"lead": _cruise(100 + 60, 22.0, T)}))
    assert (safe > 0).all()
    # gap 12 m at 24 m/s behind 22 m/s: d_safe = 9.6 + 28.8 - 23.05 = 15.35 m
    v = np.full(T, 24.0)
    tail = _monitor("R_G1", _drive(v, np.zeros(T), {"lead": _cruise(100 + 12 + 4.22, 22.0, T)}))
    assert 12.0 - (0.4 * 24 + 24 ** 2 / 20 - 22 ** 2 / 21) < -3.3  # the gap is short by 3.35 m, but
    # the implication is no more robust than its premise: the leader is 0.85 m from straddling the
    # lane boundary, i.e. "not cutting in" by 0.85 m (robustness of p -> q is max(-p, q))
    assert np.allclose(tail[:50], -0.85) and (tail < 0).all()  # (at the end the gap itself is smaller)


def test_r_g1_ignores_vehicles_in_other_lanes() -> None:
    v = np.full(T, 24.0)
    beside = _monitor("R_G1", _drive(v, np.zeros(T), {"side": _cruise(100 + 12, 22.0, T, lane=3.5)}))
    assert (beside > 0).all()


def test_r_g1_gives_a_cut_in_three_seconds() -> None:
    """A car cuts in close ahead from the left lane: no violation for 3 s after its cut-in began,
    then a violation while the gap is still short."""
    T2 = 80
    so, _, vo = _cruise(100 + 10, 20.0, T2)  # 5.78 m bumper to bumper; the safe distance is 8.95 m
    eo = np.clip(3.5 - np.maximum(DT * np.arange(T2) - 0.5, 0.0) * 3.5, 0.0, 3.5)  # crosses within 1 s
    sig = _drive(np.full(T2, 20.0), np.zeros(T2), {"lead": (so, eo, vo)})
    start = int(np.argmax(sig["cut_in[lead]"] > 0))
    assert 5 <= start <= 15  # the cut-in begins when its body crosses into the ego's lane
    rob = _monitor("R_G1", sig)
    assert (rob[: start + 30] >= 0).all()  # 3 s of grace from the cut-in's start
    assert (rob[start + 31:] < 0).all()  # then the distance is too short


def test_r_g2_needs_a_reason_to_brake_hard() -> None:
    brake = np.full(T, -4.0)
    v = np.maximum(22.0 - 4.0 * DT * np.arange(T), 0.0)
    free = _monitor("R_G2", _drive(v, brake, {"lead": _cruise(100 + 80, 22.0, T)}))
    assert (free < 0).any()
    assert free[0] == pytest.approx(-2.0)  # the leader cruises: a - a(o) = -4 < -2 by 2
    along = _monitor("R_G2", _drive(v[:50], brake[:50], {"lead": _cruise(100 + 80, 22.0, 50, accel=-4.0)}))
    assert (along[1:] >= 0).all()  # the leader brakes as hard (a(o) is 0 at the first sample)
    close = _monitor("R_G2", _drive(v, brake, {"lead": _cruise(100 + 12, 22.0, T)}))
    assert (close[:3] > 0).all()  # too close to it: braking is justified, until the gap has grown
    assert (close[5:] < 0).all()
    cruise = _monitor("R_G2", _drive(np.full(T, 22.0), np.zeros(T), {"lead": _cruise(100 + 80, 22.0, T)}))
    assert (cruise > 0).all()


def test_r_g3_speed_limits() -> None:
    v_max = np.full(T, 27.78)
    ok = _monitor("R_G3", {"v": np.full(T, 22.0), "v_max": v_max})
    assert ok == pytest.approx(np.full(T, 5.78))
    fast = _monitor("R_G3", {"v": np.full(T, 31.0), "v_max": v_max})
    assert fast == pytest.approx(np.full(T, -3.22))
    over_brake = _monitor("R_G3", {"v": np.full(T, 45.0), "v_max": np.full(T, 50.0)})
    assert over_brake == pytest.approx(np.full(T, -2.0))  # the braking limit, 43 m/s


def test_r_g4_slow_only_behind_a_slow_vehicle() -> None:
    v = np.full(T, 12.0)  # 18 m/s below the highway's 30 m/s limit
    free = _monitor("R_G4", _drive(v, np.zeros(T), {"side": _cruise(100 + 30, 25.0, T, lane=3.5)}))
    assert (free < 0).all() and free[0] == pytest.approx(12.0 - (30.0 - 15.0))
    behind_slow = _monitor("R_G4", _drive(v, np.zeros(T), {"lead": _cruise(100 + 30, 12.0, T)}))
    assert (behind_slow > 0).all()
    brisk = _monitor("R_G4", _drive(np.full(T, 25.0), np.zeros(T), {"side": _cruise(100 + 30, 25.0, T, lane=3.5)}))
    assert (brisk > 0).all()


def test_r_in1_stop_before_passing_the_line() -> None:
    t = DT * np.arange(T)
    rolled = {"v": np.full(T, 5.0), "d_stop": 3.0 - 5.0 * t}
    assert (_monitor("R_IN1", rolled) < 0).any()
    # approach, stand 0.5 m before the line for 3.5 s, then go
    stand = (t >= 1.0) & (t < 4.5)
    d = np.where(t < 1.0, 0.5 + 2.0 * (1.0 - t), np.where(stand, 0.5, 0.5 - 2.0 * (t - 4.5)))
    stopped = {"v": np.where(stand, 0.0, 2.0), "d_stop": d}
    rob = _monitor("R_IN1", stopped)
    assert (rob >= 0).all() and (d <= 0).any()
    short = {"v": np.where((t >= 1.0) & (t < 2.0), 0.0, 2.0), "d_stop": np.where(t < 2.0, d, 0.5 - 2.0 * (t - 2.0))}
    assert (_monitor("R_IN1", short) < 0).any()  # stood 1 s only


def test_r_in2_no_crossing_on_red() -> None:
    t = DT * np.arange(T)
    d = 5.0 - 4.0 * t  # crosses the line at 1.25 s
    assert (_monitor("R_IN2", {"light_red": np.zeros(T), "d_light": d}) > 0).all()
    red = _monitor("R_IN2", {"light_red": (t >= 1.0).astype(float), "d_light": d})
    assert (red[: int(1.25 / DT)] >= 0).all() and (red[int(1.3 / DT):] < 0).all()


def test_monitor_cli_runs_the_pack_on_a_trace(tmp_path: Path) -> None:
    """`twolevel monitor` on a CSV with participant columns: R_G1 violated while tailgating."""
    v = np.full(20, 24.0)
    sig = _drive(v, np.zeros(20), {"lead": _cruise(100 + 12 + 4.22, 22.0, 20)})
    names = ["v"] + [k for k in sig if k.endswith("[lead]")]
    lines = ["t," + ",".join(names)]
    for k in range(20):
        lines.append(f"{k * DT:.1f}," + ",".join(repr(float(sig[n][k])) for n in names))
    (tmp_path / "trace.csv").write_text("\n".join(lines) + "\n")
    res = CliRunner().invoke(app, ["monitor", str(PACK / "R_G1_safe_distance.stl"), str(tmp_path / "trace.csv"),
                                   "--format", "json"])
    assert res.exit_code == 1, res.output
    assert '"satisfied": false' in res.stdout and not math.isnan(float(res.stdout.split('"robustness": ')[1].split(",")[0]))
