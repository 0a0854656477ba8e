"""Several runs side by side: the headline metrics with ratios to the first run."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np

from twolevel.report.metrics import Metrics, _Serialisable

@dataclass(frozen=True)
class ComparisonRow(_Serialisable):
    """One metric across runs; ``ratios`` are value / first run's value (None when undefined)."""

    key: str
    label: str
    unit: str
    values: tuple[float | None, ...]
    ratios: tuple[float | None, ...]


@dataclass(frozen=True)
class ComparisonTable(_Serialisable):
    runs: tuple[str, ...]
    rows: tuple[ComparisonRow, ...]

    def row(self, key: str) -> ComparisonRow:
        return next(r for r in self.rows if r.key == key)


def _g(*path: str) -> Callable[[Metrics], Any]:
    def get(m: Metrics) -> Any:
        obj: Any = m
        for p in path:
            if obj is None:
                return None
            obj = getattr(obj, p)
        return obj

    return get


#: (key, label, unit, getter) of the metrics put side by side.
COMPARED: tuple[tuple[str, str, str, Callable[[Metrics], Any]], ...] = (
    ("steps", "steps", "", _g("rows")),
    ("duration", "simulated time", "s", _g("duration_s")),
    ("rate_p50", "control rate, median", "Hz", _g("rate", "hz", "p50")),
    ("rate_min", "control rate, lowest", "Hz", _g("rate", "hz", "min")),
    ("latency_p50", "control step, median", "ms", _g("latency", "total", "p50")),
    ("latency_p95", "control step, p95", "ms", _g("latency", "total", "p95")),
    ("latency_p99", "control step, p99", "ms", _g("latency", "total", "p99")),
    ("latency_max", "control step, max", "ms", _g("latency", "total", "max")),
    ("high_p50", "high level, median", "ms", _g("latency", "high", "p50")),
    ("high_p95", "high level, p95", "ms", _g("latency", "high", "p95")),
    ("low_p50", "low level, median", "ms", _g("latency", "low", "p50")),
    ("low_p95", "low level, p95", "ms", _g("latency", "low", "p95")),
    ("over_budget", "steps over 100 ms", "", _g("latency", "steps_over_budget")),
    ("tracking_max", "tracking error, max", "m", _g("tracking", "max_m")),
    ("tracking_mean", "tracking error, mean", "m", _g("tracking", "mean_m")),
    ("overspeed_max", "overspeed, max", "m/s", _g("speed", "max_overspeed_mps")),
    ("overspeed_time", "time over the limit", "s", _g("speed", "time_over_limit_s")),
    ("min_dist", "min. centre distance", "m", _g("distance", "min_dist_m")),
    ("min_gap", "min. box gap", "m", _g("distance", "min_gap_m")),
    ("below_line", "time below 4.22 m", "s", _g("distance", "time_below_line_s")),
    ("nearby_max", "nearby vehicles, max", "", _g("nearby", "max")),
    ("nearby_mean", "nearby vehicles, mean", "", _g("nearby", "mean")),
    ("violations", "rule violations", "", lambda m: len(m.violations)),
    ("collisions", "collisions", "", lambda m: m.collisions.count),
    ("share_mpc", "decision share: mpc", "%", lambda m: 100.0 * m.decisions.share("mpc") if m.decisions else None),
    ("share_sampled", "decision share: sampled", "%", lambda m: 100.0 * m.decisions.share("sampled") if m.decisions else None),
    ("share_brake", "decision share: brake", "%", lambda m: 100.0 * m.decisions.share("brake") if m.decisions else None),
    ("share_fallback", "decision share: fallback", "%", lambda m: 100.0 * m.decisions.share("fallback") if m.decisions else None),
)


def _num_or_none(v: Any) -> float | None:
    if v is None:
        return None
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        return int(v)
    f = float(v)
    return None if math.isnan(f) else f


def compare_metrics(runs: Sequence[Metrics]) -> ComparisonTable:
    """The headline metrics of several runs side by side, with ratios to the first run."""
    rows = []
    for key, label, unit, get in COMPARED:
        values = tuple(_num_or_none(get(m)) for m in runs)
        base = values[0] if values else None
        ratios = tuple(
            None if (v is None or base is None or base == 0 or not math.isfinite(base) or not math.isfinite(v)) else v / base
            for v in values
        )
        rows.append(ComparisonRow(key, label, unit, values, ratios))
    return ComparisonTable(tuple(m.label for m in runs), tuple(rows))
