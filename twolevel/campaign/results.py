"""The results table of a campaign: one row per run, loadable in pandas.

Columns: ``index`` (1-based, in the order the runs were asked for), ``case``, ``batch`` (the
optimiser's generation; 0 for sweeps), ``seed``, ``p.<name>`` per parameter, ``outcome``
(passed / failed / error), ``status`` (how the run ended), ``objective`` (the robustness a
search minimises; absent for sweeps without one), ``failed`` (the criteria not met, ``;``
separated), ``m.<criterion>`` per criterion (its margin; ≥ 0 passes), ``goal_reached_t`` [s],
``run_dir`` (relative to the campaign folder; empty once removed), and the wall-clock columns
:data:`TIMING_COLUMNS` (``run_s``: the simulation in its worker; ``wall_s``: load, simulation
and verdict) [s]. Everything but the wall-clock columns depends only on the scenario, the
parameters and the seed: the same campaign gives the same table on any executor.

Written as ``results.csv`` and ``results.json`` (records), and ``results.parquet`` when pyarrow
is installed; infinities are written as ``inf``/``-inf`` in CSV and strings in JSON.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from pathlib import Path
from typing import Any, Callable, Sequence

from twolevel.campaign.case import CaseResult

__all__ = ["table_rows", "write_table", "read_rows", "TIMING_COLUMNS"]

TIMING_COLUMNS = ("run_s", "wall_s")


def table_rows(results: Sequence[CaseResult], out_dir: str | os.PathLike[str], *, batches: Sequence[int] | None = None,
               objective: Callable[[CaseResult], float] | None = None) -> list[dict[str, Any]]:
    """The rows of the table for ``results`` (in order); ``run_dir`` relative to ``out_dir``."""
    names = list(dict.fromkeys(n for r in results for n in r.case.parameters))
    criteria = list(dict.fromkeys(n for r in results for n in r.margins))
    base = Path(out_dir).resolve()
    rows = []
    for i, r in enumerate(results):
        row: dict[str, Any] = {"index": i + 1, "case": r.case.id, "batch": batches[i] if batches else 0, "seed": r.seed}
        row.update({f"p.{n}": float(r.case.parameters[n]) if n in r.case.parameters else math.nan for n in names})
        row.update({"outcome": r.outcome, "status": r.status})
        if objective is not None:
            row["objective"] = objective(r)
        row["failed"] = ";".join(r.failed)
        row.update({f"m.{n}": float(r.margins.get(n, math.nan)) for n in criteria})
        row["goal_reached_t"] = math.nan if r.goal_reached_t is None else float(r.goal_reached_t)
        row["run_dir"] = os.path.relpath(Path(r.run_dir).resolve(), base) if r.run_dir else ""
        row["run_s"], row["wall_s"] = round(r.run_s, 4), round(r.wall_s, 4)
        rows.append(row)
    return rows


def _json_value(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None if math.isnan(v) else ("inf" if v > 0 else "-inf")
    return v


def write_table(rows: Sequence[dict[str, Any]], out_dir: str | os.PathLike[str], stem: str = "results") -> list[Path]:
    """Write the table as CSV, JSON and (with pyarrow) parquet into ``out_dir``, atomically."""
    from twolevel.atomic import write_bytes_atomic, write_text_atomic

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    columns = list(dict.fromkeys(k for row in rows for k in row))
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if v is None else v) for k, v in row.items()})
    written = [write_text_atomic(out / f"{stem}.csv", buf.getvalue())]
    records = [{k: _json_value(row.get(k)) for k in columns} for row in rows]
    written.append(write_text_atomic(out / f"{stem}.json", json.dumps(records, indent=1) + "\n"))
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return written
    sink = pa.BufferOutputStream()
    pq.write_table(pa.Table.from_pylist([{k: row.get(k) for k in columns} for row in rows]), sink)
    written.append(write_bytes_atomic(out / f"{stem}.parquet", sink.getvalue().to_pybytes()))
    return written


def read_rows(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The rows of a ``results.json`` (infinities back as floats)."""
    rows = json.loads(Path(path).read_text(encoding="utf-8"))
    back = {"inf": math.inf, "-inf": -math.inf}
    return [{k: (back[v] if isinstance(v, str) and v in back else (math.nan if v is None else v)) for k, v in r.items()}
            for r in rows]
