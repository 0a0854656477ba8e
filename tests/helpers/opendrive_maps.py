"""OpenDRIVE maps written by scenariogeneration for the importer's tests, and an independent oracle
of their geometry: the reference line integrated from its curvature (lines, arcs, spirals) and the
lanes' borders from the width polynomials of the file, with numpy only (no OpenDRIVE library)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from scenariogeneration import xodr

STEP = 0.002  # [m] integration step of the oracle's reference line


def write(odr: xodr.OpenDrive, path: Path) -> Path:
    """Adjust and write ``odr`` (the file the importer reads)."""
    odr.adjust_roads_and_lanes()
    odr.write_xml(str(path))
    return path


def reference(path: Path, road_id: str) -> tuple[np.ndarray, np.ndarray]:
    """The reference line of a road: s (N,) [m] and (x, y, heading) (N, 3) [m, rad], integrated
    every :data:`STEP` from the curvature of its planView (line, arc, spiral)."""
    road = ET.parse(path).getroot().find(f"road[@id='{road_id}']")
    assert road is not None
    geoms = road.findall("planView/geometry")
    first = geoms[0]
    x0, y0, h0 = (float(first.get(k)) for k in ("x", "y", "hdg"))
    total = sum(float(g.get("length")) for g in geoms)
    s = np.arange(0.0, total + STEP, STEP)
    kappa = np.zeros_like(s)
    for g in geoms:
        a, ln = float(g.get("s")), float(g.get("length"))
        inside = (s >= a) & (s <= a + ln)
        kind = g[0]
        if kind.tag == "arc":
            kappa[inside] = float(kind.get("curvature"))
        elif kind.tag == "spiral":
            k0, k1 = float(kind.get("curvStart")), float(kind.get("curvEnd"))
            kappa[inside] = k0 + (k1 - k0) * (s[inside] - a) / ln
    heading = h0 + np.concatenate([[0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * STEP)])
    x = x0 + np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(heading[1:]) + np.cos(heading[:-1])) * STEP)])
    y = y0 + np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(heading[1:]) + np.sin(heading[:-1])) * STEP)])
    return s, np.stack([x, y, heading], axis=1)


def widths(path: Path, road_id: str, section: int, lane: int, s: np.ndarray) -> np.ndarray:
    """Width [m] of a lane at road positions ``s`` [m] from its <width> polynomials."""
    road = ET.parse(path).getroot().find(f"road[@id='{road_id}']")
    sec = road.findall("lanes/laneSection")[section]
    el = sec.find(f"*/lane[@id='{lane}']")
    ds = s - float(sec.get("s"))
    out = np.zeros_like(s)
    for w in el.findall("width"):
        off = float(w.get("sOffset"))
        a, b, c, d = (float(w.get(k)) for k in "abcd")
        u = ds - off
        out = np.where(u >= 0, a + b * u + c * u**2 + d * u**3, out)
    return out


def borders(path: Path, road_id: str, section: int, lane: int, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Left and right boundary points (N, 2) [m] of a lane at road positions ``s`` [m], in the
    lane's direction of travel (right-hand traffic: negative lanes along s)."""
    rs, pose = reference(path, road_id)
    x, y, h = (np.interp(s, rs, pose[:, k]) for k in range(3))
    sign = -1 if lane < 0 else 1
    inner = sum(widths(path, road_id, section, sign * k, s) for k in range(1, abs(lane)))
    outer = inner + widths(path, road_id, section, lane, s)
    t_in, t_out = sign * inner, sign * outer
    normal = np.stack([-np.sin(h), np.cos(h)], axis=1)
    p_in = np.stack([x, y], axis=1) + t_in[:, None] * normal if np.ndim(t_in) else np.stack([x, y], axis=1)
    p_out = np.stack([x, y], axis=1) + t_out[:, None] * normal
    # the inner border (towards the reference line) is on the left in the direction of travel, both ways
    return p_in, p_out


def distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance [m] from each of ``points`` (N, 2) to the polyline ``line`` (M, 2)."""
    a, b = line[:-1][None], line[1:][None]
    p = points[:, None]
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-18), 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.hypot(*(p - closest).transpose(2, 0, 1)).min(axis=1)


def single_road(geometry: list, name: str, left: int = 1, right: int = 2, **kw: float) -> xodr.OpenDrive:
    """One road (id 1) of ``geometry`` pieces with ``left`` + ``right`` lanes."""
    odr = xodr.OpenDrive(name)
    odr.add_road(xodr.create_road(geometry, id=1, left_lanes=left, right_lanes=right, **kw))
    return odr


def four_way(name: str = "junction4") -> xodr.OpenDrive:
    """Four roads (ids 1-4, 2 + 2 lanes, 100 m) meeting at junction 100, every pair connected."""
    odr = xodr.OpenDrive(name)
    roads = [xodr.create_road(xodr.Line(100), id=i + 1, left_lanes=2, right_lanes=2, lane_width=3.5) for i in range(4)]
    jc = xodr.CommonJunctionCreator(id=100, name="j", startnum=200)
    for i, r in enumerate(roads):
        odr.add_road(r)
        jc.add_incoming_road_circular_geometry(r, radius=20, angle=i * math.pi / 2, road_connection="successor")
    for a in range(4):
        for b in range(a + 1, 4):
            jc.add_connection(a + 1, b + 1)
    odr.add_junction_creator(jc)
    return odr
