"""The YAML schemas of maps and scenarios (pydantic v2, the I/O boundary only).

Every value the user writes is validated here, each on its own: numbers are numbers (not
``true`` or quoted text), finite (NaN and ±inf are refused everywhere, by the models' config) and
within a physical range (coordinates within :data:`COORD_MAX`, times within :data:`TIME_MAX`, …).
What takes several values together — positions along lanes, the layout of roads and lanes,
routes, unique ids and rule names, vehicle parameters — the loader checks
(:mod:`twolevel.world.loader`, :mod:`twolevel.world.layout`). The runtime works on frozen
dataclasses and numpy arrays built from the validated models (:mod:`twolevel.world.world`).
Conventions: lengths in metres, speeds in m/s, times in seconds, **angles in degrees** (headings
are measured counter-clockwise from the x axis; a positive arc angle turns left). A lateral offset
is positive to the left of the direction the road is drawn in.

Defaults are the paper's (Aasi, Vasile, Belta 2021): H = 10, dt = 0.1 s, r = 0.3, D_safe = 1 m,
box 4.22 m × 1.8 m, l_f = 2.11 m (in ``ego.vehicle``, validated by the models package), IDM after
Treiber et al. (2000); r_near grows with the speed the scenario allows
(:data:`R_NEAR_HEADWAY`), the paper's 10 m its floor.

Imported by ``twolevel check``: pydantic and the standard library only (no numpy).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, Strict, field_validator, model_validator

__all__ = [
    "Arc", "Segment", "StartPose", "LaneSpec", "Road", "FreeLane", "MarkingSpec", "ZoneSpec", "ArmSpec",
    "ConnectionSpec", "SignalSpec", "JunctionSpec", "LaneKind", "LaneCategory", "MarkingKind", "ParticipantKind", "Point", "MAX_LANE_POINTS", "MIN_WIDTH", "SpeedLimitSign", "StopSign", "LightCycle",
    "LightStep", "TrafficLight", "MapFile", "LanePos", "Placement", "Box", "Ego", "RouteSpec",
    "IDMParams", "Waypoint", "MobilParams", "Manoeuvre", "Walk", "Participant", "Population", "RandomTrips", "SumoTraffic",
    "MANOEUVRE_ACTIONS", "TRIGGER_KEYS", "RuleRef", "ControllerSettings",
    "RunSettings", "WeightsSpec", "ScenarioFile", "KMH", "Number", "Count", "COORD_MAX", "DEFAULT_SENSOR_RANGE",
    "TIME_MAX", "CONST_MAX", "SEED_MAX", "S_MAX", "MIN_PIECE", "MIN_SPACING", "MAX_ROUTE_POINTS",
    "UserBoundsSpec", "PedestrianBoundsSpec", "ResponseSpec", "AssumptionsSpec",
    "GoalCriterion", "RoadCriterion", "R_NEAR_FLOOR", "R_NEAR_HEADWAY", "Expect", "NormalDist", "Parameter", "ParameterDeclarations", "Variant",
]

KMH = 1.0 / 3.6  # [m/s] per km/h
DEFAULT_SENSOR_RANGE = 100.0
"""[m] How far the ego senses the vehicles ahead by default (``controller.sensor_range``): the
detection range of an automotive camera, short of radar's 150–250 m. From 27 m/s (97 km/h) the
ego stops within it at RSS's 4 m/s², so the paper's scenarios (at most 14 m/s) sense far more
than they need; a faster scenario gets a ``twolevel check`` warning (YML431)."""
R_NEAR_FLOOR = 10.0
"""[m] The least default ``controller.r_near``: the paper's sensing radius."""
R_NEAR_HEADWAY = 2.0
"""[s] The default ``controller.r_near`` is the distance covered in this time headway (the
two-second rule) at the fastest speed the scenario lets the ego drive (the highest limit on its
route, capped by its desired speed, at least its start speed: :func:`twolevel.world.loader.fastest`),
at least :data:`R_NEAR_FLOOR` and at most the sensing range: 10 m below 5 m/s, 27.8 m at 50 km/h,
60 m at 30 m/s. (The paper's fixed 10 m is 0.3 s at motorway speed: a vehicle beside and ahead
of the ego enters it too late for the rules to act on it.)"""
IDM_V0_MAX = 120.0 * KMH  # [m/s] Treiber's desired speed, capped further by the lane's limit
COORD_MAX = 1e6  # [m] largest |x|, |y| of any point (a map 2000 km across)
TIME_MAX = 86_400.0  # [s] latest time in a light's script or a participant's waypoints (a day)
CONST_MAX = 1e6  # largest |value| a rule constant is bound to (metres, seconds, m/s: far beyond any)
SEED_MAX = 2**63 - 1  # largest seed (a 64-bit signed integer)
S_MAX = 1e7  # [m] largest distance along a lane (checked against the lane's length too)
MIN_PIECE = 0.01  # [m] shortest road segment, and least distance between consecutive polyline points
MIN_SPACING = 0.1  # [m] closest spacing of a route's reference points
MAX_ROUTE_POINTS = 20_000  # most reference points of a route (10 km at the default spacing)

Number = Annotated[float, Strict()]
"""A YAML number (an integer is fine). ``true``/``false`` and quoted text are refused; NaN and ±inf
are refused by every model's ``allow_inf_nan=False`` (with pydantic 2.14 a range such as ``ge=0``
alone lets +inf through, and a field without any bound lets NaN and ±inf through)."""
Count = Annotated[int, Strict()]
"""A YAML integer; ``true``/``false``, ``2.5`` and quoted text are refused."""


def _usable_path(text: str) -> str:
    if "\0" in text:
        raise ValueError("a path cannot contain a NUL character")
    return text


FilePath = Annotated[str, Field(min_length=1, max_length=4096), AfterValidator(_usable_path)]
"""A path of another file, relative to the file that names it (no NUL character)."""
Coord = Annotated[Number, Field(ge=-COORD_MAX, le=COORD_MAX)]
"""A coordinate [m] of a point in the plane."""
Along = Annotated[Number, Field(ge=0, le=S_MAX)]
"""A distance along a lane [m]."""
Speed = Annotated[Number, Field(ge=0, le=100)]
"""A speed [m/s]."""


class _Model(BaseModel):
    """Every model of a map or scenario: unknown keys refused, values immutable, and every
    number finite (NaN and ±inf are refused wherever a number goes, nested ones included)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


# ----------------------------------------------------------------------------------- maps


class Arc(_Model):
    """A circular arc continuing tangentially from the end of the previous segment."""

    radius: Number = Field(gt=0, le=1e5, description="radius of the arc [m]")
    angle: Number = Field(ge=-360, le=360, description="turning angle [deg], positive turns left")

    @model_validator(mode="after")
    def _nonzero(self) -> "Arc":
        if self.angle == 0:
            raise ValueError("an arc needs a non-zero angle [deg]; use 'line' for a straight piece")
        return self


class Segment(_Model):
    """One piece of a road's reference line: exactly one of ``line``, ``arc``, ``points``."""

    line: Number | None = Field(default=None, ge=MIN_PIECE, le=1e5, description="straight piece of this length [m]")
    arc: Arc | None = Field(default=None, description="circular arc {radius [m], angle [deg]}")
    points: list[tuple[Coord, Coord]] | None = Field(
        default=None, min_length=1, description="polyline through these absolute points [[x, y], …] [m]"
    )

    @model_validator(mode="after")
    def _exactly_one(self) -> "Segment":
        given = [k for k in ("line", "arc", "points") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError("a segment is exactly one of 'line: <length m>', 'arc: {radius, angle}' or 'points: [[x, y], …]'")
        return self


class StartPose(_Model):
    """Where a road's reference line starts."""

    x: Coord = Field(default=0.0, description="x [m]")
    y: Coord = Field(default=0.0, description="y [m]")
    heading: Number = Field(default=0.0, ge=-360, le=360, description="direction of the first segment [deg]")


LaneKind = Literal["driving", "shoulder", "parking", "bicycle", "bus", "sidewalk", "crosswalk", "restricted"]
"""Lane types (CommonRoad's lanelet types, OpenDRIVE's lane types, SUMO's vehicle classes, in short)."""
LaneCategory = Literal["interstate", "highway", "country", "urban", "main_carriageway", "access_ramp", "exit_ramp",
                       "drive_way", "intersection"]
"""What road a lane belongs to (CommonRoad's lanelet types beyond the lane's use; the interstate and
intersection rules ask for them). Carried for rules and exports; driving does not depend on it."""
MarkingKind = Literal["none", "dashed", "solid", "double_solid", "dashed_solid", "solid_dashed", "curb"]
"""Line markings, seen from the lane: a double line's first word is the line nearer to the lane
(``dashed_solid``: this lane may cross it, the lane across may not)."""
Point = tuple[Coord, Coord]
"""A point [x, y] [m]."""
MAX_LANE_POINTS = 100_000  # most points of a free-form lane's boundary or centre line
MIN_WIDTH = 0.1  # [m] narrowest a lane may be between its ends (which may taper to 0)
_USABLE = "part of the ego's drivable area; default: true for driving lanes only (declare a shoulder usable)"


class _LaneCommon(_Model):
    """What every lane may say of itself, besides its geometry."""

    type: LaneKind = Field(default="driving", description="driving, shoulder, parking, bicycle, bus, sidewalk, crosswalk or restricted")
    usable: bool | None = Field(default=None, description=_USABLE)
    speed_limit: Number | None = Field(default=None, gt=0, le=100, description="limit from the lane's start [m/s]")
    successors: list[str] = Field(default_factory=list, description="ids of lanes traffic continues into")
    left_marking: MarkingKind | None = Field(default=None, description="line on the lane's left boundary, whole length (default none)")
    right_marking: MarkingKind | None = Field(default=None, description="line on the lane's right boundary, whole length (default none)")
    categories: list[LaneCategory] = Field(
        default_factory=list, description="road categories: interstate, highway, country, urban, main_carriageway, "
                                          "access_ramp, exit_ramp, drive_way, intersection")


class LaneSpec(_LaneCommon):
    """A lane: the road's reference line shifted sideways, driven in one direction."""

    id: str = Field(min_length=1, description="lane id, unique in the map")
    offset: Number = Field(default=0.0, ge=-50, le=50, description="lateral offset from the reference line [m], + left")
    width: Number = Field(default=3.5, gt=0, le=10, description="lane width [m]")
    direction: Literal["forward", "backward"] = Field(
        default="forward", description="'forward': traffic drives the way the road is drawn; 'backward': against it"
    )


class Road(_Model):
    """A road: a reference line made of segments and the lanes along it."""

    id: str = Field(min_length=1, description="road id, unique in the map")
    start: StartPose = Field(default_factory=StartPose, description="start pose {x [m], y [m], heading [deg]}")
    segments: list[Segment] = Field(min_length=1, description="line / arc / points pieces, in order")
    lanes: list[LaneSpec] | None = Field(
        default=None, description="lanes along the road; default: one forward lane on the reference line, id = road id"
    )

    def lane_specs(self) -> list[LaneSpec]:
        """The road's lanes, with the single-lane default filled in."""
        return list(self.lanes) if self.lanes is not None else [LaneSpec(id=self.id)]


class FreeLane(_LaneCommon):
    """A free-form lane: its boundaries in its direction of travel, point by point (``left_bound[i]``
    faces ``right_bound[i]``, as in CommonRoad's lanelets), or its centre line and width."""

    id: str = Field(min_length=1, description="lane id, unique in the map")
    left_bound: list[Point] | None = Field(
        default=None, min_length=2, max_length=MAX_LANE_POINTS, description="left boundary [[x, y], …] [m], in the direction of travel")
    right_bound: list[Point] | None = Field(
        default=None, min_length=2, max_length=MAX_LANE_POINTS, description="right boundary [[x, y], …] [m], one point facing each left one")
    centre: list[Point] | None = Field(
        default=None, min_length=2, max_length=MAX_LANE_POINTS, description="centre line [[x, y], …] [m] (instead of the boundaries)")
    width: Number | None = Field(default=None, gt=0, le=20, description="with 'centre': the lane's width [m]")
    widths: list[Annotated[Number, Field(ge=0, le=20)]] | None = Field(
        default=None, max_length=MAX_LANE_POINTS, description="with 'centre': the width at each centre point [m] (instead of 'width')")
    adjacent_left: str | None = Field(default=None, description="the lane beside its left boundary (default: found where boundaries coincide)")
    adjacent_right: str | None = Field(default=None, description="the lane beside its right boundary (default: found where boundaries coincide)")

    @model_validator(mode="after")
    def _one_form(self) -> "FreeLane":
        bounds = self.left_bound is not None or self.right_bound is not None
        if bounds == (self.centre is not None):
            raise ValueError("a free-form lane is either 'left_bound' and 'right_bound' or 'centre' with 'width'")
        if bounds and (self.left_bound is None or self.right_bound is None):
            raise ValueError("give both 'left_bound' and 'right_bound'")
        if bounds and (self.width is not None or self.widths is not None):
            raise ValueError("'width' goes with 'centre'; with boundaries the width is the distance between them")
        if self.centre is not None and (self.width is None) == (self.widths is None):
            raise ValueError("a lane given by its 'centre' needs its 'width' [m] (or 'widths', one per centre point)")
        return self


class MarkingSpec(_Model):
    """A line marking along part of a lane's boundary (the lane across gets it too, mirrored)."""

    lane: str = Field(description="lane id")
    side: Literal["left", "right"] = Field(description="which boundary, in the lane's direction of travel")
    type: MarkingKind = Field(description="none, dashed, solid, double_solid, dashed_solid, solid_dashed or curb")
    s_range: tuple[Along, Along] | None = Field(default=None, description="[from, to] along the lane [m]; default the whole lane")

    @model_validator(mode="after")
    def _ordered(self) -> "MarkingSpec":
        if self.s_range is not None and self.s_range[0] > self.s_range[1]:
            raise ValueError("'s_range' must be [from, to] with from <= to")
        return self


class ZoneSpec(_Model):
    """A stretch of a lane (a no-overtaking zone: no passing over the oncoming lane)."""

    lane: str = Field(description="lane id")
    s_range: tuple[Along, Along] = Field(description="[from, to] along the lane [m]")

    @model_validator(mode="after")
    def _ordered(self) -> "ZoneSpec":
        if self.s_range[0] > self.s_range[1]:
            raise ValueError("'s_range' must be [from, to] with from <= to")
        return self


class ArmSpec(_Model):
    """A road meeting a junction with one of its ends."""

    road: str = Field(description="road id")
    end: Literal["start", "end"] = Field(description="which end of the road meets the junction")
    priority: Literal["priority", "yield", "stop", "signal"] = Field(
        description="priority road, yield, stop (sign and line) or signal (a light per incoming lane)")
    stop_time: Number = Field(default=1.0, ge=0, le=600, description="standstill a stop arm requires [s]")
    phase: Count | None = Field(default=None, ge=0, le=7, description="signal phase; default: opposite arms share one")


class ConnectionSpec(_Model):
    """A turning connection added (``allow: true``) or removed (``allow: false``)."""

    incoming: str = Field(description="lane entering the junction")
    outgoing: str = Field(description="lane leaving it")
    allow: bool = Field(default=True, description="true: build it; false: leave out the one the rules would build")


class SignalSpec(_Model):
    """The light program of a signalised junction: its phases in turn, each green, then yellow,
    then all red for the clearance."""

    green: Number = Field(gt=0, le=3600, description="green of each phase [s]")
    yellow: Number = Field(default=3.0, ge=0, le=60, description="yellow [s]")
    clearance: Number = Field(default=1.0, ge=0, le=60, description="all red between phases [s]")
    offset: Number = Field(default=0.0, ge=0, le=TIME_MAX, description="time into the cycle at t = 0 [s]")


class JunctionSpec(_Model):
    """A junction from a compact description: the roads meeting at it (which end, with which priority);
    the turning lanes, stop lines, lights and conflicts are built from it (twolevel/world/junction.py)."""

    id: str = Field(min_length=1, description="junction id")
    arms: list[ArmSpec] = Field(min_length=2, max_length=8, description="the roads meeting at the junction")
    signals: SignalSpec | None = Field(default=None, description="light program {green, yellow, clearance, offset} [s] of signal arms")
    u_turns: bool = Field(default=False, description="build U-turns (leftmost lane back into the same road)")
    min_radius: Number = Field(default=4.0, ge=1, le=1000, description="tightest turn a connecting lane may take [m]")
    setback: Number = Field(default=1.0, ge=0, le=50, description="stop lines this far before an arm's end [m]")
    speed_limit: Number | None = Field(default=None, gt=0, le=100, description="limit on the connecting lanes [m/s]; default the incoming lane's")
    connections: list[ConnectionSpec] = Field(default_factory=list, description="connections added or removed by hand")


class SpeedLimitSign(_Model):
    """A speed-limit sign: the limit holds from ``s`` on, until the next sign along the way."""

    id: str = Field(min_length=1, description="sign id")
    lane: str = Field(description="lane the sign applies to")
    s: Along = Field(description="position along the lane, in its direction of travel [m]")
    value: Number = Field(gt=0, le=100, description="the limit [m/s] (50 km/h = 13.89 m/s)")


class StopSign(_Model):
    """A stop sign and its stop line."""

    id: str = Field(min_length=1, description="sign id")
    lane: str = Field(description="lane whose traffic must stop")
    s: Along = Field(description="stop line position along the lane [m]")
    stop_time: Number = Field(default=1.0, ge=0, le=600, description="required standstill before the line [s]")


class LightCycle(_Model):
    """A fixed-time cycle green → yellow → red, repeating."""

    green: Number = Field(gt=0, le=3600, description="green phase [s]")
    yellow: Number = Field(default=3.0, ge=0, le=60, description="yellow phase [s]")
    red: Number = Field(gt=0, le=3600, description="red phase [s]")
    offset: Number = Field(default=0.0, ge=0, le=TIME_MAX, description="time into the cycle at t = 0 [s]")


class LightStep(_Model):
    """From time ``t`` on the light shows ``state`` (until the next step)."""

    t: Number = Field(ge=0, le=TIME_MAX, description="time [s]")
    state: Literal["green", "yellow", "red"] = Field(description="green, yellow or red")


class TrafficLight(_Model):
    """A traffic light and its stop line: exactly one of ``cycle`` or ``script``."""

    id: str = Field(min_length=1, description="light id")
    lane: str = Field(description="lane the light controls")
    s: Along = Field(description="stop line position along the lane [m]")
    cycle: LightCycle | None = Field(default=None, description="fixed-time cycle {green, yellow, red, offset} [s]")
    script: list[LightStep] | None = Field(default=None, min_length=1, description="scripted states [{t [s], state}]")

    @model_validator(mode="after")
    def _one_program(self) -> "TrafficLight":
        if (self.cycle is None) == (self.script is None):
            raise ValueError("a traffic light needs exactly one of 'cycle: {green, yellow, red}' or 'script: [{t, state}, …]'")
        if self.script is not None:
            ts = [step.t for step in self.script]
            if ts[0] != 0:
                raise ValueError("a light's script must start at t: 0")
            if any(b <= a for a, b in zip(ts, ts[1:])):
                raise ValueError("a light's script times must increase strictly")
        return self


class MapFile(_Model):
    """A map: roads with lanes, free-form lanes, markings, junctions, speed-limit signs, stop signs
    and traffic lights."""

    kind: Literal["map"] = Field(default="map", description="'map'")
    name: str = Field(default="", description="a name for reports")
    default_speed_limit: Number = Field(default=50 * KMH, gt=0, le=100, description="limit where no sign says otherwise [m/s]")
    roads: list[Road] = Field(default_factory=list, description="the roads")
    lanes: list[FreeLane] = Field(default_factory=list, description="free-form lanes (boundaries, or centre line and width)")
    markings: list[MarkingSpec] = Field(default_factory=list, description="line markings along parts of lane boundaries")
    no_overtaking: list[ZoneSpec] = Field(default_factory=list, description="no-overtaking zones {lane, s_range [m]}")
    junctions: list[JunctionSpec] = Field(default_factory=list, description="junctions built from the roads meeting there")
    speed_limits: list[SpeedLimitSign] = Field(default_factory=list, description="speed-limit signs")
    stop_signs: list[StopSign] = Field(default_factory=list, description="stop signs")
    traffic_lights: list[TrafficLight] = Field(default_factory=list, description="traffic lights")

    @model_validator(mode="after")
    def _some_lane(self) -> "MapFile":
        if not self.roads and not self.lanes:
            raise ValueError("a map needs 'roads' or free-form 'lanes' (at least one)")
        return self

    def lane_specs(self) -> list[LaneSpec | FreeLane]:
        """Every declared lane: each road's (:meth:`Road.lane_specs`), then the free-form ones."""
        return [ln for road in self.roads for ln in road.lane_specs()] + list(self.lanes)


# ------------------------------------------------------------------------------ scenarios


class LanePos(_Model):
    """A position given along a lane."""

    lane: str = Field(description="lane id")
    s: Along = Field(default=0.0, description="distance along the lane [m]")


class Placement(_Model):
    """A pose: either on a lane (``lane``, ``s``, ``lateral``) or free (``x``, ``y``, ``heading``)."""

    lane: str | None = Field(default=None, description="lane id")
    s: Along | None = Field(default=None, description="distance along the lane [m]")
    lateral: Number = Field(default=0.0, ge=-20, le=20, description="offset from the lane centre [m], + left")
    x: Coord | None = Field(default=None, description="x [m]")
    y: Coord | None = Field(default=None, description="y [m]")
    heading: Number | None = Field(default=None, ge=-360, le=360, description="heading [deg]")

    @model_validator(mode="after")
    def _one_form(self) -> "Placement":
        on_lane = self.lane is not None
        free = self.x is not None or self.y is not None
        if on_lane == free:
            raise ValueError("give either 'lane' (with 's' [m], 'lateral' [m]) or 'x', 'y' [m] with 'heading' [deg]")
        if free and (self.x is None or self.y is None or self.heading is None):
            raise ValueError("a free pose needs all of 'x' [m], 'y' [m] and 'heading' [deg]")
        return self


class Box(_Model):
    """A vehicle's bounding box, centred on its reference point."""

    length: Number = Field(default=4.22, ge=0.3, le=30, description="length [m]")
    width: Number = Field(default=1.8, ge=0.3, le=5, description="width [m]")


class Ego(_Model):
    """The controlled vehicle."""

    start: Placement = Field(description="initial pose")
    speed: Number = Field(default=0.0, ge=0, le=100, description="initial speed [m/s]")
    box: Box = Field(default_factory=Box, description="bounding box [m]")
    desired_speed: Number | None = Field(default=None, gt=0, le=100, description="cap on the desired speed [m/s]")
    vehicle: dict[str, Number] = Field(
        default_factory=dict, description="vehicle-parameter overrides by name (l_f, a_max, mu, …), each checked against its physical range (twolevel/models/params.py)"
    )


class RouteSpec(_Model):
    """The route from A to B; the reference path is built along it."""

    start: LanePos = Field(description="A: {lane, s [m]}")
    goal: LanePos = Field(description="B: {lane, s [m]}")
    via: list[str] | None = Field(default=None, min_length=1, max_length=1000, description="lanes from A's to B's, inclusive; default: shortest by successors")
    spacing: Number = Field(default=0.5, ge=MIN_SPACING, le=10, description="distance between reference points [m]")
    stop_at_goal: bool = Field(default=True, description="desired speed falls to 0 at B")


class IDMParams(_Model):
    """Intelligent Driver Model parameters (Treiber, Hennecke, Helbing 2000)."""

    v0: Number | None = Field(default=None, ge=0.1, le=100, description="desired speed [m/s]; default min(120 km/h, lane limit)")
    T: Number = Field(default=1.6, gt=0, le=10, description="time headway [s]")
    s0: Number = Field(default=2.0, ge=0, le=50, description="jam distance [m]")
    a: Number = Field(default=0.73, ge=0.1, le=10, description="maximum acceleration [m/s²]")
    b: Number = Field(default=1.67, ge=0.1, le=10, description="comfortable deceleration [m/s²]")
    delta: Number = Field(default=4.0, gt=0, le=10, description="acceleration exponent [-]")


class Waypoint(_Model):
    """A scripted participant is at (x, y) at time t; linear in between."""

    t: Number = Field(ge=0, le=TIME_MAX, description="time [s]")
    x: Coord = Field(description="x [m]")
    y: Coord = Field(description="y [m]")


Behaviour = Literal["stationary", "constant_velocity", "idm", "scripted"]
ParticipantKind = Literal["car", "truck", "bus", "motorcycle", "bicycle", "pedestrian", "parked", "other"]
"""What a participant is: bicycles are cyclists and pedestrians pedestrians to the safety layer's
assumptions (unless ``assumptions.road_users`` says otherwise), the rest vehicles; the kind also
sets the default behaviour, box and IDM parameters (:mod:`twolevel.world.participants`)."""
MANOEUVRE_ACTIONS = ("lane_change", "brake_to", "accelerate_to", "speed_profile", "follow_lane", "stop")
"""The manoeuvre primitives (one per ``manoeuvres:`` item)."""
TRIGGER_KEYS = ("at", "after", "after_start", "ego_within", "ego_headway")
"""What starts a manoeuvre or a walk (at most one per item; default: ``after: 0``)."""
_PARAMETERS = {"duration": ("lane_change",), "decel": ("brake_to", "accelerate_to", "follow_lane", "stop"),
               "accel": ("brake_to", "accelerate_to", "follow_lane"), "along": ("speed_profile",),
               "hold": ("follow_lane", "stop")}


class MobilParams(_Model):
    """MOBIL lane changes (Kesting, Treiber, Helbing 2007; their values are the defaults)."""

    politeness: Number = Field(default=0.5, ge=0, le=1, description="weight of the others' loss against one's gain [-]")
    threshold: Number = Field(default=0.1, ge=0, le=5, description="least net gain worth a change Δa_th [m/s²]")
    b_safe: Number = Field(default=4.0, gt=0, le=10, description="hardest braking a change may impose on the new follower [m/s²]")
    bias_right: Number = Field(default=0.3, ge=-2, le=2, description="keep-right bias Δa_bias [m/s²] (negative: keep left; 0: symmetric)")
    duration: Number = Field(default=4.0, ge=1, le=20, description="how long a lane change takes [s]")


def _triggers(item: BaseModel) -> list[str]:
    return [k for k in TRIGGER_KEYS if getattr(item, k, None) is not None]


class Manoeuvre(_Model):
    """One primitive of a scripted participant's chain: exactly one action with its parameters,
    started by at most one trigger (default: as soon as the previous one has ended). Speeds and
    lane changes follow the participant's lane; what it asks beyond the assumptions about its
    kind (twolevel/world/assumptions.py) is limited to them."""

    lane_change: str | None = Field(default=None, min_length=1, description="'left', 'right', or the id of the lane beside")
    brake_to: Speed | None = Field(default=None, description="slow down to this speed [m/s] at 'decel'")
    accelerate_to: Speed | None = Field(default=None, description="speed up to this speed [m/s] at 'accel'")
    speed_profile: list[tuple[Annotated[Number, Field(ge=0, le=TIME_MAX)], Speed]] | None = Field(
        default=None, min_length=1, max_length=1000,
        description="[[t or s, v], …]: speed [m/s] over time [s] or distance [m] since it started, linear in between")
    follow_lane: Speed | None = Field(default=None, description="keep the lane at this speed [m/s]")
    stop: Literal[True] | None = Field(default=None, description="true: brake to a standstill at 'decel' and stand")
    duration: Number | None = Field(default=None, ge=0.5, le=30, description="lane_change: how long it takes [s]; default 4")
    decel: Number | None = Field(default=None, gt=0, le=30, description="deceleration [m/s²]; default 3")
    accel: Number | None = Field(default=None, gt=0, le=30, description="acceleration [m/s²]; default 1.5")
    along: Literal["time", "distance"] = Field(default="time", description="speed_profile: its first column is time [s] or distance [m]")
    hold: Number | None = Field(default=None, ge=0, le=TIME_MAX, description="follow_lane / stop: lasts at least this long [s]")
    at: Number | None = Field(default=None, ge=0, le=TIME_MAX, description="start at this time [s]")
    after: Number | None = Field(default=None, ge=0, le=TIME_MAX, description="start this long after the previous one ended [s]")
    after_start: Number | None = Field(default=None, ge=0, le=TIME_MAX, description="start this long after the previous one started [s]")
    ego_within: Number | None = Field(default=None, gt=0, le=1000, description="start when the ego comes within this distance [m]")
    ego_headway: Number | None = Field(default=None, gt=0, le=60, description="start when the ego's distance / its speed drops below this [s]")

    @property
    def action(self) -> str:
        """The action's key."""
        return next(k for k in MANOEUVRE_ACTIONS if getattr(self, k) is not None)

    @model_validator(mode="after")
    def _one_action(self) -> "Manoeuvre":
        given = [k for k in MANOEUVRE_ACTIONS if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"a manoeuvre is exactly one of {', '.join(MANOEUVRE_ACTIONS)} (got "
                             f"{', '.join(given) or 'none'})")
        if len(_triggers(self)) > 1:
            raise ValueError(f"a manoeuvre has at most one trigger of {', '.join(TRIGGER_KEYS)}")
        for name, actions in _PARAMETERS.items():
            if name in self.model_fields_set and given[0] not in actions:
                raise ValueError(f"'{name}' belongs to {' / '.join(actions)}, not to {given[0]}")
        xs = [x for x, _ in self.speed_profile or []]
        if any(b <= a for a, b in zip(xs, xs[1:])):
            raise ValueError("a speed profile's times or distances must increase strictly")
        return self


class Walk(_Model):
    """A pedestrian's walk: across the road at a point of a lane (``lane``, ``s``: from the kerb
    on ``side`` to the other side of the road), or straight on from its ``start`` pose for
    ``distance``; it waits at the kerb for a ``gap`` in the traffic unless that is 0."""

    lane: str | None = Field(default=None, description="lane whose road it crosses")
    s: Along | None = Field(default=None, description="where along that lane it crosses [m]")
    side: Literal["right", "left"] = Field(default="right", description="the kerb it starts from, seen in the lane's direction")
    distance: Number | None = Field(default=None, gt=0, le=1000, description="walk straight on from 'start' this far [m]")
    speed: Number = Field(default=1.4, gt=0, le=15, description="walking speed [m/s]")
    gap: Number = Field(default=2.0, ge=0, le=60, description="margin [s] it keeps between walking past a lane and the next vehicle there; 0: steps out without looking")
    crosswalk: bool = Field(default=False, description="a marked crossing: vehicles stop for a pedestrian waiting at it")
    at: Number | None = Field(default=None, ge=0, le=TIME_MAX, description="sets off (to the kerb, then across) at this time [s]")
    ego_within: Number | None = Field(default=None, gt=0, le=1000, description="sets off when the ego comes within this distance [m]")
    ego_headway: Number | None = Field(default=None, gt=0, le=60, description="sets off when the ego's distance / its speed drops below this [s]")

    @model_validator(mode="after")
    def _one_path(self) -> "Walk":
        crossing = self.lane is not None or self.s is not None
        if crossing == (self.distance is not None) or (crossing and (self.lane is None or self.s is None)):
            raise ValueError("a walk is either across the road at 'lane' and 's' [m], or 'distance' [m] straight on from 'start'")
        if len(_triggers(self)) > 1:
            raise ValueError("a walk has at most one trigger of at, ego_within, ego_headway")
        return self


class Participant(_Model):
    """Another traffic participant: a vehicle, cyclist, pedestrian or parked car."""

    id: str = Field(min_length=1, description="participant id")
    kind: ParticipantKind = Field(default="car", description="car, truck, bus, motorcycle, bicycle, pedestrian, parked or other")
    behaviour: Behaviour | None = Field(
        default=None, description="stationary, constant_velocity, idm or scripted; default by kind: idm (vehicles, bicycles), "
                                  "stationary (parked), a walk (pedestrian), scripted with 'manoeuvres'")
    start: Placement | None = Field(default=None, description="initial pose (not for waypoints or a walk across a lane)")
    speed: Number = Field(default=0.0, ge=0, le=100, description="initial speed [m/s]")
    box: Box = Field(default_factory=Box, description="bounding box [m]; default by kind (cyclist 1.8 × 0.65, pedestrian 0.5 × 0.6)")
    idm: IDMParams = Field(default_factory=IDMParams, description="IDM parameters (behaviour idm); a cyclist's default v0 5 m/s, T 1 s, s0 1.5 m, a 1, b 1.5")
    mobil: MobilParams | None = Field(default=None, description="MOBIL lane changes (behaviour idm): true, or {politeness, threshold, b_safe, bias_right, duration}")
    critical_gap: Number = Field(default=6.5, ge=0, le=30, description="time gap [s] accepted in priority traffic after a stop sign")
    waypoints: list[Waypoint] | None = Field(default=None, min_length=2, description="[{t [s], x [m], y [m]}] (scripted)")
    manoeuvres: list[Manoeuvre] | None = Field(default=None, min_length=1, max_length=100, description="primitives in order (scripted along its lane)")
    walk: Walk | None = Field(default=None, description="a pedestrian's walk {lane, s, side | distance; speed, gap, crosswalk, trigger}")

    @field_validator("mobil", mode="before")
    @classmethod
    def _mobil_switch(cls, value: Any) -> Any:
        return _switch(value)

    @property
    def behaviour_of(self) -> str:
        """The behaviour, with the kind's default filled in ('walk' for a pedestrian's walk)."""
        if self.behaviour is not None:
            return self.behaviour
        if self.walk is not None:
            return "walk"
        if self.manoeuvres is not None:
            return "scripted"
        return "stationary" if self.kind in ("parked", "pedestrian") else "idm"

    @model_validator(mode="after")
    def _fits_behaviour(self) -> "Participant":
        b = self.behaviour_of
        if self.kind == "parked" and b != "stationary":
            raise ValueError("a parked car is stationary: leave out 'behaviour' (or give 'stationary')")
        if self.kind == "pedestrian" and b not in ("walk", "stationary", "scripted"):
            raise ValueError("a pedestrian walks ('walk: {…}'), stands, or follows waypoints")
        if self.walk is not None and (self.kind != "pedestrian" or self.behaviour is not None):
            raise ValueError("'walk' is a pedestrian's (kind: pedestrian, no 'behaviour')")
        if self.mobil is not None and b != "idm":
            raise ValueError("'mobil' lane changes are for idm participants")
        if b == "scripted":
            if (self.waypoints is None) == (self.manoeuvres is None):
                raise ValueError("a scripted participant needs either 'waypoints: [{t, x, y}, …]' or 'manoeuvres: [...]'")
            if self.waypoints is not None:
                ts = [w.t for w in self.waypoints]
                if any(b2 <= a for a, b2 in zip(ts, ts[1:])):
                    raise ValueError("waypoint times must increase strictly")
            elif self.start is None or self.start.lane is None:
                raise ValueError("a participant with manoeuvres follows a lane: give 'start: {lane, s}'")
        elif self.waypoints is not None or self.manoeuvres is not None:
            raise ValueError(f"'waypoints' and 'manoeuvres' are for scripted participants, not {b}")
        if b == "walk":
            assert self.walk is not None
            if self.walk.distance is not None and (self.start is None or self.start.heading is None):
                raise ValueError("a walk of a 'distance' starts from a free pose: give 'start: {x, y, heading}'")
            if self.walk.lane is not None and self.start is not None:
                raise ValueError("a walk across a lane starts at the kerb by itself: leave out 'start'")
        elif b != "scripted" and self.start is None:
            raise ValueError(f"a {b} participant needs 'start'")
        if b == "idm" and (self.start is None or self.start.lane is None):
            raise ValueError("an idm participant follows a lane: give 'start: {lane, s}'")
        return self


class Population(_Model):
    """``count`` vehicles spread over lanes, placed deterministically from a seed."""

    id: str = Field(min_length=1, description="prefix of the generated ids (id-0, id-1, …)")
    count: Count = Field(ge=1, le=5000, description="number of vehicles")
    lanes: list[str] = Field(min_length=1, description="lanes to place them on")
    s_range: tuple[Along, Along] | None = Field(default=None, description="[from, to] along each lane [m]; default whole lane")
    speed_range: tuple[Speed, Speed] = Field(default=(20.0, 30.0), description="initial speeds drawn uniformly [m/s]")
    kind: Literal["car", "truck", "bus", "motorcycle", "bicycle", "other"] = Field(default="car", description="car, truck, bus, motorcycle, bicycle or other (bicycles keep right, with a cyclist's IDM defaults)")
    behaviour: Literal["stationary", "constant_velocity", "idm"] = Field(default="idm", description="behaviour of all")
    min_gap: Number = Field(default=8.0, ge=0, le=500, description="minimum bumper-to-bumper gap when placing [m]")
    box: Box = Field(default_factory=Box, description="bounding box of each [m]")
    idm: IDMParams = Field(default_factory=IDMParams, description="IDM parameters")
    mobil: MobilParams | None = Field(default=None, description="MOBIL lane changes: true, or {politeness, threshold, b_safe, bias_right, duration}")
    critical_gap: Number = Field(default=6.5, ge=0, le=30, description="time gap [s] accepted in priority traffic after a stop sign")
    seed: Count | None = Field(default=None, ge=0, le=SEED_MAX, description="placement seed; default: the run's seed")

    @field_validator("mobil", mode="before")
    @classmethod
    def _mobil_switch(cls, value: Any) -> Any:
        return _switch(value)

    @model_validator(mode="after")
    def _ranges(self) -> "Population":
        if self.mobil is not None and self.behaviour != "idm":
            raise ValueError("'mobil' lane changes are for idm populations")
        for name in ("s_range", "speed_range"):
            r = getattr(self, name)
            if r is not None and (r[0] > r[1] or r[0] < 0):
                raise ValueError(f"'{name}' must be [low, high] with 0 <= low <= high")
        return self


class RandomTrips(_Model):
    """SUMO vehicles on random routes: ``vehicles`` are kept on the network, each one that arrives
    replaced by a new one between two edges drawn from the seed."""

    vehicles: Count = Field(ge=1, le=20_000, description="vehicles kept on the network")


class SumoTraffic(_Model):
    """Other vehicles driven by SUMO in the same process (libsumo), the ego moved in SUMO each step
    as CARLA's co-simulation does (twolevel/sim/cosim.py). The map should be the network's
    import (``twolevel import NET.net.xml``), so that lanes and lights agree."""

    engine: Literal["sumo"] = Field(description="'sumo'")
    net: FilePath = Field(description="the SUMO network (.net.xml), relative to the scenario")
    routes: list[FilePath] = Field(default_factory=list, description="SUMO route files (vehicles, routes, flows, trips)")
    random_trips: RandomTrips | None = Field(default=None, description="vehicles on random routes {vehicles}")
    seed: Count | None = Field(default=None, ge=0, le=2**31 - 1, description="SUMO's seed and the trips'; default: the run's")
    radius: Number = Field(default=100.0, gt=0, le=2000, description="SUMO vehicles within this distance of the ego are read [m]")
    slots: Count = Field(default=64, ge=1, le=1000, description="most SUMO vehicles near the ego the loop sees (the nearest)")
    box: Box = Field(default_factory=lambda: Box(length=5.0, width=1.8),
                     description="bounding box of SUMO's vehicles as the controller sees them [m] (SUMO's passenger car)")


class RuleRef(_Model):
    """A rule file and the values of its constants."""

    file: FilePath = Field(description="path of the .stl file, relative to the scenario")
    constants: dict[str, Annotated[Number, Field(ge=-CONST_MAX, le=CONST_MAX)]] = Field(
        default_factory=dict, description=f"constant name → value (a finite number, at most {CONST_MAX:g} in size)")

    @model_validator(mode="before")
    @classmethod
    def _plain_path(cls, data: Any) -> Any:
        return {"file": data} if isinstance(data, str) else data


class WeightsSpec(_Model):
    """The MPC's cost weights (the paper's: all 1)."""

    u: Number = Field(default=1.0, ge=0, le=1e4, description="weight on ‖u_k‖² (δ [rad], a [m/s²])")
    du: Number = Field(default=1.0, ge=0, le=1e4, description="weight on ‖u_k − u_(k−1)‖²")
    track: list[Annotated[Number, Field(ge=0, le=1e4)]] = Field(
        default_factory=lambda: [1.0, 1.0, 1.0, 1.0], min_length=4, max_length=4,
        description="weights on the tracking error of x, y, psi, v")


class ControllerSettings(_Model):
    """The two-level controller's settings; defaults are the paper's."""

    H: Count = Field(default=10, ge=1, le=100, description="MPC horizon [steps]")
    dt: Number = Field(default=0.1, ge=0.01, le=1, description="control period [s]")
    r_near: Number | None = Field(default=None, gt=0, le=200,
                                  description="sensing radius for nearby vehicles, signs, lights [m] (default: "
                                              "R_NEAR_HEADWAY [s] at the fastest speed the scenario allows, "
                                              "at least R_NEAR_FLOOR [m], at most the sensing range)")
    r: Number = Field(default=0.3, gt=0, le=10, description="radius of the ball sampled around u* by the low level [-]")
    D_safe: Number = Field(default=1.0, ge=0, le=50, description="collision_free distance at the high level [m]")
    samples: Count = Field(default=200, ge=0, le=10_000, description="low-level sampling budget [controls]")
    time_limit: Number = Field(default=0.1, gt=0, le=60, description="solver time limit per step [s]")
    solver: Literal["modes", "highs"] = Field(default="modes", description="'modes' (mode search, Clarabel) or 'highs' (MILP)")
    stop_speed: Number = Field(default=0.1, gt=0, le=5, description="speed counted as standing still [m/s]")
    yellow_decel: Number = Field(default=3.0, gt=0, le=15, description="deceleration that decides 'can stop at yellow' [m/s²]")
    horizon_s: Number | None = Field(default=None, gt=0, le=30,
                                     description="MPC look-ahead [s]: H steps of dt, then coarse steps (default 5 s)")
    coarse_dt: Number | None = Field(default=None, gt=0, le=10,
                                     description="length of each coarse step after the first H [s] (default 5·dt)")
    coarse_steps: list[Annotated[Number, Field(gt=0, le=10)]] | None = Field(
        default=None, max_length=50, description="the coarse steps' lengths [s], each a whole number of dt")
    sensor_range: Number | None = Field(default=None, gt=0, le=1000,
                                        description="how far the ego senses vehicles ahead [m] (default max(100, r_near))")
    rss: bool = Field(default=True, description="plan to keep RSS's safe distance behind the vehicle ahead")
    rss_brake: Number = Field(default=4.0, gt=0, le=15,
                              description="the ego's braking in its RSS distance and sensing speed bound [m/s²]")
    rss_response: Number | None = Field(default=None, ge=0, le=5,
                                        description="the ego's response time in its RSS distance [s] (default dt)")
    comfort_accel: Number = Field(default=2.0, gt=0, le=10,
                                  description="the desired speed's comfort acceleration [m/s²] (twolevel/world/speed_profile.py)")
    comfort_decel: Number = Field(default=2.0, gt=0, le=10,
                                  description="the desired speed's comfort deceleration before bends, limits, the goal [m/s²]")
    comfort_jerk: Number = Field(default=2.0, gt=0, le=50,
                                 description="how fast the desired speed's braking builds up [m/s³]")
    comfort_lat_accel: Number = Field(default=2.0, gt=0, le=10,
                                      description="lateral acceleration the desired speed allows in bends [m/s²]")
    v2i: Annotated[bool, Strict()] = Field(default=False, description="the planner knows the lights' programs (true) or only their state now")
    weights: WeightsSpec = Field(default_factory=lambda: WeightsSpec(),
                                 description="the MPC's cost weights {u, du, track: [x, y, psi, v]} (the paper's: all 1)")
    margins: dict[str, Annotated[Number, Field(ge=0, le=CONST_MAX)]] | None = Field(
        default=None, description="rule name → how far inside its bound the plan keeps that rule, in the rule's own "
                                  "units (default {clear_junction: 0.2}; a map given replaces it)")


class RunSettings(_Model):
    """The closed-loop run."""

    duration: Number = Field(default=60.0, gt=0, le=36000, description="simulated time [s]")
    seed: Count = Field(default=0, ge=0, le=SEED_MAX, description="seed of every random choice")


_ASSUMPTIONS = "defaults and sources: twolevel/world/assumptions.py"


def _bound(gt: float, le: float, what: str) -> Any:
    return Field(default=None, gt=gt, le=le, allow_inf_nan=False, description=what)


class UserBoundsSpec(_Model):
    """Assumed bounds of vehicles or cyclists; what is left out keeps its default."""

    v_max: Number | None = _bound(0, 150, "speed bound [m/s]; default vehicle 83.33, cyclist 12.5")
    speed_factor: Number | None = _bound(0, 10, "v ≤ speed_factor · limit in force [-]; default vehicle 1.2, cyclist none")
    a_max: Number | None = _bound(0, 30, "largest |acceleration|, braking and driving [m/s²]; default vehicle 8, cyclist 6")
    v_switch: Number | None = _bound(0, 100, "above it drive acceleration ≤ a_max·v_switch/v [m/s]; default 7.319, cyclist 2")
    lane_changes: bool | None = Field(default=None, description="may move to parallel lanes of its direction; default true")
    stop_lines: bool | None = Field(default=None, description="stops at stop signs' lines it can stop for; default true")
    red_lights: bool | None = Field(default=None, description="does not cross a red light it can stop for; default true")


class PedestrianBoundsSpec(_Model):
    """Assumed bounds of pedestrians (any heading, not lane-bound)."""

    v_max: Number | None = _bound(0, 15, "speed bound [m/s]; default 2")
    a_max: Number | None = _bound(0, 15, "largest |acceleration| [m/s²]; default 0.6")


class ResponseSpec(_Model):
    """RSS's response of other road users (followers keep this distance behind the ego)."""

    time: Number | None = _bound(0, 10, "response time ρ [s]; default 2")
    accel_max: Number | None = _bound(0, 30, "acceleration during the response [m/s²]; default 3.5")
    brake_min: Number | None = _bound(0, 30, "braking at least, after the response [m/s²]; default 4")
    brake_max: Number | None = _bound(0, 30, "braking at most of the vehicle ahead [m/s²]; default 8")


class AssumptionsSpec(_Model):
    """What the safety layer assumes of other road users (its guarantee holds while they keep it)."""

    vehicle: UserBoundsSpec | None = Field(default=None, description=f"vehicles' bounds ({_ASSUMPTIONS})")
    cyclist: UserBoundsSpec | None = Field(default=None, description=f"cyclists' bounds ({_ASSUMPTIONS})")
    pedestrian: PedestrianBoundsSpec | None = Field(default=None, description=f"pedestrians' bounds ({_ASSUMPTIONS})")
    response: ResponseSpec | None = Field(default=None, description="RSS response {time [s], accel_max, brake_min, brake_max [m/s²]}")
    road_users: dict[str, Literal["vehicle", "cyclist", "pedestrian"]] = Field(
        default_factory=dict, description="participant or population id → vehicle, cyclist or pedestrian (default vehicle)")


# ------------------------------------------------- pass criteria, parameters and variants

Finite = Number  # a number (not true or text), finite like every number of a scenario
PARAM_MAX = 1e9
"""Largest |value| of a parameter's range, choices, mean, default or a variant's value: whatever a
field allows is far inside, and sampling between two of them cannot overflow."""
ParamValue = Annotated[Number, Field(ge=-PARAM_MAX, le=PARAM_MAX)]


def _switch(value: Any) -> Any:
    """``true`` → the criterion with its defaults, ``false`` → off (None)."""
    if value is True:
        return {}
    if value is False:
        return None
    return value


class GoalCriterion(_Model):
    """Reach the route's goal: stand still at it (a route that stops there) or pass it."""

    by: Finite | None = Field(default=None, gt=0, le=36000, description="deadline [s]; default: within the run")
    after: Finite | None = Field(default=None, ge=0, le=36000, description="earliest arrival [s] (a time window with 'by')")

    @model_validator(mode="after")
    def _window(self) -> "GoalCriterion":
        if self.after is not None and self.by is not None and self.after > self.by:
            raise ValueError("'after' must not be later than 'by'")
        return self


class RoadCriterion(_Model):
    """Stay inside the drivable area: every corner of the ego's box within the lanes."""

    boundary: Literal["road", "lane", "area"] = Field(
        default="road", description="'road': any lane of the road (not sidewalks, crosswalks, cycle lanes); 'lane': the "
                                    "lanes of the route only; 'area': the route's drivable area (its lane, the lanes beside "
                                    "it the markings let it change to, the oncoming lane where passing is allowed)")
    tolerance: Finite = Field(default=0.5, ge=0, le=50, description="how far a corner may stray outside [m]")


class Expect(_Model):
    """Pass criteria of a run (:mod:`twolevel.verdict.criteria` judges them after the run).

    Absent, a run must reach its goal, stay on the road, collide with nothing (at fault) and
    keep every rule; ``goal: false``, ``on_road: false`` or ``no_collision: false`` turn one off.
    The bounds are off unless given.
    """

    goal: GoalCriterion | None = Field(default_factory=GoalCriterion, description="reach the goal {by [s]}; false: not judged")
    on_road: RoadCriterion | None = Field(
        default_factory=RoadCriterion, description="stay inside {boundary: road|lane, tolerance [m]}; false: not judged")
    no_collision: bool = Field(default=True, description="no collision the ego is at fault for")
    rules: Literal["all"] | list[str] = Field(default="all", description="rules that must hold: all, or a list of names")
    max_decel: Finite | None = Field(default=None, gt=0, le=100, description="peak deceleration [m/s²]")
    max_jerk: Finite | None = Field(default=None, gt=0, le=1000, description="peak |jerk| [m/s³]")
    max_lat_accel: Finite | None = Field(default=None, gt=0, le=100, description="peak |lateral acceleration| [m/s²]")
    min_gap: Finite | None = Field(default=None, ge=-10, le=100, description="smallest box gap to any vehicle [m]")
    max_stopped: Finite | None = Field(default=None, ge=0, le=36000, description="longest standstill before the goal [s]")

    @field_validator("goal", "on_road", mode="before")
    @classmethod
    def _on_off(cls, value: Any) -> Any:
        return _switch(value)


class NormalDist(_Model):
    """A normal distribution (truncated to the parameter's ``range`` when one is given)."""

    mean: ParamValue = Field(description="mean")
    std: ParamValue = Field(gt=0, description="standard deviation")


class Parameter(_Model):
    """A scenario parameter, referenced as ``${name}`` (or an expression of parameters) from any
    numeric field: a ``range`` (uniform; grids take ``steps`` points), ``choices``, or a
    ``normal`` distribution (truncated to ``range`` if both are given)."""

    range: tuple[ParamValue, ParamValue] | None = Field(default=None, description="[low, high]")
    choices: list[ParamValue] | None = Field(default=None, min_length=1, description="the values it may take")
    normal: NormalDist | None = Field(default=None, description="{mean, std}; truncated to range if given")
    steps: Count = Field(default=5, ge=1, le=1000, description="grid points across the range (sweep --grid)")
    default: ParamValue | None = Field(default=None, description="nominal value; default: middle / first choice / mean")
    integer: bool = Field(default=False, description="round drawn values to whole numbers")

    @model_validator(mode="after")
    def _one_domain(self) -> "Parameter":
        if self.choices is not None and (self.range is not None or self.normal is not None):
            raise ValueError("a parameter has either 'choices' or a 'range' / 'normal' distribution, not both")
        if self.choices is None and self.range is None and self.normal is None:
            raise ValueError("a parameter needs 'range: [low, high]', 'choices: [...]' or 'normal: {mean, std}'")
        if self.range is not None and self.range[0] > self.range[1]:
            raise ValueError("'range' must be [low, high] with low <= high")
        d = self.default
        if d is not None and self.choices is not None and d not in self.choices:
            raise ValueError(f"the default {d:g} is not one of the choices")
        if d is not None and self.range is not None and not self.range[0] <= d <= self.range[1]:
            raise ValueError(f"the default {d:g} is outside the range")
        return self

    def nominal(self) -> float:
        """The value used when none is given: ``default``, else the middle of the range, the
        first choice or the mean (clipped to the range)."""
        if self.default is not None:
            value = self.default
        elif self.choices is not None:
            value = self.choices[0]
        elif self.normal is not None:
            value = self.normal.mean
            if self.range is not None:
                value = min(max(value, self.range[0]), self.range[1])
        else:
            assert self.range is not None
            value = 0.5 * (self.range[0] + self.range[1])
        return float(round(value)) if self.integer else float(value)


class ParameterDeclarations(_Model):
    """The ``parameters:`` of a scenario alone, validated before anything refers to them."""

    parameters: dict[str, Parameter] = Field(default_factory=dict, description="parameters referenced as ${name}")


class Variant(_Model):
    """A named case of the scenario for ``twolevel test``: parameter values, a seed, criteria."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.\-]+$", description="name (letters, digits, _ . -)")
    parameters: dict[str, ParamValue] = Field(default_factory=dict, description="parameter name → value")
    seed: Count | None = Field(default=None, ge=0, le=SEED_MAX, description="seed of this case; default: the scenario's")
    expect: Expect | None = Field(default=None, description="pass criteria of this case; default: the scenario's")


class ScenarioFile(_Model):
    """A scenario: map, ego, route, other traffic, rules, controller and run settings."""

    kind: Literal["scenario"] = Field(default="scenario", description="'scenario'")
    name: str = Field(default="", description="a name for reports")
    extends: FilePath | None = Field(default=None, description="a base scenario this one overrides (relative path)")
    map: FilePath = Field(description="path of the map, relative to this file")
    ego: Ego = Field(description="the controlled vehicle")
    route: RouteSpec = Field(description="route from A to B")
    participants: list[Participant] = Field(default_factory=list, description="other traffic, one by one")
    populations: list[Population] = Field(default_factory=list, description="other traffic, by the lane-full")
    traffic: SumoTraffic | None = Field(default=None, description="more traffic from another engine {engine: sumo, net, …}")
    rules: list[RuleRef] = Field(default_factory=list, description="rule files and constant bindings")
    controller: ControllerSettings = Field(default_factory=ControllerSettings, description="controller settings")
    run: RunSettings = Field(default_factory=RunSettings, description="run settings")
    assumptions: AssumptionsSpec | None = Field(default=None, description="assumptions about other road users (safety layer)")
    expect: Expect = Field(default_factory=Expect, description="pass criteria of a run")
    parameters: dict[str, Parameter] = Field(default_factory=dict, description="parameters referenced as ${name}")
    variants: list[Variant] = Field(default_factory=list, description="named cases run by 'twolevel test'")

    @field_validator("parameters")
    @classmethod
    def _parameter_names(cls, value: dict[str, Parameter]) -> dict[str, Parameter]:
        bad = [k for k in value if not k.isidentifier()]
        if bad:
            raise ValueError(f"parameter names must be identifiers (letters, digits, _): {', '.join(bad)}")
        return value
