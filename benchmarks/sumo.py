"""SUMO traffic in the closed loop against the built-in traffic, with 160 and with 1000 vehicles.

Both levels (the MPC and the low level with its safety layer) drive the ego across two
signalised junctions of the 5x5 SUMO grid (examples/sumo/grid5.net.xml and its import) for
``--duration`` simulated seconds, among

* SUMO's vehicles on random trips (libsumo in-process; kept at N), or
* the built-in IDM traffic: N vehicles placed on the same lanes (a population).

Printed per run: simulated/wall time ratio (and simulated/CPU time, which other jobs on the
machine do not change), the control step (both levels), and the traffic's cost per step: for
SUMO, its own step and the exchange (moving the ego, reading the vehicles near it), for the
built-in traffic its step; and the start (loading the scenario and the 476-lane map, building
the world, starting SUMO, the safety layer's network) [s]. Targets: 160 vehicles ≥ 5× real time
with both levels, 1000 ≥ 1×, the exchange ≤ 1 ms per step.

    .venv/bin/python benchmarks/sumo.py [--duration 20] [--vehicles 160 1000]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from twolevel.safety.network import network_of
from twolevel.sim.engine import ClosedLoop
from twolevel.world.loader import load_scenario
from twolevel.world.world import build_world

ROOT = Path(__file__).resolve().parent.parent
SUMO = ROOT / "examples/sumo"


def scenario(folder: Path, n: int, engine: str, duration: float) -> Path:
    """The benchmark's scenario with ``n`` vehicles from ``engine`` ('sumo' or 'builtin')."""
    if engine == "sumo":
        others = f"traffic: {{engine: sumo, net: {SUMO / 'grid5.net.xml'}, random_trips: {{vehicles: {n}}}, seed: 1}}"
    else:
        spec = yaml.safe_load((SUMO / "grid5.yaml").read_text())
        lanes = [lane["id"] for lane in spec["lanes"] if not lane["id"].startswith(":")]  # not a junction's
        others = (f"populations: [{{id: idm, count: {n}, lanes: [{', '.join(lanes)}], speed_range: [5, 12], "
                  "min_gap: 8, box: {length: 5.0, width: 1.8}}]")
    path = folder / f"{engine}_{n}.yaml"
    path.write_text(f"""kind: scenario
map: {SUMO / 'grid5.yaml'}
ego: {{start: {{lane: A0B0_0, s: 20}}, speed: 8}}
route: {{start: {{lane: A0B0_0, s: 20}}, goal: {{lane: C0D0_0, s: 150}}}}
{others}
rules: [{ROOT / 'rules/speed_limit.stl'}, {ROOT / 'rules/red_light.stl'}, {ROOT / 'rules/safe_distance.stl'}]
run: {{duration: {duration}, seed: 1}}
expect: {{goal: false}}
""")
    return path


class Timed:
    """The loop's traffic engine, its steps timed [ms]."""

    def __init__(self, engine: object) -> None:
        self.engine, self.ms = engine, []

    def start(self, *args: object) -> object:
        return self.engine.start(*args)  # type: ignore[attr-defined]

    def step(self, *args: object) -> object:
        t = time.perf_counter()
        out = self.engine.step(*args)  # type: ignore[attr-defined]
        self.ms.append((time.perf_counter() - t) * 1e3)
        return out

    def close(self) -> None:
        self.engine.close()  # type: ignore[attr-defined]


def run(path: Path, out: Path) -> dict[str, float]:
    t0 = time.perf_counter()
    scn, diags = load_scenario(path)
    assert scn is not None, diags
    world = build_world(scn)
    loop, diags = ClosedLoop.create(world, scn, monitor=True, controller="twolevel", safety=True, ttr_every=0)
    assert loop is not None, diags
    network_of(world)  # the safety layer's view of the map, built once (cached for the run)
    start = time.perf_counter() - t0
    engine = loop.traffic
    timed = Timed(engine)
    loop.traffic = timed  # type: ignore[assignment]
    cpu0 = time.process_time()
    summary, diags = loop.run(str(out), None, False, [])
    cpu = time.process_time() - cpu0
    assert summary is not None and summary.status.value == "complete", diags
    sim = summary.steps * world.settings.dt
    figures = {"start": start, "rt": sim / summary.wall_time_s, "rt_cpu": sim / cpu,
               "step": float(np.median(loop.stats.step_ms)),
               "traffic": float(np.median(timed.ms)), "traffic_p95": float(np.percentile(timed.ms, 95)),
               "sumo": float("nan"), "exchange": float("nan"), "exchange_p95": float("nan")}
    if hasattr(engine, "sumo_ms"):
        figures.update(sumo=float(np.median(engine.sumo_ms)), exchange=float(np.median(engine.exchange_ms)),
                       exchange_p95=float(np.percentile(engine.exchange_ms, 95)))
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0, help="simulated seconds per run")
    parser.add_argument("--vehicles", type=int, nargs="+", default=[160, 1000])
    args = parser.parse_args()
    print(f"closed loop, both levels, {args.duration:g} s simulated on examples/sumo/grid5 (dt 0.1 s); times are medians")
    print(f"{'N':>5} {'traffic':8} {'start s':>7} {'x real time':>11} {'x (cpu)':>8} {'step ms':>8} {'traffic ms':>10} "
          f"{'p95':>6} {'SUMO step':>9} {'exchange':>8} {'p95':>6}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for n in args.vehicles:
            for engine in ("sumo", "builtin"):
                f = run(scenario(folder, n, engine, args.duration), folder / f"run_{engine}_{n}")
                print(f"{n:5d} {engine:8} {f['start']:7.2f} {f['rt']:11.1f} {f['rt_cpu']:8.1f} {f['step']:8.2f} {f['traffic']:10.3f} "
                      f"{f['traffic_p95']:6.2f} {f['sumo']:9.3f} {f['exchange']:8.3f} {f['exchange_p95']:6.3f}",
                      flush=True)
    print("targets: 160 vehicles >= 5x real time, 1000 >= 1x, exchange <= 1 ms per step")


if __name__ == "__main__":
    main()
