"""The rule library passes check cleanly and round-trips; the lint path does not import numpy."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from twolevel.stl.lint import check_file, load_ruleset
from twolevel.stl.parser import parse
from twolevel.stl.printer import format_file

RULES = sorted((Path(__file__).resolve().parents[2] / "rules").glob("*.stl"))
WORLD = frozenset("x y psi v a delta s e v_max d_stop light_red d_light d_lead v_lead rss_gap d_zone d_zone_out over_centre solid_left no_overtaking xwalk_busy d_xwalk".split())


def test_library_is_there() -> None:
    assert {p.name for p in RULES} >= {"speed_limit.stl", "stop_sign.stl", "red_light.stl", "safe_distance.stl"}


@pytest.mark.parametrize("path", RULES, ids=[p.stem for p in RULES])
def test_rule_file_is_clean(path: Path) -> None:
    r = check_file(str(path), dt=0.1, horizon=10, provided_signals=WORLD)
    assert r.diagnostics == (), [f"{d.code} {d.message}" for d in r.diagnostics]
    assert r.ruleset is not None and r.ruleset.rules and not r.ruleset.unbound
    assert r.source is not None and r.source.lstrip().startswith("//")  # a header comment


@pytest.mark.parametrize("path", RULES, ids=[p.stem for p in RULES])
def test_rule_file_round_trips(path: Path) -> None:
    rf, _ = parse(path.read_text(encoding="utf-8"), str(path))
    back, diags = parse(format_file(rf), str(path))
    assert diags == [] and back == rf


@pytest.mark.parametrize("path", RULES, ids=[p.stem for p in RULES])
def test_rule_file_loads(path: Path) -> None:
    rs, diags = load_ruleset(str(path), dt=0.1, provided_signals=WORLD)
    assert rs is not None and diags == []


def test_check_path_imports_no_heavy_module() -> None:
    code = (
        "import sys\n"
        "import twolevel.stl.lint, twolevel.stl.printer, twolevel.stl.analysis, twolevel.stl.codes\n"
        f"r = twolevel.stl.lint.check_file({str(RULES[0])!r}, dt=0.1, horizon=10)\n"
        "assert r.ok\n"
        "heavy = {'numpy', 'scipy', 'casadi', 'highspy', 'clarabel', 'matplotlib', 'typer', 'rich'}\n"
        "print(sorted(heavy & set(sys.modules)))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    assert out.stdout.strip() == "[]"
