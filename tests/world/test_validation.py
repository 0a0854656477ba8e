"""The validation boundary of maps and scenarios is total: every number finite and in range,
the layout consistent, rule names unique, paths usable — or a diagnostic at the value. One test
per hole that let a file through ``check`` and broke ``plan`` or ``simulate`` (regressions)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from helpers.world_files import MAP, SCENARIO, write
from twolevel.cli import app
from twolevel.world.loader import check_world_file, load_map, load_scenario

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


def _scenario(tmp: Path, old: str = "", new: str = "", *, map_text: str = MAP) -> Path:
    write(tmp, "map.yaml", map_text)
    assert old in SCENARIO
    return write(tmp, "scn.yaml", SCENARIO.replace(old, new, 1))


def _errors(diags) -> list[tuple[str, str, int, int]]:  # noqa: ANN001
    return [(d.code, Path(d.span.file).name, d.span.line, d.span.column) for d in diags if d.is_error]


# ------------------------------------------------------------------ numbers: finite, in range


@pytest.mark.parametrize("value", [".nan", ".inf", "-.inf", "1e300"])
@pytest.mark.parametrize("name", ["l_f", "a_max", "mu", "h_int"])
def test_vehicle_parameter_not_finite_or_huge_is_refused_at_its_value(tmp_path: Path, name: str, value: str) -> None:
    """`l_f: .nan` passed check (NaN fails every comparison of the old `<= 0` test) and made the
    MPC fall back silently; `a_max: .nan` crashed plan with an internal error."""
    p = _scenario(tmp_path, "  speed: 5\n", f"  speed: 5\n  vehicle:\n    {name}: {value}\n")
    scn, diags = load_scenario(p)
    assert scn is None and _errors(diags) == [("YML414", "scn.yaml", 7, 7 + len(name))], diags
    assert diags[0].hint


def test_road_start_at_infinity_is_refused_at_its_value(tmp_path: Path) -> None:
    """`start: {x: .inf}` passed check; simulate crashed at step 0 and left no run.json."""
    m = MAP.replace("start: {x: 0, y: 0, heading: 0}", "start: {x: .inf, y: 0, heading: 0}")
    assert m != MAP
    mp, diags = load_map(write(tmp_path, "map.yaml", m))
    assert mp is None and _errors(diags) == [("YML414", "map.yaml", 5, 16)]
    assert "finite" in diags[0].message


@pytest.mark.parametrize("value, code", [("yes", "YML413"), ("'5'", "YML413"), ("1e2", None), ("5e-1", None)])
def test_numbers_are_numbers(tmp_path: Path, value: str, code: str | None) -> None:
    """YAML 1.1 reads `yes` as true (which pydantic took for 1 m/s) and `1e2` as text (which it
    parsed); numbers are now YAML 1.2's, and nothing else is taken for one."""
    scn, diags = load_scenario(_scenario(tmp_path, "  speed: 5", f"  speed: {value}"))
    if code is None:
        assert scn is not None and scn.spec.ego.speed == float(value)
    else:
        assert scn is None and _errors(diags) == [(code, "scn.yaml", 5, 10)]


def test_a_seed_beyond_64_bits_is_refused(tmp_path: Path) -> None:
    scn, diags = load_scenario(_scenario(tmp_path, "rules: []", "rules: []\nrun: {seed: 100000000000000000000}"))
    assert scn is None and _errors(diags) == [("YML414", "scn.yaml", 12, 13)]


# --------------------------------------------------------------------------------- the layout


def test_arc_tighter_than_a_lane_offset_is_refused_at_its_radius(tmp_path: Path) -> None:
    """An arc whose radius is smaller than a lane's offset on its inner side folded the lane
    (negative arc lengths) and was accepted."""
    # the left bend's inner lane 'l' sits 1.75 m left, 3.5 m wide: the radius must exceed 3.5 m
    bad = MAP.replace("arc: {radius: 50, angle: 90}", "arc: {radius: 3, angle: 90}")
    mp, diags = load_map(write(tmp_path, "map.yaml", bad))
    assert mp is None and ("YML420", "map.yaml", 8, 23) in _errors(diags), diags
    fold = next(d for d in diags if d.code == "YML420" and d.span.line == 8)
    assert "lane 'l' folds" in fold.message and "3.5" in (fold.hint or "")
    ok = MAP.replace("arc: {radius: 50, angle: 90}", "arc: {radius: 3.6, angle: 90}").replace(
        "start: {x: 150, y: 50, heading: 90}", "start: {x: 103.6, y: 3.6, heading: 90}")
    mp, diags = load_map(write(tmp_path, "ok.yaml", ok))
    assert mp is not None and diags == []


@pytest.mark.parametrize(
    "segment, line, column, words",
    [
        ("- points: [[110, 0], [120, 0], [120, 0]]", 8, 38, "0 m from the point before"),
        ("- points: [[100, 0], [120, 0]]", 8, 18, "from where the segment starts"),
        ("- arc: {radius: 4, angle: 0.1}", 8, 14, "m long"),
    ],
)
def test_degenerate_pieces_are_refused_where_they_are(tmp_path: Path, segment: str, line: int, column: int,
                                                       words: str) -> None:
    text = MAP.replace("      - arc: {radius: 50, angle: 90}\n", f"      {segment}\n", 1).replace(
        "successors: [next]", "successors: []")
    mp, diags = load_map(write(tmp_path, "map.yaml", text))
    assert mp is None and ("YML420", "map.yaml", line, column) in _errors(diags), diags
    assert any(words in d.message for d in diags)


@pytest.mark.parametrize(
    "start, words",
    [("start: {x: 150, y: 80, heading: 90}", "starts 30.1 m from the end"),
     ("start: {x: 151.75, y: 50, heading: 270}", "heading 180° away")],
)
def test_successor_that_does_not_connect_is_refused(tmp_path: Path, start: str, words: str) -> None:
    mp, diags = load_map(write(tmp_path, "map.yaml", MAP.replace("start: {x: 150, y: 50, heading: 90}", start)))
    assert mp is None and _errors(diags) == [("YML420", "map.yaml", 10, 64)], diags
    assert words in diags[0].message


@given(st.lists(st.one_of(
    st.floats(1, 80).map(lambda x: {"line": x}),
    st.tuples(st.floats(8, 200), st.floats(-180, 180).filter(lambda a: abs(a) > 1)).map(
        lambda ra: {"arc": {"radius": ra[0], "angle": ra[1]}}),
    st.lists(st.tuples(st.floats(-60, 60), st.floats(-60, 60)), min_size=1, max_size=3).map(
        lambda d: {"points": d}),
), min_size=1, max_size=5), st.floats(-3.5, 3.5), st.sampled_from(["forward", "backward"]))
@settings(max_examples=60, deadline=None)
def test_pure_python_lane_lengths_are_the_sampled_lanes_lengths(segments, offset: float, direction: str) -> None:
    """``check`` measures lanes without numpy; the sampled lanes must have the same lengths, or
    a position ``check`` accepts lies beyond the lane the simulator builds (offset polylines
    were measured without their corners)."""
    from twolevel.world.geometry import lane_from_reference, sample_road
    from twolevel.world.layout import lane_length
    from twolevel.world.schema import Road

    x, y, pieces = 0.0, 0.0, []
    for seg in segments:  # polyline points relative to where the road was: keep them apart
        if "points" in seg:
            pts = []
            for dx, dy in seg["points"]:
                if math.hypot(dx, dy) < 1:
                    dx += 5
                x, y = x + dx, y + dy
                pts.append([x, y])
            seg = {"points": pts}
        pieces.append(seg)
    road = Road.model_validate({"id": "r", "segments": pieces, "lanes": [{"id": "a", "offset": offset, "direction": direction}]})
    lane = lane_from_reference(sample_road(road), offset=offset, direction=direction, lane_id="a", index=0, width=3.5)
    assert lane_length(road, offset) == pytest.approx(lane.length, rel=1e-9, abs=1e-9)


# --------------------------------------------------------------------------------- the route


def test_route_spacing_is_bounded_below(tmp_path: Path) -> None:
    """A spacing of 1e-5 m took 7.3 GB and 44 s before crashing."""
    scn, diags = load_scenario(_scenario(tmp_path, "goal: {lane: next, s: 45}",
                                         "goal: {lane: next, s: 45}\n  spacing: 0.00001"))
    assert scn is None and _errors(diags) == [("YML414", "scn.yaml", 9, 12)]
    assert ">= 0.1" in diags[0].message


def test_route_points_are_bounded(tmp_path: Path) -> None:
    """Looping through a lane many times multiplies the route's reference points."""
    laps = ", ".join(["r"] * 1 + ["next"])
    m = MAP.replace("  - id: next\n    start: {x: 150, y: 50, heading: 90}\n    segments:\n      - line: 50\n",
                    "  - id: next\n    start: {x: 150, y: 50, heading: 90}\n    segments:\n      - line: 50\n"
                    "      - line: 99999\n")
    scn, diags = load_scenario(_scenario(tmp_path, "goal: {lane: next, s: 45}",
                                         f"goal: {{lane: next, s: 100040}}\n  via: [{laps}]\n  spacing: 1",
                                         map_text=m))
    assert scn is None and _errors(diags) == [("YML420", "scn.yaml", 10, 12)], diags
    assert "reference points" in diags[0].message and "at least" in (diags[0].hint or "")


def test_empty_via_is_a_diagnostic_in_check_plan_and_simulate(tmp_path: Path) -> None:
    """`route: {via: []}` was an internal error in check, plan and simulate."""
    p = _scenario(tmp_path, "goal: {lane: next, s: 45}", "goal: {lane: next, s: 45}\n  via: []")
    assert _errors(check_world_file(p)) == [("YML414", "scn.yaml", 9, 8)]
    for args in (["plan", str(p)], ["simulate", str(p), "--out", str(tmp_path / "run"), "--no-progress"]):
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and isinstance(res.exception, (SystemExit, type(None))), res.output
        assert "YML414" in res.stderr and "internal error" not in res.stderr


# ------------------------------------------------------------------------------------ paths


def test_unusable_paths_are_diagnostics(tmp_path: Path) -> None:
    """A NUL in a path raised ValueError and a name longer than the system allows OSError."""
    p = _scenario(tmp_path, "rules: []", 'rules: ["a\\0b.stl", ' + "x" * 300 + ".stl]")
    assert _errors(check_world_file(p)) == [("YML415", "scn.yaml", 11, 9)]
    p = _scenario(tmp_path, "rules: []", "rules: [" + "x" * 300 + ".stl]")
    assert _errors(check_world_file(p)) == [("YML418", "scn.yaml", 11, 9)]
    p = _scenario(tmp_path, "map: map.yaml", 'map: "m\\0.yaml"\nextends: "e\\0.yaml"')
    assert [c for c, *_ in _errors(check_world_file(p))] == ["YML415", "YML415"]


@pytest.mark.parametrize("entry", ["map: loop.yaml", "map: map.yaml\nextends: loop.yaml", "rules: [loop.yaml]"])
def test_a_loop_of_symbolic_links_is_a_diagnostic(tmp_path: Path, entry: str) -> None:
    """Path.resolve() raised RuntimeError on a loop of links: an internal error in check."""
    (tmp_path / "loop.yaml").symlink_to("other.yaml")
    (tmp_path / "other.yaml").symlink_to("loop.yaml")
    old = "rules: []" if entry.startswith("rules") else "map: map.yaml"
    res = runner.invoke(app, ["check", str(_scenario(tmp_path, old, entry)), "--output-format", "concise"])
    assert res.exit_code == 1 and isinstance(res.exception, (SystemExit, type(None))), res.output
    assert "YML418" in res.output and "internal error" not in res.output


# -------------------------------------------------------------------------------- rule names

SPEED = "input float v\nconst float tol = 0.5\nspeed_limit = always[0:1] (v <= 30 + tol);\n"


def test_two_files_defining_one_rule_are_refused_naming_both(tmp_path: Path) -> None:
    """collision.stl and safe_distance.stl both define no_collision: check and plan passed,
    simulate crashed at step 0 (duplicate trace columns)."""
    rules = ROOT / "rules"
    p = _scenario(tmp_path, "rules: []", f"rules:\n  - {rules / 'collision.stl'}\n  - {rules / 'safe_distance.stl'}")
    assert _errors(check_world_file(p)) == [("YML428", "scn.yaml", 13, 5)]
    d = next(d for d in check_world_file(p) if d.code == "YML428")
    assert "'no_collision'" in d.message and "collision.stl:15" in d.message and "safe_distance.stl:17" in d.message
    run_dir = tmp_path / "run"
    for args in (["plan", str(p)], ["simulate", str(p), "--out", str(run_dir), "--no-progress"]):
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and "YML428" in res.stderr and "SIM613" not in res.stderr, res.output
    assert not run_dir.exists()  # refused before the run started


def test_one_file_listed_twice_is_refused(tmp_path: Path) -> None:
    (tmp_path / "speed.stl").write_text(SPEED)
    p = _scenario(tmp_path, "rules: []", "rules:\n  - speed.stl\n  - {file: speed.stl, constants: {tol: 1}}")
    diags = check_world_file(p)
    assert _errors(diags) == [("YML428", "scn.yaml", 13, 12)]
    assert "listed twice" in diags[0].message and "scn.yaml:12" in diags[0].message


def test_distinct_rule_names_across_files_are_fine(tmp_path: Path) -> None:
    (tmp_path / "speed.stl").write_text(SPEED)
    p = _scenario(tmp_path, "rules: []", f"rules:\n  - speed.stl\n  - {ROOT / 'rules' / 'safe_distance.stl'}")
    assert _errors(check_world_file(p)) == []


# ------------------------------------------------------------------------ vehicle parameters


def test_every_vehicle_parameter_is_checked_against_a_finite_range() -> None:
    """Every parameter has a range; defaults lie in it; NaN, ±inf and values past either end are
    refused (the old checks let NaN through every `<= 0` and had no upper bounds)."""
    from dataclasses import fields

    from twolevel.models.params import (
        BICYCLE_RANGES, VEHICLE_RANGES, BicycleParams, InvalidParameterError, VehicleParams,
    )

    for params, ranges in ((BicycleParams(), BICYCLE_RANGES), (VehicleParams(), VEHICLE_RANGES)):
        assert set(ranges) == {f.name for f in fields(params)}
        params.validate()
        for name, rng in ranges.items():
            for bad in (math.nan, math.inf, -math.inf, rng.hi + abs(rng.hi) + 1, rng.lo - abs(rng.lo) - 1):
                with pytest.raises(InvalidParameterError):
                    params.with_overrides({name: bad})
            for good in (rng.lo, rng.hi):
                open_end = (good == rng.lo and rng.lo_open) or (good == rng.hi and rng.hi_open)
                if open_end:
                    with pytest.raises(InvalidParameterError):
                        params.with_overrides({name: good})
                else:
                    assert getattr(params.with_overrides({name: good}), name) == good


# ------------------------------------------------------------------------------ populations


def test_a_population_of_tiny_boxes_is_refused_at_the_box(tmp_path: Path) -> None:
    """Boxes 1e-300 m long with no gap made build_world enumerate 1e303 places (ValueError:
    Maximum allowed size exceeded); 1e-6 m asked numpy for 4 GB."""
    pop = "populations:\n  - {id: crowd, count: 5, lanes: [r], min_gap: 0, box: {length: 1.0e-300, width: 1.8}}"
    scn, diags = load_scenario(_scenario(tmp_path, "rules: []", f"rules: []\n{pop}"))
    assert scn is None and _errors(diags) == [("YML414", "scn.yaml", 13, 65)], diags


def test_a_population_with_too_many_places_is_refused(tmp_path: Path) -> None:
    long_map = MAP.replace("      - line: 50\n", "      - line: 50\n" + "      - line: 100000\n" * 4)
    pop = "populations:\n  - {id: crowd, count: 5, lanes: [next], min_gap: 0, box: {length: 0.3}}"
    scn, diags = load_scenario(_scenario(tmp_path, "rules: []", f"rules: []\n{pop}", map_text=long_map))
    assert scn is None and _errors(diags) == [("YML420", "scn.yaml", 13, 51)], diags
    assert "places to choose from" in diags[0].message and "s_range" in (diags[0].hint or "")
    ok = pop.replace("min_gap: 0,", "min_gap: 0, s_range: [0, 1000],")
    scn, diags = load_scenario(_scenario(tmp_path, "rules: []", f"rules: []\n{ok}", map_text=long_map))
    assert scn is not None and _errors(diags) == []


def test_a_lane_listed_twice_in_a_population_is_refused(tmp_path: Path) -> None:
    pop = "populations:\n  - {id: crowd, count: 5, lanes: [next, next]}"
    scn, diags = load_scenario(_scenario(tmp_path, "rules: []", f"rules: []\n{pop}"))
    assert scn is None and _errors(diags) == [("YML417", "scn.yaml", 13, 41)], diags


@pytest.mark.parametrize("setting, column",
                         [("H: 101", 17), ("r_near: 201", 22), ("samples: 10001", 23), ("dt: 0.001", 18)])
def test_controller_settings_that_make_a_run_take_long_are_refused(tmp_path: Path, setting: str, column: int) -> None:
    """H = 200 with r_near = 500 m on the safety scenario took 15 s for 2 s of simulated time,
    100,000 samples 28 s, and dt = 1e-6 s made `simulate --duration 2` two million steps: the
    ranges now end where a step still takes a fraction of a second."""
    scn, diags = load_scenario(_scenario(tmp_path, "rules: []", f"rules: []\ncontroller: {{{setting}}}"))
    assert scn is None and _errors(diags) == [("YML414", "scn.yaml", 12, column)], diags


def test_a_run_shorter_than_one_control_period_is_refused(tmp_path: Path) -> None:
    """`run: {duration: 1e-300}` simulated no step at all and called the run complete."""
    scn, diags = load_scenario(_scenario(tmp_path, "rules: []", "rules: []\nrun: {duration: 0.05}"))
    assert scn is None and _errors(diags) == [("YML414", "scn.yaml", 12, 17)], diags
    scn, diags = load_scenario(_scenario(tmp_path, "rules: []", "rules: []\nrun: {duration: 0.1}"))
    assert scn is not None


@pytest.mark.parametrize("idm, column", [("v0: 1.0e-300", 69), ("a: 0.001", 68), ("b: 0.001", 68)])
def test_idm_parameters_that_overflow_its_acceleration_are_refused(tmp_path: Path, idm: str, column: int) -> None:
    """v0 = 1e-300 overflowed (v/v0)^delta, a·b = 1e-600 divided by zero in the desired gap:
    the IDM's acceleration became -inf (numpy warned; the vehicles stood still)."""
    p = _scenario(tmp_path, "  - {id: parked, behaviour: stationary, start: {lane: r, s: 60}}",
                  f"  - {{id: parked, behaviour: idm, start: {{lane: r, s: 60}}, idm: {{{idm}}}}}")
    scn, diags = load_scenario(p)
    assert scn is None and _errors(diags) == [("YML414", "scn.yaml", 10, column)], diags
