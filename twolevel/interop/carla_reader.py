"""CARLA's map parser asked about the lanes of an OpenDRIVE text (pip ``carla``, the extra
``opendrive``), in a forked child process (:func:`isolated`): a crash of its C++ code on a hostile
file is an answer, not the end of twolevel. Positions in OpenDRIVE's frame (CARLA mirrors y).
Units: m, rad."""

from __future__ import annotations

import contextlib
import faulthandler
import math
import os
from typing import Any, Iterator

__all__ = ["Request", "Answer", "LOOK", "read", "isolated"]

LOOK = 0.02  # [m] how far past a lane's end its successors are looked up


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """The reader prints to the C stderr (a georeference warning per map): silence fd 2 meanwhile."""
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


Request = tuple[int, int, list[float], bool, float]


Answer = tuple[list[list[float]], list[list[float]], str, str, str, list[tuple[int, int, float]]] | None


def read(name: str, text: str, requests: list[Request]) -> list[Answer] | str:
    """The reader's answers to ``requests`` (in the process that runs it), or why it refused the file."""
    import carla

    try:
        with _quiet_stderr():
            m = carla.Map(name or "map", text)
    except RuntimeError as exc:
        return str(exc)
    return [_answer(m, *req) for req in requests]


def _answer(m: Any, road: int, lane: int, order: list[float], flip: bool, end: float) -> Answer:
    left, right, mid = [], [], None
    for i, s in enumerate(order):
        w = m.get_waypoint_xodr(road, lane, s)
        if w is None:
            return None
        tf = w.transform
        x, y, yaw, half = tf.location.x, -tf.location.y, -math.radians(tf.rotation.yaw), 0.5 * w.lane_width
        if flip:
            yaw += math.pi
        nx, ny = -math.sin(yaw) * half, math.cos(yaw) * half
        left.append([x + nx, y + ny])
        right.append([x - nx, y - ny])
        if i == len(order) // 2:
            mid = w
    if mid is None or not all(math.isfinite(v) for p in left + right for v in p):
        return None
    for k in range(1, len(order)):  # a sample far from where its distance along the road allows: the reader failed
        gap = math.dist(left[k], left[k - 1]) + math.dist(right[k], right[k - 1])
        if gap > 4 * abs(order[k] - order[k - 1]) + 2.0:
            return None
    w = m.get_waypoint_xodr(road, lane, end)
    nexts = [(n.road_id, n.lane_id, n.s) for n in w.next(LOOK)] if w is not None else []
    marks = [str(getattr(x, "type", "NONE")) for x in (mid.left_lane_marking, mid.right_lane_marking)]
    return (left, right, marks[0], marks[1], str(mid.lane_change), nexts)


def isolated(fn: Any, *args: Any) -> tuple[Any, str | None]:
    """``fn(*args)`` run in a forked child process, so that a crash of the reader's C++ code on a
    hostile file (a link to a road that does not exist ends in a segmentation fault) is a finding,
    not the end of twolevel: (result, None), or (None, why it failed). In process where there is no fork."""
    import pickle

    if not hasattr(os, "fork"):
        return fn(*args), None
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: answer through the pipe, never return into the caller's code
        try:
            os.close(r)
            faulthandler.disable()  # a crash here is the parent's finding, not a dump on the terminal
            try:
                payload = pickle.dumps((True, fn(*args)), protocol=pickle.HIGHEST_PROTOCOL)
            except BaseException as exc:  # noqa: BLE001 - reported by the parent
                payload = pickle.dumps((False, f"{type(exc).__name__}: {exc}"))
            with os.fdopen(w, "wb") as out:
                out.write(payload)
        finally:
            os._exit(0)
    os.close(w)
    with os.fdopen(r, "rb") as inp:
        data = inp.read()
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        return None, f"the reader crashed (signal {os.WTERMSIG(status)})"
    if os.WEXITSTATUS(status) != 0 or not data:
        return None, "the reader ended without an answer"
    ok, value = pickle.loads(data)
    return (value, None) if ok else (None, f"the reader failed ({value})")
