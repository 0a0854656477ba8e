"""Loading maps and scenarios: YAML → validated pydantic models, or diagnostics with positions.

``load_map(path)`` and ``load_scenario(path)`` return the loaded value (or None) and every
diagnostic found; ``check_world_file(path)`` is what ``twolevel check`` calls for a ``.yaml``
file (for a scenario it also lints the rule files it names). A scenario refers to its map, its
rule files and the scenario it ``extends`` by paths relative to the file that says so.

Imported by ``twolevel check``: pydantic, PyYAML and the standard library only (no numpy).
"""

from __future__ import annotations

import difflib
import os
import re
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Literal, Mapping

from pydantic import BaseModel, ValidationError

from twolevel.diagnostics import Code, Diagnostic, Span
from twolevel.world.codes import (
    YML410, YML411, YML412, YML413, YML414, YML415, YML416, YML417, YML418, YML419, YML420, YML421,
    YML423, YML428, YML430, YML435, YML436,
)
from twolevel.world.document import Document, Path_, read_document
from twolevel.world.junction import plan_junctions
from twolevel.world.layout import check_layout, lane_lengths
from twolevel.world.parameters import check_variants, explain, substitute
from twolevel.world.schema import (DEFAULT_SENSOR_RANGE, MAX_ROUTE_POINTS, R_NEAR_FLOOR, R_NEAR_HEADWAY, MapFile,
                                   ParameterDeclarations, ScenarioFile)
from twolevel.world.scripts import check_scripts

if typing.TYPE_CHECKING:
    from twolevel.world.assumptions import ResponseBounds

__all__ = ["Map", "Scenario", "RuleFile", "Sensing", "load_map", "load_scenario", "check_world_file", "file_kind",
           "sensing_of", "fastest", "near_radius", "successors", "all_lengths"]


@dataclass(frozen=True)
class Map:
    """A validated map and where it came from."""

    spec: MapFile
    path: str


@dataclass(frozen=True)
class RuleFile:
    """A rule file named by a scenario (absolute path) and its constant bindings."""

    path: str
    constants: tuple[tuple[str, float], ...]
    span: Span


@dataclass(frozen=True)
class Scenario:
    """A validated scenario with its map resolved and its rule files located."""

    spec: ScenarioFile
    path: str
    map: Map
    rules: tuple[RuleFile, ...]


Kind = Literal["map", "scenario"]


def file_kind(data: dict[str, Any]) -> Kind | None:
    """``kind:`` if given, else guessed from the shape (``roads``/``lanes`` → map; ``ego``/``route``
    → scenario)."""
    kind = data.get("kind")
    if kind in ("map", "scenario"):
        return kind
    if "roads" in data or "lanes" in data:
        return "map"
    if "ego" in data or "route" in data or "map" in data:
        return "scenario"
    return None


# ------------------------------------------------------------ pydantic errors → diagnostics

_TYPE_WORDS = {
    "float": "a number", "int": "a whole number", "bool": "true or false", "string": "text",
    "list": "a list", "tuple": "a list", "dict": "a mapping (key: value)", "model": "a mapping (key: value)",
    "model_attributes": "a mapping (key: value)", "none": "nothing (null)",
}
_RANGE = {"greater_than": ("gt", ">"), "greater_than_equal": ("ge", ">="), "less_than": ("lt", "<"),
          "less_than_equal": ("le", "<=")}


def _unwrap(ann: Any) -> Any:
    args = [a for a in typing.get_args(ann) if a is not type(None)]
    if typing.get_origin(ann) in (typing.Union, getattr(__import__("types"), "UnionType", None)) and len(args) == 1:
        return args[0]
    return ann


def _model_at(root: type[BaseModel], loc: Path_) -> Any:
    """The annotation the schema expects at ``loc`` (a model class, a list type, …) or None."""
    ann: Any = root
    for part in loc:
        ann = _unwrap(ann)
        origin = typing.get_origin(ann)
        if isinstance(part, str) and isinstance(ann, type) and issubclass(ann, BaseModel):
            field = ann.model_fields.get(part)
            if field is None:
                return None
            ann = field.annotation
        elif isinstance(part, int) and origin in (list, tuple):
            ann = typing.get_args(ann)[0]
        elif origin is dict:
            ann = typing.get_args(ann)[1]
        else:
            return None
    return _unwrap(ann)


def _description(root: type[BaseModel], loc: Path_) -> str:
    """The description of the field at ``loc``, or of the nearest field holding it (a point of a
    polyline is described by ``points``, a vehicle override by ``vehicle``)."""
    for n in range(len(loc), 0, -1):
        parent = _model_at(root, loc[: n - 1])
        if isinstance(parent, type) and issubclass(parent, BaseModel) and isinstance(loc[n - 1], str):
            field = parent.model_fields.get(loc[n - 1])
            if field is not None and field.description:
                return field.description
    return ""


def _unit(description: str) -> str:
    found = re.findall(r"\[([^\]]+)\]", description)
    return f" [{found[-1]}]" if found else ""


def _name(loc: Path_) -> str:
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "the document"


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "…"


def validation_diagnostics(exc: ValidationError, doc: Document, root: type[BaseModel]) -> list[Diagnostic]:
    """Turn a pydantic ``ValidationError`` into YML41x diagnostics at the offending key or value."""
    out: list[Diagnostic] = []
    for err in exc.errors(include_url=False):
        loc = tuple(p for p in err["loc"] if isinstance(p, (str, int)))
        kind = err["type"]
        desc = _description(root, loc)
        where = _name(loc)
        ctx = err.get("ctx") or {}
        if kind == "extra_forbidden":
            key = loc[-1]
            parent = _model_at(root, loc[:-1])
            known = list(parent.model_fields) if isinstance(parent, type) and issubclass(parent, BaseModel) else []
            close = difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
            hint = f"keys allowed here: {', '.join(known)}" if known else None
            msg = f"unknown key '{key}'" + (f" — did you mean '{close[0]}'?" if close else "")
            out.append(YML411(msg, doc.locate(loc), hint=hint))
        elif kind == "missing":
            key = loc[-1]
            parent_name = _name(loc[:-1])
            out.append(YML412(f"missing key '{key}' in {parent_name}", doc.locate(loc[:-1]),
                              hint=f"add '{key}: …'" + (f" — {desc}" if desc else "")))
        elif kind in _RANGE or kind in ("too_short", "too_long"):
            if kind in _RANGE:
                attr, sym = _RANGE[kind]
                bound = f"{sym} {ctx.get(attr)}"
            elif kind == "too_short":
                bound = f"at least {ctx.get('min_length')} item(s)"
            else:
                bound = f"at most {ctx.get('max_length')} item(s)"
            msg = f"'{where}' must be {bound}{_unit(desc)} (got {_shown(err.get('input'))})"
            out.append(YML414(msg, doc.locate(loc, value=True), hint=desc or None))
        elif kind == "literal_error":
            msg = f"'{where}' must be {ctx.get('expected')} (got {_shown(err.get('input'))})"
            out.append(YML415(msg, doc.locate(loc, value=True), hint=desc or None))
        elif kind == "finite_number":
            msg = f"'{where}' must be a finite number{_unit(desc)} (got {_shown(err.get('input'))})"
            out.append(YML414(msg, doc.locate(loc, value=True), hint=desc or None))
        elif kind.endswith(("_type", "_parsing")) or kind in ("bool_parsing", "int_from_float"):
            base = kind.rsplit("_", 1)[0] if kind != "int_from_float" else "int"
            words = _TYPE_WORDS.get(base, base.replace("_", " "))
            msg = f"'{where}' must be {words}{_unit(desc)} (got {_shown(err.get('input'))})"
            out.append(YML413(msg, doc.locate(loc, value=True), hint=desc or None))
        else:  # value_error from a model validator, and anything else
            text = err["msg"].removeprefix("Value error, ")
            out.append(YML415(f"{where}: {text}", doc.locate(loc), hint=desc or None))
    return out


# ------------------------------------------------------------------- reading with extends


def _resolve(relative: str, span: Span) -> Path:
    """``relative`` as written in the file of ``span``, resolved against that file's folder."""
    return _resolved(Path(span.file).parent / relative)


def _resolved(path: Path) -> Path:
    """``path`` made absolute with its symbolic links resolved, or only made absolute when they
    cannot be (a loop of links: reading it then reports why)."""
    try:
        return path.resolve()
    except (OSError, RuntimeError):  # RuntimeError: a symlink loop (Python < 3.13)
        return Path(os.path.abspath(path))


def _read_kind(path: Path, expected: Kind, referrer: Span | None,
               stack: tuple[Path, ...] = ()) -> tuple[Document | None, list[Diagnostic]]:
    """Read a file, check its kind, and apply ``extends`` (scenarios) with cycle detection."""
    doc, diags = read_document(_display(path))
    if doc is None:
        if referrer is not None and diags and diags[0].code == "YML401":
            missing = diags[0].message.startswith("no such file")
            what = f"referenced file not found: {_display(path)}" if missing else f"referenced file unusable: {diags[0].message}"
            return None, [YML418(what, referrer, hint="paths are relative to the file that names them")]
        return None, diags
    kind = file_kind(doc.data)
    if kind != expected:
        what = f"a {kind}" if kind else "neither a map nor a scenario"
        span = referrer or doc.locate(("kind",))
        return None, [YML410(f"{_display(path)} is {what}; expected a {expected}", span,
                             hint=f"add 'kind: {expected}' at the top, or name the right file")]
    base = doc.data.get("extends") if expected == "scenario" else None
    if base is None:
        return doc, []
    if not isinstance(base, str) or not base or "\0" in base:
        return doc, []  # the schema reports it
    at = doc.locate(("extends",), value=True)
    target = _resolve(base, at)
    here = _resolved(path)
    if target in stack or target == here:
        chain = " → ".join(p.name for p in (*stack, here, target))
        return None, [YML419(f"'extends' forms a cycle: {chain}", at, hint="a scenario cannot extend itself")]
    parent, pdiags = _read_kind(target, "scenario", at, stack + (here,))
    if parent is None:
        return None, pdiags
    return _merge(parent, doc), pdiags


def _merge(base: Document, over: Document) -> Document:
    """``over`` on top of ``base``: mappings merge key by key, anything else is replaced."""
    where = dict(base.where)

    def merge(a: Any, b: Any, path: Path_) -> Any:
        if isinstance(a, dict) and isinstance(b, dict):
            out = dict(a)
            for k, v in b.items():
                out[k] = merge(a.get(k), v, path + (k,)) if k in a else v
                if k not in a or not (isinstance(a.get(k), dict) and isinstance(v, dict)):
                    for p in [p for p in where if p[: len(path) + 1] == path + (k,)]:
                        del where[p]
                    where.update({p: w for p, w in over.where.items() if p[: len(path) + 1] == path + (k,)})
            return out
        return b

    data = merge(base.data, over.data, ())
    data.pop("extends", None)
    where[()] = over.where.get((), base.where.get(()))  # type: ignore[assignment]
    return Document(over.path, data, where)


def _is_file(path: str | Path) -> bool:
    """Whether ``path`` is a regular file; False for a name the system refuses (too long, …)."""
    try:
        return Path(path).is_file()
    except (OSError, ValueError):  # ENAMETOOLONG and the like; ValueError: a NUL in the name
        return False


def _display(path: Path) -> str:
    try:
        rel = os.path.relpath(path)
    except ValueError:
        return str(path)
    return str(path) if rel.startswith("..") else rel


# ------------------------------------------------------------------------- cross-checks


def _suggest(name: str, known: Iterable[str]) -> str | None:
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.5)
    return f"did you mean '{close[0]}'?" if close else None


def _check_ids(items: list[tuple[str, Path_]], doc: Document, what: str) -> list[Diagnostic]:
    seen: dict[str, Path_] = {}
    out = []
    for ident, loc in items:
        if ident in seen:
            first = doc.locate(seen[ident], value=True)
            out.append(YML417(f"duplicate {what} id '{ident}'", doc.locate(loc, value=True),
                              hint=f"first defined at {first.file}:{first.line}"))
        else:
            seen[ident] = loc
    return out


def successors(spec: MapFile) -> dict[str, list[str]]:
    """Lane id → ids of the lanes that follow it (road, free-form and junctions' connecting lanes)."""
    out = {lane.id: list(lane.successors) for road in spec.roads for lane in road.lane_specs()}
    for lane in spec.lanes:
        out.setdefault(lane.id, list(lane.successors))
    for plan in plan_junctions(spec):
        for c in plan.connections:
            out.setdefault(c.incoming, []).append(c.id)
            out[c.id] = [c.outgoing]
    return out


def all_lengths(spec: MapFile) -> dict[str, float]:
    """Length [m] of every lane of the map by id, junctions' connecting lanes included."""
    out = lane_lengths(spec)
    for plan in plan_junctions(spec):
        out.update({c.id: c.length for c in plan.connections})
    return out


def _check_lane_pos(lane: str, s: float | None, loc: Path_, doc: Document, lengths: dict[str, float],
                    s_key: str = "s") -> list[Diagnostic]:
    if lane not in lengths:
        return [YML416(f"no lane '{lane}' in the map", doc.locate(loc + ("lane",), value=True),
                       hint=_suggest(lane, lengths) or f"lanes: {', '.join(sorted(lengths)[:12])}")]
    if s is not None and s > lengths[lane] + 1e-6:
        return [YML420(f"s = {s:g} m is beyond the end of lane '{lane}' ({lengths[lane]:.1f} m long)",
                       doc.locate(loc + (s_key,), value=True))]
    return []


_PROBLEM_CODES = {"YML415": YML415, "YML416": YML416, "YML420": YML420}


def _check_lane_refs(spec: MapFile, doc: Document, lengths: dict[str, float]) -> list[Diagnostic]:
    """Lanes named by successors, neighbours, markings and no-overtaking zones exist; the stretches
    of markings and zones lie on their lanes."""
    out: list[Diagnostic] = []

    def ref(name: str | None, loc: Path_) -> None:
        if name is not None and name not in lengths:
            out.append(YML416(f"no lane '{name}' in the map", doc.locate(loc, value=True), hint=_suggest(name, lengths)))

    for i, road in enumerate(spec.roads):
        for j, lane in enumerate(road.lanes or []):
            for k, nxt in enumerate(lane.successors):
                ref(nxt, ("roads", i, "lanes", j, "successors", k))
    for i, lane in enumerate(spec.lanes):
        for k, nxt in enumerate(lane.successors):
            ref(nxt, ("lanes", i, "successors", k))
        ref(lane.adjacent_left, ("lanes", i, "adjacent_left"))
        ref(lane.adjacent_right, ("lanes", i, "adjacent_right"))
    for group in ("markings", "no_overtaking"):
        for i, item in enumerate(getattr(spec, group)):
            if item.lane not in lengths:
                ref(item.lane, (group, i, "lane"))
            elif item.s_range is not None and item.s_range[0] > lengths[item.lane] + 1e-6:
                out.append(YML420(f"the stretch starts at {item.s_range[0]:g} m, beyond the end of lane '{item.lane}' "
                                  f"({lengths[item.lane]:.1f} m long)", doc.locate((group, i, "s_range"), value=True)))
    return out


def _check_map(spec: MapFile, doc: Document) -> list[Diagnostic]:
    out: list[Diagnostic] = []
    out += _check_ids([(r.id, ("roads", i, "id")) for i, r in enumerate(spec.roads)], doc, "road")
    plans = plan_junctions(spec)
    lanes: list[tuple[str, Path_]] = []
    for i, road in enumerate(spec.roads):
        if road.lanes is None:
            lanes.append((road.id, ("roads", i, "id")))
        else:
            lanes += [(ln.id, ("roads", i, "lanes", j, "id")) for j, ln in enumerate(road.lanes)]
    lanes += [(ln.id, ("lanes", i, "id")) for i, ln in enumerate(spec.lanes)]
    lanes += [(c.id, ("junctions", plan.index, "id")) for plan in plans for c in plan.connections]
    out += _check_ids(lanes, doc, "lane")
    out += _check_ids([(j.id, ("junctions", i, "id")) for i, j in enumerate(spec.junctions)], doc, "junction")
    for plan in plans:
        out += [_PROBLEM_CODES[pr.code](pr.message, doc.locate(pr.at, value=pr.code != "YML415"), hint=pr.hint)
                for pr in plan.problems]
    lengths = lane_lengths(spec)
    lengths.update({c.id: c.length for plan in plans for c in plan.connections})
    out += _check_lane_refs(spec, doc, lengths)
    items: list[tuple[str, Path_]] = []
    for group in ("speed_limits", "stop_signs", "traffic_lights"):
        for i, item in enumerate(getattr(spec, group)):
            items.append((item.id, (group, i, "id")))
            out += _check_lane_pos(item.lane, item.s, (group, i), doc, lengths)
    items += [(line.id, ("junctions", plan.index, "id")) for plan in plans for line in plan.lines if line.kind != "yield"]
    out += _check_ids(items, doc, "sign or light")
    return out


def _route_lanes(spec: ScenarioFile, succ: dict[str, list[str]]) -> list[str] | None:
    """The lanes from A's to B's: ``via`` if given, else a shortest path by successors."""
    a, b = spec.route.start.lane, spec.route.goal.lane
    if spec.route.via is not None:
        return list(spec.route.via)
    if a == b and spec.route.goal.s >= spec.route.start.s:
        return [a]
    prev: dict[str, str] = {}
    frontier = [a]
    while frontier:
        nxt = []
        for lane in frontier:
            for s in succ.get(lane, []):
                if s not in prev and s != a:
                    prev[s] = lane
                    nxt.append(s)
        if b in prev:
            path = [b]
            while path[-1] != a:
                path.append(prev[path[-1]])
            return path[::-1]
        frontier = nxt
    return None


def route_length(spec: ScenarioFile, lanes: list[str], lengths: dict[str, float]) -> float:
    """Length [m] of the route from start to goal along ``lanes`` (pure Python)."""
    r = spec.route
    if len(lanes) == 1:
        return r.goal.s - r.start.s
    return lengths[lanes[0]] - r.start.s + sum(lengths[x] for x in lanes[1:-1]) + r.goal.s


MIN_ROUTE_LENGTH = 1.0
"""Shortest route accepted [m] (and at least two reference points, one ``spacing`` apart)."""


def _check_route_length(spec: ScenarioFile, lanes: list[str], lengths: dict[str, float], doc: Document) -> list[Diagnostic]:
    """YML420 at the goal when the route from start to goal along ``lanes`` is too short to
    follow (a goal on the start: zero length, reference spacing 0, divisions by zero)."""
    r = spec.route
    length = route_length(spec, lanes, lengths)
    least = max(MIN_ROUTE_LENGTH, r.spacing)
    if length < least:
        return [YML420(f"the route from start to goal is {length:g} m long; it must be at least {least:g} m",
                       doc.locate(("route", "goal", "s"), value=True),
                       hint="the goal is (almost) at the start: move it further along the lanes")]
    points = length / r.spacing
    if points > MAX_ROUTE_POINTS:
        where = ("route", "spacing") if ("route", "spacing") in doc.where else ("route", "goal", "s")
        return [YML420(f"the route is {length:.6g} m long: at a spacing of {r.spacing:g} m that is {points:.3g} "
                       f"reference points, more than the {MAX_ROUTE_POINTS} allowed",
                       doc.locate(where, value=True),
                       hint=f"raise 'route.spacing' to at least {length / MAX_ROUTE_POINTS:.3g} m, or shorten the route")]
    return []


def _check_scenario(spec: ScenarioFile, doc: Document, m: MapFile) -> list[Diagnostic]:
    out: list[Diagnostic] = []
    lengths = all_lengths(m)
    succ = successors(m)
    r = spec.route
    out += _check_lane_pos(r.start.lane, r.start.s, ("route", "start"), doc, lengths)
    out += _check_lane_pos(r.goal.lane, r.goal.s, ("route", "goal"), doc, lengths)
    for k, lane in enumerate(r.via or []):
        if lane not in lengths:
            out.append(YML416(f"no lane '{lane}' in the map", doc.locate(("route", "via", k), value=True),
                              hint=_suggest(lane, lengths)))
    behind = r.via is None and r.start.lane == r.goal.lane and r.goal.s < r.start.s
    if not out and behind:
        out.append(YML420("the goal is behind the start on the same lane", doc.locate(("route", "goal", "s"), value=True),
                          hint=f"put the goal ahead of s = {r.start.s:g} m, or route via other lanes with 'via'"))
    elif not out:
        lanes = _route_lanes(spec, succ)
        if lanes is None:
            out.append(YML420(f"no way from lane '{r.start.lane}' to lane '{r.goal.lane}' along lane successors",
                              doc.locate(("route", "goal", "lane"), value=True), hint="add 'successors' in the map or give 'via'"))
        elif r.via is not None:
            if not lanes or lanes[0] != r.start.lane or lanes[-1] != r.goal.lane:
                out.append(YML420("'via' must begin with the start lane and end with the goal lane",
                                  doc.locate(("route", "via"), value=True)))
            for k, (x, y) in enumerate(zip(lanes, lanes[1:])):
                if y not in succ.get(x, []):
                    out.append(YML420(f"lane '{y}' does not follow lane '{x}' in the map",
                                      doc.locate(("route", "via", k + 1), value=True)))
        if lanes is not None and not out:
            out += _check_route_length(spec, lanes, lengths, doc)
    if spec.ego.start.lane is not None:
        out += _check_lane_pos(spec.ego.start.lane, spec.ego.start.s, ("ego", "start"), doc, lengths)
    ids: list[tuple[str, Path_]] = [("ego", ())]
    for i, p in enumerate(spec.participants):
        ids.append((p.id, ("participants", i, "id")))
        if p.start is not None and p.start.lane is not None:
            out += _check_lane_pos(p.start.lane, p.start.s, ("participants", i, "start"), doc, lengths)
    for i, pop in enumerate(spec.populations):
        ids.append((pop.id, ("populations", i, "id")))
        out += _check_population(i, spec, doc, lengths)
    out += _check_ids(ids[1:], doc, "participant")
    out += _check_vehicle(spec, doc)
    if spec.run.duration < spec.controller.dt:
        out.append(YML414(f"the run lasts {spec.run.duration:g} s, less than one control period (dt = "
                          f"{spec.controller.dt:g} s): it would take no step", doc.locate(("run", "duration"), value=True),
                          hint="a run lasts at least dt"))
    out += _check_assumptions(spec, doc, [i for i, _ in ids[1:]])
    out += check_scripts(spec, doc, m)
    out += _check_controller(spec, doc, m, succ)
    return out


@dataclass(frozen=True)
class Sensing:
    """What the ego can see and stop for (one definition for ``twolevel check``, the world's
    signals and the MPC): its RSS ``response`` as the rear car — its response time (``controller.
    rss_response``, default one period dt), its largest acceleration during it (the bicycle's
    ``a_max`` with the ego's overrides), its braking ``controller.rss_brake`` and the assumed
    ``brake_max`` of the vehicle ahead (:mod:`twolevel.world.assumptions`) —, the sensing
    ``range`` [m] (``controller.sensor_range``, default the larger of
    :data:`~twolevel.world.schema.DEFAULT_SENSOR_RANGE` and r_near), the ``margin`` [m] it keeps at
    standstill (``controller.D_safe``) and ``v_bound`` [m/s], the speed from which it stops (RSS's
    distance to a standing vehicle, plus the margin) behind a standing car of its own length whose
    centre is just beyond the range."""

    response: "ResponseBounds"
    range: float
    margin: float
    v_bound: float


def sensing_of(spec: ScenarioFile) -> Sensing:
    """The ego's :class:`Sensing` under a scenario's settings (pure Python)."""
    from twolevel.models.params import BicycleParams
    from twolevel.world.assumptions import ResponseBounds, from_spec, stopping_speed

    c = spec.controller
    a_max = float(spec.ego.vehicle.get("a_max", BicycleParams.a_max))
    response = ResponseBounds(c.dt if c.rss_response is None else c.rss_response, a_max, c.rss_brake,
                              from_spec(spec.assumptions).response.brake_max)
    rng = max(DEFAULT_SENSOR_RANGE, c.r_near or 0.0) if c.sensor_range is None else c.sensor_range
    return Sensing(response, rng, c.D_safe, stopping_speed(rng - spec.ego.box.length - c.D_safe, response))


def fastest(scn: "Scenario", lanes: list[str]) -> tuple[float, str]:
    """The highest speed [m/s] a scenario lets the ego drive along its route's ``lanes``: the
    highest limit on them (their own or the map's default, and the signs on them), capped by the
    ego's desired speed, and at least its speed at the start; and what set it, in words."""
    spec, m = scn.spec, scn.map.spec
    own = {ln.id: ln.speed_limit for ln in m.lane_specs()}
    limits = [own.get(lane) or m.default_speed_limit for lane in lanes]
    limits += [sign.value for sign in m.speed_limits if sign.lane in lanes]
    top = max(limits)
    v, why = top, f"speed limit {top:g} m/s"
    if spec.ego.desired_speed is not None:
        v, why = min(v, spec.ego.desired_speed), why + f", desired speed {spec.ego.desired_speed:g} m/s"
    if spec.ego.speed > v:
        v, why = spec.ego.speed, f"start speed {spec.ego.speed:g} m/s"
    return v, why


def near_radius(scn: "Scenario") -> float:
    """The scenario's ``r_near`` [m]: ``controller.r_near`` where it is given, else the distance
    covered in :data:`~twolevel.world.schema.R_NEAR_HEADWAY` at the fastest speed the scenario
    lets the ego drive along its route (:func:`fastest`), at least
    :data:`~twolevel.world.schema.R_NEAR_FLOOR`, at most the sensing range (pure Python)."""
    spec = scn.spec
    if spec.controller.r_near is not None:
        return float(spec.controller.r_near)
    v, _ = fastest(scn, _route_lanes(spec, successors(scn.map.spec)) or [spec.route.start.lane])
    return min(max(R_NEAR_FLOOR, R_NEAR_HEADWAY * v), sensing_of(spec).range)


def _check_controller(spec: ScenarioFile, doc: Document, m: MapFile, succ: dict[str, list[str]]) -> list[Diagnostic]:
    """The look-ahead is whole periods and consistent (YML430, at the setting it names); the
    sensing range is at least r_near (YML414). (Whether the ego can stop within it is a warning
    of :mod:`twolevel.world.lint`.)"""
    from twolevel.world.look_ahead import look_ahead_periods

    c = spec.controller
    out: list[Diagnostic] = []
    try:
        look_ahead_periods(c.H, c.dt, c.horizon_s, c.coarse_dt, c.coarse_steps)
    except ValueError as exc:
        text = str(exc)
        key = next((k for k in ("coarse_steps", "coarse_dt", "horizon_s") if k in text and getattr(c, k) is not None),
                   "horizon_s" if c.horizon_s is not None else "H")
        if "a coarse step" in text:
            key = "coarse_steps"
        out.append(YML430(text, doc.locate(("controller", key), value=True),
                          hint=f"the look-ahead is H = {c.H} steps of dt = {c.dt:g} s, then coarse steps that are "
                               "whole numbers of dt"))
    if c.sensor_range is not None and c.r_near is not None and c.sensor_range < c.r_near:
        out.append(YML414(f"sensor_range = {c.sensor_range:g} m is shorter than r_near = {c.r_near:g} m",
                          doc.locate(("controller", "sensor_range"), value=True),
                          hint="the MPC constrains the vehicles within r_near, which the ego must see"))
    return out


def _check_assumptions(spec: ScenarioFile, doc: Document, known: list[str]) -> list[Diagnostic]:
    """``assumptions.road_users`` names participants or populations (YML416); a bound tighter
    than its documented default is a warning (YML423): the guarantee then covers fewer of the
    behaviours others may show (twolevel/world/assumptions.py decides what is tighter)."""
    from twolevel.world.assumptions import tighter_than_default

    a = spec.assumptions
    if a is None:
        return []
    out: list[Diagnostic] = []
    for name in a.road_users:
        if name not in known:
            out.append(YML416(f"no participant or population '{name}' in the scenario",
                              doc.locate(("assumptions", "road_users", name)),
                              hint=_suggest(name, known) or "keys are participant ids or population ids"))
    for kind in ("vehicle", "cyclist", "pedestrian", "response"):
        section = getattr(a, kind)
        if section is None:
            continue
        given = {k: getattr(section, k) for k in type(section).model_fields}
        for name, value, default in tighter_than_default(kind, given):
            out.append(YML423(f"assumption '{kind}.{name}' = {value!r} is tighter than the default {default!r}",
                              doc.locate(("assumptions", kind, name), value=True),
                              hint="others may do more than assumed here; the safety guarantee covers only what "
                                   "is assumed (defaults and sources: twolevel/world/assumptions.py)"))
    return out


MAX_SLOTS = 1_000_000
"""Most places a population may choose from (one every box length + ``min_gap`` along its lanes)."""


def _check_population(i: int, spec: ScenarioFile, doc: Document, lengths: dict[str, float]) -> list[Diagnostic]:
    """A population's lanes exist, each once; there are places for its vehicles (a warning when
    too few), and not so many that enumerating them runs out of memory."""
    pop = spec.populations[i]
    at = ("populations", i)
    out: list[Diagnostic] = []
    seen: set[str] = set()
    for k, lane in enumerate(pop.lanes):
        if lane not in lengths:
            out.append(YML416(f"no lane '{lane}' in the map", doc.locate(at + ("lanes", k), value=True),
                              hint=_suggest(lane, lengths)))
        elif lane in seen:
            out.append(YML417(f"lane '{lane}' is listed twice: its vehicles would be placed on top of each other",
                              doc.locate(at + ("lanes", k), value=True), hint="list each lane once"))
        seen.add(lane)
    if out:
        return out
    pitch = pop.box.length + pop.min_gap
    room = 0
    for lane in pop.lanes:
        lo, hi = pop.s_range or (0.0, lengths[lane])
        span = min(hi, lengths[lane]) - lo - pop.box.length
        room += int(span // pitch) + 1 if span >= 0 else 0
        if lane == spec.ego.start.lane:
            room -= 2
    if room > MAX_SLOTS:
        where = at + ("min_gap",) if at + ("min_gap",) in doc.where else at
        out.append(YML420(f"one place every {pitch:g} m along these lanes gives {room:,} places to choose from; "
                          f"at most {MAX_SLOTS:,} are allowed", doc.locate(where, value=True),
                          hint="place the population on part of its lanes with 's_range', or raise 'min_gap'"))
    elif pop.count > room:
        out.append(YML421(f"room for about {max(room, 0)} vehicles of {pop.count} on these lanes; the rest are left out",
                          doc.locate(at + ("count",), value=True), hint="lower 'min_gap', widen 's_range' or add lanes"))
    return out


def _check_vehicle(spec: ScenarioFile, doc: Document) -> list[Diagnostic]:
    """Ego vehicle-parameter overrides name real parameters of the bicycle (``l_f``) or the
    detailed model, with physically valid values (twolevel/models/params.py decides)."""
    from twolevel.models.params import (
        BICYCLE_RANGES, VEHICLE_RANGES, BicycleParams, InvalidParameterError, UnknownParameterError, VehicleParams,
    )

    out: list[Diagnostic] = []
    bicycle_names = {f for f in BicycleParams.__dataclass_fields__}
    vehicle_names = {f for f in VehicleParams.__dataclass_fields__}
    for name, value in spec.ego.vehicle.items():
        loc = ("ego", "vehicle", name)
        target = BicycleParams() if name in bicycle_names else VehicleParams()
        try:
            target.with_overrides({name: value})
        except UnknownParameterError:
            known = sorted(bicycle_names | vehicle_names)
            hint = _suggest(name, known)
            out.append(YML411(f"unknown vehicle parameter '{name}'", doc.locate(loc),
                              hint=hint or f"known parameters: {', '.join(known)}"))
        except InvalidParameterError as exc:
            unit = (BICYCLE_RANGES if name in bicycle_names else VEHICLE_RANGES)[name].unit
            out.append(YML414(f"vehicle parameter '{name}' = {value!r}: {exc.reason}", doc.locate(loc, value=True),
                              hint=f"the default is {getattr(target, name):g} {unit} "
                                   f"({type(target).__name__} in twolevel/models/params.py says what it means)"))
    return out


def _rule_names(path: str) -> list[tuple[str, Span]] | None:
    """The rules ``path`` defines, with where each name is; None if it cannot be read or parsed
    (its own diagnostics say why)."""
    from twolevel.stl.parser import parse  # lazy: no numpy, but only scenarios with rules need it
    from twolevel.stl.source import read_source

    shown = _display(Path(path))
    text, _ = read_source(shown)
    rulefile = parse(text, shown)[0] if text is not None else None
    if rulefile is None:
        return None
    return [(r.name, r.name_span or Span.whole_file(shown)) for r in rulefile.rules]


def _check_rule_names(rules: Iterable[RuleFile]) -> tuple[list[Diagnostic], dict[str, Span] | None]:
    """YML428 at a scenario's rule entry that repeats a file, or whose file defines a rule another
    entry's file already defines: a scenario's rules share one name space (each is a trace
    column ``rob_<name>``, a monitor verdict and a constraint group of the MPC). Also returns
    the rules defined {name: where}, None when a rule file is missing or cannot be parsed (its
    own diagnostics say why)."""
    out: list[Diagnostic] = []
    listed: dict[str, RuleFile] = {}
    defined: dict[str, Span] = {}  # rule name → where the first file defines it
    complete = True
    for rf in rules:
        if not _is_file(rf.path):
            complete = False
            continue  # reported as a missing file
        if rf.path in listed:
            first = listed[rf.path].span
            out.append(YML428(f"{_display(Path(rf.path))} is listed twice (first at {first.file}:{first.line})", rf.span,
                              hint="list each rule file once; to check a rule at other constants, copy it under another name"))
            continue
        listed[rf.path] = rf
        parsed = _rule_names(rf.path)
        complete = complete and parsed is not None
        names = parsed or []
        for name, span in names:  # a name repeated within one file is the rule checker's (STL2xx)
            first_def = defined.get(name)
            if first_def is not None:
                out.append(YML428(
                    f"rule '{name}' is defined twice: at {first_def.file}:{first_def.line} and at {span.file}:{span.line}",
                    rf.span, hint="rule names are unique across a scenario's rule files: rename one of the rules, "
                                  "or leave out the file that repeats it"))
        for name, span in names:
            defined.setdefault(name, span)
    return out, (defined if complete else None)


def _check_rule_refs(spec: ScenarioFile, doc: Document, defined: Mapping[str, Span] | None) -> list[Diagnostic]:
    """Each rule name the scenario refers to that no rule of its rule files (``defined``) has:
    YML435 at a key of ``controller.margins``, YML436 at an entry of ``expect.rules`` (the
    scenario's or a variant's) — there a run would only fail its criterion after it has run. Not
    judged when one of the rule files is missing or unparsable: its own diagnostics come first."""
    if defined is None:
        return []
    refs: list[tuple[str, tuple[Any, ...], Code, str]] = [
        (name, ("controller", "margins", name), YML435, "margin for rule") for name in spec.controller.margins or ()]
    expects = [(("expect",), spec.expect)] + [(("variants", j, "expect"), v.expect) for j, v in enumerate(spec.variants)]
    for at, expect in expects:
        if expect is not None and expect.rules != "all":
            refs += [(name, (*at, "rules", i), YML436, "expect.rules names rule") for i, name in enumerate(expect.rules)]
    out: list[Diagnostic] = []
    known = sorted(defined)
    rules = ", ".join(known) if known else "none (the scenario lists no rule file)"
    for name, key, code, what in refs:
        if name in defined:
            continue
        close = _suggest(name, known)
        out.append(code(f"{what} '{name}', which no rule file of the scenario defines" + (f" — {close}" if close else ""),
                        doc.locate(key), hint=f"rules defined: {rules}"))
    return out


# ----------------------------------------------------------------------------- public API


def _validate(doc: Document, model: type[BaseModel]) -> tuple[Any, list[Diagnostic]]:
    try:
        return model.model_validate(doc.data), []
    except ValidationError as exc:
        return None, validation_diagnostics(exc, doc, model)


def _load_map(path: Path, referrer: Span | None) -> tuple[Map | None, list[Diagnostic]]:
    doc, diags = _read_kind(path, "map", referrer)
    if doc is None:
        return None, diags
    spec, vdiags = _validate(doc, MapFile)
    if spec is None:
        return None, diags + vdiags
    cdiags = _check_map(spec, doc)
    cdiags += check_layout(spec, doc)
    return (None if any(d.is_error for d in cdiags) else Map(spec, doc.path)), diags + cdiags


def load_map(path: str | os.PathLike[str]) -> tuple[Map | None, list[Diagnostic]]:
    """Load and validate a map file. Returns ``(map or None, diagnostics)``; never raises."""
    return _load_map(Path(path), None)


def _traffic_files(spec: ScenarioFile, doc: Document) -> tuple[ScenarioFile, list[Diagnostic]]:
    """The scenario with its traffic engine's files resolved (relative to the file naming them),
    and YML418 for each that does not exist."""
    t = spec.traffic
    if t is None:
        return spec, []
    diags: list[Diagnostic] = []
    found = []
    for key, name in [(("traffic", "net"), t.net)] + [(("traffic", "routes", i), r) for i, r in enumerate(t.routes)]:
        at = doc.locate(key, value=True)
        target = _resolve(name, at)
        if not _is_file(target):
            diags.append(YML418(f"SUMO file not found: {name}", at, hint="paths are relative to the scenario file"))
        found.append(str(target))
    return spec.model_copy(update={"traffic": t.model_copy(update={"net": found[0], "routes": found[1:]})}), diags


def load_scenario(path: str | os.PathLike[str], parameters: Mapping[str, float] | None = None
                  ) -> tuple[Scenario | None, list[Diagnostic]]:
    """Load a scenario, the scenarios it extends, and its map; locate its rule files.

    ``parameters`` give values to the scenario's declared parameters (the others take their
    nominal values; :mod:`twolevel.world.parameters`). Returns ``(scenario or None,
    diagnostics)``; the map's own diagnostics are included (pointing into the map file).
    Never raises for bad input.
    """
    doc, diags = _read_kind(Path(path), "scenario", None)
    if doc is None:
        return None, diags
    sub, sdiags = substitute(doc, parameters)
    diags += sdiags
    if any(d.is_error for d in sdiags):
        # a reference to a parameter whose declaration is invalid: say what is wrong with it too
        declarations = Document(doc.path, {"parameters": doc.data.get("parameters", {})}, doc.where)
        return None, diags + _validate(declarations, ParameterDeclarations)[1]
    doc = sub.document
    spec, vdiags = _validate(doc, ScenarioFile)
    if spec is None:
        return None, diags + explain(vdiags, sub)
    at_map = doc.locate(("map",), value=True)
    m, mdiags = _load_map(_resolve(spec.map, at_map), at_map)
    diags = diags + mdiags
    rules = []
    for i, ref in enumerate(spec.rules):
        at = doc.locate(("rules", i, "file"), value=True) if ("rules", i, "file") in doc.where else doc.locate(("rules", i), value=True)
        target = _resolve(ref.file, at)
        if not _is_file(target):
            diags.append(YML418(f"rule file not found: {ref.file}", at, hint="paths are relative to the scenario file"))
        rules.append(RuleFile(str(target), tuple(sorted(ref.constants.items())), at))
    ndiags, defined = _check_rule_names(rules)
    diags += ndiags + _check_rule_refs(spec, doc, defined)
    spec, tdiags = _traffic_files(spec, doc)
    diags += tdiags
    if m is None:
        return None, diags
    diags += explain(_check_scenario(spec, doc, m.spec), sub) + check_variants(spec, doc)
    if any(d.is_error for d in diags):
        return None, diags
    return Scenario(spec, doc.path, m, tuple(rules)), diags


def check_world_file(path: str | os.PathLike[str]) -> list[Diagnostic]:
    """Everything ``twolevel check`` reports for one ``.yaml``/``.yml`` map or scenario file.

    A scenario is checked with its map and, through ``twolevel.stl.lint.check_file``, its rule
    files (with the scenario's dt, horizon H and :data:`~twolevel.world.provided.PROVIDED_SIGNALS`).
    """
    doc, diags = read_document(path)
    if doc is None:
        return diags
    kind = file_kind(doc.data)
    if kind == "map":
        return load_map(path)[1]
    if kind is None:
        return [YML410("neither a map nor a scenario: no 'roads' (map) or 'ego'/'route'/'map' (scenario)",
                       doc.locate(()), hint="add 'kind: map' or 'kind: scenario' at the top")]
    scenario, diags = load_scenario(path)
    spec = scenario.spec if scenario else _validate(substitute(doc)[0].document, ScenarioFile)[0]
    if spec is None:
        return diags
    rule_files = scenario.rules if scenario else ()
    diags += _lint_rules(rule_files, spec)
    return diags


def _lint_rules(rule_files: Iterable[RuleFile], spec: ScenarioFile) -> list[Diagnostic]:
    out: list[Diagnostic] = []
    files = [rf for rf in rule_files if _is_file(rf.path)]
    if not files:
        return out
    try:
        from twolevel.stl.lint import check_file, load_ruleset  # lazy: heavy-free, owned by the STL package
    except ImportError:
        return out
    from twolevel.world.provided import PROVIDED_PARTICIPANT_SIGNALS, PROVIDED_SIGNALS

    for rf in files:
        shown = _display(Path(rf.path))
        result = check_file(shown, dt=spec.controller.dt, horizon=spec.controller.H, provided_signals=PROVIDED_SIGNALS,
                            participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
        diags = list(result.diagnostics)
        if rf.constants and not any(d.is_error for d in diags):
            # bindings the file does not declare (reported by the rule loader)
            _, bound = load_ruleset(shown, dict(rf.constants), dt=spec.controller.dt, provided_signals=PROVIDED_SIGNALS,
                                    participant_signals=PROVIDED_PARTICIPANT_SIGNALS)
            seen = {(d.code, d.span, d.message) for d in diags}
            for d in bound:
                if (d.code, d.span, d.message) not in seen:
                    diags.append(d if d.span.file != shown or d.code != "STL219" else
                                 type(d)(d.code, d.severity, d.message, rf.span, d.hint))
        out += diags
    return out
