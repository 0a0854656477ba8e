"""The MILC encoding of the CommonRoad rule pack: the linear rules (R_G3, R_G4, R_IN1, R_IN2)
encode, and a plan's robustness equals the offline monitor's on it; the braking-distance rules
(R_G1, R_G2) are MIL501, as their ego speed is squared.

The system is the test double integrator: p is the ego's route position, v its speed, a its
acceleration (decision variables over the horizon). Two vehicles are in range: d_lon[i] = c_i − p
(affine, as the MPC would predict it), their speed, lane and presence known at solve time; a stop
sign's line and a red light's line lie just behind the vehicle ahead (d_stop, d_light affine)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twolevel.compiler.driver import encode
from twolevel.compiler.signals import AffineSignal
from twolevel.compiler.types import Requirement
from twolevel.milp.builder import ModelBuilder
from twolevel.milp.highs import solve_highs
from twolevel.milp.solution import Status
from twolevel.monitor.robustness import robustness
from twolevel.stl.lint import load_ruleset
from twolevel.world.provided import PROVIDED_PARTICIPANT_SIGNALS

from helpers.milp_systems import DT, H, PAST, T, double_integrator

PACK = Path(__file__).resolve().parents[2] / "rules" / "commonroad"
NOW = PAST
PIDS = ("lead", "side")


def _rule(prefix: str):
    path = next(PACK.glob(prefix + "_*.stl"))
    rs, diags = load_ruleset(str(path), dt=DT, participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
    assert rs is not None, diags
    return rs.formula(rs.names[0])


def _world(b: ModelBuilder, v_past: np.ndarray, anchor: dict[str, np.ndarray]):
    p_past = np.linspace(0.0, 0.3, PAST + 1)
    pb, vb, ab, sig = double_integrator(b, p_past, v_past)
    n = b.n_cols
    sig.update({"v_max": np.full(T, 3.0), "light_red": np.ones(T), "a": np.zeros(T)})
    line = float(anchor["lead"][0])  # a stop sign's line and a red light's line there
    for name, at in (("d_stop", line), ("d_light", line + 1.0)):
        sig[name] = AffineSignal.of_columns(pb.idx, n, past=at - p_past, scale=-1.0, offset=at)
    for pid, c in anchor.items():
        sig[f"d_lon[{pid}]"] = AffineSignal.of_columns(pb.idx, n, past=c[: PAST + 1] - p_past, scale=-1.0,
                                                       offset=c[PAST + 1:])
        sig[f"present[{pid}]"] = np.full(T, np.inf)
        sig[f"v[{pid}]"] = np.full(T, 0.5 if pid == "lead" else 3.0)
        sig[f"in_same_lane[{pid}]"] = np.full(T, 2.65 if pid == "lead" else -0.85)
        sig[f"precedes[{pid}]"] = np.full(T, 2.65 if pid == "lead" else -0.85)
        sig[f"cut_in[{pid}]"] = np.full(T, -0.85)
        sig[f"a[{pid}]"] = np.zeros(T)
    return pb, vb, ab, sig


@pytest.mark.parametrize("prefix", ["R_G3", "R_G4", "R_IN1", "R_IN2"])
@pytest.mark.parametrize("lead_at", [4.0, 40.0])
def test_linear_rules_encode_and_the_plan_meets_the_monitor(prefix: str, lead_at: float) -> None:
    """Maximise the rule's worst robustness over the horizon: the optimum equals the monitor's
    value on the plan (R_G4's constants scaled to the double integrator's speeds: the pack's
    dv_min is bound to 1 m/s)."""
    f = _rule(prefix)
    if prefix == "R_G4":
        path = next(PACK.glob("R_G4_*.stl"))
        rs, _ = load_ruleset(str(path), {"dv_min": 1.0, "v_road": 3.5, "v_fov": 3.5, "v_brake": 3.5}, dt=DT,
                             participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
        f = rs.formula("R_G4")
    b = ModelBuilder()
    anchor = {"lead": np.full(T, lead_at), "side": np.full(T, 6.0)}
    pb, vb, ab, sig = _world(b, np.full(PAST + 1, 1.5), anchor)
    times = tuple(range(NOW + 1, T))
    enc = encode(b, [Requirement(prefix, f, times)], sig, DT, mode="robustness", rho_bounds=(-50.0, 50.0))
    assert not [d for d in enc.diagnostics if d.code != "MIL503"], [d.message for d in enc.diagnostics]
    sol = solve_highs(b.build(), mip_gap=1e-9, options={"mip_abs_gap": 1e-9})
    assert sol.status is Status.OPTIMAL
    x = sol.x
    p = np.concatenate([np.linspace(0.0, 0.3, PAST + 1), x[pb.idx]])
    v = np.concatenate([np.full(PAST + 1, 1.5), x[vb.idx]])
    mon = {k: val for k, val in sig.items() if not isinstance(val, AffineSignal)}
    mon.update({"p": p, "v": v})
    mon.update({f"d_lon[{pid}]": anchor[pid] - p for pid in PIDS})
    mon.update({"d_stop": anchor["lead"][0] - p, "d_light": anchor["lead"][0] + 1.0 - p})
    rho = robustness(f, mon, DT)
    want = min(float(rho[t]) for t in times)
    assert x[enc.rho] == pytest.approx(min(want, 50.0), abs=1e-6)


@pytest.mark.parametrize("prefix", ["R_G1", "R_G2"])
def test_braking_distance_rules_are_mil501(prefix: str) -> None:
    b = ModelBuilder()
    _, _, _, sig = _world(b, np.full(PAST + 1, 1.5), {"lead": np.full(T, 4.0), "side": np.full(T, 6.0)})
    enc = encode(b, [Requirement(prefix, _rule(prefix), (NOW + 1,))], sig, DT)
    assert [d.code for d in enc.diagnostics] == ["MIL501"]
