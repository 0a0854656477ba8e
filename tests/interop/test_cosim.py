"""SUMO traffic in the closed loop (libsumo in the same process): the ego in SUMO is where
twolevel has it, SUMO's vehicles brake behind it, runs are deterministic for a seed.

SUMO is read here directly through libsumo (one simulation per process, the run's own), as
the oracle of what the engine exchanged.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
from pathlib import Path

import pytest

from twolevel.sim.cosim import EGO_ID
from twolevel.sim.engine import TIMING_COLUMNS, simulate_scenario
from twolevel.sim.summary import StepInfo

ls = pytest.importorskip("libsumo", reason="the optional 'sumo' extra (libsumo) is not installed")

ROOT = Path(__file__).resolve().parents[2]
SUMO = ROOT / "examples/sumo"
RULES = ROOT / "rules"


def _scenario(tmp_path: Path, net: str = "grid3", *, ego: str = "{lane: A0B0_0, s: 20}", speed: float = 8.0,
              desired: float = 30.0,
              goal: str = "{lane: B0C0_0, s: 100}", traffic: str = "random_trips: {vehicles: 40}",
              duration: float = 8.0, seed: int = 3) -> Path:
    text = f"""kind: scenario
map: {SUMO / (net + '.yaml')}
ego: {{start: {ego}, speed: {speed}, desired_speed: {desired}}}
route: {{start: {ego}, goal: {goal}}}
traffic:
  engine: sumo
  net: {SUMO / (net + '.net.xml')}
  {traffic}
rules: [{RULES / 'speed_limit.stl'}, {RULES / 'red_light.stl'}]
run: {{duration: {duration}, seed: {seed}}}
expect: {{goal: false}}
"""
    path = tmp_path / "scenario.yaml"
    path.write_text(text)
    return path


def _trace(run: Path) -> list[dict[str, str]]:
    with open(run / "trace.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _sumo_ego() -> tuple[float, float, float]:
    """The ego's centre [m] and heading [rad] in SUMO now (its front bumper less half its length)."""
    fx, fy = ls.vehicle.getPosition(EGO_ID)
    h = math.radians(90.0 - ls.vehicle.getAngle(EGO_ID))
    half = 0.5 * ls.vehicle.getLength(EGO_ID)
    return fx - half * math.cos(h), fy - half * math.sin(h), h


def test_the_ego_in_sumo_follows_twolevels_pose_every_step(tmp_path: Path) -> None:
    seen: dict[int, tuple[float, float, float]] = {}

    def progress(info: StepInfo) -> None:  # after step k: SUMO is at t = (k + 1) dt
        seen[info.step] = _sumo_ego()

    summary, diags = simulate_scenario(str(_scenario(tmp_path)), str(tmp_path / "run"), progress=progress,
                                       frames=False, ttr_every=0)
    assert summary is not None and summary.status.value == "complete", diags
    rows = _trace(tmp_path / "run")
    assert len(seen) == len(rows) > 50
    for k, row in enumerate(rows[1:], start=1):
        x, y, h = seen[k]
        assert math.hypot(x - float(row["x"]), y - float(row["y"])) < 0.05, row["t"]
        assert abs((h - float(row["psi"]) + math.pi) % (2 * math.pi) - math.pi) < math.radians(1.0), row["t"]
    assert max(float(r["v"]) for r in rows) > 9.0  # the ego moved: the check is not of a standstill
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    net = SUMO / "grid3.net.xml"
    assert meta["traffic"]["engine"] == "sumo" and meta["traffic"]["random_trips"] == 40
    assert meta["traffic"]["net"]["sha256"] == hashlib.sha256(net.read_bytes()).hexdigest()


def test_an_ego_starting_inside_a_junction_is_placed_there(tmp_path: Path) -> None:
    seen: list[tuple[float, float, float]] = []
    scenario = _scenario(tmp_path, ego="{lane: ':B0_6_0', s: 3}", speed=5.0, duration=1.0)
    summary, diags = simulate_scenario(str(scenario), str(tmp_path / "run"), frames=False, ttr_every=0,
                                       progress=lambda info: seen.append(_sumo_ego()))
    assert summary is not None and summary.status.value == "complete", diags
    rows = _trace(tmp_path / "run")
    assert all(math.hypot(x - float(r["x"]), y - float(r["y"])) < 0.05 for (x, y, _), r in zip(seen, rows[1:]))


def test_sumo_vehicles_brake_behind_the_ego(tmp_path: Path) -> None:
    routes = tmp_path / "follower.rou.xml"
    routes.write_text("""<routes>
    <vType id="keep_lane" lcStrategic="-1" lcSpeedGain="0" lcKeepRight="0" lcCooperative="-1"/>
    <route id="east" edges="A0B0 B0C0"/>
    <vehicle id="follower" type="keep_lane" route="east" depart="0" departLane="0" departPos="0" departSpeed="13"/>
</routes>
""")
    scenario = _scenario(tmp_path, ego="{lane: A0B0_0, s: 40}", speed=1.0, desired=1.0, traffic=f"routes: [{routes}]",
                         duration=15.0)
    speed: list[float] = []
    pos: list[float] = []
    ego_rear: list[float] = []

    def progress(info: StepInfo) -> None:
        if "follower" in ls.vehicle.getIDList():
            speed.append(ls.vehicle.getSpeed("follower"))
            pos.append(ls.vehicle.getPosition("follower")[0])
            x, _, _ = _sumo_ego()
            ego_rear.append(x - 0.5 * ls.vehicle.getLength(EGO_ID))

    summary, diags = simulate_scenario(str(scenario), str(tmp_path / "run"), progress=progress, frames=False,
                                       ttr_every=0)
    assert summary is not None and summary.status.value == "complete" and summary.steps == 150, diags
    assert max(speed[:10]) > 11.0, "the follower came fast"
    assert speed[-1] < 1.5, "and drives at the ego's 1 m/s at the end"
    # behind the creeping ego, far before the light's stop line at x = 143.6 m: it braked for the ego
    assert pos[-1] < ego_rear[-1] < 70.0
    assert min(e - p for e, p in zip(ego_rear, pos)) > 0.5
    assert not summary.collisions
    rows = _trace(tmp_path / "run")
    assert min(float(r["min_dist"]) for r in rows) < 12.0  # twolevel saw it (it filled a slot)


def _fingerprint() -> str:
    rows = [f"{v} {x:.6f} {y:.6f} {ls.vehicle.getSpeed(v):.6f}"
            for v in sorted(ls.vehicle.getIDList()) for x, y in [ls.vehicle.getPosition(v)]]
    return hashlib.sha256("\n".join(rows).encode()).hexdigest()


def _run_1000(tmp_path: Path, name: str, seed: int) -> tuple[str, list[dict[str, str]], tuple[int, int]]:
    out = tmp_path / name
    (tmp_path / f"{name}_in").mkdir()
    scenario = _scenario(tmp_path / f"{name}_in", net="grid5", traffic=f"random_trips: {{vehicles: 1000}}\n  seed: {seed}",
                         duration=6.0, seed=seed)
    state: dict[str, object] = {}

    def progress(info: StepInfo) -> None:
        if info.step == info.steps:
            state["hash"], state["running"] = _fingerprint(), ls.vehicle.getIDCount() - 1
            state["kept"] = state["running"] + len(ls.simulation.getPendingVehicles())

    summary, diags = simulate_scenario(str(scenario), str(out), progress=progress, frames=False, ttr_every=0)
    assert summary is not None and summary.status.value == "complete", diags
    rows = [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in _trace(out)]
    return str(state["hash"]), rows, (int(state["running"]), int(state["kept"]))  # type: ignore[call-overload]


@pytest.mark.slow
def test_a_run_among_1000_sumo_vehicles_is_deterministic_for_a_seed(tmp_path: Path) -> None:
    h1, rows1, n1 = _run_1000(tmp_path, "a", 11)
    h2, rows2, _ = _run_1000(tmp_path, "b", 11)
    h3, _, _ = _run_1000(tmp_path, "c", 12)
    assert h1 == h2 and rows1 == rows2
    assert h3 != h1
    running, kept = n1
    assert kept == 1000 and running >= 800  # 1000 kept (driving or waiting to enter), most of them driving


def test_missing_and_broken_sumo_files_are_diagnostics(tmp_path: Path) -> None:
    scenario = _scenario(tmp_path, traffic="routes: [nowhere.rou.xml]")
    summary, diags = simulate_scenario(str(scenario), str(tmp_path / "run"))
    assert summary is None and [d.code for d in diags] == ["YML418"]
    span = diags[0].span
    assert scenario.read_text().splitlines()[span.line - 1][span.column - 1:].startswith("nowhere.rou.xml")
    broken = tmp_path / "broken.rou.xml"
    broken.write_text("<routes><vehicle id='x' route='nope' depart='0'/></routes>\n")
    summary, diags = simulate_scenario(str(_scenario(tmp_path, traffic=f"routes: [{broken}]")), str(tmp_path / "run"))
    assert summary is None and "SIM631" in [d.code for d in diags]


def test_sumo_failing_mid_run_aborts_the_run_with_a_diagnostic_and_keeps_its_steps(tmp_path: Path) -> None:
    """A vehicle of the route files that SUMO cannot insert when it is due (faster than its type
    allows, at 2 s): libsumo raises in that step. The run ends 'aborted' with SIM632 (SUMO's words,
    the time, a hint naming the files), exit 2, no traceback; the 20 completed steps are readable
    (trace, run.json, `twolevel monitor`)."""
    from typer.testing import CliRunner

    from twolevel.cli import app
    from twolevel.monitor.tracefile import read_trace

    routes = tmp_path / "late.rou.xml"
    routes.write_text("<routes><vType id='car'/>"
                      "<vehicle id='late' type='car' depart='2' departSpeed='200'><route edges='A0B0'/></vehicle>"
                      "</routes>\n")
    scenario = _scenario(tmp_path, traffic=f"routes: [{routes}]", duration=6.0)
    res = CliRunner().invoke(app, ["simulate", str(scenario), "--out", str(tmp_path / "run")])
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "Traceback" not in res.stderr
    finding = next(ln for ln in res.stderr.splitlines() if "SIM632" in ln)
    assert finding.startswith(f"{scenario}:1:1: SIM632 [error] the run was aborted after 20 steps (2 s)")
    assert "Departure speed for vehicle 'late' is too high" in finding and "t = 2.1 s" in finding
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    assert meta["status"] == "aborted" and "traceback" not in meta and "'late'" in meta["error"]
    assert meta["summary"]["steps"] == 20
    trace, diags = read_trace(tmp_path / "run" / "trace.csv")
    assert trace is not None and not diags and trace.samples == 20 and trace.t[-1] == pytest.approx(1.9)
    mon = CliRunner().invoke(app, ["monitor", str(RULES / "speed_limit.stl"), str(tmp_path / "run" / "trace.csv")])
    assert mon.exit_code == 0, mon.output
    # the hint, in the library's diagnostic: SUMO's own run of the same files
    summary, diags = simulate_scenario(str(scenario), str(tmp_path / "again"), frames=False, ttr_every=0)
    assert summary is not None and summary.status.value == "aborted"
    sim632 = [d for d in diags if d.code == "SIM632"]
    assert len(sim632) == 1 and f"-r {routes}" in (sim632[0].hint or "") and str(tmp_path / "again") in sim632[0].hint


def test_without_libsumo_sumo_traffic_says_how_to_install_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(__import__("sys").modules, "libsumo", None)  # import libsumo raises ImportError
    summary, diags = simulate_scenario(str(_scenario(tmp_path)), str(tmp_path / "run"))
    assert summary is None and [d.code for d in diags if d.is_error] == ["SIM630"]
    assert "twolevel[sumo]" in (diags[-1].hint or "")
