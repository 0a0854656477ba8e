"""examples/town with SUMO traffic: SUMO's conversion of the Town-like OpenDRIVE (town.net.xml)
lies on the map imported from it (town.yaml), and the paper's safety and scalability scenarios
among SUMO's vehicles (safety_sumo.yaml, scalability_sumo.yaml) pass their verdicts."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from twolevel.cli import app
from twolevel.world.loader import load_scenario
from twolevel.world.world import build_world

ls = pytest.importorskip("libsumo", reason="the optional 'sumo' extra (libsumo) is not installed")

TOWN = Path(__file__).resolve().parents[2] / "examples" / "town"
runner = CliRunner()
BOULEVARD = {"-600_0": "r600_0_-3", "-600_1": "r600_0_-2", "-600_2": "r600_0_-1"}  # SUMO counts from the right


def test_sumos_boulevard_lies_on_the_imported_maps_lanes() -> None:
    scn, diags = load_scenario(TOWN / "safety_sumo.yaml")
    assert scn is not None, diags
    lanes = build_world(scn).lanes
    ls.start(["sumo", "-n", str(TOWN / "town.net.xml"), "--no-step-log", "true"])
    try:
        for sumo_lane, lane in BOULEVARD.items():
            shape = np.array(ls.lane.getShape(sumo_lane), dtype=float)
            i = lanes.index[lane]
            s, lat = lanes.project(np.full(len(shape), i), shape)
            assert np.abs(lat).max() < 0.01, sumo_lane
            assert s.min() < 0.01 and abs(s.max() - float(lanes.length[i])) < 0.01
            assert ls.lane.getMaxSpeed(sumo_lane) == pytest.approx(100 / 3.6, abs=0.01)  # the map's limit
    finally:
        ls.close()


def _run(tmp_path: Path, name: str) -> tuple[dict, list[dict[str, str]]]:
    out = tmp_path / name
    result = runner.invoke(app, ["simulate", str(TOWN / f"{name}.yaml"), "--out", str(out)])
    run = json.loads((out / "run.json").read_text())
    assert result.exit_code == 0, (run.get("verdict"), result.output[-2000:])
    assert run["verdict"]["passed"] and run["traffic"]["engine"] == "sumo"
    with open(out / "trace.csv", newline="") as f:
        return run, list(csv.DictReader(f))


@pytest.mark.slow
def test_the_safety_scenario_among_sumo_vehicles_stops_behind_the_stalled_car(tmp_path: Path) -> None:
    run, rows = _run(tmp_path, "safety_sumo")
    assert run["summary"]["collisions"] == []
    assert max(float(r["n_near"]) for r in rows) >= 2  # SUMO's vehicles were there to be seen
    stalled_x = -400.0 + 160.0  # the stalled SUMO car's centre on the boulevard (lane r600_0_-2, s = 160)
    last = rows[-1]
    assert float(last["v"]) < 0.1 and float(last["x"]) < stalled_x - 5.0  # standing behind it
    assert abs(float(last["y"]) - 444.75) < 1.75 - 0.9  # its box within its lane, not past it on another


@pytest.mark.slow
def test_the_scalability_scenario_among_sumo_vehicles_keeps_its_rules(tmp_path: Path) -> None:
    run, rows = _run(tmp_path, "scalability_sumo")
    assert run["summary"]["collisions"] == []
    assert max(float(r["n_near"]) for r in rows) >= 10  # dense: many SUMO vehicles within r_near
    assert float(rows[-1]["x"]) > float(rows[0]["x"]) + 150.0  # it drove with the pack
