"""An OpenDRIVE file's roads as the import needs them, read from the parsed XML with each value
checked (a value that is not a finite number, an id that is not an integer, a geometry that is no
known piece: the road is reported at its element and left out), and the repairs the reader needs
(:func:`repair`). Pure Python (no reader, no numpy). Units: m, 1/m, m/s."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from bisect import bisect_right
from dataclasses import dataclass, field

from twolevel.interop.codes import IMP710, IMP711, IMP712
from twolevel.interop.source import XmlSource

__all__ = ["EPS", "FLAT", "Lane", "Section", "Road", "lane_key", "number", "speed_limit", "read_road", "repair",
           "report_unconverted", "is_number"]

EPS = 1e-3
"""[m] samples stay this far inside a lane section (the reader answers for one section); shorter
sections are left out."""
_SPEED_UNITS = {"m/s": 1.0, "km/h": 1 / 3.6, "mph": 0.44704}
FLAT = 1e-6  # [1/m] curvature below which an arc is read as a line (its sag over 100 m: 5 mm)


@dataclass
class Lane:
    """One lane of one section as the XML gives it."""

    element: ET.Element
    id: int
    type: str
    bend: float  # largest |second derivative| of its width or border polynomials [1/m] (0: linear)
    speeds: list[tuple[float, float]]  # (sOffset from the section [m], limit [m/s])


@dataclass
class Section:
    """A lane section from ``s0`` to ``s1`` [m] along its road, its lanes by id."""

    s0: float
    s1: float
    element: ET.Element
    lanes: dict[int, Lane]


@dataclass
class Road:
    """A road: its planView pieces, lane sections, speed records and where it stands in the file."""

    element: ET.Element
    id: int
    length: float
    junction: int
    lht: bool
    pieces: list[tuple[float, float, float]]  # (s0, s1, largest |curvature| [1/m], inf: unknown)
    offset_bend: float  # largest |second derivative| of its lane offset [1/m]
    sections: list[Section] = field(default_factory=list)
    limits: list[tuple[float, float]] = field(default_factory=list)  # road type records (s, limit [m/s])

    def section_at(self, s: float) -> int:
        return max(0, bisect_right([sec.s0 for sec in self.sections], s) - 1)


def number(src: XmlSource, el: ET.Element, name: str, default: float | None = None) -> float:
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


def speed_limit(src: XmlSource, el: ET.Element) -> float | None:
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
        return abs(number(src, kind, "curvature"))
    if kind.tag == "spiral":
        return max(abs(number(src, kind, "curvStart")), abs(number(src, kind, "curvEnd")))
    return math.inf


def _lane(src: XmlSource, el: ET.Element) -> Lane:
    widths = el.findall("width") + el.findall("border")
    speeds = []
    for sp in el.findall("speed"):
        v = speed_limit(src, sp)
        if v is not None:
            speeds.append((number(src, sp, "sOffset", 0.0), v))
    for tag in ("access", "rule", "height"):
        for extra in el.findall(tag):
            src.report(IMP710, f"lane {el.get('id')}: <{tag}> is not converted", extra)
    return Lane(el, _int(src, el, "id"), el.get("type", "none"), _bend(widths), speeds)


def read_road(src: XmlSource, el: ET.Element) -> Road | None:
    """The road ``el`` as far as the import needs it, or None (reported) when it is unusable."""
    try:
        rid, length = _int(src, el, "id"), number(src, el, "length")
        junction = int(el.get("junction", "-1") or -1)
        pieces = []
        for g in el.findall("planView/geometry"):
            s0, ln = number(src, g, "s"), number(src, g, "length")
            pieces.append((s0, s0 + ln, _curvature(src, g)))
        if not pieces:
            src.report(IMP712, f"road {rid} has no <planView> geometry; left out", el)
            return None
        offsets = el.findall("lanes/laneOffset")
        road = Road(el, rid, length, junction, el.get("rule", "RHT").upper() == "LHT", pieces, _bend(offsets))
        secs = el.findall("lanes/laneSection")
        starts = [number(src, sec, "s") for sec in secs]
        for k, sec in enumerate(secs):
            s1 = starts[k + 1] if k + 1 < len(starts) else length
            if s1 - starts[k] < 2 * EPS:
                continue
            lanes = {ln.id: ln for ln in (_lane(src, x) for side in ("left", "right") for x in sec.findall(f"{side}/lane"))}
            road.sections.append(Section(starts[k], s1, sec, lanes))
        for t in el.findall("type"):
            sp = t.find("speed")
            v = speed_limit(src, sp) if sp is not None else None
            if v is not None:
                road.limits.append((number(src, t, "s"), v))
    except ValueError:
        src.report(IMP712, f"road {el.get('id')} has invalid values (above); left out", el)
        return None
    return road


def repair(src: XmlSource) -> bool:
    """Rewrite what the reader mishandles, in the tree (reported); True when anything changed."""
    changed = False
    spirals = [sp for sp in src.root.iter("spiral") if is_number(sp.get("curvStart")) and is_number(sp.get("curvEnd"))
               and (abs(float(sp.get("curvStart", "0")) - float(sp.get("curvEnd", "0"))) <= 1e-12
                    or max(abs(float(sp.get("curvStart", "0"))), abs(float(sp.get("curvEnd", "0")))) < FLAT)]
    for sp in spirals:
        c = float(sp.get("curvStart", "0"))
        sp.tag, sp.attrib = ("line", {}) if abs(c) < FLAT else ("arc", {"curvature": repr(c)})
    flat = [arc for arc in src.root.iter("arc") if is_number(arc.get("curvature")) and abs(float(arc.get("curvature", "0"))) < FLAT]
    for arc in flat:
        arc.tag, arc.attrib = "line", {}
    spirals += flat
    if spirals:
        src.report(IMP711, f"{len(spirals)} spiral(s) of constant curvature (curvStart = curvEnd) read as arcs, and those "
                           f"and arcs flatter than {FLAT:g} 1/m as lines (the reader gives NaN or zero positions on them)",
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


def report_unconverted(src: XmlSource) -> None:
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
    return any(float(el.get(k, "0") or 0) != 0 for k in ("a", "b", "c", "d") if is_number(el.get(k, "0")))


def is_number(raw: str | None) -> bool:
    try:
        return raw is not None and math.isfinite(float(raw))
    except ValueError:
        return False


def lane_key(road: int, section: int, lane: int) -> str:
    """The imported lane's id: ``r<road>_<section>_<lane>`` (text, never a YAML number)."""
    return f"r{road}_{section}_{lane}"
