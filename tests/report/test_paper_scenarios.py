"""The report renders for a real run of every paper scenario (short runs of the simulator)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from twolevel.report import build_report
from twolevel.sim.engine import simulate_scenario

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["comparison", "traffic_rules", "safety", "scalability"])
def test_report_of_a_real_run(tmp_path: Path, name: str) -> None:
    run_dir = tmp_path / name
    summary, diags = simulate_scenario(str(ROOT / "scenarios" / f"{name}.yaml"), str(run_dir), duration=1.5)
    assert summary is not None and summary.status == "complete", [d.message for d in diags]
    res = build_report(run_dir, gif=(name == "scalability"), formats=("png",))
    assert res.metrics.rows == summary.steps == 15
    html = Path(res.html).read_text()
    assert "<img" in html and "http://" not in html and "https://" not in html
    data = json.loads((run_dir / "summary.json").read_text())
    assert data  # machine-readable summary written
    if name == "scalability":
        assert (run_dir / "animation.gif").stat().st_size > 1000
    # the report's figures agree with the simulator's own summary
    assert res.metrics.collisions.collided == bool(summary.collisions)
    assert sum(json.loads((run_dir / "run.json").read_text())["summary"]["decisions"].values()) == res.metrics.rows
