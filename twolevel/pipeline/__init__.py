"""The library side of the commands: each returns values and diagnostics, the CLI only chooses
output formats and exit codes.

``checking`` (``twolevel check``), ``monitoring`` (``twolevel monitor``), ``conversion``
(``twolevel import``, ``export``), ``planning`` (``twolevel plan``); ``simulate`` and ``report``
have theirs in :mod:`twolevel.sim.engine` and :mod:`twolevel.report`. The light stages are
re-exported here (``twolevel check`` imports no numpy: import :mod:`twolevel.pipeline.planning` itself).
"""

from twolevel.pipeline.checking import CheckResult, check, collect_paths, dedupe, exit_code
from twolevel.pipeline.monitoring import MonitorResult, monitor

__all__ = ["CheckResult", "check", "collect_paths", "dedupe", "exit_code", "MonitorResult", "monitor"]
