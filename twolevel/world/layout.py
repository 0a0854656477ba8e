"""A map's layout in pure Python: poses along each road, lane lengths and ends, and the geometric
consistency a map needs before it is sampled (:mod:`twolevel.world.geometry`, numpy).

The schema checks each number on its own; what only the geometry shows is checked here, at load,
so that whatever ``twolevel check`` accepts can be sampled, planned on and simulated:

- an arc on which a lane would fold: the lane's inner edge, at radius R − offset·sign(angle) −
  width/2, must stay on the outside of the arc's centre;
- degenerate pieces: an arc shorter than :data:`~twolevel.world.schema.MIN_PIECE`, polyline
  points closer than that to the point before them (a free-form lane's centre points too);
- free-form lanes: boundaries paired point by point (as many left as right points), a width of at
  least :data:`~twolevel.world.schema.MIN_WIDTH` between the lane's ends (the ends may taper to 0),
  boundaries that do not cross (each left point left of the lane's direction from its right point,
  the boundaries' pieces disjoint), a lane given by its centre whose inner boundary would fold at
  a corner, and a declared neighbour whose boundary is not beside the lane's;
- successors that do not connect: a lane must start within half a lane width of the end of the
  lane it follows, heading the same way (within 90°).

It also says which lanes lie side by side (:func:`road_neighbours`, one criterion for the runtime's
lane adjacency in :mod:`twolevel.world.lanes` and for ``check``) and, for ``check``'s scripted lane
changes, the lane of the same direction beside each lane (:func:`lanes_beside`).

Lengths agree with the sampled lanes (:func:`twolevel.world.geometry.lane_from_reference`) to
rounding: arcs at an offset are exact, and an offset polyline turns each corner with a chord
2·|offset|·sin(|turn|/2) long, as the sampled lane does; a free-form lane's centre line is the
polyline through the midpoints of its facing boundary points (:mod:`twolevel.world.lanes`).

Imported by ``twolevel check``: standard library only (no numpy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator

from twolevel.diagnostics import Diagnostic
from twolevel.world.codes import YML420
from twolevel.world.document import Document
from twolevel.world.schema import MIN_PIECE, MIN_WIDTH, FreeLane, LaneSpec, MapFile, Road, Segment

__all__ = ["Pose", "Piece", "pieces", "lane_pieces", "lane_length", "lane_lengths", "lane_ends", "check_layout", "free_centre",
           "free_ends", "polyline_length", "all_lane_ends", "road_outline", "road_neighbours", "lanes_beside"]


@dataclass(frozen=True)
class Pose:
    """A point x, y [m] of a line and the line's heading there [rad]."""

    x: float
    y: float
    heading: float

    def shifted(self, offset: float) -> "Pose":
        """The pose ``offset`` [m] to the left of this one (+ left), same heading."""
        return Pose(self.x - offset * math.sin(self.heading), self.y + offset * math.cos(self.heading), self.heading)


@dataclass(frozen=True)
class Piece:
    """One straight or circular piece of a reference line between two poses.

    ``curvature`` [1/m] is 0 for straight pieces (line segments and each leg of a polyline);
    ``length`` [m] is measured on the reference line. ``segment``/``point`` say where in the road
    it comes from (``point`` is the index of a polyline point, else None).
    """

    start: Pose
    end: Pose
    length: float
    curvature: float
    segment: int
    point: int | None = None


def _wrap(angle: float) -> float:
    """``angle`` [rad] wrapped into [−π, π), as the sampled line unwraps its headings."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def pieces(road: Road) -> Iterator[Piece]:
    """The pieces of ``road``'s reference line, in order (coincident polyline points are skipped,
    as the sampled line skips them)."""
    pose = Pose(road.start.x, road.start.y, math.radians(road.start.heading))
    for j, seg in enumerate(road.segments):
        if seg.line is not None:
            end = Pose(pose.x + seg.line * math.cos(pose.heading), pose.y + seg.line * math.sin(pose.heading), pose.heading)
            yield Piece(pose, end, seg.line, 0.0, j)
            pose = end
        elif seg.arc is not None:
            r, th = seg.arc.radius, math.radians(seg.arc.angle)
            sign = 1.0 if th > 0 else -1.0
            cx, cy = pose.x - sign * r * math.sin(pose.heading), pose.y + sign * r * math.cos(pose.heading)
            h2 = pose.heading + th
            end = Pose(cx + sign * r * math.sin(h2), cy - sign * r * math.cos(h2), h2)
            yield Piece(pose, end, r * abs(th), sign / r, j)
            pose = end
        else:
            for k, (px, py) in enumerate(seg.points or []):
                dist = math.hypot(px - pose.x, py - pose.y)
                if dist == 0:
                    continue
                h = pose.heading + _wrap(math.atan2(py - pose.y, px - pose.x) - pose.heading)
                end = Pose(px, py, h)
                yield Piece(Pose(pose.x, pose.y, h), end, dist, 0.0, j, k)
                pose = end


def lane_pieces(road: Road, offset: float) -> Iterator[tuple[float, float, Piece]]:
    """The pieces of the lane ``offset`` [m] left of ``road``'s reference line with where each
    starts and ends along the lane, (s_from, s_to [m], piece), in the road's direction: arcs at
    radius R − offset·sign(angle), straight legs as drawn, and a chord 2·|offset|·sin(|turn|/2)
    at each corner where the heading jumps (the sampled lane's corner) before the leg after it."""
    s = 0.0
    heading = math.radians(road.start.heading)  # a polyline may turn at the very start
    for p in pieces(road):
        if p.start.heading != heading:
            s += 2 * abs(offset) * abs(math.sin((p.start.heading - heading) / 2))
        length = p.length * abs(1 - offset * p.curvature) if p.curvature else p.length
        yield s, s + length, p
        s += length
        heading = p.end.heading


def lane_length(road: Road, offset: float) -> float:
    """Length [m] of the lane ``offset`` [m] left of ``road``'s reference line
    (:func:`lane_pieces`)."""
    return max((b for _, b, _ in lane_pieces(road, offset)), default=0.0)


def lane_lengths(spec: MapFile) -> dict[str, float]:
    """Length [m] of every road and free-form lane of the map by id (junctions' connecting lanes:
    :func:`twolevel.world.junction.plan_junctions`)."""
    out = {lane.id: lane_length(road, lane.offset) for road in spec.roads for lane in road.lane_specs()}
    for lane in spec.lanes:
        out.setdefault(lane.id, polyline_length(free_centre(lane)[0]))
    return out


def free_centre(lane: FreeLane) -> tuple[list[tuple[float, float]], list[float]]:
    """A free-form lane's centre points [m] and the width there [m]: the midpoints of facing
    boundary points and their distance, or its centre line and width."""
    if lane.centre is not None:
        width = lane.widths if lane.widths is not None else [float(lane.width or 0.0)] * len(lane.centre)
        return [(float(x), float(y)) for x, y in lane.centre], [float(w) for w in width]
    left, right = lane.left_bound or [], lane.right_bound or []
    return ([(0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])) for a, b in zip(left, right)],
            [math.hypot(a[0] - b[0], a[1] - b[1]) for a, b in zip(left, right)])


def polyline_length(points: list[tuple[float, float]]) -> float:
    """Length [m] of a polyline through ``points``."""
    return sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(points, points[1:]))


def _direction(points: list[tuple[float, float]], k: int, step: int) -> float:
    """Heading [rad] of the first chord of positive length from point ``k`` on (``step`` +1) or
    back (−1), in the direction of travel (0 if every chord is degenerate)."""
    j = k
    while 0 <= j + step < len(points):
        a, b = (points[j], points[j + step]) if step > 0 else (points[j + step], points[j])
        if math.hypot(b[0] - a[0], b[1] - a[1]) > 0:
            return math.atan2(b[1] - a[1], b[0] - a[0])
        j += step
    return 0.0


def _heading(points: list[tuple[float, float]], k: int) -> float:
    """The centre line's heading [rad] at point ``k``: halfway between the chords before and after
    it (the one chord at an end)."""
    if k == 0:
        return _direction(points, 0, 1)
    if k == len(points) - 1:
        return _direction(points, k, -1)
    back = _direction(points, k, -1)
    return back + 0.5 * _wrap(_direction(points, k, 1) - back)


def free_ends(lane: FreeLane) -> tuple[Pose, Pose]:
    """Where a free-form lane starts and ends (its centre line's end points and end chords)."""
    pts, _ = free_centre(lane)
    return (Pose(pts[0][0], pts[0][1], _direction(pts, 0, 1)),
            Pose(pts[-1][0], pts[-1][1], _direction(pts, len(pts) - 1, -1)))


def all_lane_ends(spec: MapFile) -> dict[str, tuple[Pose, Pose, float, float]]:
    """Start and end pose and the width there [m] of every road and free-form lane by id."""
    out: dict[str, tuple[Pose, Pose, float, float]] = {}
    for road in spec.roads:
        for lane in road.lane_specs():
            out.setdefault(lane.id, (*lane_ends(road, lane), lane.width, lane.width))
    for lane in spec.lanes:
        if lane.id not in out and len(free_centre(lane)[0]) >= 2:
            _, width = free_centre(lane)
            out[lane.id] = (*free_ends(lane), width[0], width[-1])
    return out


def road_neighbours(spec: MapFile) -> Iterator[tuple[LaneSpec, LaneSpec]]:
    """Lanes of one road beside each other, (a, b) with b left of a in the road's frame: their
    offsets half their widths apart [m] (to 1e-6 m)."""
    for road in spec.roads:
        lanes = sorted(road.lane_specs(), key=lambda ln: ln.offset)
        for a, b in zip(lanes, lanes[1:]):
            if abs((b.offset - a.offset) - 0.5 * (a.width + b.width)) <= 1e-6:
                yield a, b


def lanes_beside(spec: MapFile) -> dict[str, tuple[str | None, str | None]]:
    """Every lane's id → (the lane on its left, the lane on its right) in its direction of travel that runs
    the same way (within 90° at their starts), or None: road lanes by :func:`road_neighbours`,
    free-form lanes by their declared ``adjacent_left`` / ``adjacent_right``. The runtime's
    :attr:`twolevel.world.geometry.LaneSet.left` / ``right`` are the same lanes, except that it also
    finds undeclared free-form neighbours from their boundaries (numpy, not for ``check``)."""
    side: dict[str, dict[bool, str]] = {}
    for a, b in road_neighbours(spec):
        if a.direction == b.direction:
            forward = a.direction == "forward"
            side.setdefault(a.id, {})[forward] = b.id  # b is on a's left when a runs forward
            side.setdefault(b.id, {})[not forward] = a.id
    ends = all_lane_ends(spec)
    for lane in spec.lanes:
        for left, other in ((True, lane.adjacent_left), (False, lane.adjacent_right)):
            if other is None or lane.id not in ends or other not in ends:
                continue
            turn = _wrap(ends[other][0].heading - ends[lane.id][0].heading)
            if abs(turn) < math.pi / 2:
                side.setdefault(lane.id, {})[left] = other
    return {lid: (side.get(lid, {}).get(True), side.get(lid, {}).get(False)) for lid in ends}


def road_outline(road: Road, lane: LaneSpec, step: float = math.radians(5.0)) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
    """Points of a road lane's left and right boundaries (in its direction of travel): the
    pieces' ends, and every ``step`` [rad] along arcs."""
    left: list[tuple[float, float]] = []
    right: list[tuple[float, float]] = []

    def add(x: float, y: float, h: float) -> None:
        for side, out in ((lane.offset + lane.width / 2, left), (lane.offset - lane.width / 2, right)):
            p = Pose(x, y, h).shifted(side)
            out.append((p.x, p.y))

    first = True
    for p in pieces(road):
        if first:
            add(p.start.x, p.start.y, p.start.heading)
            first = False
        if p.curvature:
            r = 1.0 / abs(p.curvature)
            th = p.length * p.curvature
            n = max(1, math.ceil(abs(th) / step))
            sign = 1.0 if th > 0 else -1.0
            cx, cy = p.start.x - sign * r * math.sin(p.start.heading), p.start.y + sign * r * math.cos(p.start.heading)
            for k in range(1, n + 1):
                h = p.start.heading + th * k / n
                add(cx + sign * r * math.sin(h), cy - sign * r * math.cos(h), h)
        else:
            add(p.start.x, p.start.y, p.start.heading)
            add(p.end.x, p.end.y, p.end.heading)
    if lane.direction == "backward":
        left, right = right[::-1], left[::-1]
    return left, right


def lane_ends(road: Road, lane: LaneSpec) -> tuple[Pose, Pose]:
    """Where ``lane`` of ``road`` starts and ends, in its direction of travel."""
    first = Pose(road.start.x, road.start.y, math.radians(road.start.heading))
    last = first
    for last_piece in pieces(road):
        last = last_piece.end
    a, b = first.shifted(lane.offset), last.shifted(lane.offset)
    if lane.direction == "backward":
        a, b = Pose(b.x, b.y, b.heading + math.pi), Pose(a.x, a.y, a.heading + math.pi)
    return a, b


# ------------------------------------------------------------------------------------ checks


def _check_segments(i: int, road: Road, doc: Document) -> list[Diagnostic]:
    """Degenerate arcs and polyline points, and arcs on which a lane folds."""
    out: list[Diagnostic] = []
    lanes = road.lane_specs()
    ends = {p.segment: (p.end.x, p.end.y) for p in pieces(road)}  # where each segment ends
    previous = (road.start.x, road.start.y)
    for j, seg in enumerate(road.segments):
        at = ("roads", i, "segments", j)
        if seg.arc is not None:
            out += _check_arc(seg, lanes, at, doc)
        for k, (px, py) in enumerate(seg.points or []):
            gap = math.hypot(px - previous[0], py - previous[1])
            if gap < MIN_PIECE:
                what = "the point before it" if k else "where the segment starts (the end of the one before)"
                out.append(YML420(f"this point is {gap:.3g} m from {what}; points must be at least {MIN_PIECE:g} m apart",
                                  doc.locate(at + ("points", k), value=True), hint="remove the repeated point"))
            previous = (px, py)
        previous = ends.get(j, previous)
    return out


def _check_arc(seg: Segment, lanes: list[LaneSpec], at: tuple[str | int, ...], doc: Document) -> list[Diagnostic]:
    """An arc too short to be a piece of road, or so tight that a lane's inner edge folds."""
    assert seg.arc is not None
    out: list[Diagnostic] = []
    length = seg.arc.radius * math.radians(abs(seg.arc.angle))
    if length < MIN_PIECE:
        out.append(YML420(f"this arc is {length:.3g} m long; a road piece must be at least {MIN_PIECE:g} m",
                          doc.locate(at + ("arc",), value=True), hint="give a larger radius or angle, or leave the piece out"))
    inner = 1.0 if seg.arc.angle > 0 else -1.0  # lanes offset to this side are inside the bend
    side = "left" if inner > 0 else "right"
    for lane in lanes:
        least = inner * lane.offset + lane.width / 2  # the radius of the lane's inner edge is R − least
        if seg.arc.radius <= least:
            out.append(YML420(
                f"lane '{lane.id}' folds on this arc: its inner edge would turn at radius "
                f"{seg.arc.radius - least:.3g} m (offset {lane.offset:g} m, width {lane.width:g} m)",
                doc.locate(at + ("arc", "radius"), value=True),
                hint=f"the arc turns {side}: its radius must exceed {least:.3g} m, the lane's offset to the {side} "
                     "plus half its width"))
    return out


def _cross(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


def _segments_cross(p: tuple[float, float], q: tuple[float, float], r: tuple[float, float], s: tuple[float, float]) -> bool:
    """Whether segments p–q and r–s cross properly (each one's ends strictly on both sides of the other)."""
    d1 = _cross(q[0] - p[0], q[1] - p[1], r[0] - p[0], r[1] - p[1])
    d2 = _cross(q[0] - p[0], q[1] - p[1], s[0] - p[0], s[1] - p[1])
    d3 = _cross(s[0] - r[0], s[1] - r[1], p[0] - r[0], p[1] - r[1])
    d4 = _cross(s[0] - r[0], s[1] - r[1], q[0] - r[0], q[1] - r[1])
    return d1 * d2 < 0 and d3 * d4 < 0


def _check_free(i: int, lane: FreeLane, doc: Document) -> list[Diagnostic]:
    """A free-form lane's boundaries pair up, its centre points are apart, it has a width and its
    boundaries do not cross (or, given by its centre, do not fold at a corner)."""
    at = ("lanes", i)
    bounds = lane.centre is None
    field = "left_bound" if bounds else "centre"
    if bounds and len(lane.left_bound or []) != len(lane.right_bound or []):
        return [YML420(f"right_bound has {len(lane.right_bound or [])} points and left_bound {len(lane.left_bound or [])}: "
                       "the boundaries are paired point by point", doc.locate(at + ("right_bound",), value=True),
                       hint="give each left point the right point facing it (as CommonRoad lanelets do)")]
    if not bounds and lane.widths is not None and len(lane.widths) != len(lane.centre or []):
        return [YML420(f"{len(lane.widths)} widths for {len(lane.centre or [])} centre points",
                       doc.locate(at + ("widths",), value=True), hint="one per centre point, or 'width' for the whole lane")]
    pts, width = free_centre(lane)
    out: list[Diagnostic] = []
    for k in range(1, len(pts)):
        gap = math.hypot(pts[k][0] - pts[k - 1][0], pts[k][1] - pts[k - 1][1])
        if gap < MIN_PIECE:
            out.append(YML420(f"the lane's centre here is {gap:.3g} m from where it is at the point before; "
                              f"points must be at least {MIN_PIECE:g} m apart", doc.locate(at + (field, k), value=True),
                              hint="remove the repeated point (of both boundaries)"))
    if out:
        return out
    inner = range(1, len(pts) - 1) if len(pts) > 2 else range(0)
    for k in inner:
        if width[k] < MIN_WIDTH:
            where = at + ("right_bound", k) if bounds else (at + ("widths", k) if lane.widths is not None else at + ("width",))
            out.append(YML420(f"the lane is {width[k]:.3g} m wide here: between its ends a lane is at least {MIN_WIDTH:g} m wide",
                              doc.locate(where, value=True), hint="only a lane's first and last points may be narrower (a taper)"))
    if max(width) < MIN_WIDTH:
        out.append(YML420(f"the lane is nowhere wider than {max(width):.3g} m (at least {MIN_WIDTH:g} m somewhere)",
                          doc.locate(at + (("right_bound",) if bounds else ("widths",) if lane.widths is not None else ("width",)), value=True)))
    if out:
        return out
    if bounds:
        left, right = lane.left_bound or [], lane.right_bound or []
        for k in range(len(pts)):
            h = _heading(pts, k)
            rung = (left[k][0] - right[k][0], left[k][1] - right[k][1])
            if math.hypot(*rung) >= 1e-9 and _cross(math.cos(h), math.sin(h), *rung) <= 0:
                return [YML420("the boundaries cross: this left point is not to the left of the right point facing it",
                               doc.locate(at + ("left_bound", k), value=True),
                               hint="left and right are seen in the direction of travel; swap them, or reverse both")]
        for k in range(len(pts) - 1):
            if _segments_cross(left[k], left[k + 1], right[k], right[k + 1]):
                return [YML420(f"the boundaries cross between points {k} and {k + 1}",
                               doc.locate(at + ("left_bound", k + 1), value=True), hint="the left boundary stays left of the right one")]
    else:
        for k in range(1, len(pts) - 1):
            turn = abs(_wrap(_direction(pts, k, 1) - _direction(pts, k, -1)))
            a = math.hypot(pts[k][0] - pts[k - 1][0], pts[k][1] - pts[k - 1][1])
            b = math.hypot(pts[k + 1][0] - pts[k][0], pts[k + 1][1] - pts[k][1])
            if turn >= math.pi / 2 or width[k] / 2 * math.tan(turn / 2) > 0.5 * min(a, b):
                out.append(YML420(f"the lane folds here: it turns by {math.degrees(turn):.0f}° within {min(a, b):.3g} m, "
                                  f"too sharp for its {width[k]:g} m width", doc.locate(at + ("centre", k), value=True),
                                  hint="round the corner with more points, or narrow the lane"))
    return out


def _boundary(spec: MapFile, lane_id: str) -> tuple[list[tuple[float, float]], list[tuple[float, float]]] | None:
    """A lane's left and right boundary points (road or free-form lane), None if it has none."""
    for road in spec.roads:
        for lane in road.lane_specs():
            if lane.id == lane_id:
                return road_outline(road, lane)
    for lane in spec.lanes:
        if lane.id == lane_id:
            if lane.centre is None:
                return list(lane.left_bound or []), list(lane.right_bound or [])
            pts, width = free_centre(lane)
            left, right = [], []
            for k, (x, y) in enumerate(pts):
                h = _heading(pts, k)
                left.append((x - width[k] / 2 * math.sin(h), y + width[k] / 2 * math.cos(h)))
                right.append((x + width[k] / 2 * math.sin(h), y - width[k] / 2 * math.cos(h)))
            return left, right
    return None


def _distance(p: tuple[float, float], line: list[tuple[float, float]]) -> float:
    """Distance [m] from ``p`` to the polyline ``line``."""
    best = math.inf
    for a, b in zip(line, line[1:]):
        dx, dy = b[0] - a[0], b[1] - a[1]
        l2 = dx * dx + dy * dy
        t = 0.0 if l2 == 0 else min(1.0, max(0.0, ((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2))
        best = min(best, math.hypot(p[0] - a[0] - t * dx, p[1] - a[1] - t * dy))
    return best


BESIDE = 0.5
"""How far [m] a declared neighbour's boundary may be from the lane's boundary it is beside."""


def _check_beside(spec: MapFile, doc: Document) -> list[Diagnostic]:
    """A declared ``adjacent_left`` / ``adjacent_right`` lies beside the lane: the middle point of the
    lane's boundary on that side is within :data:`BESIDE` of one of the neighbour's boundaries."""
    out: list[Diagnostic] = []
    for i, lane in enumerate(spec.lanes):
        for side in ("left", "right"):
            other = getattr(lane, f"adjacent_{side}")
            mine = _boundary(spec, lane.id)
            theirs = _boundary(spec, other) if other is not None else None
            if other is None or theirs is None or mine is None:
                continue  # a missing lane is reported as a bad reference
            edge = mine[0] if side == "left" else mine[1]
            mid = edge[len(edge) // 2]
            gap = min(_distance(mid, theirs[0]), _distance(mid, theirs[1]))
            if other == lane.id or gap > BESIDE:
                what = "is the lane itself" if other == lane.id else f"has no boundary within {BESIDE:g} m of this lane's {side} one ({gap:.3g} m)"
                out.append(YML420(f"lane '{other}' {what}", doc.locate(("lanes", i, f"adjacent_{side}"), value=True),
                                  hint="the lane beside shares the boundary; leave 'adjacent_*' out to find it from the geometry"))
    return out


def _check_successors(spec: MapFile, doc: Document) -> list[Diagnostic]:
    """Each successor starts where its predecessor ends (within half a lane width), heading the
    same way (within 90°)."""
    ends = all_lane_ends(spec)
    declared = [(("roads", i, "lanes", j), lane) for i, road in enumerate(spec.roads) for j, lane in enumerate(road.lanes or [])]
    declared += [(("lanes", i), lane) for i, lane in enumerate(spec.lanes)]
    out: list[Diagnostic] = []
    for at_lane, lane in declared:
        if lane.id not in ends:
            continue
        end, width = ends[lane.id][1], ends[lane.id][3]
        for k, nxt in enumerate(lane.successors):
            if nxt not in ends:
                continue  # reported as a bad reference (or a junction's lane, built to fit)
            start, _, nwidth, _ = ends[nxt]
            at = doc.locate(at_lane + ("successors", k), value=True)
            gap = math.hypot(start.x - end.x, start.y - end.y)
            tolerance = max(width, nwidth, 2 * MIN_WIDTH) / 2
            turn = abs(math.degrees(_wrap(start.heading - end.heading)))
            if gap > tolerance + 1e-6:
                out.append(YML420(
                    f"lane '{nxt}' starts {gap:.3g} m from the end of lane '{lane.id}': it does not follow it",
                    at, hint=f"a successor starts within half a lane width ({tolerance:g} m) of where its lane ends: "
                             f"lane '{lane.id}' ends at ({end.x:.2f}, {end.y:.2f}), '{nxt}' starts at "
                             f"({start.x:.2f}, {start.y:.2f})"))
            elif turn > 90:
                out.append(YML420(
                    f"lane '{nxt}' starts heading {turn:.0f}° away from where lane '{lane.id}' ends: traffic would turn back",
                    at, hint="a successor continues in about the same direction (within 90°); check its 'direction'"))
    return out


def check_layout(spec: MapFile, doc: Document) -> list[Diagnostic]:
    """Every geometric inconsistency of the map (YML420), each at the value that causes it."""
    out: list[Diagnostic] = []
    for i, road in enumerate(spec.roads):
        out += _check_segments(i, road, doc)
    for i, lane in enumerate(spec.lanes):
        out += _check_free(i, lane, doc)
    if not out:
        out += _check_successors(spec, doc)
        out += _check_beside(spec, doc)
    return out
