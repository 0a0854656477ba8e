"""Reports of run directories: metrics, the paper's figures, a GIF, one self-contained HTML page.

``build_report(run_dir, compare=(), *, gif=True, formats=("png", "svg"), out_dir=None)`` is the
entry point (see :mod:`twolevel.report.build`). Attributes load lazily so that importing this
package costs nothing until a report is built (numpy and matplotlib are heavy).
"""

from __future__ import annotations

from typing import Any

__all__ = ["build_report", "ReportError", "ReportResult", "compute_metrics", "compare_metrics", "ComparisonTable", "Metrics"]


def __getattr__(name: str) -> Any:
    if name in ("build_report", "ReportError", "ReportResult"):
        from twolevel.report import build

        return getattr(build, name)
    if name in ("compare_metrics", "ComparisonTable"):
        from twolevel.report import comparison

        return getattr(comparison, name)
    if name in ("compute_metrics", "Metrics"):
        from twolevel.report import metrics

        return getattr(metrics, name)
    raise AttributeError(f"module 'twolevel.report' has no attribute {name!r}")
