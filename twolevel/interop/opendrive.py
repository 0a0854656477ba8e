"""OpenDRIVE (1.4–1.6) → a twolevel map of free-form lanes.

**The reader** is the CARLA client's map parser (pip ``carla``, the optional extra ``opendrive``):
``carla.Map(name, xodr_text)`` builds CARLA's road network without a server and answers
``get_waypoint_xodr(road, lane, s)`` — the centre, heading and width of any lane at any s, in
OpenDRIVE's own coordinates — and ``Waypoint.next`` across lane sections, roads and junctions.
It is CARLA's own reading of the maps CARLA users have (why it was chosen: the README's
"Importing maps"). Two things it gets wrong are repaired on the XML before it reads it
(:func:`_repair`): a spiral whose curvature does not change (``curvStart == curvEnd``, how
scenariogeneration writes every junction turn) yields NaN positions — it is rewritten as the arc
(or line) it is; a junction whose id equals a road's id loses every lane entering it — the
junction is renumbered.

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

Units: m, rad (OpenDRIVE's own), speeds converted to m/s.
"""

from __future__ import annotations

import contextlib
import math
import os
import xml.etree.ElementTree as ET
from bisect import bisect_right
from dataclasses import dataclass, field
from typing import Any, Iterator

from twolevel.interop.codes import IMP703, IMP704, IMP705, IMP706, IMP710, IMP711, IMP712, IMP713
from twolevel.interop.source import XmlSource

__all__ = ["Options", "convert", "DRIVING", "OPTIONAL_KINDS", "STEP", "TOLERANCE"]

STEP = 5.0
"""Longest distance [m] between samples of a lane where its geometry or width is not straight."""
TOLERANCE = 0.01
"""Largest distance [m] between a sampled boundary polyline and the curve it follows (chord sag)."""
_EPS = 1e-3  # [m] samples stay this far inside a lane section (the reader answers for one section)
_FLAT = 1e-6  # [1/m] curvature below which an arc is read as a line (its sag over 100 m: 5 mm)
_LOOK = 0.02  # [m] how far past a lane's end its successors are looked up
DRIVING = ("driving", "entry", "exit", "onRamp", "offRamp", "connectingRamp")
"""OpenDRIVE lane types imported as driving lanes."""
OPTIONAL_KINDS = {"shoulder": "shoulder", "parking": "parking", "biking": "bicycle", "bicycle": "bicycle",
                  "sidewalk": "sidewalk", "bus": "bus", "restricted": "restricted"}
"""OpenDRIVE lane type → twolevel lane kind, for the types imported on request."""
_MARKINGS = {"Solid": "solid", "Broken": "dashed", "SolidSolid": "double_solid", "BrokenBroken": "dashed",
             "BottsDots": "dashed", "Curb": "curb"}
_SPEED_UNITS = {"m/s": 1.0, "km/h": 1 / 3.6, "mph": 0.44704}
_SPEED_SIGNS = {("274", None), ("R2-1", None), ("R2", "1")}
_STOP_SIGNS = {("206", None), ("R1-1", None), ("R1", "1")}
_STOP_LINES = {("294", None)}
_LINE_REACH = 30.0  # [m] farthest a stop line may be past its sign or light
_LIGHT_GREEN, _LIGHT_YELLOW = 20.0, 3.0  # [s] the default program's green and yellow


@dataclass(frozen=True)
class Options:
    """What to import besides driving lanes: ``include`` holds OpenDRIVE lane types of
    :data:`OPTIONAL_KINDS` (``shoulder``, ``parking``, …)."""

    include: tuple[str, ...] = ()


@dataclass
class _Lane:
    """One lane of one section as the XML gives it."""

    element: ET.Element
    id: int
    type: str
    bend: float  # largest |second derivative| of its width or border polynomials [1/m] (0: linear)
    speeds: list[tuple[float, float]]  # (sOffset from the section [m], limit [m/s])


@dataclass
class _Section:
    s0: float
    s1: float
    element: ET.Element
    lanes: dict[int, _Lane]


@dataclass
class _Road:
    element: ET.Element
    id: int
    length: float
    junction: int
    lht: bool
    pieces: list[tuple[float, float, float]]  # (s0, s1, largest |curvature| [1/m], inf: unknown)
    offset_bend: float  # largest |second derivative| of its lane offset [1/m]
    sections: list[_Section] = field(default_factory=list)
    limits: list[tuple[float, float]] = field(default_factory=list)  # road type records (s, limit [m/s])

    def section_at(self, s: float) -> int:
        return max(0, bisect_right([sec.s0 for sec in self.sections], s) - 1)


# ------------------------------------------------------------------------------------- reading


def _num(src: XmlSource, el: ET.Element, name: str, default: float | None = None) -> float:
    """Attribute ``name`` of ``el`` as a finite number; raises ValueError (reported) otherwise."""
    raw = el.get(name)
    if raw is None:
        if default is not None:
            return default
        src.report(IMP712, f"<{el.tag}> has no '{name}'", el)
        raise ValueError(name)
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        src.report(IMP712, f"<{el.tag}> {name}=\"{raw[:40]}\" is not a finite number", el)
        raise ValueError(name)
    return value


def _int(src: XmlSource, el: ET.Element, name: str) -> int:
    raw = el.get(name, "")
    try:
        return int(raw)
    except ValueError:
        src.report(IMP712, f"<{el.tag}> {name}=\"{raw[:40]}\" is not an integer (the reader needs integer ids)", el)
        raise


def _speed(src: XmlSource, el: ET.Element) -> float | None:
    """The limit [m/s] of a <speed> (lane record or a road type's), None when there is none."""
    raw = el.get("max", "")
    try:
        value = float(raw)
    except ValueError:
        if raw not in ("no limit", "undefined", ""):
            src.report(IMP712, f"speed max=\"{raw[:40]}\" is not a number", el)
        return None
    factor = _SPEED_UNITS.get(el.get("unit", "m/s"))
    if factor is None:
        src.report(IMP712, f"speed unit \"{el.get('unit')}\" is not m/s, km/h or mph", el)
        return None
    value *= factor
    if not (0 < value <= 100):
        src.report(IMP712, f"speed limit {value:.3g} m/s is outside (0, 100] m/s", el)
        return None
    return value


def _bend(polys: list[ET.Element], span: float = 100.0) -> float:
    """Largest |second derivative| [1/m] of cubic polynomials a + b·u + c·u² + d·u³ over ``span``
    [m] (a bound: |2c| + |6d|·span); inf when a coefficient is not a number."""
    out = 0.0
    for el in polys:
        try:
            c, d = float(el.get("c", "0") or 0), float(el.get("d", "0") or 0)
        except ValueError:
            return math.inf
        out = max(out, abs(2 * c) + abs(6 * d) * span)
    return out if math.isfinite(out) else math.inf


def _curvature(src: XmlSource, geom: ET.Element) -> float:
    """Largest |curvature| [1/m] of a planView piece (inf: not known, sampled at the finest step)."""
    kind = next(iter(geom), None)
    if kind is None or kind.tag not in ("line", "arc", "spiral", "poly3", "paramPoly3"):
        src.report(IMP712, f"<geometry> holds <{'nothing' if kind is None else kind.tag}>, not a line, arc, spiral, "
                           "poly3 or paramPoly3", geom)
        raise ValueError("geometry")
    if kind.tag == "line":
        return 0.0
    if kind.tag == "arc":
        return abs(_num(src, kind, "curvature"))
    if kind.tag == "spiral":
        return max(abs(_num(src, kind, "curvStart")), abs(_num(src, kind, "curvEnd")))
    return math.inf


def _lane(src: XmlSource, el: ET.Element) -> _Lane:
    widths = el.findall("width") + el.findall("border")
    speeds = []
    for sp in el.findall("speed"):
        v = _speed(src, sp)
        if v is not None:
            speeds.append((_num(src, sp, "sOffset", 0.0), v))
    for tag in ("access", "rule", "height"):
        for extra in el.findall(tag):
            src.report(IMP710, f"lane {el.get('id')}: <{tag}> is not converted", extra)
    return _Lane(el, _int(src, el, "id"), el.get("type", "none"), _bend(widths), speeds)


def _road(src: XmlSource, el: ET.Element) -> _Road | None:
    """The road ``el`` as far as the import needs it, or None (reported) when it is unusable."""
    try:
        rid, length = _int(src, el, "id"), _num(src, el, "length")
        junction = int(el.get("junction", "-1") or -1)
        pieces = []
        for g in el.findall("planView/geometry"):
            s0, ln = _num(src, g, "s"), _num(src, g, "length")
            pieces.append((s0, s0 + ln, _curvature(src, g)))
        if not pieces:
            src.report(IMP712, f"road {rid} has no <planView> geometry; left out", el)
            return None
        offsets = el.findall("lanes/laneOffset")
        road = _Road(el, rid, length, junction, el.get("rule", "RHT").upper() == "LHT", pieces, _bend(offsets))
        secs = el.findall("lanes/laneSection")
        starts = [_num(src, sec, "s") for sec in secs]
        for k, sec in enumerate(secs):
            s1 = starts[k + 1] if k + 1 < len(starts) else length
            if s1 - starts[k] < 2 * _EPS:
                continue
            lanes = {ln.id: ln for ln in (_lane(src, x) for side in ("left", "right") for x in sec.findall(f"{side}/lane"))}
            road.sections.append(_Section(starts[k], s1, sec, lanes))
        for t in el.findall("type"):
            sp = t.find("speed")
            v = _speed(src, sp) if sp is not None else None
            if v is not None:
                road.limits.append((_num(src, t, "s"), v))
    except ValueError:
        src.report(IMP712, f"road {el.get('id')} has invalid values (above); left out", el)
        return None
    return road


# ----------------------------------------------------------------------------------- repairs


def _repair(src: XmlSource) -> bool:
    """Rewrite what the reader mishandles, in the tree (reported); True when anything changed."""
    changed = False
    spirals = [sp for sp in src.root.iter("spiral") if _is_float(sp.get("curvStart")) and _is_float(sp.get("curvEnd"))
               and (abs(float(sp.get("curvStart", "0")) - float(sp.get("curvEnd", "0"))) <= 1e-12
                    or max(abs(float(sp.get("curvStart", "0"))), abs(float(sp.get("curvEnd", "0")))) < _FLAT)]
    for sp in spirals:
        c = float(sp.get("curvStart", "0"))
        sp.tag, sp.attrib = ("line", {}) if abs(c) < _FLAT else ("arc", {"curvature": repr(c)})
    flat = [arc for arc in src.root.iter("arc") if _is_float(arc.get("curvature")) and abs(float(arc.get("curvature", "0"))) < _FLAT]
    for arc in flat:
        arc.tag, arc.attrib = "line", {}
    spirals += flat
    if spirals:
        src.report(IMP711, f"{len(spirals)} spiral(s) of constant curvature (curvStart = curvEnd) read as arcs, and those "
                           f"and arcs flatter than {_FLAT:g} 1/m as lines (the reader gives NaN or zero positions on them)",
                   spirals[0])
        changed = True
    road_ids = {r.get("id") for r in src.root.findall("road")}
    junction_ids = {j.get("id") for j in src.root.findall("junction")}
    for r in src.root.findall("road"):
        for parent in r.findall("link"):
            for link in list(parent):
                known = road_ids if link.get("elementType", "road") == "road" else junction_ids
                target = link.get("elementId", link.get("id"))
                if target not in known:
                    src.report(IMP712, f"road {r.get('id')}: its {link.tag} {link.get('elementType', 'road')} {target} "
                                       "does not exist; the link is left out", link)
                    parent.remove(link)
                    changed = True
    for j in src.root.findall("junction"):
        for c in list(j.findall("connection")):
            if c.get("incomingRoad") not in road_ids or c.get("connectingRoad") not in road_ids:
                src.report(IMP712, f"junction {j.get('id')}: connection {c.get('id')} names a road that does not exist; "
                                   "left out", c)
                j.remove(c)
                changed = True
    taken = set(road_ids) | {j.get("id") for j in src.root.findall("junction")}
    numeric = [int(x) for x in taken if x is not None and x.lstrip("-").isdigit()]
    fresh = max(numeric, default=0) + 1
    for j in src.root.findall("junction"):
        old = j.get("id")
        if old not in road_ids:
            continue
        new = str(fresh)
        fresh += 1
        j.set("id", new)
        for r in src.root.findall("road"):
            if r.get("junction") == old:
                r.set("junction", new)
            for link in r.findall("link/*"):
                if link.get("elementType") == "junction" and link.get("elementId") == old:
                    link.set("elementId", new)
        src.report(IMP711, f"junction id {old} is also a road's id: renumbered {new} "
                           "(the reader loses every lane entering such a junction)", j)
        changed = True
    return changed


# ------------------------------------------------------------------------------------ sampling


def _samples(road: _Road, sec: _Section) -> list[float]:
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


# ---------------------------------------------------------------------------------- conversion


def _lane_key(road: int, section: int, lane: int) -> str:
    return f"r{road}_{section}_{lane}"


def _marking(kind: str, can_cross: bool) -> str | None:
    if kind in ("SolidBroken", "BrokenSolid"):
        return "dashed_solid" if can_cross else "solid_dashed"
    return _MARKINGS.get(kind)


Request = tuple[int, int, list[float], bool, float]
"""What the reader is asked of one lane: road id, lane id, the s [m] to sample in the order of travel,
whether travel is opposite to the reader's assumption (negative lanes along s), the s of its end [m]."""
Answer = tuple[list[list[float]], list[list[float]], str, str, str, list[tuple[int, int, float]]] | None
"""Left and right boundary [[x, y], …] [m] in the direction of travel, the reader's left and right
marking types and lane-change permission at the middle sample, and (road, lane, s) of the lanes
just past the end; None when the reader has no such lane or gives positions that cannot be."""


def _read(name: str, text: str, requests: list[Request]) -> list[Answer] | str:
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
    nexts = [(n.road_id, n.lane_id, n.s) for n in w.next(_LOOK)] if w is not None else []
    marks = [str(getattr(x, "type", "NONE")) for x in (mid.left_lane_marking, mid.right_lane_marking)]
    return (left, right, marks[0], marks[1], str(mid.lane_change), nexts)


def _isolated(fn: Any, *args: Any) -> tuple[Any, str | None]:
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


def _lane_type(lane: _Lane, options: Options) -> str | None:
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


def _signals(src: XmlSource, roads: dict[int, _Road], built: dict[str, dict], out: dict[str, list]) -> None:
    """Speed-limit signs, stop signs and lights with their stop lines, on the lanes they govern."""
    lights: list[tuple[str, dict, str | None, int]] = []  # (signal id, record, controller, junction)
    controller_of = {}
    for ctrl in src.root.findall("controller"):
        for ref in ctrl.findall("control"):
            controller_of[ref.get("signalId")] = ctrl.get("id")
    junction_of_ctrl = {}
    for j in src.root.findall("junction"):
        for c in j.findall("controller"):
            junction_of_ctrl[c.get("id")] = j.get("id")
    for road in roads.values():
        lines: dict[bool, list[tuple[float, ET.Element]]] = {True: [], False: []}  # stop lines by direction
        pending: list[tuple[ET.Element, str, float, bool, list[str], float]] = []
        for sig in road.element.findall("signals/signal"):
            key = (sig.get("type", ""), sig.get("subtype") if sig.get("type") in ("R1", "R2") else None)
            dynamic = sig.get("dynamic", "no") == "yes"
            kind = ("speed" if key in _SPEED_SIGNS else "stop" if key in _STOP_SIGNS else
                    "line" if key in _STOP_LINES else "light" if dynamic and sig.get("type", "").startswith("1000") else None)
            if kind is None:
                src.report(IMP710, f"signal {sig.get('id')} (country {sig.get('country')}, type {sig.get('type')}, "
                                   f"subtype {sig.get('subtype')}) is not converted", sig,
                           hint="converted: speed limits (274, R2-1), stop signs (206, R1-1), stop lines (294), lights (1000xxx)")
                continue
            try:
                s = min(max(_num(src, sig, "s"), 0.0), road.length)
            except ValueError:
                continue
            orient = sig.get("orientation", "+")
            for forward in (True, False):  # "+": lanes driving along s, "-": against it, "none": both
                if orient != "none" and (orient == "+") != forward:
                    continue
                if kind == "line":
                    lines[forward].append((s, sig))
                    continue
                lanes = _valid_lanes(src, sig, road, s, forward, built)
                if not lanes:
                    src.report(IMP710, f"signal {sig.get('id')}: no imported lane at s = {s:.1f} m of road {road.id} "
                                       f"in its direction ({orient}); not converted", sig)
                    continue
                value = 0.0
                if kind == "speed":
                    v = _speed(src, ET.Element("speed", {"max": sig.get("value", ""), "unit": sig.get("unit", "km/h")}))
                    if v is None:
                        src.report(IMP712, f"speed-limit sign {sig.get('id')} has no usable value", sig)
                        continue
                    value = v
                pending.append((sig, kind, s, forward, lanes, value))
        used: set[int] = set()
        for sig, kind, s, forward, lanes, value in pending:
            stop_s = s
            if kind in ("stop", "light"):  # its stop line: the nearest one drawn up to 30 m ahead of it
                ahead = [(abs(x - s), x, line) for x, line in lines[forward]
                         if -1.0 <= (x - s) * (1 if forward else -1) <= _LINE_REACH]
                if ahead:
                    _, stop_s, line = min(ahead, key=lambda a: a[0])
                    used.add(id(line))
            for lane_id in lanes:
                rec = built[lane_id]
                sec = rec["_section"]
                along = stop_s - sec.s0 if forward else sec.s1 - stop_s
                along = min(max(along, 0.0), rec["_length"])
                sid = f"{sig.get('id')}@{lane_id}"
                if kind == "speed":
                    out["speed_limits"].append({"id": sid, "lane": lane_id, "s": round(along, 3), "value": round(value, 4)})
                elif kind == "stop":
                    out["stop_signs"].append({"id": sid, "lane": lane_id, "s": round(along, 3)})
                else:
                    ctrl = controller_of.get(sig.get("id"))
                    junction = junction_of_ctrl.get(ctrl) if ctrl is not None else None
                    rec_l = {"id": sid, "lane": lane_id, "s": round(along, 3)}
                    lights.append((sig.get("id", ""), rec_l, ctrl, junction))
                    out["traffic_lights"].append(rec_l)
        for line in (line for side in lines.values() for _, line in side if id(line) not in used):
            src.report(IMP710, f"stop line {line.get('id')} has no stop sign or light on its lanes; not converted", line)
    _programs(src, lights)
    for ref in src.root.iter("signalReference"):
        src.report(IMP710, f"signal reference to {ref.get('id')} is not converted (only signals placed on their road)", ref)


def _programs(src: XmlSource, lights: list[tuple[str, dict, str | None, str | None]]) -> None:
    """A default fixed-time program on every light: one phase per controller, a junction's
    controllers in turn (green :data:`_LIGHT_GREEN`, yellow :data:`_LIGHT_YELLOW`)."""
    if not lights:
        return
    phase = _LIGHT_GREEN + _LIGHT_YELLOW
    per_junction: dict[str | None, list[str]] = {}
    for _, _, ctrl, junction in lights:
        group = per_junction.setdefault(junction, [])
        if ctrl is not None and ctrl not in group:
            group.append(ctrl)
    for sid, rec, ctrl, junction in lights:
        group = per_junction.get(junction, [])
        n = max(len(group), 2) if ctrl is not None and junction is not None else 2
        k = group.index(ctrl) if ctrl is not None and ctrl in group else 0
        rec["cycle"] = {"green": _LIGHT_GREEN, "yellow": _LIGHT_YELLOW, "red": (n - 1) * phase,
                        "offset": ((n - k) % n) * phase}
    src.report(IMP713, f"{len(lights)} light(s) got a default program (OpenDRIVE holds none): green {_LIGHT_GREEN:g} s, "
                       f"yellow {_LIGHT_YELLOW:g} s per phase, one phase per controller, a junction's controllers in turn",
               None, hint="edit 'traffic_lights[].cycle' in the imported map")


def _valid_lanes(src: XmlSource, sig: ET.Element, road: _Road, s: float, forward: bool, built: dict[str, dict]) -> list[str]:
    """Ids of the imported lanes a signal at ``s`` governs in one direction (its <validity>, else all)."""
    k = road.section_at(s)
    sec = road.sections[k] if road.sections else None
    if sec is None:
        return []
    valid = sig.findall("validity")
    ids = []
    for lane_id in sec.lanes:
        fw = (lane_id < 0) != road.lht
        if fw != forward:
            continue
        if valid and not any(min(int(v.get("fromLane", "0")), int(v.get("toLane", "0"))) <= lane_id
                             <= max(int(v.get("fromLane", "0")), int(v.get("toLane", "0"))) for v in valid):
            continue
        key = _lane_key(road.id, k, lane_id)
        if key in built and built[key]["type"] == "driving":
            ids.append(key)
    return ids


def _unconverted(src: XmlSource) -> None:
    """Report what the import leaves out: objects, elevation, superelevation, junction priorities."""
    for objs in src.root.iter("objects"):
        n = len(list(objs))
        if n:
            src.report(IMP710, f"{n} object(s) (crosswalks, poles, buildings, …) are not converted", objs)
    for tag, what in (("elevationProfile", "elevation"), ("lateralProfile", "superelevation and shape")):
        for el in src.root.iter(tag):
            if any(_nonzero(x) for x in el):
                src.report(IMP710, f"{what} is not converted (the map is flat)", el)
                break
    junctions = src.root.findall("junction")
    if junctions:
        src.report(IMP710, f"{len(junctions)} junction(s): their connecting lanes are converted, their priorities and "
                           "conflicts are not (right of way among free-form lanes is not modelled)", junctions[0])
    for tag in ("railroad", "bridge", "tunnel", "surface", "station", "junctionGroup"):
        for el in src.root.iter(tag):
            src.report(IMP710, f"<{tag}> is not converted", el)


def _nonzero(el: ET.Element) -> bool:
    return any(float(el.get(k, "0") or 0) != 0 for k in ("a", "b", "c", "d") if _is_float(el.get(k, "0")))


def _is_float(raw: str | None) -> bool:
    try:
        return raw is not None and math.isfinite(float(raw))
    except ValueError:
        return False


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
    roads: dict[int, _Road] = {}
    changed = False
    for el in src.root.findall("road"):
        road = _road(src, el)
        if road is not None and road.id in roads:
            src.report(IMP712, f"road id {road.id} used twice; the second is left out", el)
            road = None
        if road is None:  # the reader is not given what the import left out (it may crash on it)
            src.root.remove(el)
            changed = True
            continue
        roads[road.id] = road
    changed = _repair(src) or changed
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
    wanted: list[tuple[_Road, int, _Section, _Lane, str, bool]] = []
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
    answers, crash = _isolated(_read, name or "map", text, requests)
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
        key = _lane_key(road.id, k, lane.id)
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
    _signals(src, roads, built, out)
    _inner_limits(roads, built, out)
    _unconverted(src)
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


def _link(src: XmlSource, roads: dict[int, _Road], built: dict[str, dict]) -> None:
    """Successors from the reader (just past each lane's end; one that starts away from the end is
    reported and dropped), adjacency within a section."""
    for key, rec in built.items():
        road, lane = rec["_road"], rec["_lane"]
        succ = []
        for n_road, n_lane, n_s in rec["_next"]:
            r = roads.get(n_road)
            if r is None or not r.sections:
                continue
            other = _lane_key(n_road, r.section_at(n_s), n_lane)
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
            other = _lane_key(road.id, sec_index, lid)
            if other in built:
                rec[side] = other


def _inner_limits(roads: dict[int, _Road], built: dict[str, dict], out: dict[str, list]) -> None:
    """Limits that change inside a lane (road type or lane speed records after its start) as signs."""
    for key, rec in built.items():
        road, lane, sec, forward = rec["_road"], rec["_lane"], rec["_section"], rec["_forward"]
        changes = [(s, v) for s, v in road.limits if sec.s0 + 0.5 < s < sec.s1 - 0.5]
        changes += [(sec.s0 + s, v) for s, v in lane.speeds if 0.5 < s < sec.s1 - sec.s0 - 0.5]
        for n, (s, v) in enumerate(sorted(changes)):
            along = s - sec.s0 if forward else sec.s1 - s
            out["speed_limits"].append({"id": f"limit{n}@{key}", "lane": key, "s": round(along, 3), "value": round(v, 4)})
