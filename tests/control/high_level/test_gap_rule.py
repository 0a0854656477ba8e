"""The gap a right-of-way rule asks for, read from the rule itself (its constants as the scenario
binds them), as the MPC's give-way line keeps it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.control.high_level.right_of_way import GapRule, gap_rule
from twolevel.stl.lint import load_ruleset

ROOT = Path(__file__).resolve().parents[3]
RULE = str(ROOT / "rules" / "right_of_way.stl")


def _load(path: str, consts: dict[str, float] | None = None):  # noqa: ANN202
    rs, diags = load_ruleset(path, consts)
    assert rs is not None, [d.message for d in diags]
    return rs


def test_the_shipped_rule_s_constants() -> None:
    assert gap_rule([_load(RULE)]) == GapRule(1.5, 4.0)


@pytest.mark.parametrize("margin,speed", [(3.0, 4.0), (1.5, 2.5), (0.5, 6.0)])
def test_constants_bound_by_a_scenario(margin: float, speed: float) -> None:
    got = gap_rule([_load(RULE, {"t_margin": margin, "v_go": speed})])
    assert got.margin == pytest.approx(margin) and got.speed == pytest.approx(speed)
    assert got.needs(np.array([20.0, -1.0])) == pytest.approx([margin + 20.0 / speed, margin])


def test_a_rule_written_the_other_way_round(tmp_path: Path) -> None:
    p = tmp_path / "gap.stl"
    p.write_text("input float d_zone\ninput float d_zone_out\n"
                 "g = always[0:1] (forall o in vehicles: (((priority(o) > 0.5) and (d_zone <= 0) and (d_zone_out > 0))"
                 " -> (2 * (1 + d_exit(o) / 10) <= t_reach(o))));\n")
    assert gap_rule([_load(str(p))]) == GapRule(pytest.approx(2.0), pytest.approx(5.0))


def test_no_such_rule_gives_the_defaults(tmp_path: Path) -> None:
    p = tmp_path / "speed.stl"
    p.write_text("input float v\nslow = always[0:1] (v <= 10);\n")
    assert gap_rule([_load(str(p))]) == GapRule()
