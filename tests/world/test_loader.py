"""Golden cases for loading maps and scenarios: each error kind, its code and its line."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers.world_files import MAP, SCENARIO, write
from twolevel.world.loader import check_world_file, load_map, load_scenario

def codes_lines(diags):
    return [(d.code, d.span.line) for d in diags]


@pytest.fixture
def world(tmp_path: Path) -> Path:
    write(tmp_path, "map.yaml", MAP)
    return write(tmp_path, "scn.yaml", SCENARIO)


def test_clean_map_and_scenario_load(world: Path) -> None:
    scn, diags = load_scenario(world)
    assert diags == []
    assert scn is not None and scn.map.spec.name == "tiny"
    assert [p.id for p in scn.spec.participants] == ["parked"]
    assert scn.spec.controller.H == 10 and scn.spec.controller.dt == 0.1
    assert scn.spec.controller.r_near is None  # by default 2 s at the fastest speed allowed (test_near_radius.py)
    assert scn.spec.ego.box.length == 4.22 and scn.spec.ego.box.width == 1.8
    assert check_world_file(world) == []


@pytest.mark.parametrize(
    "old, new, code, line, words",
    [
        ("speed_limit: 13.9", "sped_limit: 13.9", "YML411", 10, "did you mean 'speed_limit'"),
        ("radius: 50", "radius: fifty", "YML413", 8, "must be a number [m]"),
        ("radius: 50", "radius: -50", "YML414", 8, "must be > 0"),
        ("direction: backward", "direction: sideways", "YML415", 11, "'forward' or 'backward'"),
        ("successors: [next]", "successors: [nxt]", "YML416", 10, "no lane 'nxt'"),
        ("id: l,", "id: r,", "YML417", 11, "duplicate lane id 'r'"),
        ("{id: stop1, lane: r, s: 80}", "{id: stop1, lane: r, s: 800}", "YML420", 19, "beyond the end"),
        ("  - id: next\n    start", "  - id: next\n    strat", "YML411", 13, "did you mean 'start'"),
        ("      - line: 50\n", "      - line: 50\n        arc: {radius: 3, angle: 9}\n", "YML415", 15, "exactly one of"),
        ("    segments:\n      - line: 50\n", "", "YML412", 12, "missing key 'segments'"),
    ],
)
def test_map_errors_golden(tmp_path: Path, old: str, new: str, code: str, line: int, words: str) -> None:
    assert old in MAP
    p = write(tmp_path, "map.yaml", MAP.replace(old, new, 1))
    m, diags = load_map(p)
    assert m is None
    assert (code, line) in codes_lines(diags), diags
    assert any(words in d.message or words in (d.hint or "") for d in diags if d.code == code), diags


@pytest.mark.parametrize(
    "old, new, code, line",
    [
        ("map: map.yaml", "map: nomap.yaml", "YML418", 2),
        ("map: map.yaml", "map: scn.yaml", "YML410", 2),
        ("  speed: 5", "  speed: [5]", "YML413", 5),
        ("goal: {lane: next, s: 45}", "goal: {lane: nxt, s: 45}", "YML416", 8),
        ("goal: {lane: next, s: 45}", "goal: {lane: l, s: 45}", "YML420", 8),
        ("rules: []", "rules: [missing.stl]", "YML418", 11),
        ("rules: []", "rules: []\ncontroler: {H: 5}", "YML411", 12),
        ("rules: []", "rules: []\ncontroller: {H: 0}", "YML414", 12),
        ("rules: []", "rules: []\ncontroller: {solver: gurobi}", "YML415", 12),
        ("rules: []", "rules: []\npopulations:\n  - {id: parked, count: 3, lanes: [r]}", "YML417", 13),
        ("  - {id: parked", "  - {id: parked2, behaviour: idm, start: {lane: rr, s: 9}}\n  - {id: parked", "YML416", 10),
    ],
)
def test_scenario_errors_golden(tmp_path: Path, old: str, new: str, code: str, line: int) -> None:
    write(tmp_path, "map.yaml", MAP)
    p = write(tmp_path, "scn.yaml", SCENARIO.replace(old, new, 1))
    scn, diags = load_scenario(p)
    assert scn is None
    assert (code, line) in codes_lines(diags), diags


def test_map_errors_point_into_the_map(tmp_path: Path) -> None:
    write(tmp_path, "map.yaml", MAP.replace("value: 8.3", "value: 0"))
    p = write(tmp_path, "scn.yaml", SCENARIO)
    scn, diags = load_scenario(p)
    assert scn is None
    assert [(d.code, Path(d.span.file).name, d.span.line) for d in diags] == [("YML414", "map.yaml", 17)]


def test_wrong_kind_scenario_given_a_map(world: Path) -> None:
    scn, diags = load_scenario(world.parent / "map.yaml")
    assert scn is None and [d.code for d in diags] == ["YML410"]
    m, diags = load_map(world)
    assert m is None and [d.code for d in diags] == ["YML410"]


def test_extends_overrides_and_cycles(tmp_path: Path, world: Path) -> None:
    child = write(tmp_path, "child.yaml", "extends: scn.yaml\nrun: {duration: 7}\nego: {speed: 2}\n")
    scn, diags = load_scenario(child)
    assert diags == [] and scn is not None
    assert scn.spec.run.duration == 7 and scn.spec.ego.speed == 2 and scn.spec.ego.start.s == 5
    write(tmp_path, "a.yaml", "kind: scenario\nextends: b.yaml\n")
    b = write(tmp_path, "b.yaml", "kind: scenario\nextends: a.yaml\n")
    scn, diags = load_scenario(b)
    assert scn is None and [(d.code, d.span.line) for d in diags] == [("YML419", 2)]
    bad = write(tmp_path, "bad.yaml", "kind: scenario\nextends: scn.yaml\nego: {sped: 2}\n")
    scn, diags = load_scenario(bad)
    assert [(d.code, Path(d.span.file).name, d.span.line) for d in diags] == [("YML411", "bad.yaml", 3)]


# ---------------------------------------------------------------------------- hostile YAML

BOMB = """\
kind: map
a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]
b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]
c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]
d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]
e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]
f: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]
g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]
h: &h [*g,*g,*g,*g,*g,*g,*g,*g,*g]
i: &i [*h,*h,*h,*h,*h,*h,*h,*h,*h]
"""


@pytest.mark.parametrize(
    "content, code, line",
    [
        (b"kind: map\nroads: !!python/object/apply:os.system ['echo hacked']\n", "YML407", 2),
        (b"kind: map\nx: !!python/name:os.system\n", "YML407", 2),
        (b"kind: map\nroads: !!binary aGVsbG8=\n", "YML407", 2),
        (b"kind: map\nroads: !custom 3\n", "YML407", 2),
        (BOMB.encode(), "YML408", None),
        (b"kind: map\na: &a [*a]\n", "YML408", 2),
        (b"kind: map\nroads: \x00\x01\x02\n", "YML403", 2),
        (b"kind: map\nname: caf\xe9\n", "YML404", 2),
        (b"", "YML405", 1),
        (b"# only a comment\n", "YML405", 1),
        (b"kind: map\nkind: map\n", "YML409", 2),
        (b"kind: map\nroads: [1, 2\n", "YML406", None),
        (b"- just\n- a list\n", "YML422", 1),
        (b"[" * 5000, None, None),
    ],
)
def test_hostile_yaml_refused(tmp_path: Path, content: bytes, code: str | None, line: int | None) -> None:
    p = tmp_path / "evil.yaml"
    p.write_bytes(content)
    start = time.perf_counter()
    m, diags = load_map(p)
    assert time.perf_counter() - start < 15.0  # a hang guard (alias bombs, deep nesting), not a speed claim
    assert m is None and len(diags) == 1
    if code is not None:
        assert diags[0].code == code, diags
    else:
        assert diags[0].code.startswith("YML4")
    if line is not None:
        assert diags[0].span.line == line


def test_enormous_file_refused_by_size(tmp_path: Path) -> None:
    p = tmp_path / "big.yaml"
    p.write_bytes(b"kind: map\n" + b"# padding padding padding padding\n" * 300_000)
    assert p.stat().st_size > 10_000_000
    import tracemalloc

    tracemalloc.start()
    m, diags = load_map(p)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 1_000_000  # refused by its size: the 10 MB were never read
    assert m is None and [d.code for d in diags] == ["YML402"]


def test_missing_file_and_directory(tmp_path: Path) -> None:
    assert [d.code for d in load_map(tmp_path / "nope.yaml")[1]] == ["YML401"]
    assert [d.code for d in load_map(tmp_path)[1]] == ["YML401"]


def test_anchors_and_merge_keys_are_fine(tmp_path: Path) -> None:
    text = MAP.replace("  - {id: sl1, lane: r, s: 60, value: 8.3}",
                       "  - &sign {id: sl1, lane: r, s: 60, value: 8.3}\n  - {<<: *sign, id: sl2, s: 70}")
    m, diags = load_map(write(tmp_path, "map.yaml", text))
    assert diags == [] and m is not None
    assert [(s.id, s.s, s.value) for s in m.spec.speed_limits] == [("sl1", 60, 8.3), ("sl2", 70, 8.3)]


def test_check_path_does_not_import_numpy(world: Path) -> None:
    code = (
        "import sys\nfrom twolevel.world.loader import check_world_file\n"
        f"assert check_world_file({str(world)!r}) == []\n"
        "bad = sorted(m for m in ('numpy', 'scipy', 'casadi', 'matplotlib') if m in sys.modules)\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def _returns_within(fn, fifo: Path, seconds: float = 5.0):
    """``fn()``'s result, failing (not hanging) if it blocks: a reader stuck on the FIFO is
    released by opening the write end and closing it (end of file)."""
    import os
    import threading

    box: list = []
    th = threading.Thread(target=lambda: box.append(fn()), daemon=True)
    th.start()
    th.join(seconds)
    if th.is_alive():
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
        th.join(seconds)
        pytest.fail(f"reading {fifo} blocked")
    return box[0]


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="no FIFOs here")
def test_fifo_is_refused_without_blocking(tmp_path: Path) -> None:
    import os

    fifo = tmp_path / "fifo.yaml"
    os.mkfifo(fifo)
    m, diags = _returns_within(lambda: load_map(fifo), fifo)
    assert m is None and [d.code for d in diags] == ["YML401"] and "FIFO" in diags[0].message
    write(tmp_path, "map.yaml", MAP)
    scn = write(tmp_path, "scn.yaml", SCENARIO.replace("map: map.yaml", "map: fifo.yaml"))
    s, diags = _returns_within(lambda: load_scenario(scn), fifo)
    assert s is None and codes_lines(diags) == [("YML418", 2)] and "FIFO" in diags[0].message, diags


@pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero")
def test_device_file_is_refused_without_reading_it() -> None:
    m, diags = load_map("/dev/zero")
    assert m is None and [d.code for d in diags] == ["YML401"] and "device" in diags[0].message


def test_shared_reader_reads_at_most_the_limit(tmp_path: Path) -> None:
    from twolevel.files import read_regular

    p = tmp_path / "f.txt"
    p.write_bytes(b"x" * 100)
    assert read_regular(p, 100) == (b"x" * 100, None)
    data, refusal = read_regular(p, 99)
    assert data is None and refusal is not None and refusal.kind == "too-large" and refusal.size == 100
    assert read_regular(tmp_path / "nope", 10)[1].kind == "missing"
    assert read_regular(tmp_path, 10)[1].kind == "directory"


@pytest.mark.parametrize(
    "goal, words",
    [
        ("goal: {lane: r, s: 5}", "0 m long"),  # the goal is the start: spacing 0, divisions by zero
        ("goal: {lane: r, s: 5.3}", "0.3 m long"),
        ("goal: {lane: r, s: 2}", "behind the start"),  # used to say "no way from lane 'r' to lane 'r'"
        ("goal: {lane: r, s: 2}\n  via: [r]", "-3 m long"),
    ],
)
def test_route_too_short_or_backwards_is_refused_at_the_goal(tmp_path: Path, goal: str, words: str) -> None:
    write(tmp_path, "map.yaml", MAP)
    p = write(tmp_path, "scn.yaml", SCENARIO.replace("goal: {lane: next, s: 45}", goal, 1))
    scn, diags = load_scenario(p)
    assert scn is None and codes_lines(diags) == [("YML420", 8)], diags
    assert words in diags[0].message and diags[0].span.column > 1
    assert check_world_file(p) != []


def test_short_route_on_the_next_lane_is_measured_across_lanes(tmp_path: Path) -> None:
    write(tmp_path, "map.yaml", MAP)
    p = write(tmp_path, "scn.yaml", SCENARIO.replace("goal: {lane: next, s: 45}", "goal: {lane: next, s: 0.5}", 1))
    scn, diags = load_scenario(p)
    assert diags == [] and scn is not None  # 100 m + a 50 m-radius quarter arc - 5 m + 0.5 m: long enough


@pytest.mark.parametrize("value", [".nan", ".inf", "-.inf", "1e999"])
def test_non_finite_rule_constant_is_refused_at_its_value(tmp_path: Path, value: str) -> None:
    write(tmp_path, "map.yaml", MAP)
    (tmp_path / "speed.stl").write_text("input float v\nconst float tol\nr = always[0:1] (v <= 10 + tol);\n")
    rules = "rules:\n  - file: speed.stl\n    constants: {tol: " + value + "}"
    p = write(tmp_path, "scn.yaml", SCENARIO.replace("rules: []", rules, 1))
    scn, diags = load_scenario(p)
    assert scn is None and codes_lines(diags) == [("YML414", 13)], diags
    assert "finite" in diags[0].message and diags[0].span.column == 22  # the value, not the key
    ok = write(tmp_path, "ok.yaml", SCENARIO.replace("rules: []", rules.replace(value, "0.5"), 1))
    assert load_scenario(ok)[1] == []


def test_a_document_read_again_is_a_fresh_copy_and_follows_the_file(tmp_path: Path) -> None:
    """Documents are kept by content (loading reads a scenario and its map again per stage):
    changing one read's data changes no later read, and a changed file is read anew."""
    from twolevel.world.document import read_document

    path = tmp_path / "m.yaml"
    path.write_text("a: {b: [1, 2]}\nc: &x [3]\nd: *x\n", encoding="utf-8")
    first, _ = read_document(path)
    assert first is not None
    first.data["a"]["b"].append(99)
    first.where.clear()
    again, _ = read_document(path)
    assert again is not None and again.data == {"a": {"b": [1, 2]}, "c": [3], "d": [3]} and again.where
    path.write_text("a: 1\na: 2\n", encoding="utf-8")
    refused, diags = read_document(path)
    assert refused is None and diags and diags[0].code == "YML409"
    diags.clear()
    assert read_document(path)[1][0].code == "YML409"
