"""A map's layout in pure Python: poses along each road, lane lengths and ends, and the geometric
consistency a map needs before it is sampled (:mod:`twolevel.world.geometry`, numpy).

The schema checks each number on its own; what only the geometry shows is checked here, at load,
so that whatever ``twolevel check`` accepts can be sampled, planned on and simulated:

- an arc on which a lane would fold: the lane's inner edge, at radius R − offset·sign(angle) −
  width/2, must stay on the outside of the arc's centre;
- degenerate pieces: an arc shorter than :data:`~twolevel.world.schema.MIN_PIECE`, polyline
  points closer than that to the point before them;
- successors that do not connect: a lane must start within half a lane width of the end of the
  lane it follows, heading the same way (within 90°).

Lengths agree with the sampled lanes (:func:`twolevel.world.geometry.lane_from_reference`) to
rounding: arcs at an offset are exact, and an offset polyline turns each corner with a chord
2·|offset|·sin(|turn|/2) long, as the sampled lane does.

Imported by ``twolevel check``: standard library only (no numpy).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterator

from twolevel.diagnostics import Diagnostic
from twolevel.world.codes import YML420
from twolevel.world.document import Document
from twolevel.world.schema import MIN_PIECE, LaneSpec, MapFile, Road, Segment

__all__ = ["Pose", "Piece", "pieces", "lane_length", "lane_lengths", "lane_ends", "check_layout"]


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


def lane_length(road: Road, offset: float) -> float:
    """Length [m] of the lane ``offset`` [m] left of ``road``'s reference line: arcs at radius
    R − offset·sign(angle), straight legs as drawn, plus a chord 2·|offset|·sin(|turn|/2) at each
    corner where the heading jumps (the sampled lane's corner)."""
    total = 0.0
    heading = math.radians(road.start.heading)  # a polyline may turn at the very start
    for p in pieces(road):
        if p.start.heading != heading:
            total += 2 * abs(offset) * abs(math.sin((p.start.heading - heading) / 2))
        total += p.length * abs(1 - offset * p.curvature) if p.curvature else p.length
        heading = p.end.heading
    return total


def lane_lengths(spec: MapFile) -> dict[str, float]:
    """Length [m] of every lane of the map by id."""
    return {lane.id: lane_length(road, lane.offset) for road in spec.roads for lane in road.lane_specs()}


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


def _check_successors(spec: MapFile, doc: Document) -> list[Diagnostic]:
    """Each successor starts where its predecessor ends (within half a lane width), heading the
    same way (within 90°)."""
    ends: dict[str, tuple[Pose, Pose, float]] = {}
    for road in spec.roads:
        for lane in road.lane_specs():
            ends.setdefault(lane.id, (*lane_ends(road, lane), lane.width))
    out: list[Diagnostic] = []
    for i, road in enumerate(spec.roads):
        for j, lane in enumerate(road.lanes or []):
            end, width = ends[lane.id][1], lane.width
            for k, nxt in enumerate(lane.successors):
                if nxt not in ends:
                    continue  # reported as a bad reference
                start, _, nwidth = ends[nxt]
                at = doc.locate(("roads", i, "lanes", j, "successors", k), value=True)
                gap = math.hypot(start.x - end.x, start.y - end.y)
                tolerance = max(width, nwidth) / 2
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
    if not out:
        out += _check_successors(spec, doc)
    return out

