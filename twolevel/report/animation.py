"""Top-down animation of a run as a GIF, from the simulator's ``frames.jsonl``.

Each line of ``frames.jsonl`` is one step::

    {"t": 12.3, "ego": [x, y, psi, length, width], "plan": [[x, y], ...],
     "others": [[x, y, psi, length, width], ...], "lights": [{"x": .., "y": .., "state": "red"}]}

Boxes are centred on (x, y) [m] with heading psi [rad]. The map's lane centre lines come from
run.json's ``map_lines`` (polylines). The camera follows the ego. Frames are subsampled evenly
(at most ``max_frames``), drawn with Agg on one reused figure (axes drawn once, each frame blitted over them,
in coordinates relative to the ego), mapped to a fixed web-safe palette
(no flicker, no per-frame palette) and written with Pillow's GIF encoder: the same run gives
the same bytes.
"""

from __future__ import annotations

import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from twolevel.files import open_regular
from twolevel.models import obb
from twolevel.sim.trace import FRAMES_FILE

EGO, PLAN, OTHER, OTHER_EDGE, LANE, PATH = "#3366cc", "#ff6600", "#999999", "#333333", "#cccccc", "#99ccff"
LIGHT = {"red": "#cc0000", "yellow": "#ffcc00", "green": "#00cc00", "none": "#999999"}


@dataclass(frozen=True)
class Animation:
    """The GIF (None when it could not be made), how many frames it shows out of how many
    recorded steps, the playback time per frame [ms], and what went wrong."""

    gif: bytes | None
    frames: int
    problems: tuple[str, ...]
    total: int = 0
    frame_ms: int = 0


def box_corners(boxes: np.ndarray) -> np.ndarray:
    """Corners [m] of oriented boxes ``(n, 5)`` rows [x, y, psi, length, width] → ``(n, 4, 2)``."""
    b = np.asarray(boxes, dtype=float).reshape(-1, 5)
    return obb.box_corners(b[:, 0], b[:, 1], b[:, 2], b[:, 3], b[:, 4])


def read_frames(path: str | Path, max_frames: int) -> tuple[list[dict[str, Any]], int, list[str]]:
    """Evenly subsampled frames (first and last kept), the number of readable lines, problems."""
    problems: list[str] = []
    fh, refusal = open_regular(path)  # a FIFO placed there would block a plain read
    if fh is None:
        assert refusal is not None
        raise OSError(refusal.detail)
    with fh:
        text = fh.read().decode("utf-8", errors="replace")
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if lines:
        try:
            json.loads(lines[-1])
        except json.JSONDecodeError:
            problems.append(f"{path}: the last line is truncated and was ignored")
            lines.pop()
    n = len(lines)
    if n == 0:
        return [], 0, problems + [f"{path} holds no frame"]
    idx = np.unique(np.linspace(0, n - 1, min(n, max(1, max_frames))).round().astype(int))
    frames, bad = [], 0
    for i in idx.tolist():
        try:
            f = json.loads(lines[i])
            _ = float(f["t"]), np.asarray(f["ego"], dtype=float).reshape(5)
            frames.append(f)
        except (json.JSONDecodeError, KeyError, TypeError, ValueError):
            bad += 1
    if bad:
        problems.append(f"{path}: {bad} malformed frame(s) skipped")
    return frames, n, problems


def _palette() -> Any:
    from PIL import Image

    cube = [(r, g, b) for r in range(0, 256, 51) for g in range(0, 256, 51) for b in range(0, 256, 51)]
    greys = [(v, v, v) for v in np.linspace(8, 248, 40).round().astype(int).tolist()]
    flat = [c for rgb in cube + greys for c in rgb]
    pal = Image.new("P", (1, 1))
    pal.putpalette(flat)
    return pal


def render_gif(
    frames_path: str | Path,
    meta: Mapping[str, Any] | None = None,
    trace: Mapping[str, Any] | None = None,
    *,
    max_frames: int = 200,
    size_px: int = 440,
    view_m: float = 70.0,
) -> Animation:
    """Draw the run seen from above. ``trace`` (the run's columns) adds the travelled path and
    the speed and decision in each frame's title. Never raises on bad input: see ``problems``."""
    path = Path(frames_path)
    if not path.exists():
        return Animation(None, 0, (f"{path} is missing: no animation",))
    try:
        frames, total, problems = read_frames(path, max_frames)
    except OSError as exc:
        return Animation(None, 0, (f"{path}: unreadable ({exc})",))
    if not frames:
        return Animation(None, 0, tuple(problems))
    import matplotlib

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection, PolyCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Polygon
    from matplotlib.transforms import Affine2D
    from PIL import Image

    dpi = 80
    half = view_m / 2
    with matplotlib.rc_context({"font.size": 8, "axes.grid": False}):
        fig = Figure(figsize=(size_px / dpi, size_px / dpi), dpi=dpi)
        canvas = FigureCanvasAgg(fig)
        ax = fig.add_axes((0.14, 0.1, 0.82, 0.8))
        ax.set_aspect("equal", adjustable="box")
        ax.set(xlabel="x − x_ego [m]", ylabel="y − y_ego [m]", xlim=(-half, half), ylim=(-half, half))
        moving: list[Any] = []  # drawn in world coordinates, shifted so that the ego is at (0, 0)
        lines = (meta or {}).get("map_lines") or []
        try:
            segs = [np.asarray(ln, dtype=float).reshape(-1, 2) for ln in lines]
            moving.append(ax.add_collection(LineCollection(segs, colors=LANE, linewidths=1.0, linestyles="--"), autolim=False))
        except (TypeError, ValueError):
            problems.append("run.json's map_lines is malformed: lane lines not drawn")
        t_col = v_col = dec = gap = None
        if trace is not None:
            t_col, v_col, dec, gap = trace.get("t"), trace.get("v"), trace.get("decision"), trace.get("min_gap")
            x, y = trace.get("x"), trace.get("y")
            if isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and x.size == y.size:
                moving += ax.plot(x, y, color=PATH, linewidth=1.0, scalex=False, scaley=False)
        others = ax.add_collection(PolyCollection([], facecolors=OTHER, edgecolors=OTHER_EDGE, linewidths=0.8, alpha=0.8), autolim=False)
        (plan,) = ax.plot([], [], color=PLAN, linewidth=1.5, marker=".", markersize=3, scalex=False, scaley=False)
        ego = ax.add_patch(Polygon(np.zeros((4, 2)), closed=True, facecolor=EGO, edgecolor="#003399"))
        lights = ax.scatter([], [], s=40, edgecolors="#333333", linewidths=0.6, zorder=5)
        moving += [plan, ego, others]  # others last: an overlap with the ego stays visible
        title = fig.text(0.55, 0.95, "", ha="center", va="center", fontsize=9)
        for a in (*moving, lights, title):
            a.set_animated(True)
        ax.set(xlim=(-half, half), ylim=(-half, half))
        canvas.draw()  # axes, ticks and labels once; frames are blitted over them
        background = canvas.copy_from_bbox(fig.bbox)
        pal = _palette()
        images = []
        for f in frames:
            e = np.asarray(f["ego"], dtype=float).reshape(5)
            shift = Affine2D().translate(-e[0], -e[1]) + ax.transData
            ego.set_xy(box_corners(e)[0])
            p = np.asarray(f.get("plan") or np.zeros((0, 2)), dtype=float).reshape(-1, 2)
            plan.set_data(p[:, 0], p[:, 1])
            o = np.asarray(f.get("others") or np.zeros((0, 5)), dtype=float).reshape(-1, 5)
            others.set_verts(list(box_corners(o)))
            lt = [lg for lg in f.get("lights") or [] if isinstance(lg, Mapping)]
            lights.set_offsets(np.array([[_num(lg.get("x")), _num(lg.get("y"))] for lg in lt]).reshape(-1, 2))
            lights.set_facecolors([LIGHT.get(str(lg.get("state", "none")), LIGHT["none"]) for lg in lt] or ["none"])
            lights.set_offset_transform(shift)
            k = _row(float(f["t"]), t_col)
            hit = k is not None and isinstance(gap, np.ndarray) and gap.size == t_col.size and bool(gap[k] < 0)
            ego.set_edgecolor(LIGHT["red"] if hit else "#003399")
            ego.set_linewidth(2.0 if hit else 1.0)
            title.set_text(_title(float(f["t"]), e, k, v_col, dec) + ("   BOXES OVERLAP" if hit else ""))
            canvas.restore_region(background)
            for a in moving:
                a.set_transform(shift)
                ax.draw_artist(a)
            ax.draw_artist(lights)
            fig.draw_artist(title)
            rgb = Image.frombuffer("RGBA", canvas.get_width_height(), bytes(canvas.buffer_rgba()), "raw", "RGBA", 0, 1).convert("RGB")
            images.append(rgb.quantize(palette=pal, dither=Image.Dither.NONE))
    times = [float(f["t"]) for f in frames]
    step = float(np.median(np.diff(times))) if len(times) > 1 else 0.1
    duration = int(min(1000, max(40, round(1000 * step))))  # real time, within what viewers play
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=duration, loop=0)
    return Animation(buf.getvalue(), len(frames), tuple(problems), total, duration)


def _num(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _row(t: float, t_col: Any) -> int | None:
    """The trace row recorded at time ``t`` [s] (the first at or after it)."""
    if not isinstance(t_col, np.ndarray) or not t_col.size:
        return None
    return int(np.clip(np.searchsorted(t_col, t - 1e-9), 0, t_col.size - 1))


def _title(t: float, ego: np.ndarray, k: int | None, v_col: Any, dec: Any) -> str:
    text = f"t = {t:.2f} s   ego at ({ego[0]:.1f}, {ego[1]:.1f}) m"
    if k is None:
        return text
    parts = []
    if isinstance(v_col, np.ndarray) and k < v_col.size and math.isfinite(v_col[k]):
        parts.append(f"v = {v_col[k]:.2f} m/s")
    if isinstance(dec, Sequence) and k < len(dec):
        parts.append(f"decision: {dec[k]}")
    return text + ("\n" + "   ".join(parts) if parts else "")
