"""A scenario simulated in the closed loop and judged against its own ``expect:``, for the tests
that then read the run back (their own way: trace columns, run meta, a few columns).

A uniquely named module (not conftest) so that it imports unambiguously in a whole-suite run."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from twolevel.sim.engine import simulate_scenario
from twolevel.verdict.judge import judge_run


def judged_run(path: Path, out: Path, *, judge: bool = True, **options: Any) -> Path:
    """Simulates scenario ``path`` into ``out`` (no frames, no TTR; ``options`` go to
    :func:`~twolevel.sim.engine.simulate_scenario`), asserts that it completed and, with
    ``judge``, that its verdict passed (goal, road, collisions at fault, the rules); returns the
    run directory."""
    summary, diags = simulate_scenario(str(path), str(out), frames=False, ttr_every=0, **options)
    assert summary is not None and summary.status == "complete", [d.message for d in diags]
    if judge:
        verdict, _ = judge_run(summary.run_dir, str(path))
        assert verdict.passed, [c.detail for c in verdict.failed]
    return Path(summary.run_dir)
