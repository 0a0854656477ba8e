"""OpenDRIVE signals placed on the imported lanes they govern: speed-limit signs (DE 274, US
R2-1), stop signs (DE 206, US R1-1) with their stop line (DE 294) within :data:`_LINE_REACH`,
traffic lights (OpenDRIVE 1000001…, dynamic) with a default fixed-time program (OpenDRIVE holds
none). Units: m, m/s, s."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from twolevel.interop.codes import IMP710, IMP712, IMP713
from twolevel.interop.opendrive_roads import Road, lane_key, number, speed_limit
from twolevel.interop.source import XmlSource

__all__ = ["place_signals"]

_SPEED_SIGNS = {("274", None), ("R2-1", None), ("R2", "1")}
_STOP_SIGNS = {("206", None), ("R1-1", None), ("R1", "1")}
_STOP_LINES = {("294", None)}
_LINE_REACH = 30.0  # [m] farthest a stop line may be past its sign or light
_LIGHT_GREEN, _LIGHT_YELLOW = 20.0, 3.0  # [s] the default program's green and yellow


def place_signals(src: XmlSource, roads: dict[int, Road], built: dict[str, dict], out: dict[str, list]) -> None:
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
                s = min(max(number(src, sig, "s"), 0.0), road.length)
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
                    v = speed_limit(src, ET.Element("speed", {"max": sig.get("value", ""), "unit": sig.get("unit", "km/h")}))
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


def _valid_lanes(src: XmlSource, sig: ET.Element, road: Road, s: float, forward: bool, built: dict[str, dict]) -> list[str]:
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
        key = lane_key(road.id, k, lane_id)
        if key in built and built[key]["type"] == "driving":
            ids.append(key)
    return ids
