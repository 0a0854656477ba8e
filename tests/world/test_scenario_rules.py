"""A scenario's references to rules by name (``expect.rules``, ``controller.margins``) must name
rules its rule files define: refused when the scenario is loaded (``twolevel check``), at the
entry, with a close name and the rules defined — not found failed after a run."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from twolevel.cli import app

ROOT = Path(__file__).resolve().parents[2]

SCENARIO = f"""kind: scenario
name: refs
map: {ROOT / 'maps' / 'one_lane.yaml'}
ego:
  start: {{lane: lane, s: 10}}
  speed: 5.0
route:
  start: {{lane: lane, s: 10}}
  goal: {{lane: lane, s: 100}}
rules:
  - {ROOT / 'rules' / 'speed_limit.stl'}
run: {{duration: 5, seed: 0}}
expect: {{rules: [speed_limit, speed_limt]}}
variants:
  - {{name: fine, expect: {{rules: [speed_limit]}}}}
  - {{name: other, expect: {{rules: [give_way]}}}}
"""


def test_an_expected_rule_no_file_defines_is_an_error_at_its_entry(tmp_path: Path) -> None:
    path = tmp_path / "refs.yaml"
    path.write_text(SCENARIO, encoding="utf-8")
    res = CliRunner().invoke(app, ["check", str(path)])
    assert res.exit_code == 1, res.output
    found = [ln for ln in res.output.splitlines() if "YML436" in ln]
    assert found[0].startswith(f"{path}:13:31: YML436 [error]") and "'speed_limt'" in found[0]
    assert "did you mean 'speed_limit'?" in found[0]
    assert found[1].startswith(f"{path}:16:36: YML436 [error]") and "'give_way'" in found[1]
    assert len(found) == 2 and "Traceback" not in res.output
    doc = json.loads(CliRunner().invoke(app, ["check", str(path), "-f", "json"]).stdout)
    assert [(d["code"], d["hint"]) for d in doc["diagnostics"]] == [("YML436", "rules defined: speed_limit")] * 2


def test_expected_rules_the_files_define_load(tmp_path: Path) -> None:
    path = tmp_path / "refs.yaml"
    path.write_text(SCENARIO.replace("speed_limt", "speed_limit").replace("[give_way]", "all"), encoding="utf-8")
    res = CliRunner().invoke(app, ["check", str(path)])
    assert "YML436" not in res.output and res.exit_code == 0, res.output
