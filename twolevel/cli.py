"""The ``twolevel`` command line. The only module that imports typer and rich.

Exit codes (every command):

* 0 — clean: no finding that fails, every monitored rule satisfied;
* 1 — findings that fail (errors; warnings too under ``--strict``), or a monitored rule violated;
* 2 — usage error, unreadable input, or an internal error (reported, never a traceback);
* 128 + N — stopped by signal N outside a run: SIGINT (130), SIGTERM, SIGHUP
  (:mod:`twolevel.interruption`; ``simulate`` records its run's interruption and exits 2).
"""

from __future__ import annotations

import enum
import math
import os
import sys
from typing import List, NoReturn, Optional

import typer

from twolevel import __version__

app = typer.Typer(
    name="twolevel",
    help="Provably-correct two-level control for autonomous driving from STL traffic rules.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)

EXIT_OK, EXIT_FAIL, EXIT_USAGE = 0, 1, 2


class OutputFormat(str, enum.Enum):
    full = "full"
    concise = "concise"
    json = "json"
    github = "github"
    sarif = "sarif"


class MonitorFormat(str, enum.Enum):
    table = "table"
    json = "json"


def _console(stderr: bool = False):  # noqa: ANN202 - rich is imported lazily
    from rich.console import Console

    return Console(stderr=stderr, highlight=False, soft_wrap=True)


def _default_format() -> OutputFormat:
    if os.environ.get("GITHUB_ACTIONS") == "true":
        return OutputFormat.github
    return OutputFormat.full if sys.stdout.isatty() else OutputFormat.concise


def _emit(text: str) -> None:
    """Write plain text to stdout (machine formats must not pass through rich's markup)."""
    sys.stdout.write(text)
    sys.stdout.flush()


def _emit_json(payload: object) -> None:
    """One JSON document on stdout. Non-finite numbers are converted by the library (NaN as
    null, ±inf as the strings "inf"/"-inf"); ``allow_nan=False`` guarantees strict JSON."""
    import json

    _emit(json.dumps(payload, allow_nan=False) + "\n")


def _print_full(text: str) -> None:
    """Colour the severities of the ``full`` format on a terminal; plain otherwise."""
    if not sys.stdout.isatty():
        _emit(text)
        return
    from rich.text import Text

    console = _console()
    for line in text.splitlines():
        t = Text(line)
        t.highlight_regex(r"error\[[A-Z]+\d+\]", "bold red")
        t.highlight_regex(r"warning\[[A-Z]+\d+\]", "bold yellow")
        t.highlight_regex(r"info\[[A-Z]+\d+\]", "bold cyan")
        t.highlight_regex(r"^\s+\|\s+\^+$", "bold red")
        t.highlight_regex(r"= hint:.*$", "green")
        console.print(t)


def _version_callback(value: bool) -> None:
    if value:
        _emit(f"twolevel {__version__}\n")
        raise typer.Exit(EXIT_OK)


@app.callback()
def _root(
    version: bool = typer.Option(False, "--version", callback=_version_callback, is_eager=True, help="Print the version and exit."),
) -> None:
    """twolevel: check rules, plan, simulate, monitor and report."""


@app.command()
def check(
    paths: List[str] = typer.Argument(..., metavar="PATH...", help="Rule files (.stl), maps and scenarios (.yaml), or folders holding them."),
    output_format: Optional[OutputFormat] = typer.Option(
        None, "--output-format", "-f", help="full (default on a terminal), concise, json, github (default under GitHub Actions), sarif."
    ),
    strict: bool = typer.Option(False, "--strict", help="Warnings fail the check too."),
    exit_zero: bool = typer.Option(False, "--exit-zero", help="Always exit 0 (report only)."),
    dt: Optional[float] = typer.Option(None, "--dt", min=1e-9, metavar="SECONDS", help="Sample period [s]: intervals must be multiples of it."),
    horizon: Optional[int] = typer.Option(None, "--horizon", min=1, metavar="STEPS", help="MPC horizon [steps]: longer formulas are reported (needs --dt)."),
) -> None:
    """Check rule files, maps and scenarios without solving anything.

    Exit 0 when clean, 1 on errors (and warnings under --strict), 2 when an input cannot be read.
    """
    from twolevel import pipeline
    from twolevel.diagnostics import render

    if dt is not None and not math.isfinite(dt):
        raise typer.BadParameter("must be a finite number of seconds", param_hint="--dt")
    if horizon is not None and dt is None:
        raise typer.BadParameter("needs --dt (the horizon is horizon × dt seconds)", param_hint="--horizon")
    fmt = output_format or _default_format()
    result = pipeline.check(paths, dt=dt, horizon=horizon)
    text = render(fmt.value, result.diagnostics, sources=result.sources, files_checked=result.files_checked, tool_version=__version__)
    if fmt is OutputFormat.full:
        _print_full(text)
        n_err = sum(d.is_error for d in result.diagnostics)
        n_warn = sum(d.severity.value == "warning" for d in result.diagnostics)
        summary = f"{result.files_checked} file(s) checked: {n_err} error(s), {n_warn} warning(s)\n"
        (_console().print(summary, end="") if sys.stdout.isatty() else _emit(summary))
    else:
        _emit(text)
    if result.bad_input and not exit_zero:
        raise typer.Exit(EXIT_USAGE)
    raise typer.Exit(pipeline.exit_code(result.diagnostics, strict=strict, exit_zero=exit_zero))


@app.command("import")
def import_command(
    path: str = typer.Argument(..., metavar="FILE", help="A map or scenario of another tool: OpenDRIVE (.xodr), CommonRoad (.xml)."),
    out: str = typer.Option(..., "--out", "-o", metavar="DIR", help="Folder the twolevel files are written to."),
    include: List[str] = typer.Option(
        [], "--include", metavar="TYPE", help="OpenDRIVE: also import lanes of this type (shoulder, parking, biking, sidewalk, bus, restricted); repeatable."),
    rules: List[str] = typer.Option([], "--rules", "-r", metavar="RULES.stl", help="CommonRoad: a rule file the scenario lists (repeatable)."),
    output_format: Optional[OutputFormat] = typer.Option(
        None, "--output-format", "-f", help="How findings are shown: full, concise, json, github, sarif."),
    strict: bool = typer.Option(False, "--strict", help="Warnings (elements not converted exactly) fail the import too."),
) -> None:
    """Convert another tool's map or scenario into twolevel files: an OpenDRIVE map into DIR/<name>.yaml
    (free-form lanes; pip install 'twolevel[opendrive]'), a CommonRoad scenario into DIR/map.yaml and
    DIR/scenario.yaml (pip install 'twolevel[commonroad]').

    What does not convert exactly is reported at its element and line (IMP7xx). Exit 0 when the files
    were written and pass the checks, 1 on errors (warnings too under --strict), 2 when the file cannot be used.
    """
    from twolevel import interop, pipeline
    from twolevel.diagnostics import render

    fmt_in = interop.format_of(path)
    if fmt_in is None:
        known = ", ".join(f"{f.name} {f.suffix}" for f in interop.FORMATS)
        raise typer.BadParameter(f"no importer reads '{path}' (known: {known})", param_hint="FILE")
    options: dict[str, object] = {}
    if include:
        from twolevel.interop.opendrive import OPTIONAL_KINDS

        if fmt_in.name != "OpenDRIVE":
            raise typer.BadParameter(f"--include applies to OpenDRIVE maps, not {fmt_in.name}", param_hint="--include")
        bad = [t for t in include if t not in OPTIONAL_KINDS]
        if bad:
            raise typer.BadParameter(f"unknown lane type(s) {', '.join(bad)} (known: {', '.join(OPTIONAL_KINDS)})",
                                     param_hint="--include")
        options["include"] = tuple(include)
    if rules:
        if fmt_in.name != "CommonRoad":
            raise typer.BadParameter(f"--rules applies to CommonRoad scenarios, not {fmt_in.name}", param_hint="--rules")
        options["rules"] = tuple(rules)
    fmt = output_format or _default_format()
    result = interop.import_file(path, out, **options)
    diags = pipeline.dedupe(result.diagnostics)
    sources = {path: _read_source(path)} if fmt is OutputFormat.full else {}
    text = render(fmt.value, diags, sources=sources, files_checked=1, tool_version=__version__)
    if fmt in (OutputFormat.full, OutputFormat.concise):
        sys.stderr.write(text)
        for written in result.written:
            _emit(f"wrote {written}" + (f": {result.summary}" if written == result.written[0] and result.summary else "") + "\n")
    else:
        _emit(text)
    if result.bad_input:
        raise typer.Exit(EXIT_USAGE)
    raise typer.Exit(pipeline.exit_code(diags, strict=strict))


def _read_source(path: str) -> str:
    """The text of an imported file, for the source lines under its findings (at most 64 MB)."""
    from twolevel.files import read_text_quietly

    return read_text_quietly(path, limit=64 << 20)


def _parse_consts(items: List[str]) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            if not sep or not name.strip():
                raise ValueError
            out[name.strip()] = float(value)
            if not math.isfinite(out[name.strip()]):
                raise ValueError
        except ValueError:
            raise typer.BadParameter(f"expected NAME=NUMBER with a finite number, got {item!r}", param_hint="--const") from None
    return out


@app.command()
def monitor(
    rules: str = typer.Argument(..., metavar="RULES.stl", help="A rule file (.stl)."),
    trace: str = typer.Argument(..., metavar="TRACE.csv", help="A recorded trace (.csv) with a time column t or time [s] and one column per signal."),
    dt: Optional[float] = typer.Option(None, "--dt", min=1e-9, metavar="SECONDS", help="Sample period [s] (default: read from the uniform time column)."),
    output: MonitorFormat = typer.Option(MonitorFormat.table, "--format", help="table or json."),
    series: bool = typer.Option(False, "--series", help="Include each rule's whole robustness signal."),
    const: List[str] = typer.Option([], "--const", metavar="NAME=VALUE", help="Bind or override a constant: NAME=NUMBER (repeatable)."),
) -> None:
    """Evaluate every rule of RULES over a recorded drive (offline, RTAMT semantics).

    Exit 0 when every rule holds at every time of the trace, 1 when some rule is violated
    somewhere (first_violation_t), 2 when the rule file or the trace cannot be used or some rule
    could not be judged (verdict "not judged": it reads a column the trace lacks, or it
    quantifies over participants the trace does not record, SIM609, unless the run.json beside
    the trace says the run had none).
    """
    from twolevel import pipeline
    from twolevel.diagnostics import render

    res = pipeline.monitor(rules, trace, dt=dt, consts=_parse_consts(const), series=series)
    if res.diagnostics:
        fmt = "full" if sys.stderr.isatty() else "concise"
        sys.stderr.write(render(fmt, res.diagnostics, sources=res.sources))
    if res.report is None:
        raise typer.Exit(EXIT_USAGE)
    from twolevel.monitor.tracefile import to_json

    payload = to_json(res.report)
    if not payload["rules"] and any(d.is_error for d in res.diagnostics):
        raise typer.Exit(EXIT_USAGE)  # no rule to give a verdict: the findings above say why
    if output is MonitorFormat.json:
        _emit_json(payload)
    else:
        rows = payload["rules"]
        from rich.table import Table

        table = Table(title=f"{rules} over {trace} ({res.report.samples} samples, dt = {res.report.dt:g} s)", title_justify="left")
        for col, justify in (("rule", "left"), ("verdict", "left"), ("robustness at t=0", "right"), ("at t=0", "center"),
                             ("first violation \\[s]", "right")):
            table.add_column(col, justify=justify)
        for r in rows:
            first, rob = r["first_violation_t"], r["robustness"]
            judged = r["satisfied"] is not None
            table.add_row(
                r["name"],
                r["verdict"] if judged else f"{r['verdict']} ({r['code']})",
                f"{rob:.4g}" if isinstance(rob, float) else "-" if rob is None else str(rob),
                ("holds" if r["satisfied"] else "violated") if judged else "-",
                "-" if first is None else f"{first:g}",
            )
        _console().print(table)
    if any(d.is_error for d in res.diagnostics):  # some rule could not be judged
        raise typer.Exit(EXIT_USAGE)
    raise typer.Exit(EXIT_FAIL if res.violated else EXIT_OK)


def _print_diagnostics(diags, sources=None) -> None:  # noqa: ANN001
    """Findings of plan/simulate go to stderr (stdout carries the result)."""
    if diags:
        from twolevel.diagnostics import render
        from twolevel.pipeline import dedupe

        sys.stderr.write(render("full" if sys.stderr.isatty() else "concise", dedupe(diags), sources=sources or {}))


@app.command()
def plan(
    scenario: str = typer.Argument(..., metavar="SCENARIO.yaml", help="A scenario file."),
    solver: str = typer.Option("highs", "--solver", help="highs (exact L1 MILP + Clarabel polish), modes (real-time mode search), gurobi (if installed)."),
    at: Optional[float] = typer.Option(None, "--at", metavar="SECONDS", help="Plan from the state recorded at this time of --trace."),
    trace: Optional[str] = typer.Option(None, "--trace", metavar="RUN_DIR/trace.csv", help="A run's trace to take the state and history from."),
    emit: Optional[str] = typer.Option(None, "--emit", metavar="MODEL.mps|MODEL.lp", help="Write the MILC model for any other solver."),
    output: MonitorFormat = typer.Option(MonitorFormat.table, "--format", help="table or json."),
    time_limit: float = typer.Option(10.0, "--time-limit", min=0.001, metavar="SECONDS", help="Solver time limit."),
) -> None:
    """Solve one MPC problem of SCENARIO (at its start, or at --at T of a recorded --trace).

    Exit 0 with a plan, 1 when no plan satisfies the rules (the conflicting rules are named
    where they can be found), 2 on bad input.
    """
    from twolevel.pipeline.planning import plan_scenario

    report_, diags = plan_scenario(scenario, solver=solver, at=at, trace=trace, emit=emit, time_limit=time_limit)
    _print_diagnostics(diags)
    if report_ is None:
        raise typer.Exit(EXIT_USAGE)
    bad_input = any(d.bad_input for d in diags)  # e.g. a rule that cannot be encoded, an unwritable --emit
    if output is MonitorFormat.json:
        _emit_json(report_.to_json())
    else:
        from rich.markup import escape
        from rich.table import Table

        head, rows = report_.table()
        table = Table(title=f"{scenario}: {report_.status}, objective {report_.objective:.6g}", title_justify="left")
        for h in head:
            table.add_column(escape(h), justify="right")
        for row in rows:
            table.add_row(*row)
        console = _console()
        console.print(table)
        facts = [
            ("solver", report_.solver),
            ("binaries / rows / columns", f"{report_.binaries} / {report_.rows} / {report_.columns}"),
            ("QPs solved", str(report_.qps)),
            ("certified", report_.certificate),
        ] + [(f"time: {k} [ms]", f"{v:.2f}") for k, v in report_.solve_ms.items()]
        facts += [(f"rule {name}: robustness", f"{rob:.4g}") for name, rob in report_.rules]
        if report_.conflicts:
            facts.append(("conflicting rules", ", ".join(report_.conflicts)))
        if report_.emitted:
            facts.append(("model written to", report_.emitted))
        if report_.message:
            facts.append(("note", report_.message))
        console.print(_table("solve", facts))
    if bad_input:
        raise typer.Exit(EXIT_USAGE)
    raise typer.Exit(EXIT_OK if report_.status.ok else EXIT_FAIL)


def _summary_rows(s) -> list[tuple[str, str]]:  # noqa: ANN001 - RunSummary, imported lazily
    def f(v: float, unit: str = "", digits: int = 3) -> str:
        return "-" if v != v else (f"{v:.{digits}g} {unit}".strip() if abs(v) != float("inf") else "inf")

    rows = [
        ("status", s.status),
        ("controller", s.controller + ("" if s.monitor else " (no monitor)")
         + ("" if not s.monitor or s.safety else " (no safety layer)")),
        ("simulated time", f(s.duration, "s", 4)),
        ("goal reached at", "-" if s.goal_reached_t is None else f(s.goal_reached_t, "s", 4)),
        ("steps", str(s.steps)),
        ("control step median / p95 / max", f"{s.step_ms_median:.2f} / {s.step_ms_p95:.2f} / {s.step_ms_max:.2f} ms"),
        ("its CPU time median / p99 / max", f"{s.step_cpu_ms_median:.2f} / {s.step_cpu_ms_p99:.2f} / {s.step_cpu_ms_max:.2f} ms"),
        ("high level median / max", f"{s.high_ms_median:.2f} / {s.high_ms_max:.2f} ms"),
        ("low level median / max", f"{s.low_ms_median:.2f} / {s.low_ms_max:.2f} ms"),
        ("control rate", f(s.control_rate_hz, "Hz", 4)),
        ("steps over 100 ms", str(s.steps_over_budget)),
        ("simulated / wall time", f(s.realtime, "x", 3)),
        ("tracking error max / mean", f"{s.tracking_error_max:.3f} / {s.tracking_error_mean:.3f} m"),
        ("max speed over the limit", f(s.speed_over_limit_max, "m/s")),
        ("min distance (centres)", f(s.min_distance, "m")),
        ("min gap (boxes)", f(s.min_gap, "m")),
        ("collisions", str(len(s.collisions)) + "".join(
            f"\n  t={c.t:.1f} s with {c.other} at ({c.x:.1f}, {c.y:.1f}): "
            + ("EGO AT FAULT" if c.at_fault else "not at fault") + f" ({c.verdict})" for c in s.collisions)),
        ("collisions the ego's fault", str(s.at_fault)),
        ("safe start", "-" if s.safe_start is None else ("yes" if s.safe_start else "NO (no fail-safe at t = 0)")),
        ("verification", ", ".join(f"{k}: {n}" for k, n in sorted(s.verification.items())) or "-"),
        ("min time to react", f(s.ttr_min_s, "s")),
        ("peak deceleration", f(s.decel_peak, "m/s²")),
        ("steps braking > 4 m/s²", "-" if s.hard_braking_share != s.hard_braking_share else f"{100 * s.hard_braking_share:.1f} %"),
    ]
    rows.append(("no plan satisfied the rules", "never" if not s.unsatisfiable else "\n".join(
        f"t={u.t_start:.1f}-{u.t_end:.1f} s: " + (", ".join(u.rules) if u.rules else "unexplained") + " → "
        + ", ".join(f"{d} {n}" for d, n in sorted(u.decisions.items())) for u in s.unsatisfiable)))
    for v in s.violations:
        rows.append((f"rule {v.rule}", "holds" if v.steps == 0 else f"violated in {v.steps} steps from t={v.first_t:.1f} s (worst {v.worst:.3g})"))
    rows.append(("decisions", ", ".join(f"{k}: {n}" for k, n in sorted(s.decisions.items()))))
    return rows


@app.command()
def simulate(
    scenario: str = typer.Argument(..., metavar="SCENARIO.yaml", help="A scenario file."),
    out: Optional[str] = typer.Option(None, "--out", "-o", metavar="RUN_DIR", help="Run directory (default: runs/<scenario name>)."),
    no_monitor: bool = typer.Option(False, "--no-monitor", help="Apply the MPC's controls directly (the paper's 'without monitor'): no low level, no safety layer."),
    no_safety: bool = typer.Option(False, "--no-safety", help="The paper's low level alone: rules checked, controls not verified (no fail-safes)."),
    controller: str = typer.Option("twolevel", "--controller", help="twolevel (the MILP MPC), nmpc (baseline) or reckless (ignores traffic and rules); the low level checks each."),
    nmpc_model: str = typer.Option("kinematic", "--nmpc-model", help="With --controller nmpc: kinematic or fourwheel."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Override the scenario's seed."),
    duration: Optional[float] = typer.Option(None, "--duration", metavar="SECONDS", help="Override the scenario's duration."),
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar on a terminal."),
) -> None:
    """Run SCENARIO in closed loop (detailed vehicle model as the plant) and write a run
    directory: trace.csv (one row per step, written as it goes), run.json, frames.jsonl.

    The run is judged against the scenario's pass criteria (expect:; by default: goal reached,
    on the road, no collision at fault, every rule holds). Exit 0 when every criterion is met,
    1 when one is not, 2 on bad input or an interrupted, crashed or aborted run (SUMO failing
    mid-run: SIM632).
    """
    from pathlib import Path

    from twolevel import interruption

    with interruption.deferred():  # a signal stops the run where stopping is safe (run.json records it)
        summary, diags = _simulate(scenario, out, no_monitor, no_safety, controller, nmpc_model, seed, duration,
                                   progress)
    if any(d.code == "SIM612" for d in diags):
        interruption.clear()  # the run stopped for it and says so
    interruption.checkpoint()  # a signal that came as the run ended is not swallowed
    if summary is None:
        _print_diagnostics(diags)
        raise typer.Exit(EXIT_USAGE)
    from twolevel.sim.trace import RunStatus
    from twolevel.verdict.judge import judge_run

    verdict, more = judge_run(summary.run_dir, scenario)
    _print_diagnostics(diags + more)
    console = _console()
    console.print(_table(f"{scenario} → {summary.run_dir}", _summary_rows(summary)))
    if verdict is not None:
        console.print(_criteria_table(verdict))
    console.print(f"trace: {Path(summary.run_dir) / 'trace.csv'}   report: twolevel report {summary.run_dir}", markup=False)
    if summary.status is not RunStatus.COMPLETE or verdict is None:
        raise typer.Exit(EXIT_USAGE)
    raise typer.Exit(EXIT_OK if verdict.passed else EXIT_FAIL)


def _simulate(scenario: str, out: Optional[str], no_monitor: bool, no_safety: bool, controller: str, nmpc_model: str,
              seed: Optional[int], duration: Optional[float], progress: bool):  # noqa: ANN202 - imported lazily
    """``simulate_scenario`` with the command's options (and a progress bar on a terminal)."""
    from pathlib import Path

    from twolevel import interruption

    interruption.checkpoint()
    from twolevel.sim.engine import simulate_scenario

    run_dir = out or str(Path("runs") / Path(scenario).stem)
    ctrl = controller if controller != "nmpc" or nmpc_model == "kinematic" else f"nmpc-{nmpc_model}"
    show = progress and sys.stderr.isatty()
    if show:
        from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

        bar = Progress(
            TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.fields[info]}"), TimeRemainingColumn(),
            console=_console(stderr=True), transient=True,
        )
        task = bar.add_task(Path(scenario).stem, total=None, info="")

        def on_step(info) -> None:  # noqa: ANN001
            bar.update(task, total=info.steps, completed=info.step,
                       info=f"t={info.t:5.1f}/{info.duration:.0f} s  {info.rate_hz:6.1f} Hz  near={info.n_near:2d}  {info.decision}")

        with bar:
            return simulate_scenario(scenario, run_dir, monitor=not no_monitor, safety=not no_safety,
                                     controller=ctrl, seed=seed, duration=duration, progress=on_step)
    return simulate_scenario(scenario, run_dir, monitor=not no_monitor, safety=not no_safety,
                             controller=ctrl, seed=seed, duration=duration)


def _criteria_table(verdict):  # noqa: ANN001, ANN202 - Verdict and rich are imported lazily
    """The verdict as a table: each criterion with its measured value, bound and margin."""
    from rich.markup import escape
    from rich.table import Table

    from twolevel.sim.trace import RunStatus

    def num(v: float | None, unit: str) -> str:
        if v is None:
            return "-"
        return (f"{v:.4g} {unit}".strip()) if v == v and abs(v) != float("inf") else str(v)

    title = "PASS: every criterion met" if verdict.passed else \
        f"FAIL: {len(verdict.failed)} of {len(verdict.criteria)} criteria not met" + ("" if verdict.status == RunStatus.COMPLETE else f" (run {verdict.status})")
    table = Table(title=title, title_justify="left")
    for col, justify in (("criterion", "left"), ("verdict", "center"), ("measured", "right"), ("bound", "right"),
                         ("margin", "right")):
        table.add_column(col, justify=justify, no_wrap=True)
    table.add_column("detail", justify="left", ratio=1)
    for c in verdict.criteria:
        table.add_row(escape(c.name), "pass" if c.passed else "[bold red]FAIL[/]", escape(num(c.measured, c.unit)),
                      escape(num(c.bound, c.unit)), escape(num(c.margin, "")), escape(c.detail))
    return table


def _table(title: str, rows: list[tuple[str, str]]):  # noqa: ANN202 - rich is imported lazily
    from rich.markup import escape
    from rich.table import Table

    table = Table(title=escape(title), show_header=False, title_justify="left")
    table.add_column("metric", style="bold")
    table.add_column("value", justify="right")
    for label, value in rows:
        table.add_row(escape(label), escape(value))
    return table


@app.command()
def report(
    run_dir: str = typer.Argument(..., metavar="RUN_DIR", help="A run directory written by `twolevel simulate`."),
    compare: List[str] = typer.Option([], "--compare", "-c", metavar="RUN_DIR", help="Other run directories to overlay and compare (repeatable)."),
    gif: bool = typer.Option(True, "--gif/--no-gif", help="Animate the run (top-down GIF) from frames.jsonl."),
    figure_format: List[str] = typer.Option(["png", "svg"], "--figure-format", help="Figure formats (png, svg, pdf; repeatable)."),
    out: Optional[str] = typer.Option(None, "--out", "-o", help="Write the report here instead of into RUN_DIR."),
) -> None:
    """Turn a run directory into metrics, the paper's figures, a GIF and one self-contained
    report.html (with summary.json and summary.md).

    Exit 0 when the report was written (problems with the run are listed as warnings),
    2 when nothing in the run could be read or the output cannot be written.
    """
    from twolevel.report import ReportError, build_report
    from twolevel.report.summary import headline

    err = _console(stderr=True)
    try:
        res = build_report(run_dir, compare=compare, gif=gif, formats=tuple(figure_format), out_dir=out)
    except ReportError as exc:
        err.print(f"error: {exc}", markup=False)
        raise typer.Exit(EXIT_USAGE)
    for problem in res.problems:
        err.print(f"warning: {problem}", markup=False)
    console = _console()
    console.print(_table(f"run {run_dir}", headline(res.metrics)))
    for other in res.compared:
        console.print(_table(f"run {other.label}", headline(other)))
    console.print(f"report: {res.html}  ({len(res.files)} files written)", markup=False)
    raise typer.Exit(EXIT_OK)


class ExportFormat(str, enum.Enum):
    commonroad = "commonroad"


@app.command("export")
def export(
    run_dir: str = typer.Argument(..., metavar="RUN_DIR", help="A run directory written by `twolevel simulate`."),
    fmt: ExportFormat = typer.Option(ExportFormat.commonroad, "--format", help="commonroad: a solution file and the scenario with the ego as an obstacle."),
    out: Optional[str] = typer.Option(None, "--out", "-o", metavar="DIR", help="Where to write (default: RUN_DIR/<format>)."),
) -> None:
    """Export a run for other tools: with --format commonroad, solution.xml (the ego's trajectory,
    kinematic single-track states) and the scenario with the ego as a dynamic obstacle.

    Exit 0 when written (what the format cannot hold is listed, IMP730), 2 when the run cannot be
    read or the format's package is missing.
    """
    from twolevel.pipeline.conversion import export_run

    res = export_run(run_dir, out or os.path.join(run_dir, fmt.value), fmt.value)
    _print_diagnostics(list(res.diagnostics))
    if not res.written:
        raise typer.Exit(EXIT_USAGE)
    for path in res.written:
        _emit(f"wrote {path}\n")
    raise typer.Exit(EXIT_OK)


def _campaign_executor(scheduler: Optional[str], jobs: Optional[int]):  # noqa: ANN202
    from twolevel.campaign.executor import ExecutorError, make_executor

    try:
        return make_executor(scheduler, jobs)
    except ExecutorError as exc:
        _console(stderr=True).print(f"error: {exc}", markup=False)
        raise typer.Exit(EXIT_USAGE)


_OUTCOME_STYLE = {"passed": "green", "failed": "bold red", "error": "bold magenta"}


def _suite_table(rows: dict, shown: int = 40):  # noqa: ANN001, ANN202 - rich is imported lazily
    """The live table of a suite: the cases done so far (the last ``shown``), each with its
    outcome, time and failed criteria."""
    from rich.markup import escape
    from rich.table import Table

    done = [kv for kv in rows.items() if kv[1][0] != "pending"]
    table = Table(title=f"{len(done)}/{len(rows)} cases done", title_justify="left")
    for col in ("case", "outcome", "time [s]", "failed criteria"):
        table.add_column(col)
    for case_id, (state, secs, failed) in done[-shown:]:
        table.add_row(escape(case_id), f"[{_OUTCOME_STYLE.get(state, '')}]{state}[/]", secs, escape(failed))
    return table


@app.command("test")
def test_scenarios(
    paths: List[str] = typer.Argument(..., metavar="PATH...", help="Scenario files or folders holding them."),
    keyword: Optional[str] = typer.Option(None, "-k", metavar="EXPRESSION", help="Only cases whose id matches: words as substrings, and/or/not, parentheses."),
    failed_first: bool = typer.Option(False, "--failed-first", help="Run the cases that failed last time first."),
    jobs: Optional[int] = typer.Option(None, "--jobs", "-j", min=1, help="Worker processes (default: one per core)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", metavar="tcp://HOST:PORT", help="Run on a Dask cluster (pip install 'twolevel[dask]')."),
    seed: Optional[int] = typer.Option(None, "--seed", min=0, help="Seed of every case (default: each scenario's or variant's)."),
    runs_dir: str = typer.Option("runs/test", "--runs-dir", metavar="DIR", help="Where run directories go (kept for cases that did not pass)."),
    keep_passed: bool = typer.Option(False, "--keep-passed", help="Keep the run directories of passing cases too."),
    junit: Optional[str] = typer.Option(None, "--junit-xml", metavar="FILE", help="Write a JUnit XML report."),
    json_out: Optional[str] = typer.Option(None, "--json", metavar="FILE", help="Write the results as JSON."),
    github: Optional[bool] = typer.Option(None, "--github/--no-github", help="Print GitHub annotations (default: under GitHub Actions)."),
    cache_file: str = typer.Option(".twolevel_cache/test.json", "--cache-file", metavar="FILE", help="Where the last failures are remembered."),
) -> None:
    """Run every scenario below PATH... (and every variant they list) as a suite, in parallel,
    each judged by its criteria (expect:).

    Exit 0 when every case passed, 1 when some case failed or could not be run, 2 on a usage
    error (no scenario found, a bad -k expression, no Dask scheduler there).
    """
    from twolevel.atomic import write_json_atomic, write_text_atomic
    from twolevel.campaign import suite as S

    cases, diags = S.discover(paths)
    _print_diagnostics(diags)
    if any(d.is_error for d in diags):
        raise typer.Exit(EXIT_USAGE)
    try:
        cases = S.select(cases, keyword)
    except S.KeywordError as exc:
        raise typer.BadParameter(str(exc), param_hint="-k") from None
    if seed is not None:
        from dataclasses import replace

        cases = [replace(c, seed=seed) for c in cases]
    if failed_first:
        cases = S.order_failed_first(cases, S.read_cache(cache_file))
    console = _console()
    if not cases:
        console.print(f"no case matches -k {keyword!r}", markup=False)
        raise typer.Exit(EXIT_USAGE)
    rows = {c.id: ("pending", "", "") for c in cases}
    live_view = sys.stdout.isatty()

    def finished(r) -> None:  # noqa: ANN001
        rows[r.case.id] = (r.outcome, f"{r.wall_s:.1f}", ", ".join(r.failed) or (r.messages[0].splitlines()[0][:80] if r.messages else ""))
        if live_view:
            live.update(_suite_table(rows))
        else:
            _emit(f"{r.outcome.upper():7s} {r.case.id} ({r.wall_s:.1f} s){': ' + ', '.join(r.failed) if r.failed else ''}\n")

    with _campaign_executor(scheduler, jobs) as executor:
        if live_view:
            from rich.live import Live

            with Live(_suite_table(rows), console=console, refresh_per_second=4) as live:
                result = S.run_cases(cases, executor, runs_dir, keep_passed=keep_passed, on_result=finished)
        else:
            result = S.run_cases(cases, executor, runs_dir, keep_passed=keep_passed, on_result=finished)
    if result.interrupted is None:  # an interrupted suite would forget the failures of the cases not run
        S.write_cache(cache_file, result.results)
    bad = [r for r in result.results if not r.passed]
    if bad:
        from rich.markup import escape
        from rich.table import Table

        table = Table(title="cases that did not pass", title_justify="left")
        for col in ("case", "outcome", "why", "run directory"):
            table.add_column(col)
        for r in bad:
            why = "; ".join(f"{c['name']}: {c['detail']}" for c in (r.verdict or {}).get("criteria", []) if not c["passed"])
            table.add_row(escape(r.case.id), r.outcome, escape(why or (r.messages[0].splitlines()[0] if r.messages else r.status)),
                          escape(r.run_dir or "-"))
        console.print(table)
    n = result.counts
    console.print(f"{len(result.results)} cases: {n['passed']} passed, {n['failed']} failed, {n['error']} errors "
                  f"in {result.wall_s:.1f} s", markup=False)
    if junit:
        write_text_atomic(junit, S.junit_xml(result))
    if json_out:
        write_json_atomic(json_out, S.suite_json(result))
    if github if github is not None else os.environ.get("GITHUB_ACTIONS") == "true":
        _emit(S.annotations(result))
    if result.interrupted is not None:
        _exit_interrupted(result.interrupted, f"{len(result.results)} of {len(cases)} cases completed "
                                              f"(the outputs hold those)")
    raise typer.Exit(EXIT_OK if result.passed else EXIT_FAIL)


def _exit_interrupted(signum: int, what: str) -> NoReturn:
    """End a campaign a signal stopped (its outputs written): one line, exit 128 + the signal."""
    global _INTERRUPT_REPORTED
    from twolevel import interruption

    sys.stderr.write(f"twolevel: {interruption.describe(signum)}: {what}\n")
    _INTERRUPT_REPORTED = True
    raise typer.Exit(interruption.exit_code(signum))


_INTERRUPT_REPORTED = False
"""A command said itself how a signal ended it (``main`` adds nothing)."""


def _campaign_scenario(scenario: str):  # noqa: ANN202
    """The scenario of a sweep or search, loaded with nominal values (exit 2 when it is not valid)."""
    from twolevel.world.loader import load_scenario

    scn, diags = load_scenario(scenario)
    _print_diagnostics(diags)
    if scn is None:
        raise typer.Exit(EXIT_USAGE)
    if not scn.spec.parameters:
        _console(stderr=True).print(f"error: {scenario} declares no parameters (add 'parameters:' and refer to them as ${{name}})",
                                    markup=False)
        raise typer.Exit(EXIT_USAGE)
    return scn


def _batch_runner(executor, runs_dir: str, keep_passed: bool):  # noqa: ANN001, ANN202
    """Run a list of cases on ``executor``: their results in order, or ``SuiteInterrupted``
    with those that completed."""
    from twolevel.campaign.suite import SuiteInterrupted, run_cases

    def run(cases):  # noqa: ANN001, ANN202
        suite = run_cases(cases, executor, runs_dir, keep_passed=keep_passed, frames=False)
        if suite.interrupted is not None:
            raise SuiteInterrupted(suite.interrupted, suite.results)
        return list(suite.results)

    return run


@app.command()
def sweep(
    scenario: str = typer.Argument(..., metavar="SCENARIO.yaml", help="A scenario that declares parameters."),
    grid: bool = typer.Option(False, "--grid", help="Every combination of the parameters' grid values (steps, choices)."),
    samples: Optional[int] = typer.Option(None, "--samples", "-n", min=1, help="This many random draws from the parameters' distributions."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of the random draws."),
    out: Optional[str] = typer.Option(None, "--out", "-o", metavar="DIR", help="Campaign folder (default: runs/sweep-<scenario>)."),
    jobs: Optional[int] = typer.Option(None, "--jobs", "-j", min=1, help="Worker processes (default: one per core)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", metavar="tcp://HOST:PORT", help="Run on a Dask cluster."),
    keep_passed: bool = typer.Option(False, "--keep-passed", help="Keep the run directories of passing runs too."),
    objective: str = typer.Option("verdict", "--objective", help="Robustness tabulated per run: rule:NAME, at_fault, criterion:NAME, verdict."),
) -> None:
    """Run SCENARIO over a grid or random samples of its parameters; write the results table
    (results.csv, results.json, results.parquet with pyarrow) and report.html into the folder.

    Exit 0 when every run passed its criteria, 1 when some did not, 2 on a usage error.
    """
    from pathlib import Path

    from twolevel.campaign import sampling
    from twolevel.campaign.falsify import ObjectiveError, parse_objective
    from twolevel.campaign.report import write_campaign_report
    from twolevel.campaign.case import Case
    from twolevel.campaign.results import table_rows, write_table
    from twolevel.verdict.judge import criteria_of

    if grid == (samples is not None):
        raise typer.BadParameter("give exactly one of --grid or --samples N", param_hint="--grid/--samples")
    scn = _campaign_scenario(scenario)
    params = scn.spec.parameters
    try:
        obj = parse_objective(objective, criteria_of(scn))
        points = sampling.grid(params) if grid else sampling.random_points(params, samples or 0, seed)
    except (ObjectiveError, ValueError) as exc:
        raise typer.BadParameter(str(exc)) from None
    folder = Path(out or Path("runs") / f"sweep-{Path(scenario).stem}")
    cases = [Case(f"#{i + 1:04d}", scenario, p) for i, p in enumerate(points)]
    console = _console()
    from twolevel.campaign.suite import SuiteInterrupted

    interrupted = None
    with _campaign_executor(scheduler, jobs) as executor:
        try:
            results = _batch_runner(executor, str(folder / "runs"), keep_passed)(cases)
        except SuiteInterrupted as exc:
            results, interrupted = list(exc.results), exc.signum
    rows = table_rows(results, folder, objective=obj.of)
    files = write_table(rows, folder)
    report = write_campaign_report(folder, rows, params, obj.text, title=f"sweep of {scenario}")
    failed = sum(1 for r in results if not r.passed)
    console.print(f"{len(results)} runs: {len(results) - failed} passed, {failed} did not; "
                  f"table: {files[0]}; report: {report}", markup=False)
    if interrupted is not None:
        _exit_interrupted(interrupted, f"{len(results)} of {len(cases)} runs completed (the table holds those)")
    raise typer.Exit(EXIT_OK if failed == 0 else EXIT_FAIL)


@app.command()
def falsify(
    scenario: str = typer.Argument(..., metavar="SCENARIO.yaml", help="A scenario that declares parameters."),
    objective: str = typer.Option("verdict", "--objective", help="Robustness to minimise: rule:NAME, at_fault, criterion:NAME, verdict (the smallest margin)."),
    budget: int = typer.Option(100, "--budget", min=1, help="Most simulations to run."),
    optimizer: str = typer.Option("cma", "--optimizer", help="cma (CMA-ES; cross-entropy without the cma package), ce, random."),
    batch: Optional[int] = typer.Option(None, "--batch", min=2, help="Runs per generation (default: the optimiser's)."),
    seed: int = typer.Option(0, "--seed", min=0, help="Seed of the search."),
    out: Optional[str] = typer.Option(None, "--out", "-o", metavar="DIR", help="Campaign folder (default: runs/falsify-<scenario>)."),
    jobs: Optional[int] = typer.Option(None, "--jobs", "-j", min=1, help="Worker processes (default: one per core)."),
    scheduler: Optional[str] = typer.Option(None, "--scheduler", metavar="tcp://HOST:PORT", help="Run on a Dask cluster."),
) -> None:
    """Search SCENARIO's parameters for a run whose OBJECTIVE robustness is negative; stop at
    the first counterexample or after BUDGET simulations. A counterexample is written as a
    standalone scenario (counterexample.yaml) with its run (counterexample/); the results table
    and report.html go into the folder too.

    Exit 1 when a counterexample was found, 0 when none was within the budget, 2 on a usage error.
    """
    import json
    from pathlib import Path

    from twolevel.campaign import falsify as F
    from twolevel.campaign.report import write_campaign_report
    from twolevel.campaign.results import table_rows, write_table
    from twolevel.verdict.judge import criteria_of

    if optimizer not in F.OPTIMIZERS:
        raise typer.BadParameter(f"choose one of {', '.join(F.OPTIMIZERS)}", param_hint="--optimizer")
    scn = _campaign_scenario(scenario)
    try:
        obj = F.parse_objective(objective, criteria_of(scn))
    except F.ObjectiveError as exc:
        raise typer.BadParameter(str(exc), param_hint="--objective") from None
    folder = Path(out or Path("runs") / f"falsify-{Path(scenario).stem}")
    console = _console()

    def progress(generation: int, got, vals) -> None:  # noqa: ANN001
        finite = [v for v in vals if v == v]
        console.print(f"generation {generation}: {len(got)} runs, lowest {obj.text} {min(finite) if finite else float('nan'):.4g}",
                      markup=False)

    with _campaign_executor(scheduler, jobs) as executor:
        res = F.falsify(scenario, scn.spec.parameters, obj, budget=budget, optimizer=optimizer, seed=seed, batch=batch,
                        run_batch=_batch_runner(executor, str(folder / "runs"), False), on_batch=progress)
    rows = table_rows(res.results, folder, batches=res.batches, objective=obj.of)
    write_table(rows, folder)
    summary = F.record(res, obj, folder, seed)
    report = write_campaign_report(folder, rows, scn.spec.parameters, obj.text, title=f"falsification of {scenario}",
                                   first=res.first)
    ce = res.counterexample
    if res.interrupted is not None and ce is None:
        _exit_interrupted(res.interrupted, f"{len(res.results)} simulations completed, no counterexample among "
                                           f"them (the table and {F.SUMMARY_FILE} hold those)")
    if ce is None:
        best = summary["best"]
        console.print(f"no counterexample in {len(res.results)} simulations ({res.optimizer}); lowest {obj.text} "
                      f"{json.dumps(best['objective'] if best else None)} at {json.dumps(best['parameters'] if best else None)}; "
                      f"report: {report}", markup=False)
        raise typer.Exit(EXIT_OK)
    console.print(f"counterexample after {res.first} simulations ({res.optimizer}): "
                  f"{', '.join(f'{k} = {v:g}' for k, v in ce.case.parameters.items())}; {obj.text} = "
                  f"{res.values[res.first - 1]:.4g}; scenario: {folder / 'counterexample.yaml'}; report: {report}", markup=False)
    raise typer.Exit(EXIT_FAIL)


def main() -> None:
    """Console-script entry point: never let a Python traceback reach the user."""
    from twolevel import interruption

    try:
        app()
    except SystemExit as exc:
        if exc.code == 130 and not _INTERRUPT_REPORTED:  # typer's silent exit for a KeyboardInterrupt: say which signal it was
            signum = interruption.received()
            sys.stderr.write(f"twolevel: {interruption.describe(signum)}\n")
            sys.exit(interruption.exit_code(signum))
        raise
    except KeyboardInterrupt as exc:  # Ctrl-C, or SIGTERM / SIGHUP (twolevel.interruption)
        signum = getattr(exc, "signum", None)
        sys.stderr.write(f"twolevel: {interruption.describe(signum)}\n")
        sys.exit(interruption.exit_code(signum))
    except Exception as exc:  # pragma: no cover - the last line of defence
        sys.stderr.write(f"twolevel: internal error: {type(exc).__name__}: {exc}\n")
        sys.stderr.write("This is a bug in twolevel; please report it with the command you ran.\n")
        sys.exit(EXIT_USAGE)


if __name__ == "__main__":  # pragma: no cover
    main()
