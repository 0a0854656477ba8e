"""Outputs are created safely: never through a symbolic link, never into a FIFO or a device,
with the user's umask; a run directory is held by one process at a time."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from twolevel.atomic import write_json_atomic
from twolevel.files import DirectoryBusy, DirectoryLock, UnsafeOutput, check_output, create_output
from twolevel.sim.trace import RunDirectory, TraceWriter, read_run


@pytest.fixture
def umask():
    """Set the process's umask for a test (restored after)."""
    old = os.umask(0o022)
    os.umask(old)
    yield lambda mask: os.umask(mask)
    os.umask(old)


@pytest.mark.parametrize("mask", [0o022, 0o027, 0o002])
def test_outputs_get_the_users_umask(tmp_path: Path, umask, mask: int) -> None:
    umask(mask)
    write_json_atomic(tmp_path / "run.json", {"a": 1})
    os.close(create_output(tmp_path / "trace.csv"))
    for name in ("run.json", "trace.csv"):
        assert stat.S_IMODE((tmp_path / name).stat().st_mode) == 0o666 & ~mask, name


def test_a_symbolic_link_is_refused_and_its_target_untouched(tmp_path: Path) -> None:
    victim = tmp_path / "precious.txt"
    victim.write_text("keep me")
    (tmp_path / "trace.csv").symlink_to(victim)
    (tmp_path / "run.json").symlink_to(tmp_path / "nowhere")  # dangling: still refused
    with pytest.raises(UnsafeOutput, match="symbolic link"):
        create_output(tmp_path / "trace.csv")
    with pytest.raises(UnsafeOutput, match="symbolic link"):
        write_json_atomic(tmp_path / "run.json", {"a": 1})
    assert victim.read_text() == "keep me" and not (tmp_path / "nowhere").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_special_files_are_refused_without_blocking(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "trace.csv")
    (tmp_path / "frames.jsonl").mkdir()
    with pytest.raises(UnsafeOutput, match="FIFO"):
        create_output(tmp_path / "trace.csv")
    with pytest.raises(UnsafeOutput, match="directory"):
        check_output(tmp_path / "frames.jsonl")
    with pytest.raises(UnsafeOutput, match="FIFO"):
        RunDirectory(tmp_path, {})
    run = read_run(tmp_path)  # a FIFO would block a plain read
    assert any("FIFO" in p for p in run.problems)


def test_a_regular_file_is_replaced(tmp_path: Path) -> None:
    (tmp_path / "trace.csv").write_text("old")
    fd = create_output(tmp_path / "trace.csv")
    os.write(fd, b"new")
    os.close(fd)
    assert (tmp_path / "trace.csv").read_text() == "new"


def test_an_unsafe_output_is_found_before_the_previous_run_is_removed(tmp_path: Path) -> None:
    with TraceWriter(tmp_path, ("t",), {"seed": 1}) as w:
        w.write({"t": 0.0})
    before = (tmp_path / "run.json").read_text()
    os.symlink(tmp_path / "elsewhere", tmp_path / "frames.jsonl")
    with pytest.raises(UnsafeOutput):
        RunDirectory(tmp_path, {})
    assert (tmp_path / "run.json").read_text() == before and (tmp_path / "trace.csv").exists()


def test_a_held_directory_refuses_a_second_holder_in_this_process(tmp_path: Path) -> None:
    with RunDirectory(tmp_path, {"seed": 1}):
        with pytest.raises(DirectoryBusy) as err:
            RunDirectory(tmp_path, {"seed": 2})
        assert err.value.holder == os.getpid() and str(os.getpid()) in str(err.value)
        assert json.loads((tmp_path / "run.json").read_text())["seed"] == 1  # the holder's, untouched
    RunDirectory(tmp_path, {"seed": 3}).release()  # released: free again


def test_a_held_directory_refuses_another_process(tmp_path: Path) -> None:
    code = textwrap.dedent(f"""
        from twolevel.files import DirectoryBusy
        from twolevel.sim.trace import RunDirectory
        try:
            RunDirectory({str(tmp_path)!r}, {{}})
        except DirectoryBusy as exc:
            print("busy", exc.holder)
        else:
            print("taken")
    """)
    with RunDirectory(tmp_path, {}):
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120).stdout
    assert out.split() == ["busy", str(os.getpid())]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120).stdout
    assert out.split() == ["taken"]


def test_a_lock_adds_nothing_to_the_directory(tmp_path: Path) -> None:
    with DirectoryLock(tmp_path / "new") as lock:
        assert lock.locked and (tmp_path / "new").is_dir()
    assert list((tmp_path / "new").iterdir()) == []


def test_a_half_written_last_row_is_dropped(tmp_path: Path) -> None:
    with TraceWriter(tmp_path, ("t", "x"), {}) as w:
        for k in range(3):
            w.write({"t": k * 0.1, "x": float(k)})
    with open(tmp_path / "trace.csv", "a") as fh:
        fh.write("0.3,12")  # a row being written when the process died (no line end)
    run = read_run(tmp_path)
    assert run.rows == 3 and list(run.columns["x"]) == [0.0, 1.0, 2.0]
    assert any("truncated" in p for p in run.problems)
