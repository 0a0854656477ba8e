"""``build_report``: a run directory (and runs to compare it with) → metrics, figures, GIF,
``report.html``, ``summary.json`` and ``summary.md``. The library call behind
``twolevel report RUN_DIR [--compare OTHER ...]``.

A damaged run gives a partial report that lists what is missing (``ReportResult.problems``,
also shown at the top of the HTML page); a directory where nothing at all can be read raises
:class:`ReportError`, whose message is meant to be printed as is.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

from twolevel import __version__
from twolevel.atomic import write_text_atomic
from twolevel.report.comparison import ComparisonTable, compare_metrics
from twolevel.report.metrics import Metrics, compute_metrics
from twolevel.sim.trace import RunData, read_run, write_json_atomic

REPORT_FILE = "report.html"
SUMMARY_JSON = "summary.json"
SUMMARY_MD = "summary.md"
GIF_FILE = "animation.gif"
FIGURES_DIR = "figures"
FORMATS = ("png", "svg", "pdf")


class ReportError(Exception):
    """Nothing could be reported (no readable run, bad arguments, unwritable output). The
    message says what and where; the CLI prints it and exits 2."""


@dataclass(frozen=True)
class ReportResult:
    """What ``build_report`` wrote and found. ``metrics`` is the main run's; ``compared`` the
    others' in the order given; ``problems`` everything missing or doubtful, for the user."""

    out_dir: str
    files: tuple[str, ...]
    metrics: Metrics
    compared: tuple[Metrics, ...]
    comparison: ComparisonTable | None
    problems: tuple[str, ...]

    @property
    def html(self) -> str:
        return str(Path(self.out_dir) / REPORT_FILE)


def _load(run_dir: str | os.PathLike[str], role: str) -> RunData:
    path = Path(run_dir)
    if not path.exists():
        raise ReportError(f"{role} '{path}' does not exist")
    if not path.is_dir():
        raise ReportError(f"{role} '{path}' is not a directory (expected a run directory with trace.csv and run.json)")
    run = read_run(path)
    if run.rows == 0 and not run.meta:
        why = "; ".join(run.problems) or "no trace.csv and no run.json"
        raise ReportError(f"nothing to report in {role} '{path}': {why}")
    return run


def _labels(runs: Sequence[RunData]) -> list[str]:
    paths = [Path(r.run_dir).resolve() for r in runs]
    labels = [p.name or str(p) for p in paths]
    if len(set(labels)) < len(labels):
        labels = [f"{p.parent.name}/{p.name}" for p in paths]
    seen: dict[str, int] = {}
    out = []
    for lb in labels:
        seen[lb] = seen.get(lb, 0) + 1
        out.append(lb if seen[lb] == 1 and labels.count(lb) == 1 else f"{lb} #{seen[lb]}")
    return out


def _remove_stale(fig_dir: Path, written: set[str]) -> None:
    """Remove figures an earlier report wrote that this one did not (so the folder matches
    the page). Only names this package writes are touched."""
    from twolevel.report.figures import FIGURES

    for name in FIGURES:
        for fmt in FORMATS:
            f = fig_dir / f"{name}.{fmt}"
            if str(f) not in written and f.exists():
                f.unlink()


def build_report(
    run_dir: str | os.PathLike[str],
    compare: Sequence[str | os.PathLike[str]] = (),
    *,
    gif: bool = True,
    formats: Sequence[str] = ("png", "svg"),
    out_dir: str | os.PathLike[str] | None = None,
    max_frames: int = 200,
) -> ReportResult:
    """Write the report of ``run_dir`` (compared with ``compare``, overlaid in every figure)
    into ``out_dir`` (default: ``run_dir``): ``report.html``, ``summary.json``, ``summary.md``,
    ``figures/<name>.<fmt>`` and, with ``gif``, ``animation.gif`` from ``frames.jsonl``.

    Raises :class:`ReportError` when a run has nothing readable, a format is unknown or the
    output cannot be written."""
    bad = [f for f in formats if f not in FORMATS]
    if bad:
        raise ReportError(f"unknown figure format(s) {', '.join(map(repr, bad))}: choose from {', '.join(FORMATS)}")
    main = _load(run_dir, "run directory")
    others = [_load(c, "run directory to compare") for c in compare]
    runs = [main, *others]
    labels = _labels(runs)
    metrics = [compute_metrics(r, label=lb) for r, lb in zip(runs, labels)]
    problems: list[str] = list(metrics[0].problems)
    for m in metrics[1:]:
        problems += [f"[{m.label}] {p}" for p in m.problems]
    comparison = compare_metrics(metrics) if others else None
    out = Path(out_dir) if out_dir is not None else Path(run_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        return _write(out, runs, metrics, comparison, problems, gif=gif, formats=tuple(formats), max_frames=max_frames)
    except OSError as exc:
        raise ReportError(f"cannot write the report into '{out}': {exc.strerror or exc}") from exc


def _write(
    out: Path, runs: Sequence[RunData], metrics: Sequence[Metrics], comparison: ComparisonTable | None,
    problems: list[str], *, gif: bool, formats: tuple[str, ...], max_frames: int,
) -> ReportResult:
    from twolevel.report.figures import Series, render_figures
    from twolevel.report.html import render_html
    from twolevel.report.summary import render_markdown, summary_payload

    main, m0 = runs[0], metrics[0]
    files: list[str] = []
    from twolevel.report.road import road_of

    series = []
    for r, m in zip(runs, metrics):
        if m.rows > 0:
            road, why = road_of(r)
            if why is not None and r is main:
                problems.append(why)
            series.append(Series(m.label, r, m, road))
    figures: tuple[Any, ...] = ()
    if series:
        figures, skipped = render_figures(series, out / FIGURES_DIR, formats)
        problems += list(skipped)
        files += [f for fig in figures for f in fig.files]
    if (out / FIGURES_DIR).is_dir():
        _remove_stale(out / FIGURES_DIR, set(files))
    gif_bytes, gif_note = None, None
    if gif:
        from twolevel.report.animation import FRAMES_FILE, render_gif

        anim = render_gif(Path(main.run_dir) / FRAMES_FILE, main.meta, main.columns, max_frames=max_frames)
        problems += list(anim.problems)
        if anim.gif is not None:
            gif_bytes = anim.gif
            path = out / GIF_FILE
            from twolevel.atomic import write_bytes_atomic

            files.append(str(write_bytes_atomic(path, anim.gif)))
            if anim.total > anim.frames:
                gif_note = f"The animation shows {anim.frames} of {anim.total} recorded steps, evenly spaced, {anim.frame_ms} ms per frame."
        else:
            gif_note = "No animation: " + "; ".join(anim.problems)
    meta: Mapping[str, Any] = main.meta
    paths = [str(out / REPORT_FILE), str(out / SUMMARY_JSON), str(out / SUMMARY_MD)]
    all_files = files + paths
    page = render_html(
        m0, meta, figures, comparison=comparison, compared=[(m, r.meta) for r, m in zip(runs[1:], metrics[1:])],
        problems=problems, gif=gif_bytes, gif_note=gif_note, version=__version__,
    )
    write_text_atomic(paths[0], page)
    write_json_atomic(paths[1], summary_payload(m0, meta, compared=metrics[1:], comparison=comparison, files=all_files, problems=problems, version=__version__))
    write_text_atomic(paths[2], render_markdown(m0, meta, comparison=comparison, files=all_files, problems=problems))
    return ReportResult(str(out), tuple(all_files), m0, tuple(metrics[1:]), comparison, tuple(problems))
