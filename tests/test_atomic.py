"""Atomic writes leave the old file or the whole new one, and no temporary file behind."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from twolevel.atomic import write_bytes_atomic, write_json_atomic


def test_replaces_the_whole_file(tmp_path: Path) -> None:
    target = tmp_path / "x.json"
    target.write_text("old")
    write_json_atomic(target, {"a": np.float64(1.5), "b": np.arange(3)})
    assert json.loads(target.read_text()) == {"a": 1.5, "b": [0, 1, 2]}
    assert [p.name for p in tmp_path.iterdir()] == ["x.json"]


def test_a_failed_write_keeps_the_target_and_removes_its_temporary(tmp_path: Path) -> None:
    target = tmp_path / "busy"
    target.mkdir()  # os.replace of a file over a directory fails after the data was written
    with pytest.raises(OSError):
        write_bytes_atomic(target, b"data")
    assert target.is_dir() and [p.name for p in tmp_path.iterdir()] == ["busy"]
