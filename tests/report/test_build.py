"""The report renders (figures, HTML, summaries, GIF), stays self-contained, and degrades to a
partial report or a ReportError on damaged run directories."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from PIL import Image

from twolevel.report import ReportError, build_report
from twolevel.report.animation import render_gif
from twolevel.report.figures import FIGURES
from twolevel.sim.trace import read_run

PNG = b"\x89PNG\r\n\x1a\n"


def _svg_texts(path: Path) -> str:
    """Matplotlib writes each text drawn as paths with the text in a comment."""
    return " ".join(re.findall(r"<!-- (.*?) -->", path.read_text(encoding="utf-8")))


def assert_self_contained(page: str) -> None:
    refs = re.findall(r"""(?:src|href)\s*=\s*["']([^"']*)["']""", page, flags=re.I)
    refs += re.findall(r"""url\(\s*["']?([^"')]*)""", page, flags=re.I)
    assert all(r.startswith("data:") or r.startswith("#") for r in refs), [r[:60] for r in refs if not r.startswith("data:")]
    for bad in ("http://", "https://", "//cdn", "<link", "<script", "@import"):
        assert bad not in page.lower(), bad


def test_traffic_rules_run_renders_every_figure_and_summary(make_traffic_run) -> None:
    run = make_traffic_run("traffic_rules")
    res = build_report(run, gif=False)
    assert res.problems == () and res.out_dir == str(run)
    for name in FIGURES:
        png, svg = run / "figures" / f"{name}.png", run / "figures" / f"{name}.svg"
        assert png.read_bytes().startswith(PNG) and svg.read_text(encoding="utf-8").lstrip().startswith("<?xml")
        assert str(png) in res.files and str(svg) in res.files
    page = (run / "report.html").read_text(encoding="utf-8")
    assert_self_contained(page)
    assert page.count('src="data:image/png;base64,') == len(FIGURES)
    assert "No violation" in page and "No collision" in page and "sha256:abc123" in page and "CRASHED" not in page
    assert "traffic_rules" in page and "speed_limit" in page
    summary = json.loads((run / "summary.json").read_text(encoding="utf-8"))
    assert summary["metrics"]["rows"] == 300 and summary["metrics"]["violations"] == []
    assert summary["provenance"]["seed"] == 7 and summary["provenance"]["status"] == "complete"
    assert summary["metrics"]["distance"]["collision_line_m"] == 4.22
    md = (run / "summary.md").read_text(encoding="utf-8")
    assert "| control step p50 / p95 / p99 / max |" in md and "None: every rule" in md
    # the figures say what they show: units, limits dashed and named, the collision line
    assert "speed [m/s]" in _svg_texts(run / "figures" / "speed.svg") and "speed limit in force" in _svg_texts(run / "figures" / "speed.svg")
    dist = _svg_texts(run / "figures" / "distance.svg")
    assert "4.22 m: collision (paper's measure)" in dist and "min. distance [m]" in dist
    assert "10 Hz requirement (100 ms per step)" in _svg_texts(run / "figures" / "control_rate.svg")
    assert not list(run.rglob(".*.tmp"))  # atomic writes leave nothing behind


def test_violations_and_collision_are_reported_with_animation(make_traffic_run) -> None:
    summary = {"collisions": [{"t": 6.5, "x": 70.0, "y": 0.0, "other": "parked_1"}]}
    run = make_traffic_run("crash", violate=True, collide=True, frames=True, summary=summary)
    res = build_report(run, formats=("png",))
    m = res.metrics
    assert m.collisions.collided and m.collisions.reported[0].other == "parked_1"
    assert {v.rule for v in m.violations} == {"speed_limit", "collision"}
    sl = next(v for v in m.violations if v.rule == "speed_limit")
    assert sl.depth == pytest.approx(-1.0) and sl.t_start == pytest.approx(15.1) and sl.t_end == pytest.approx(16.9)
    page = (run / "report.html").read_text(encoding="utf-8")
    assert_self_contained(page)
    assert 'class="alert">COLLISION' in page and "parked_1" in page and "rule violation(s) in collision, speed_limit" in page
    assert "<td>speed_limit</td><td class=\"num\">15.10</td><td class=\"num\">16.90</td>" in page
    assert not list((run / "figures").glob("*.svg"))  # only the formats asked for
    # the GIF: real, subsampled to at most 200 frames, embedded, deterministic
    gif = (run / "animation.gif").read_bytes()
    assert gif.startswith(b"GIF89a") and 'src="data:image/gif;base64,' in page
    with Image.open(run / "animation.gif") as im:
        assert im.n_frames == 200 and im.size == (440, 440)
    assert "200 of 300 recorded steps" in page
    data = read_run(run)
    small = render_gif(run / "frames.jsonl", data.meta, data.columns, max_frames=12)
    assert small.frames == 12 and small.total == 300 and small.problems == ()
    assert render_gif(run / "frames.jsonl", data.meta, data.columns, max_frames=12).gif == small.gif


def test_comparison_overlays_runs_and_tabulates_ratios(make_traffic_run) -> None:
    fast = make_traffic_run("twolevel", n=120)
    slow = make_traffic_run("nmpc", n=120, slow=4.0, seed=3)
    res = build_report(fast, [slow], gif=False, formats=("svg",))
    assert [m.label for m in (res.metrics, *res.compared)] == ["twolevel", "nmpc"]
    row = res.comparison.row("latency_p50")
    assert row.ratios[0] == 1.0 and row.ratios[1] == pytest.approx(row.values[1] / row.values[0]) and row.ratios[1] > 3
    for name in ("control_rate", "latency", "speed", "distance", "robustness"):
        texts = _svg_texts(fast / "figures" / f"{name}.svg")
        assert "twolevel" in texts and "nmpc" in texts, name
    page = (fast / "report.html").read_text(encoding="utf-8")
    assert_self_contained(page)
    assert "<h2>Comparison</h2>" in page and "(×" in page and str(slow) in page
    summary = json.loads((fast / "summary.json").read_text(encoding="utf-8"))
    assert summary["comparison"]["runs"] == ["twolevel", "nmpc"] and len(summary["compared"]) == 1
    assert "## Comparison (ratio to the first run)" in (fast / "summary.md").read_text(encoding="utf-8")


def test_same_directory_names_get_distinct_labels(tmp_path, make_traffic_run) -> None:
    from helpers.report_runs import traffic_rows, write_run

    a = write_run(tmp_path / "with" / "run", traffic_rows(20)[0])
    b = write_run(tmp_path / "without" / "run", traffic_rows(20)[0])
    res = build_report(a, [b], gif=False, formats=())
    assert res.comparison.runs == ("with/run", "without/run")
    assert not (a / "figures").exists() or not list((a / "figures").iterdir())


def test_missing_run_json_and_frames_give_a_partial_report(make_traffic_run) -> None:
    run = make_traffic_run("partial", n=30)
    (run / "run.json").unlink()
    res = build_report(run, formats=())  # gif asked, but there is no frames.jsonl
    assert any("run.json is missing" in p for p in res.problems)
    assert any("frames.jsonl is missing" in p for p in res.problems)
    page = (run / "report.html").read_text(encoding="utf-8")
    assert "partial" in page and "run.json is missing" in page and "No animation" in page
    assert "settings and provenance unknown" in page
    assert res.metrics.rows == 30 and not (run / "animation.gif").exists()


def test_truncated_crashed_run_says_so(make_traffic_run) -> None:
    run = make_traffic_run("crashed", n=40, status="crashed", meta={"error": "RuntimeError: solver exploded"})
    with open(run / "trace.csv", "a", encoding="utf-8") as fh:
        fh.write("4.0,12.5,0.1")  # the process died mid-row
    res = build_report(run, gif=False, formats=())
    assert res.metrics.rows == 40
    page = (run / "report.html").read_text(encoding="utf-8")
    assert 'class="alert">This run is CRASHED after 40 step(s): RuntimeError: solver exploded' in page
    assert 'class="alert">The trace is TRUNCATED' in page and "row 42 is truncated" in page
    assert "CRASHED" in (run / "summary.md").read_text(encoding="utf-8")


def test_missing_trace_with_run_json_reports_provenance_only(make_traffic_run) -> None:
    run = make_traffic_run("notrace", n=5)
    (run / "trace.csv").unlink()
    res = build_report(run, gif=False)
    assert res.metrics.rows == 0 and any("trace.csv is missing" in p for p in res.problems)
    page = (run / "report.html").read_text(encoding="utf-8")
    assert "No steps could be read" in page and "sha256:abc123" in page and "<figure" not in page


def test_nothing_readable_is_a_report_error(tmp_path) -> None:
    (tmp_path / "empty").mkdir()
    with pytest.raises(ReportError, match="nothing to report in run directory .*empty.*run.json is missing"):
        build_report(tmp_path / "empty")
    with pytest.raises(ReportError, match="does not exist"):
        build_report(tmp_path / "nowhere")
    (tmp_path / "file.csv").write_text("t\n")
    with pytest.raises(ReportError, match="not a directory"):
        build_report(tmp_path / "file.csv")
    assert not list((tmp_path / "empty").iterdir())  # nothing written on failure


def test_bad_compare_run_and_format_are_report_errors(make_traffic_run, tmp_path) -> None:
    run = make_traffic_run("ok", n=5)
    (tmp_path / "hollow").mkdir()
    with pytest.raises(ReportError, match="run directory to compare .*hollow"):
        build_report(run, [tmp_path / "hollow"], gif=False)
    with pytest.raises(ReportError, match="unknown figure format.*'jpeg'"):
        build_report(run, formats=("jpeg",))
