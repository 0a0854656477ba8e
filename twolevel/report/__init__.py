"""Reports of run directories: metrics, the paper's figures, a GIF, one self-contained HTML page.

``build_report(run_dir, compare=(), *, gif=True, formats=("png", "svg"), out_dir=None)`` is the
entry point (:mod:`twolevel.report.build`). Importing the package imports numpy; matplotlib is
imported only when figures are drawn.
"""

from twolevel.report.build import ReportError, ReportResult, build_report
from twolevel.report.comparison import ComparisonTable, compare_metrics
from twolevel.report.metrics import Metrics, compute_metrics

__all__ = ["build_report", "ReportError", "ReportResult", "compute_metrics", "compare_metrics", "ComparisonTable", "Metrics"]
