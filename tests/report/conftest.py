"""Fixtures for the report tests: hand-made run directories (see helpers/report_runs.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

import pytest

from helpers.report_runs import traffic_rows, write_run


@pytest.fixture
def make_traffic_run(tmp_path: Path) -> Callable[..., Path]:
    def make(name: str = "run", *, frames: bool = False, n: int = 300, **kw: Any) -> Path:
        status = kw.pop("status", "complete")
        summary = kw.pop("summary", None)
        meta = kw.pop("meta", None)
        rows, fr = traffic_rows(n, **kw)
        return write_run(tmp_path / name, rows, frames=fr if frames else None, status=status, summary=summary, meta=meta)

    return make
