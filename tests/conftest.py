"""Suite-wide settings: under CI (``CI`` set, as ``.ci/run`` does) property tests draw the same
examples on every run, so a red CI points at a change, not at a new random draw; locally they
explore afresh each run (and keep what failed in .hypothesis/)."""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("CI"):
    settings.load_profile("ci")
