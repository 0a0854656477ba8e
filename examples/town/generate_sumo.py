"""Regenerate the SUMO network of the Town-like map (town.net.xml) and the route files of its
SUMO scenarios (safety_sumo.rou.xml, scalability_sumo.rou.xml).

    .venv/bin/pip install eclipse-sumo==1.28.0           # SUMO's netconvert (not needed to run anything)
    .venv/bin/python examples/town/generate_sumo.py

The network is SUMO's own conversion of town.xodr::

    netconvert --opendrive-files town.xodr --offset.disable-normalization true -o town.net.xml
    netconvert -s town.net.xml -e boulevard.edg.xml -o town.net.xml    # the boulevard's 100 km/h

with the coordinates kept (no offset), so that SUMO's vehicles and the map imported from the
same OpenDRIVE (town.yaml) lie on each other; netconvert reads no speed from the road's type, so
the boulevard's limit is patched in. SUMO's lane ``-600_k`` is the map's ``r600_0_-(3-k)`` (SUMO
counts from the right). The vehicles are those of safety.yaml and scalability.yaml (placed by
the same rules from fixed seeds), as SUMO vehicles: SUMO then drives them, sees the ego and
changes lanes by its own model; the stalled car is a SUMO vehicle stopped for the whole run.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
BOULEVARD = "-600"  # eastbound: the map's r600_0_-1 .. -3
LANES = {"r600_0_-3": 0, "r600_0_-2": 1, "r600_0_-1": 2}
LENGTH = 5.0  # [m] SUMO's passenger car (the scenarios' box: traffic.box)


def netconvert() -> str:
    """The netconvert executable (the eclipse-sumo wheel's, or one on PATH)."""
    found = shutil.which("netconvert") or shutil.which("netconvert", path=str(Path(sys.executable).parent))
    if found is None:
        raise SystemExit("netconvert not found: pip install eclipse-sumo==1.28.0")
    return found


def network(out: Path) -> None:
    """town.xodr → ``out``, coordinates kept, the boulevard at 100 km/h."""
    exe = netconvert()
    subprocess.run([exe, "--opendrive-files", str(HERE / "town.xodr"), "--offset.disable-normalization", "true",
                    "--no-warnings", "true", "-o", str(out)], check=True)
    with tempfile.TemporaryDirectory() as tmp:
        patch = Path(tmp) / "boulevard.edg.xml"
        patch.write_text(f'<edges>\n    <edge id="{BOULEVARD}" speed="27.78"/>\n    <edge id="600" speed="27.78"/>\n</edges>\n')
        subprocess.run([exe, "-s", str(out), "-e", str(patch), "--offset.disable-normalization", "true",
                        "--no-warnings", "true", "-o", str(out)], check=True)


def _vehicles(rng: np.random.Generator, lanes: list[str], count: int, s_range: tuple[float, float],
              speed: tuple[float, float], pitch: float, keep_clear: tuple[str, float] | None = None
              ) -> list[tuple[str, float, float]]:
    """``count`` (lane, centre s [m], speed [m/s]) drawn from slots ``pitch`` apart along
    ``lanes`` within ``s_range``, none within a pitch of ``keep_clear`` (lane, s)."""
    slots = []
    for lane in lanes:
        for s in np.arange(s_range[0] + LENGTH / 2, s_range[1] - LENGTH / 2 + 1e-9, pitch):
            if keep_clear is None or lane != keep_clear[0] or abs(s - keep_clear[1]) >= pitch:
                slots.append((lane, float(s)))
    take = np.sort(rng.choice(len(slots), size=min(count, len(slots)), replace=False))
    speeds = rng.uniform(*speed, size=len(take))
    return [(slots[k][0], slots[k][1], float(v)) for k, v in zip(take, speeds)]


def routes(path: Path, v_max: float, cars: list[tuple[str, str, float, float]], stopped: tuple[str, ...] = ()) -> None:
    """A route file: cars of at most ``v_max`` [m/s] (SUMO's passenger car, no driver
    imperfection), ``cars`` (id, map lane, centre s [m], drawn speed [m/s]) departing at t = 0
    along the boulevard where they are placed (no insertion checks), each at the speed SUMO finds
    safe behind the one ahead up to ``v_max`` (a drawn speed can be one SUMO's model must brake
    hard from at once; listed front first, so that each finds its leader there), those in
    ``stopped`` standing there for the run."""
    vtype = f'<vType id="car" length="{LENGTH}" width="1.8" minGap="2.5" maxSpeed="{v_max}" speedFactor="1.0" sigma="0.0"/>'
    rows = ['<routes>', f'    {vtype}', f'    <route id="boulevard" edges="{BOULEVARD}"/>']
    for vid, lane, s, v in cars:
        front = s + LENGTH / 2  # SUMO places a vehicle by its front
        stop = (f'\n        <stop lane="{BOULEVARD}_{LANES[lane]}" endPos="{front:.2f}" duration="3600"/>\n    '
                if vid in stopped else "")
        rows.append(f'    <vehicle id="{vid}" type="car" route="boulevard" depart="0" departLane="{LANES[lane]}" '
                    f'departPos="{front:.2f}" departSpeed="{"0" if vid in stopped else "max"}" insertionChecks="none">{stop}'
                    '</vehicle>')
    rows.append('</routes>\n')
    path.write_text("\n".join(rows))


def main() -> int:
    network(HERE / "town.net.xml")
    rng = np.random.default_rng(1)  # safety.yaml: a stalled car ahead, 60 ahead of it, 99 beside
    cars = [("stalled", "r600_0_-2", 160.0, 0.0)]
    cars += [(f"ahead-{j}", *c) for j, c in enumerate(_vehicles(rng, ["r600_0_-2"], 60, (175, 1500), (20, 28), 20.0))]
    cars += [(f"beside-{j}", *c) for j, c in enumerate(_vehicles(rng, ["r600_0_-3", "r600_0_-1"], 99, (0, 1600),
                                                                  (18, 28), 20.0))]
    routes(HERE / "safety_sumo.rou.xml", 28.0, sorted(cars, key=lambda c: -c[2]), ("stalled",))
    rng = np.random.default_rng(2)  # scalability.yaml: a pack of 121 around the ego (lane -2, s 250)
    pack = _vehicles(rng, list(LANES), 121, (0, 560), (12, 15), LENGTH + 8.0, ("r600_0_-2", 250.0))
    routes(HERE / "scalability_sumo.rou.xml", 14.0,  # the pack's IDM v0
           sorted(((f"pack-{j}", *c) for j, c in enumerate(pack)), key=lambda c: -c[2]))
    print("wrote town.net.xml, safety_sumo.rou.xml, scalability_sumo.rou.xml")
    return 0


if __name__ == "__main__":
    sys.exit(main())
