"""OpenDRIVE (1.4–1.6) → a twolevel map of free-form lanes.

**The reader** is the CARLA client's map parser (pip ``carla``, the optional extra ``opendrive``):
``carla.Map(name, xodr_text)`` builds CARLA's road network without a server and answers
``get_waypoint_xodr(road, lane, s)`` — the centre, heading and width of any lane at any s, in
OpenDRIVE's own coordinates — and ``Waypoint.next`` across lane sections, roads and junctions.
It is CARLA's own reading of the maps CARLA users have (why it was chosen, with the figures: the
README's "`twolevel import`"). Two things it gets wrong are repaired on the XML before it reads it
(:func:`~twolevel.interop.opendrive_roads.repair`): a spiral whose curvature does not change
(``curvStart == curvEnd``, how scenariogeneration writes every junction turn) yields NaN
positions — it is rewritten as the arc (or line) it is; a junction whose id equals a road's id
loses every lane entering it — the junction is renumbered.

**What is converted.** Every lane of the selected types (driving, and the ramps' entry, exit,
onRamp, offRamp, connectingRamp; shoulders, parking, … on request) in every lane section becomes
one free-form lane ``r<road>_<section>_<lane>`` given by its boundaries in its direction of travel
(right-hand traffic: lanes with negative ids drive along the reference line; ``rule="LHT"`` roads
the other way). Boundaries are the centre ± half the width along the normal, sampled at every
geometry piece's ends and, on curves and where widths or offsets vary, close enough that the
polyline stays within :data:`TOLERANCE` of the curve (at most :data:`STEP` apart). Successors
come from the reader (lane links, junction connections, contact points); lanes beside each other
in a section are adjacent; line markings and lane types carry over; junctions' connecting roads
become free-form lanes too. Speed limits from road types and lane speed records; signals:
speed-limit signs (DE 274, US R2-1), stop signs (DE 206, US R1-1) with the stop line (DE 294) of
their lanes where one is drawn, traffic lights (OpenDRIVE 1000001…, dynamic) with a default
program (OpenDRIVE holds none): lights of one controller share a phase, a junction's controllers
take turns. Whatever else the file holds (objects, signal references, unknown signals, elevation,
junction priorities) is reported at its element and line (:mod:`twolevel.interop.codes`).

The XML's roads are read and repaired by :mod:`twolevel.interop.opendrive_roads`, the reader runs
in :mod:`twolevel.interop.carla_reader`, signals are placed by :mod:`twolevel.interop.opendrive_signals`.
Units: m, rad (OpenDRIVE's own), speeds converted to m/s.
"""

from __future__ import annotations

import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twolevel.interop import ImportResult
from twolevel.interop.carla_reader import Request, isolated, read
from twolevel.interop.codes import IMP703, IMP704, IMP705, IMP706, IMP712, IMP713
from twolevel.interop.opendrive_roads import EPS as _EPS
from twolevel.interop.opendrive_roads import Lane, Road, Section, lane_key, read_road, repair, report_unconverted
from twolevel.interop.opendrive_signals import place_signals
from twolevel.interop.source import XmlSource

__all__ = ["Options", "convert", "import_file", "DRIVING", "OPTIONAL_KINDS", "STEP", "TOLERANCE"]

STEP = 5.0
"""Longest distance [m] between samples of a lane where its geometry or width is not straight."""
TOLERANCE = 0.01
"""Largest distance [m] between a sampled boundary polyline and the curve it follows (chord sag)."""
DRIVING = ("driving", "entry", "exit", "onRamp", "offRamp", "connectingRamp")
"""OpenDRIVE lane types imported as driving lanes."""
OPTIONAL_KINDS = {"shoulder": "shoulder", "parking": "parking", "biking": "bicycle", "bicycle": "bicycle",
                  "sidewalk": "sidewalk", "bus": "bus", "restricted": "restricted"}
"""OpenDRIVE lane type → twolevel lane kind, for the types imported on request."""
_MARKINGS = {"Solid": "solid", "Broken": "dashed", "SolidSolid": "double_solid", "BrokenBroken": "dashed",
             "BottsDots": "dashed", "Curb": "curb"}


@dataclass(frozen=True)
class Options:
    """What to import besides driving lanes: ``include`` holds OpenDRIVE lane types of
    :data:`OPTIONAL_KINDS` (``shoulder``, ``parking``, …)."""

    include: tuple[str, ...] = ()


def _samples(road: Road, sec: Section) -> list[float]:
    """The s [m] at which a section's lanes are sampled: every piece's ends, and between them close
    enough for :data:`TOLERANCE` on curves (or :data:`STEP` where widths or offsets vary)."""
    a, b = sec.s0 + _EPS, sec.s1 - _EPS
    bend = road.offset_bend + sum(ln.bend for ln in sec.lanes.values())  # bounds the borders' sideways bend
    out = [a, b]
    for p0, p1, kappa in road.pieces:
        lo, hi = max(p0, a), min(p1, b)
        if hi <= lo:
            continue
        step = min(STEP, math.sqrt(8 * TOLERANCE / bend)) if bend > 0 else math.inf
        if kappa > 0:
            step = min(step, STEP, math.sqrt(8 * TOLERANCE / kappa)) if math.isfinite(kappa) else 1.0
        step = max(step, 0.25)
        n = max(1, math.ceil((hi - lo) / step)) if math.isfinite(step) else 1
        out.extend(lo + (hi - lo) * i / n for i in range(n + 1))
    out.sort()
    dedup = [out[0]]
    for s in out[1:]:
        if s - dedup[-1] > 0.02:
            dedup.append(s)
    if b - dedup[-1] > 1e-9:
        dedup[-1] = b
    return dedup


def _marking(kind: str, can_cross: bool) -> str | None:
    if kind in ("SolidBroken", "BrokenSolid"):
        return "dashed_solid" if can_cross else "solid_dashed"
    return _MARKINGS.get(kind)


"""What the reader is asked of one lane: road id, lane id, the s [m] to sample in the order of travel,
whether travel is opposite to the reader's assumption (negative lanes along s), the s of its end [m]."""
"""Left and right boundary [[x, y], …] [m] in the direction of travel, the reader's left and right
marking types and lane-change permission at the middle sample, and (road, lane, s) of the lanes
just past the end; None when the reader has no such lane or gives positions that cannot be."""


def _lane_type(lane: Lane, options: Options) -> str | None:
    if lane.type in DRIVING:
        return "driving"
    if lane.type in options.include:
        return OPTIONAL_KINDS[lane.type]
    return None


def _trim_tapers(left: list[list[float]], right: list[list[float]]) -> None:
    """Drop the samples next to an end where a tapering lane is already narrower than 0.1 m (in
    place): its ends may be 0 wide, not the points between them."""
    def width(i: int) -> float:
        return math.dist(left[i], right[i])

    while len(left) > 2 and width(1) < 0.1:
        del left[1], right[1]
    while len(left) > 2 and width(-2) < 0.1:
        del left[-2], right[-2]


def _width_ok(left: list[list[float]], right: list[list[float]]) -> bool:
    """The lane is at least 0.1 m wide except at its ends (which may taper to 0)."""
    w = [math.hypot(a[0] - b[0], a[1] - b[1]) for a, b in zip(left, right)]
    return max(w) >= 0.1 and all(x >= 0.1 for x in w[1:-1])


def _limit_at(records: list[tuple[float, float]], s: float) -> float | None:
    found = None
    for s0, v in records:
        if s0 <= s + 1e-9:
            found = v
    return found


def convert(src: XmlSource, options: Options = Options()) -> dict[str, Any] | None:
    """The map (the content of a twolevel map file) the OpenDRIVE document ``src`` describes, or
    None when it cannot be used; what is left out, repaired or assumed goes to ``src.findings``."""
    if src.root.tag != "OpenDRIVE":
        src.report(IMP703, f"the root element is <{src.root.tag[:40]}>, not <OpenDRIVE>", src.root)
        return None
    header = src.root.find("header")
    if header is not None:
        version = (header.get("revMajor"), header.get("revMinor"))
        if version[0] != "1" or version[1] not in ("4", "5", "6", "7", "8"):
            src.report(IMP713, f"OpenDRIVE {version[0]}.{version[1]}: read as 1.4-1.6", header)
    roads: dict[int, Road] = {}
    changed = False
    for el in src.root.findall("road"):
        road = read_road(src, el)
        if road is not None and road.id in roads:
            src.report(IMP712, f"road id {road.id} used twice; the second is left out", el)
            road = None
        if road is None:  # the reader is not given what the import left out (it may crash on it)
            src.root.remove(el)
            changed = True
            continue
        roads[road.id] = road
    changed = repair(src) or changed
    if not roads:
        src.report(IMP706, "the file has no usable <road>", src.root)
        return None
    try:
        import carla  # noqa: F401 - imported again where it reads
    except ImportError:
        src.report(IMP704, "reading OpenDRIVE needs the CARLA client's map parser: pip install 'twolevel[opendrive]'",
                   src.root, hint="the extra installs carla 0.9.16 (wheels for Python 3.11 and 3.12)")
        return None
    text = ET.tostring(src.root, encoding="unicode") if changed else src.text
    name = (header.get("name") if header is not None else None) or os.path.splitext(os.path.basename(src.file))[0]
    wanted: list[tuple[Road, int, Section, Lane, str, bool]] = []
    requests: list[Request] = []
    for road in roads.values():
        for k, sec in enumerate(road.sections):
            ss = _samples(road, sec)
            for lane in sec.lanes.values():
                kind = _lane_type(lane, options)
                if kind is None:
                    continue
                forward = (lane.id < 0) != road.lht
                wanted.append((road, k, sec, lane, kind, forward))
                requests.append((road.id, lane.id, ss if forward else ss[::-1], forward != (lane.id < 0),
                                 (sec.s1 - _EPS) if forward else (sec.s0 + _EPS)))
    answers, crash = isolated(read, name or "map", text, requests)
    if crash is not None or isinstance(answers, str):
        src.report(IMP705, f"the CARLA map parser refused the file: {answers if crash is None else crash}", src.root,
                   hint="the findings above may name the element; `twolevel check` the file after fixing it")
        return None
    built: dict[str, dict] = {}
    lanes_out: list[dict] = []
    skipped = 0
    for (road, k, sec, lane, kind, forward), got in zip(wanted, answers):
        if got is None:
            src.report(IMP712, f"road {road.id} section {k} lane {lane.id}: the reader gives no usable position; "
                               "left out", lane.element)
            continue
        left, right, lm_kind, rm_kind, change, nexts = got
        _trim_tapers(left, right)
        if not _width_ok(left, right):
            skipped += 1
            continue
        key = lane_key(road.id, k, lane.id)
        rec: dict[str, Any] = {"id": key, "type": kind, "left_bound": left, "right_bound": right}
        lm = _marking(lm_kind, change in ("Left", "Both"))
        rm = _marking(rm_kind, change in ("Right", "Both"))
        if forward != (lane.id < 0):
            lm, rm = rm, lm
        if lm:
            rec["left_marking"] = lm
        if rm:
            rec["right_marking"] = rm
        start_s = sec.s0 if forward else sec.s1
        limit = _limit_at(lane.speeds, start_s - sec.s0) or _limit_at(road.limits, start_s)
        if limit is not None:
            rec["speed_limit"] = round(limit, 4)
        rec["_section"], rec["_road"], rec["_lane"], rec["_forward"], rec["_next"] = sec, road, lane, forward, nexts
        rec["_length"] = sum(math.hypot(a[0] - b[0], a[1] - b[1]) for a, b in zip(left, left[1:]))
        built[key] = rec
        lanes_out.append(rec)
    if skipped:
        src.report(IMP713, f"{skipped} lane(s) narrower than 0.1 m along their length left out (placeholders)", None)
    if not lanes_out:
        src.report(IMP706, "no lane of the selected types could be converted", src.root,
                   hint="--include shoulder/parking/… imports other lane types")
        return None
    _link(src, roads, built)
    out: dict[str, Any] = {"speed_limits": [], "stop_signs": [], "traffic_lights": []}
    place_signals(src, roads, built, out)
    _inner_limits(roads, built, out)
    report_unconverted(src)
    for rec in lanes_out:
        for k in [k for k in rec if k.startswith("_")]:
            del rec[k]
    data: dict[str, Any] = {"kind": "map", "name": name, "lanes": lanes_out}
    data.update({k: v for k, v in out.items() if v})
    return data


def _ends(rec: dict) -> tuple[list[float], list[float], float]:
    """A lane's centre at its start and end [m] and its widest width [m]."""
    lb, rb = rec["left_bound"], rec["right_bound"]
    mid = [[(a[0] + b[0]) / 2, (a[1] + b[1]) / 2] for a, b in ((lb[0], rb[0]), (lb[-1], rb[-1]))]
    return mid[0], mid[1], max(math.dist(a, b) for a, b in zip(lb, rb))


def _link(src: XmlSource, roads: dict[int, Road], built: dict[str, dict]) -> None:
    """Successors from the reader (just past each lane's end; one that starts away from the end is
    reported and dropped), adjacency within a section."""
    for key, rec in built.items():
        road, lane = rec["_road"], rec["_lane"]
        succ = []
        for n_road, n_lane, n_s in rec["_next"]:
            r = roads.get(n_road)
            if r is None or not r.sections:
                continue
            other = lane_key(n_road, r.section_at(n_s), n_lane)
            if other != key and other in built and other not in succ:
                end, (start, _, width) = _ends(rec)[1], _ends(built[other])
                if math.dist(end, start) > 0.5 * width + 0.5:
                    src.report(IMP712, f"lane {key} leads into lane {other}, which starts {math.dist(end, start):.1f} m "
                                       "away from its end: the link is left out (the geometry does not meet)", road.element)
                    continue
                succ.append(other)
        if succ:
            rec["successors"] = succ
        k = rec["_section"]
        sec_index = road.sections.index(k)
        forward = rec["_forward"]
        inner = lane.id + 1 if lane.id < 0 else lane.id - 1
        inner = inner if inner != 0 else (1 if lane.id < 0 else -1)
        outer = lane.id - 1 if lane.id < 0 else lane.id + 1
        # the travel-left side is the inner one for lanes driving their usual way
        left_id, right_id = (inner, outer) if forward == (lane.id < 0) else (outer, inner)
        for side, lid in (("adjacent_left", left_id), ("adjacent_right", right_id)):
            other = lane_key(road.id, sec_index, lid)
            if other in built:
                rec[side] = other


def _inner_limits(roads: dict[int, Road], built: dict[str, dict], out: dict[str, list]) -> None:
    """Limits that change inside a lane (road type or lane speed records after its start) as signs."""
    for key, rec in built.items():
        road, lane, sec, forward = rec["_road"], rec["_lane"], rec["_section"], rec["_forward"]
        changes = [(s, v) for s, v in road.limits if sec.s0 + 0.5 < s < sec.s1 - 0.5]
        changes += [(sec.s0 + s, v) for s, v in lane.speeds if 0.5 < s < sec.s1 - sec.s0 - 0.5]
        for n, (s, v) in enumerate(sorted(changes)):
            along = s - sec.s0 if forward else sec.s1 - s
            out["speed_limits"].append({"id": f"limit{n}@{key}", "lane": key, "s": round(along, 3), "value": round(v, 4)})


def import_file(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], include: tuple[str, ...] = ()) -> ImportResult:
    """Convert the OpenDRIVE map at ``path`` and write ``<out_dir>/<stem>.yaml`` (``include``: lane
    types of :data:`OPTIONAL_KINDS` imported besides driving lanes); the written map is checked by
    the map loader (its findings, at the YAML's lines, come with the import's)."""
    from twolevel.interop.output import write_map
    from twolevel.interop.source import read_xml

    src, diags = read_xml(path)
    if src is None:
        return ImportResult((), tuple(diags))
    data = convert(src, Options(include=tuple(include)))
    if data is None:
        return ImportResult((), tuple(src.findings))
    header = (f"Imported from {Path(path).name} (OpenDRIVE) by `twolevel import`: free-form lanes r<road>_<section>_<lane>.\n"
              "Regenerate rather than edit by hand.")
    return write_map(data, header, path, Path(out_dir) / f"{Path(path).stem}.yaml", src.findings)
