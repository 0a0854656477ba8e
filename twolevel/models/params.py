"""Vehicle parameters in one place: the kinematic bicycle's and the detailed model's.

Defaults are a passenger car, CommonRoad vehicle 2 (BMW 320i; Althoff & Würsching,
"CommonRoad: Vehicle Models", 2020, Tab. 6, shipped as ``parameters_vehicle2.yaml`` in
``commonroad-vehicle-models`` 3.0.2), with Pacejka's generic dry-tarmac tyre figures, CARLA's
default car's brake and engine figures and the paper's boxes. Every field says its unit and
source ([CR2], [PAC], [CARLA], [PAPER]: see :class:`VehicleParams`).

Per-scenario changes go through :meth:`VehicleParams.with_overrides` (also on
:class:`BicycleParams`), which rejects unknown names with :class:`UnknownParameterError`
(carrying the name, the known names and the closest match, so the YAML loader can turn it into
a positioned diagnostic).

Light module: no numpy.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, fields, replace
from typing import Any, Mapping, TypeVar

__all__ = [
    "G",
    "Range",
    "BicycleParams",
    "VehicleParams",
    "UnknownParameterError",
    "InvalidParameterError",
    "BICYCLE_RANGES",
    "VEHICLE_RANGES",
]

G = 9.81
"""Gravitational acceleration [m/s²] (CommonRoad's value)."""

_P = TypeVar("_P", "BicycleParams", "VehicleParams")


class UnknownParameterError(KeyError):
    """An override names a parameter that does not exist."""

    def __init__(self, name: str, known: tuple[str, ...], owner: str) -> None:
        close = difflib.get_close_matches(name, known, n=1)
        self.name = name
        self.known = known
        self.owner = owner
        self.suggestion: str | None = close[0] if close else None
        hint = f"; did you mean {self.suggestion!r}?" if self.suggestion else ""
        super().__init__(f"unknown {owner} parameter {name!r}{hint} (known: {', '.join(known)})")

    def __str__(self) -> str:  # KeyError quotes its message otherwise
        return str(self.args[0])


class InvalidParameterError(ValueError):
    """An override has a value of the wrong type or outside its physical range."""

    def __init__(self, name: str, value: Any, reason: str) -> None:
        self.name = name
        self.value = value
        self.reason = reason
        super().__init__(f"parameter {name!r} = {value!r}: {reason}")


@dataclass(frozen=True)
class Range:
    """The physically valid values of one parameter: ``lo`` to ``hi`` in ``unit``, each end
    closed unless ``lo_open``/``hi_open``. NaN and ±inf lie in no range."""

    lo: float
    hi: float
    unit: str
    lo_open: bool = False
    hi_open: bool = False

    def contains(self, value: float) -> bool:
        """Whether ``value`` is a finite number in the range (written so that NaN fails)."""
        above = value > self.lo if self.lo_open else value >= self.lo
        below = value < self.hi if self.hi_open else value <= self.hi
        return math.isfinite(value) and above and below

    def __str__(self) -> str:
        return f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'} {self.unit}"


def _check_ranges(obj: object, ranges: Mapping[str, Range]) -> None:
    for name, rng in ranges.items():
        value = getattr(obj, name)
        if not rng.contains(value):
            raise InvalidParameterError(name, value, f"must be in {rng}")


def _override(obj: _P, mapping: Mapping[str, Any]) -> _P:
    known = tuple(f.name for f in fields(obj))
    clean: dict[str, float] = {}
    for name, value in mapping.items():
        if name not in known:
            raise UnknownParameterError(str(name), known, type(obj).__name__)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise InvalidParameterError(name, value, "expected a number")
        try:
            clean[name] = float(value)
        except OverflowError:  # an integer beyond the float range
            raise InvalidParameterError(name, value, "expected a finite number") from None
    out = replace(obj, **clean)
    out.validate()
    return out


@dataclass(frozen=True)
class BicycleParams:
    """The paper's kinematic bicycle (Aasi, Vasile, Belta, arXiv 2105.02759, Sec. V).

    The paper writes the yaw rate as ψ̇ = v/l_f · tan δ with l_f = 2.11 m, i.e. ``l_f`` plays the
    role of the wheelbase in the usual rear-axle-referenced form; we keep the paper's form.
    """

    l_f: float = 2.11
    """Length in the yaw-rate law ψ̇ = v/l_f·tan δ [m]; the paper's 2.11 m."""
    delta_max: float = 0.5
    """Steering-angle bound used by the MPC [rad] (≈ 29°, within vehicle 2's 1.066 rad)."""
    a_min: float = -9.0
    """Most negative commanded acceleration [m/s²] (≈ 0.92·μ·g, what the brakes deliver)."""
    a_max: float = 3.0
    """Largest commanded acceleration [m/s²] (a comfortable, reachable drive acceleration)."""
    v_max: float = 30.0
    """Speed bound used by the MPC [m/s]."""
    a_lat_max: float = 4.0
    """Largest planned lateral acceleration v²/l_f·tan δ [m/s²]: at speed it bounds the steering
    to |tan δ| ≤ a_lat_max·l_f/v² (well inside the tyres' μ·g ≈ 9.8 m/s², where the detailed
    model follows the kinematic plan; it also keeps the linearised model near its point)."""

    def validate(self) -> None:
        """Raise :class:`InvalidParameterError` on a value outside its :data:`BICYCLE_RANGES`
        (NaN and ±inf included)."""
        _check_ranges(self, BICYCLE_RANGES)

    def with_overrides(self, mapping: Mapping[str, Any]) -> "BicycleParams":
        """A copy with the named fields replaced; unknown names raise :class:`UnknownParameterError`."""
        return _override(self, mapping)


@dataclass(frozen=True)
class VehicleParams:
    """Detailed four-wheel model parameters (SI units throughout).

    Sources: [CR2] CommonRoad vehicle 2, BMW 320i (parameters_vehicle2.yaml, 3.0.2);
    [PAC] Pacejka, "Tire and Vehicle Dynamics", generic dry-tarmac Magic Formula (B 10, C 1.9,
    D 1 × μ·Fz, E 0.97); [CARLA] CARLA's default car: brake torque 1500 N·m per wheel, engine
    torque 400–500 N·m, final ratio 4; [PAPER] the paper's boxes (4.22 m × 1.8 m).
    """

    # --- mass and geometry -------------------------------------------------------------------
    m: float = 1093.2952334674046
    """Total mass [kg]. [CR2] m."""
    a: float = 1.1561957064
    """CoG to front axle [m]. [CR2] a."""
    b: float = 1.4227170936
    """CoG to rear axle [m]. [CR2] b."""
    I_z: float = 1791.5995300122856
    """Yaw moment of inertia [kg·m²]. [CR2] I_z."""
    T_f: float = 1.38684
    """Front track width [m]. [CR2] T_f."""
    T_r: float = 1.36398
    """Rear track width [m]. [CR2] T_r."""
    h_cg: float = 0.5748689544000001
    """CoG height [m], for load transfer. [CR2] h_cg."""
    R_w: float = 0.344
    """Effective wheel rolling radius [m]. [CR2] R_w."""
    I_w: float = 1.7
    """Wheel spin inertia, per wheel [kg·m²]. [CR2] I_y_w."""
    length: float = 4.22
    """Bounding-box length [m]. [PAPER] 4.22 m."""
    width: float = 1.8
    """Bounding-box width [m]. [PAPER] 1.8 m."""

    # --- tyres: Magic Formula, F0 = D·μ·Fz·sin(C·atan(B·s − E·(B·s − atan(B·s)))) -------------
    mu: float = 1.0
    """Road friction coefficient [-] (dry tarmac); scales both D's."""
    B_x: float = 10.0
    """Longitudinal stiffness factor [-]. [PAC] generic dry tarmac."""
    C_x: float = 1.9
    """Longitudinal shape factor [-]. [PAC]."""
    D_x: float = 1.0
    """Longitudinal peak factor [-], times μ·Fz. [PAC]."""
    E_x: float = 0.97
    """Longitudinal curvature factor [-]. [PAC]."""
    B_y: float = 10.0
    """Lateral stiffness factor [1/rad]. [PAC]."""
    C_y: float = 1.9
    """Lateral shape factor [-]. [PAC]."""
    D_y: float = 1.0
    """Lateral peak factor [-], times μ·Fz. [PAC]."""
    E_y: float = 0.97
    """Lateral curvature factor [-]. [PAC]."""
    load_sensitivity: float = 0.1
    """Peak friction falls with load: D·(1 − ε·(Fz − Fz0)/Fz0), Fz0 = m·g/4 [-]. Pacejka's
    p_Dx2/p_Dy2 ≈ −0.1 for passenger tyres; it is what makes the front-heavy car understeer
    (with cornering stiffness ∝ Fz alone it would be neutral). 0 gives the plain formula."""

    # --- resistances -------------------------------------------------------------------------
    c_rr: float = 0.013
    """Rolling-resistance coefficient [-] (passenger tyre on tarmac, Gillespie 1992 ≈ 0.013)."""
    rho_air: float = 1.225
    """Air density [kg/m³] (ISA sea level)."""
    cd_area: float = 0.61
    """Drag area C_d·A [m²] (BMW 3-series E90: C_d 0.29 × A ≈ 2.1 m²)."""

    # --- actuators ---------------------------------------------------------------------------
    engine_force_max: float = 5200.0
    """Largest drive force at the wheels [N] (CARLA: ≈ 450 N·m × final ratio 4 / 0.344 m)."""
    engine_power_max: float = 110_000.0
    """Drive power limit [W] (BMW 320i E90, 110 kW); drive force ≤ P/v above the corner speed."""
    rear_drive_share: float = 1.0
    """Share of drive torque on the rear axle [-] ([CR2] T_se = 0: rear-wheel drive)."""
    brake_torque_max: float = 1500.0
    """Largest brake torque per wheel [N·m]. [CARLA]."""
    brake_friction_use: float = 0.95
    """Brake torque per wheel is limited to this share of μ·Fz·R_w [-] (ideal distribution
    with an ABS-like margin below the tyre's peak, so full braking keeps steering)."""

    # --- numerics of the detailed model --------------------------------------------------------
    v_low: float = 0.5
    """Slip denominators are max(|v|, v_low) [m/s]: no division by a vanishing wheel speed."""
    v_blend: float = 0.5
    """Below ≈ this speed [m/s] lateral/yaw motion blends to the kinematic bicycle."""
    v_blend_width: float = 0.1
    """Width of the tanh blend around v_blend [m/s]."""
    tau_kin: float = 0.02
    """Relaxation time of vy, r towards their kinematic values in the blend [s]."""
    tau_load: float = 0.1
    """First-order lag of the load-transfer accelerations (pitch/roll of the body) [s]."""
    h_int: float = 0.005
    """Internal integration step [s] (see fourwheel.py for the halving test)."""

    @property
    def wheelbase(self) -> float:
        """a + b [m]."""
        return self.a + self.b

    def validate(self) -> None:
        """Raise :class:`InvalidParameterError` on a value outside its :data:`VEHICLE_RANGES`
        (NaN and ±inf included)."""
        _check_ranges(self, VEHICLE_RANGES)

    def with_overrides(self, mapping: Mapping[str, Any]) -> "VehicleParams":
        """A copy with the named fields replaced; unknown names raise :class:`UnknownParameterError`,
        bad values :class:`InvalidParameterError`."""
        return _override(self, mapping)


BICYCLE_RANGES: Mapping[str, Range] = {
    "l_f": Range(0.5, 10.0, "m"),
    "delta_max": Range(0.0, 1.5, "rad", lo_open=True, hi_open=True),
    "a_min": Range(-20.0, 0.0, "m/s²", hi_open=True),
    "a_max": Range(0.0, 20.0, "m/s²", lo_open=True),
    "v_max": Range(0.0, 100.0, "m/s", lo_open=True),
    "a_lat_max": Range(0.0, 30.0, "m/s²", lo_open=True),
}
"""Physically valid values of every :class:`BicycleParams` field (a car: the wheelbase-like
l_f of a city car to a bus; accelerations within what tyres deliver, μ ≤ 2)."""

VEHICLE_RANGES: Mapping[str, Range] = {
    "m": Range(100.0, 50_000.0, "kg"),
    "a": Range(0.1, 10.0, "m"),
    "b": Range(0.1, 10.0, "m"),
    "I_z": Range(10.0, 1e6, "kg·m²"),
    "T_f": Range(0.3, 5.0, "m"),
    "T_r": Range(0.3, 5.0, "m"),
    "h_cg": Range(0.0, 3.0, "m"),
    "R_w": Range(0.1, 2.0, "m"),
    "I_w": Range(0.01, 100.0, "kg·m²"),
    "length": Range(0.0, 30.0, "m", lo_open=True),
    "width": Range(0.0, 5.0, "m", lo_open=True),
    "mu": Range(0.05, 2.0, "-"),
    "B_x": Range(0.0, 100.0, "-", lo_open=True),
    "C_x": Range(0.0, 5.0, "-", lo_open=True),
    "D_x": Range(0.0, 5.0, "-", lo_open=True),
    "E_x": Range(-10.0, 1.0, "-"),
    "B_y": Range(0.0, 100.0, "1/rad", lo_open=True),
    "C_y": Range(0.0, 5.0, "-", lo_open=True),
    "D_y": Range(0.0, 5.0, "-", lo_open=True),
    "E_y": Range(-10.0, 1.0, "-"),
    "load_sensitivity": Range(0.0, 1.0, "-"),
    "c_rr": Range(0.0, 1.0, "-"),
    "rho_air": Range(0.0, 10.0, "kg/m³"),
    "cd_area": Range(0.0, 20.0, "m²"),
    "engine_force_max": Range(0.0, 1e6, "N", lo_open=True),
    "engine_power_max": Range(0.0, 1e7, "W", lo_open=True),
    "rear_drive_share": Range(0.0, 1.0, "-"),
    "brake_torque_max": Range(0.0, 1e5, "N·m"),
    "brake_friction_use": Range(0.0, 1.0, "-"),
    "v_low": Range(0.01, 10.0, "m/s"),
    "v_blend": Range(0.0, 20.0, "m/s"),
    "v_blend_width": Range(0.01, 10.0, "m/s"),
    "tau_kin": Range(0.001, 10.0, "s"),
    "tau_load": Range(0.001, 10.0, "s"),
    "h_int": Range(0.001, 0.02, "s"),
}
"""Physically valid values of every :class:`VehicleParams` field: a passenger car to a heavy
truck (mass, inertias, geometry), Magic-Formula factors of real tyres (E ≤ 1), and numerics
the integrator stays accurate with (an internal step of 1 to 20 ms)."""
