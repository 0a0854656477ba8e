"""Regenerate the Town-like OpenDRIVE map (town.xodr) and its import (town.yaml).

    .venv/bin/python examples/town/generate.py        # needs the dev extra (scenariogeneration, carla)

The map, drawn with scenariogeneration as CARLA's Town maps are laid out:

* a 3 × 3 grid of four-way junctions 150 m apart (2 + 2 lanes, 50 km/h town roads); a stop sign
  (DE 206) at the end of road 1 (eastbound into junction 1001) and a traffic light (1000001) at
  the end of road 3 (eastbound into junction 1002);
* a curved road south of the grid (arcs joined by spirals, 1 + 1 lanes) whose limit changes four
  times (40, 30, 50, 30, 40 km/h);
* a straight boulevard north of the grid, 1600 m, 3 + 3 lanes, 100 km/h.

The scenarios beside this script use the imported lanes by id (``r<road>_<section>_<lane>``).
:func:`town` is also the benchmark's map (benchmarks/opendrive.py, a larger grid).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

from scenariogeneration import xodr

HERE = Path(__file__).resolve().parent
BLOCK, RADIUS = 150.0, 20.0  # [m] junction spacing and junction radius


def _grid(odr: xodr.OpenDrive, n: int, lanes: int = 2) -> dict[tuple[int, int, int], xodr.Road]:
    """An n × n grid of four-way junctions (ids 1000 + i·n + j); roads numbered from 1, each from
    junction (i, j) east (d = 0) or north (d = 1). Returns the roads by (i, j, d)."""
    jcs = [[xodr.CommonJunctionCreator(id=1000 + i * n + j, name=f"j{i}_{j}", startnum=10000 + 100 * (i * n + j))
            for j in range(n)] for i in range(n)]
    roads, rid = {}, 1
    for i in range(n):
        for j in range(n):
            for d, (di, dj, ang) in enumerate(((0, 1, 0.0), (1, 0, math.pi / 2))):
                ii, jj = i + di, j + dj
                if ii >= n or jj >= n:
                    continue
                road = xodr.create_road(xodr.Line(BLOCK - 2 * RADIUS), id=rid, left_lanes=lanes, right_lanes=lanes,
                                        lane_width=3.5)
                road.add_type(xodr.RoadType.town, s=0, country="DE", speed=50, speed_unit="km/h")
                roads[(i, j, d)] = road
                rid += 1
                odr.add_road(road)
                jcs[i][j].add_incoming_road_circular_geometry(road, RADIUS, ang, "predecessor")
                jcs[ii][jj].add_incoming_road_circular_geometry(road, RADIUS, ang + math.pi, "successor")
    for row in jcs:
        for jc in row:
            ids = [r.id for r in jc.incoming_roads]
            for a in range(len(ids)):
                for b in range(a + 1, len(ids)):
                    jc.add_connection(ids[a], ids[b])
            odr.add_junction_creator(jc)
    return roads


def town(n: int = 3, extras: bool = True) -> xodr.OpenDrive:
    """The Town-like map: the grid, and (``extras``) its signs, the curved road and the boulevard."""
    odr = xodr.OpenDrive("town")
    roads = _grid(odr, n)
    if not extras:
        return odr
    roads[(0, 0, 0)].planview.set_start_point(RADIUS, 0.0, 0.0)  # the grid's anchor: junction 1000 at the origin
    length = BLOCK - 2 * RADIUS
    stop = xodr.Signal(s=length - 3, t=-8, country="DE", Type="206", id="1", name="stop")
    stop.add_validity(-2, -1)
    roads[(0, 0, 0)].add_signal(stop)
    light = xodr.Signal(s=length - 3, t=-8, country="OpenDRIVE", Type="1000001", dynamic=xodr.Dynamic.yes, id="2",
                        name="light")
    light.add_validity(-2, -1)
    roads[(0, 1, 0)].add_signal(light)
    curve = xodr.create_road([xodr.Line(40), xodr.Spiral(0.0, 0.02, length=30), xodr.Arc(0.02, length=40),
                              xodr.Spiral(0.02, -0.015, length=50), xodr.Arc(-0.015, length=60),
                              xodr.Spiral(-0.015, 0.0, length=30), xodr.Line(60)], id=500, left_lanes=1, right_lanes=1,
                             lane_width=3.5)
    curve.planview.set_start_point(0.0, -150.0, 0.0)
    for s, kmh in ((0, 40), (60, 30), (130, 50), (200, 30), (260, 40)):
        curve.add_type(xodr.RoadType.town, s=s, country="DE", speed=kmh, speed_unit="km/h")
    odr.add_road(curve)
    boulevard = xodr.create_road(xodr.Line(1600), id=600, left_lanes=3, right_lanes=3, lane_width=3.5)
    boulevard.planview.set_start_point(-400.0, BLOCK * (n - 1) + 150.0, 0.0)
    boulevard.add_type(xodr.RoadType.rural, s=0, country="DE", speed=100, speed_unit="km/h")
    odr.add_road(boulevard)
    return odr


def write(odr: xodr.OpenDrive, path: Path) -> Path:
    """Adjust and write ``odr`` to ``path``."""
    odr.adjust_roads_and_lanes()
    odr.write_xml(str(path))
    return path


def main() -> int:
    from twolevel.interop import import_file

    xodr_path = write(town(), HERE / "town.xodr")
    result = import_file(xodr_path, HERE)
    for d in result.diagnostics:
        print(f"{d.span}: {d.code} {d.message}", file=sys.stderr)
    print(f"wrote {xodr_path.name} and {result.written[0].name if result.written else 'nothing'}")
    return 2 if result.bad_input else 0


if __name__ == "__main__":
    sys.exit(main())
