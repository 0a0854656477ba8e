"""SUMO networks (``.net.xml``) as twolevel maps, read with ``sumolib`` (the ``sumo`` extra).

What is translated, element by element:

* every ``<lane>`` of every ``<edge>``, internal ones (a junction's connecting lanes) included, is
  a free-form lane given by its centre line (SUMO's lane shape) and its ``width`` [m], with its
  ``speed`` [m/s] as the lane's limit; points closer than the map's least spacing are merged;
* its type from the classes allowed on it: ``driving`` (passenger cars), else ``bus``,
  ``bicycle``, ``sidewalk`` (pedestrians), else ``restricted``; a ``crossing`` edge is a
  ``crosswalk``;
* successors from the ``<connection>`` elements: an incoming lane continues into the connection's
  internal lane (``via``), which continues into the outgoing lane (or the next internal lane);
* neighbours: the lanes of one (normal) edge are beside each other (index 0 is the rightmost,
  the leftmost in a ``lefthand`` network); a junction's turning lanes, which SUMO draws apart,
  only where their boundaries meet (as for any free-form lane);
* ``<tlLogic>`` programs: each controlled link (``linkIndex``) becomes a traffic light whose stop
  line is the start of the link's internal lane (the end of the incoming lane when the link has
  none), its states the link's column of the phases (``G``/``g``/``o``/``O`` green, ``y``/``Y``
  yellow, the rest red), as a fixed-time cycle when green, yellow and red follow each other once
  per cycle (the program's ``offset`` shifts it as SUMO does: the cycle is at ``(t − offset) mod
  cycle``), else as a script over :data:`SCRIPT_HORIZON`. A link green in every phase gets no
  light. Actuated programs are translated by their phases' nominal durations (IMP714);
* links of state ``s`` (stop sign) or ``w`` (all-way stop): a stop sign at the end of the incoming
  lane.

What is not (IMP710, at the element's line): walking areas, the right of way at priority
junctions (a twolevel map has no priorities between free-form lanes: SUMO's vehicles keep it,
the ego's rules do not see it), roundabouts as such (their lanes are translated), prohibitions,
lane-change restrictions, stop offsets, and any element this module does not know.
Coordinates are SUMO's network coordinates [m] (the ``netOffset`` already applied), which libsumo
uses too, so a map imported here and a co-simulation on the same network agree.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from twolevel.diagnostics import Diagnostic, Span
from twolevel.interop import ImportResult
from twolevel.interop.codes import IMP703, IMP704, IMP705, IMP710, IMP714
from twolevel.interop.source import XmlSource, read_xml
from twolevel.world.schema import MIN_PIECE

__all__ = ["read_net", "import_file", "net_lines", "light_program", "SCRIPT_HORIZON"]

SCRIPT_HORIZON = 3600.0
"""[s] How long a light program that is not one green–yellow–red cycle is written out as a script."""
_GREEN, _YELLOW = frozenset("GgoO"), frozenset("yY")
_KNOWN = {"net", "location", "type", "edge", "lane", "junction", "request", "connection", "tlLogic", "phase",
          "param", "restriction"}
_UNTRANSLATED = {
    "roundabout": "a roundabout as such (its lanes and connections are translated)",
    "prohibition": "a prohibition between connections (the right of way is SUMO's)",
    "neigh": "an opposite-direction lane for overtaking (adjacency is found from the boundaries)",
    "stopOffset": "a stop offset (stop lines are at the lane ends)",
    "condition": "a condition of a traffic-light program (its nominal phases are translated)",
    "assignment": "an assignment of a traffic-light program (its nominal phases are translated)",
    "function": "a function of a traffic-light program (its nominal phases are translated)",
}


@dataclass
class NetLines:
    """Where elements are in the file: line of each (tag, id), of the first element of each tag,
    and the ``lefthand`` attribute of the network."""

    of: dict[tuple[str, str], int] = field(default_factory=dict)
    first: dict[str, int] = field(default_factory=dict)
    lefthand: bool = False


def net_lines(src: XmlSource) -> NetLines:
    """Line numbers of the elements of the network file read as ``src``."""
    out = NetLines(lefthand=src.root.get("lefthand", "false").lower() in ("true", "1"))
    for element in src.root.iter():
        line = src.where[id(element)][0]
        out.first.setdefault(element.tag, line)
        key = element.get("id")
        if element.tag == "connection":
            a = element.attrib
            key = f"{a.get('from')}_{a.get('fromLane')}>{a.get('to')}_{a.get('toLane')}"
        if key is not None:
            out.of.setdefault((element.tag, key), line)
    return out


def light_program(states: list[str], durations: list[float], offset: float) -> dict[str, Any] | None:
    """A twolevel light program for one link: ``states`` its colour per phase ('green', 'yellow',
    'red'), ``durations`` [s] the phases', ``offset`` [s] the program's. A ``cycle`` when green,
    yellow (optional) and red follow each other once per cycle, else a ``script`` over
    :data:`SCRIPT_HORIZON`; None when it is green throughout."""
    if all(s == "green" for s in states):
        return None
    period = float(sum(durations))
    starts = [float(sum(durations[:k])) for k in range(len(durations))]
    # runs of one colour, cyclically, starting where a green run starts (else where red starts)
    n = len(states)
    first = next((k for k in range(n) if states[k] == "green" and states[k - 1] != "green"), None)
    if first is None:
        first = next(k for k in range(n) if states[k] != states[k - 1]) if len(set(states)) > 1 else 0
    runs: list[list[Any]] = []
    for j in range(n):
        k = (first + j) % n
        if runs and runs[-1][0] == states[k]:
            runs[-1][1] += durations[k]
        else:
            runs.append([states[k], float(durations[k])])
    colours = [r[0] for r in runs]
    if colours in (["green", "yellow", "red"], ["green", "red"]):
        # SUMO's cycle position at t is (t - offset) mod period; the twolevel cycle's green starts at its 0
        shift = (-offset - starts[first]) % period
        green, red = runs[0][1], runs[-1][1]
        yellow = runs[1][1] if len(runs) == 3 else 0.0
        return {"cycle": {"green": green, "yellow": yellow, "red": red, "offset": round(shift, 9)}}
    script: list[dict[str, Any]] = []
    t = 0.0
    pos = (-offset) % period
    k = max(j for j in range(n) if starts[j] <= pos)
    left = starts[k] + durations[k] - pos
    while t < SCRIPT_HORIZON:
        if not script or script[-1]["state"] != states[k]:
            script.append({"t": round(t, 9), "state": states[k]})
        t += left
        k = (k + 1) % n
        left = float(durations[k])
    return {"script": script}


def _colour(c: str) -> str:
    return "green" if c in _GREEN else "yellow" if c in _YELLOW else "red"


def _kind(lane: Any, function: str) -> str:
    if function == "crossing":
        return "crosswalk"
    allowed = lane.getPermissions()
    for vclass, kind in (("passenger", "driving"), ("bus", "bus"), ("bicycle", "bicycle"), ("pedestrian", "sidewalk")):
        if vclass in allowed:
            return kind
    return "restricted"


def _clean(shape: list[tuple[float, float]]) -> list[list[float]]:
    """The shape without points closer than the least spacing to the last one kept (the last
    point of the shape is kept, replacing a kept point too close before it)."""
    out: list[list[float]] = []
    for x, y in shape:
        if out and math.hypot(x - out[-1][0], y - out[-1][1]) < MIN_PIECE * 1.01:
            continue
        out.append([round(float(x), 4), round(float(y), 4)])
    last = [round(float(shape[-1][0]), 4), round(float(shape[-1][1]), 4)]
    if len(out) >= 2 and out[-1] != last:
        out[-1] = last
    if len(out) >= 2 and math.hypot(out[-1][0] - out[-2][0], out[-1][1] - out[-2][1]) < MIN_PIECE * 1.01:
        del out[-2]
    return out


def _fitted_widths(points: list[list[float]], width: float) -> list[float]:
    """The lane's width [m] at each centre point, narrowed where the centre line turns so sharply
    that a boundary half the width away would fold back: at a point turning by θ between pieces of
    lengths a and b, at most 0.98·min(a, b)/tan(θ/2) (the fold check of twolevel/world/layout.py)."""
    out = [width] * len(points)
    for k in range(1, len(points) - 1):
        (x0, y0), (x1, y1), (x2, y2) = points[k - 1], points[k], points[k + 1]
        turn = abs((math.atan2(y2 - y1, x2 - x1) - math.atan2(y1 - y0, x1 - x0) + math.pi) % (2 * math.pi) - math.pi)
        if turn > 1e-9:
            limit = 0.98 * min(math.hypot(x1 - x0, y1 - y0), math.hypot(x2 - x1, y2 - y1)) / math.tan(turn / 2)
            out[k] = min(width, max(round(math.floor(limit * 1000) / 1000, 3), 0.1))
    return out


def _length(points: list[list[float]]) -> float:
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(points, points[1:]))


def read_net(path: str) -> tuple[dict[str, Any] | None, list[Diagnostic]]:
    """The twolevel map document (plain data, as YAML would hold it) of the SUMO network ``path``,
    and the diagnostics of what was not or only approximately translated (see the module
    docstring); None and IMP701–IMP705 when the network cannot be used (read by the importers' shared
    :func:`~twolevel.interop.source.read_xml`: size limit, no DTD)."""
    src, diags = read_xml(path)
    if src is None:
        return None, diags
    whole = Span.whole_file(path)
    if src.root.tag != "net":
        return None, [IMP703(f"not a SUMO network: the root element is <{src.root.tag}>, not <net>", src.span(src.root),
                             hint="give a .net.xml written by netconvert, netgenerate or netedit")]
    lines = net_lines(src)
    try:
        import sumolib  # noqa: PLC0415 - the optional 'sumo' extra
    except ImportError:
        return None, [IMP704("reading SUMO networks needs sumolib", whole, hint="pip install 'twolevel[sumo]'")]
    try:
        net = sumolib.net.readNet(path, withInternal=True, withPrograms=True)
    except Exception as exc:  # sumolib's own errors are plain exceptions
        return None, [IMP705(f"sumolib cannot read the network: {exc}", whole)]
    return _translate(net, path, lines)


def _at(path: str, lines: NetLines, tag: str, key: str | None = None) -> Span:
    line = lines.of.get((tag, key), lines.first.get(tag, 1)) if key is not None else lines.first.get(tag, 1)
    return Span(path, line, 1)


def _translate(net: Any, path: str, lines: NetLines) -> tuple[dict[str, Any], list[Diagnostic]]:
    diags: list[Diagnostic] = []
    lanes: dict[str, dict[str, Any]] = {}
    length: dict[str, float] = {}
    dropped: set[str] = set()
    tight: list[tuple[str, float]] = []
    edges = net.getEdges(withInternal=True)
    for edge in edges:
        function = edge.getFunction() or ""
        if function in ("walkingarea", "connector"):
            dropped.update(ln.getID() for ln in edge.getLanes())
            continue
        ordered = sorted(edge.getLanes(), key=lambda ln: ln.getIndex())
        for ln in ordered:
            lid = ln.getID()
            pts = _clean(ln.getShape())
            if len(pts) < 2:
                dropped.add(lid)  # shorter than the least spacing: its predecessors continue into its successors
                continue
            width, speed = float(ln.getWidth()), float(ln.getSpeed())
            if not 0 < width <= 20 or not 0 < speed <= 100:
                diags.append(IMP714(f"lane '{lid}': width {width:g} m / speed {speed:g} m/s clipped to the map's "
                                    "ranges (0, 20] m and (0, 100] m/s", _at(path, lines, "lane", lid)))
                width, speed = min(max(width, 0.1), 20.0), min(max(speed, 0.1), 100.0)
            spec: dict[str, Any] = {"id": lid, "type": _kind(ln, function), "centre": pts}
            widths = _fitted_widths(pts, width)
            if min(widths) < width:
                tight.append((lid, min(widths)))
                spec["widths"] = widths
            else:
                spec["width"] = round(width, 6)
            lanes[lid] = {**spec, "speed_limit": round(speed, 6), "successors": []}
            length[lid] = _length(pts)
        for a, b in zip(ordered, ordered[1:]):  # b is left of a (right of it in a left-hand network)
            if not function and a.getID() in lanes and b.getID() in lanes:  # turning lanes are drawn apart
                left, right = (b, a) if not lines.lefthand else (a, b)
                lanes[right.getID()]["adjacent_left"] = left.getID()
                lanes[left.getID()]["adjacent_right"] = right.getID()
    if tight:
        lid, w = min(tight, key=lambda t: t[1])
        diags.append(IMP714(f"{len(tight)} lane(s) turn tighter than half their width; narrowed where they do (down to "
                            f"{w:.2f} m on '{lid}') so that their inner boundary does not fold",
                            _at(path, lines, "lane", lid), hint="SUMO draws such lanes overlapping themselves"))
    walking = [e.getID() for e in edges if e.getFunction() == "walkingarea"]
    if walking:
        diags.append(IMP710(f"{len(walking)} walking area(s) (areas, not lanes) are left out, e.g. '{walking[0]}'",
                            _at(path, lines, "edge", walking[0])))
    # successors: the connection's internal lane (via), else its target lane; past dropped lanes
    nexts: dict[str, list[str]] = {}
    for edge in edges:
        for ln in edge.getLanes():
            out = nexts.setdefault(ln.getID(), [])
            for c in ln.getOutgoing():
                target = c.getViaLaneID() or c.getToLane().getID()
                if target not in out:
                    out.append(target)

    def resolve(lid: str, seen: frozenset[str] = frozenset()) -> list[str]:
        if lid not in dropped:
            return [lid] if lid in lanes else []
        return [r for n in nexts.get(lid, []) if n not in seen for r in resolve(n, seen | {lid})]

    for lid, spec in lanes.items():
        spec["successors"] = list(dict.fromkeys(r for n in nexts.get(lid, []) for r in resolve(n)))
    lights, stops = _signals(net, path, lines, lanes, length, diags)
    diags += _unexpressed(net, path, lines)
    doc: dict[str, Any] = {"kind": "map", "name": Path(path).name.removesuffix(".net.xml"),
                           "lanes": list(lanes.values())}
    if stops:
        doc["stop_signs"] = stops
    if lights:
        doc["traffic_lights"] = lights
    return doc, diags


def _signals(net: Any, path: str, lines: NetLines, lanes: dict[str, dict[str, Any]], length: dict[str, float],
             diags: list[Diagnostic]) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Traffic lights (one per controlled link) and stop signs (one per incoming lane)."""
    lights: list[dict[str, Any]] = []
    stops: dict[str, dict[str, Any]] = {}
    programs: dict[str, Any] = {}
    for tls in net.getTrafficLights():
        progs = tls.getPrograms()
        if not progs:
            continue
        pid = sorted(progs)[0]
        prog = progs[pid]
        programs[tls.getID()] = prog
        if len(progs) > 1:
            diags.append(IMP714(f"traffic light '{tls.getID()}' has {len(progs)} programs; program '{pid}' is translated",
                                _at(path, lines, "tlLogic", tls.getID())))
        if prog.getType() != "static":
            diags.append(IMP714(f"traffic light '{tls.getID()}' is '{prog.getType()}': translated by its phases' nominal "
                                "durations; SUMO may switch it otherwise", _at(path, lines, "tlLogic", tls.getID())))
    for edge in net.getEdges(withInternal=False):
        for ln in edge.getLanes():
            lid = ln.getID()
            if lid not in lanes:
                continue
            for c in ln.getOutgoing():
                if c.getState() in ("s", "w") and lid not in stops:
                    stops[lid] = {"id": f"stop_{lid}", "lane": lid, "s": math.floor(length[lid] * 1000) / 1000}
                prog = programs.get(c.getTLSID())
                if prog is None or c.getTLLinkIndex() < 0:
                    continue
                i = c.getTLLinkIndex()
                phases = prog.getPhases()
                program = light_program([_colour(p.state[i]) if i < len(p.state) else "red" for p in phases],
                                        [float(p.duration) for p in phases], float(prog.getOffset() or 0.0))
                if program is None:
                    continue
                via = c.getViaLaneID()
                on, s = (via, 0.0) if via in lanes else (lid, math.floor(length[lid] * 1000) / 1000)
                lights.append({"id": f"{c.getTLSID()}_{i}_{lid}", "lane": on, "s": s, **program})
    return lights, list(stops.values())


def _unexpressed(net: Any, path: str, lines: NetLines) -> list[Diagnostic]:
    """One IMP710 per kind of element a twolevel map cannot express."""
    out: list[Diagnostic] = []
    yielding = [n.getID() for n in net.getNodes() if n.getType() in ("priority", "priority_stop", "right_before_left",
                                                                       "left_before_right", "zipper")]
    if yielding:
        out.append(IMP710(f"the right of way at {len(yielding)} junction(s) without lights, e.g. '{yielding[0]}', is "
                          "SUMO's only: free-form lanes carry no priorities", _at(path, lines, "junction", yielding[0]),
                          hint="SUMO's vehicles keep it; the ego's rules see stop signs and lights only"))
    for tag, what in _UNTRANSLATED.items():
        if tag in lines.first:
            out.append(IMP710(f"<{tag}>: {what}", _at(path, lines, tag)))
    for tag in sorted(set(lines.first) - _KNOWN - set(_UNTRANSLATED)):
        out.append(IMP710(f"<{tag}> is not translated (an element twolevel does not know)", _at(path, lines, tag)))
    return out


def import_file(path: str | os.PathLike[str], out_dir: str | os.PathLike[str]) -> ImportResult:
    """Translate the network ``path`` and write it as ``out_dir/<name>.yaml``, checked by the map
    loader (:func:`twolevel.interop.output.write_map`)."""
    from twolevel.interop.output import write_map  # noqa: PLC0415

    doc, diags = read_net(os.fspath(path))
    if doc is None:
        return ImportResult((), tuple(diags))
    header = (f"Imported from the SUMO network {Path(path).name} by `twolevel import`; coordinates are the\n"
              "network's [m]. Lanes are SUMO's lanes (internal ones too), ids unchanged.")
    return write_map(doc, header, path, Path(out_dir) / f"{doc['name'] or 'network'}.yaml", diags)
