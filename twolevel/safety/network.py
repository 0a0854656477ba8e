"""The map as the safety layer reads it: lane groups, lane trees, cells, stop lines, conflict zones.

Built once per world (:func:`network_of` caches it) from the sampled lanes of
:class:`~twolevel.world.geometry.LaneSet`:

* **Lane groups** — lanes beside each other that run the same way (the lane set's explicit
  adjacency, :attr:`~twolevel.world.geometry.LaneSet.left` / ``right``), rightmost first: where a
  lane change leads. Members that are exact parallel offsets of the group's rightmost lane (lanes
  of one road: the same vertices shifted along the normals) share its arc-length coordinate, and
  ``dlat[i]`` is lane i's lateral offset [m] (+ left of travel) from it. Other members (free-form
  lanes, widths that vary) are mapped through ``root_s``, s on the rightmost lane level with
  each of their vertices, and their bands are drawn on their own lane over the stretch that maps
  onto the path's, widened by :data:`MAP_SLACK` (``dlat`` is then their median offset).
* **Lane trees** — from each lane, every way forward along successors (every branch through a
  junction) up to :data:`REACH` metres: nodes ``(ref lane, offset)`` where the ref lane's s = 0
  lies ``offset`` [m] along the path from the root lane's s = 0. Two kinds: lane-bound users who
  keep their lane (members = the lane itself) and users who may change lanes (members = the
  lane's group, successors of every member). A node's ``natural`` lane is the one reached
  without changing lanes (−1 when there is none).
* **Cells** — each lane cut into convex pieces (heading monotone, turning ≤ :data:`CELL_TURN`,
  at most :data:`CELL_LENGTH` long) for turning a longitudinal interval into convex polygons.
* **Lines** — stop signs and traffic lights by lane (and on each tree node, their position along
  the path).
* **Conflict zones** — the parts of other lanes the ego's route crosses or merges with: polygons
  of every lane others may come along (not the route's, not one entered only from the route's,
  which branches off ahead of the ego), for the invariably-safe test at standstill, and the
  route intervals [s_in, s_out] [m] over which the ego's body, centred on the route, overlaps
  them.

Units: m, rad, m/s. Everything here is numpy arrays in frozen dataclasses.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from twolevel.models.obb import box_corners, overlaps, rect_axes
from twolevel.safety.polygons import band_pieces
from twolevel.world.world import World

__all__ = ["Network", "LaneTrees", "network_of", "REACH", "CELL_TURN", "CELL_LENGTH", "KINK", "STOP_SIGN", "LIGHT"]

REACH = 1500.0
"""Depth of the lane trees [m] (a participant whose reach goes beyond is predicted freely)."""
MAX_NODES = 256
"""Nodes per lane tree at most (a branching network deeper than this is cut; see REACH)."""
CELL_TURN = 0.08
"""Largest heading change within a cell [rad]."""
CELL_LENGTH = 50.0
"""Longest cell [m]."""
KINK = 4.0
"""The turn [rad] that marks a kink cell (its band is bounded by discs around its ends)."""
BODY_REACH = 10.0
"""Half a long vehicle [m]: a body on a cell may reach this far into the neighbouring ones."""
MAP_SLACK = 0.5
"""How far [m] a stretch mapped from one lane of a group onto another (not a parallel offset of it)
is widened at each end."""
STOP_SIGN, LIGHT = 0, 1
_MAX_LINES = 4  # lines per lane kept on a tree node


@dataclass(frozen=True, eq=False)
class LaneTrees:
    """Every lane's tree, concatenated: the nodes of lane l's tree are ``ptr[l]:ptr[l+1]``
    (root first, parents before children). Per node: ``ref`` lane, ``natural`` lane (−1),
    ``offset`` [m], ``parent`` (index within the same tree, −1 for the root), ``depth`` (0 at the
    root), ``leaf`` (the ref
    lane has no successor: the band continues straight past its end), ``members`` (N, M) lanes
    (−1 padded) with their lateral offset ``dlat`` (N, M) [m] from the ref lane, and the lines on
    each member ``line`` (N, M, K) (index into :attr:`Network.line_kind`, −1 padded) at path
    position ``line_x`` (N, M, K) [m]. Per tree: the largest speed limit on it ``limit`` (L,)
    [m/s], the extremes of d(ref s)/d(member s) over its members ``stretch``/``shrink`` (L,) [-]
    (a member lane on the inside of a bend is shorter than the ref lane), its ``extent`` (L,) [m]
    (path length covered; +inf when every branch ends on the map). Per node and member: ``half``
    (N, M) [m] half the member's width, ``own`` (N, M) whether its band is drawn on the member
    itself (not a parallel offset of the ref lane; ``dlat`` then its median offset) and ``spread``
    (N, M) [m] how far it may then lie beyond ``dlat`` ± ``half`` in the ref lane's frame; per node
    ``kappa`` (N,) [1/m] the sharpest turning of its lanes (the ref's, or every member's)."""

    ptr: np.ndarray
    ref: np.ndarray
    natural: np.ndarray
    offset: np.ndarray
    parent: np.ndarray
    depth: np.ndarray
    leaf: np.ndarray
    members: np.ndarray
    dlat: np.ndarray
    line: np.ndarray
    line_x: np.ndarray
    limit: np.ndarray
    stretch: np.ndarray
    shrink: np.ndarray
    extent: np.ndarray
    half: np.ndarray
    own: np.ndarray
    spread: np.ndarray
    kappa: np.ndarray


@dataclass(frozen=True, eq=False)
class Network:
    """The road network for prediction and verification (see the module docstring).

    ``group`` (L,) group id of each lane, ``dlat`` (L,) [m] offset in its group, ``exact`` (L,)
    whether it is a parallel offset of its group's rightmost lane, ``root_s`` (K,) [m] s on that
    lane level with each vertex of the lane set; ``keep`` and
    ``change``: the lane trees without and with lane changes; cells ``cell_ptr`` (L+1,),
    ``cell_s0``/``cell_s1`` (C,) [m], ``cell_turn`` (C,) [rad], ``cell_key`` (C,) the start's
    global key (the lane set's ``base`` + s0, sorted), ``cell_kappa`` (C,) [1/m] the largest
    turning per metre within :data:`BODY_REACH` of the cell (corners, and joints with a jump of
    heading, counted as turning over a metre); ``lane_kappa`` (L,) [1/m]: the largest over each
    lane's cells; lines ``line_kind`` (Q,)
    (:data:`STOP_SIGN` or :data:`LIGHT`), ``line_index`` (Q,) into the world's stops or lights,
    ``line_lane`` (Q,), ``line_s`` (Q,) [m]; ``route_lanes``: lane indices the route runs along;
    ``foreign`` (F, 4, 2) [m]: quads covering every other lane near the route (shrunk by
    ``FOREIGN_TOLERANCE``), their edge normals ``foreign_axes`` (F, 2, 2), centres
    ``foreign_centre`` (F, 2) [m] and lanes ``foreign_lane`` (F,); ``zones`` (Z, 2) [m]: route intervals where
    the ego centred on the route overlaps one of them."""

    world: World
    group: np.ndarray
    dlat: np.ndarray
    exact: np.ndarray
    root_s: np.ndarray
    keep: LaneTrees
    change: LaneTrees
    cell_ptr: np.ndarray
    cell_s0: np.ndarray
    cell_s1: np.ndarray
    cell_turn: np.ndarray
    cell_key: np.ndarray
    cell_kappa: np.ndarray
    lane_kappa: np.ndarray
    line_kind: np.ndarray
    line_index: np.ndarray
    line_lane: np.ndarray
    line_s: np.ndarray
    route_lanes: frozenset[int]
    foreign: np.ndarray
    foreign_axes: np.ndarray
    foreign_centre: np.ndarray
    foreign_lane: np.ndarray
    zones: np.ndarray

    def trees(self, lane_changes: bool) -> LaneTrees:
        """The lane trees of users who may (or may not) change lanes."""
        return self.change if lane_changes else self.keep

    def along(self, lane: int, s: np.ndarray) -> np.ndarray:
        """s [m] on lane ``lane`` → s on its group's rightmost lane (linear beyond its ends)."""
        a, b = self.world.lanes.vptr[lane], self.world.lanes.vptr[lane + 1]
        own = self.world.lanes.key[a:b] - self.world.lanes.base[lane]
        inside = np.clip(s, own[0], own[-1])
        return np.interp(inside, own, self.root_s[a:b]) + (s - inside)

    def member_s(self, ref: int, member: int, s: np.ndarray) -> np.ndarray:
        """s [m] on lane ``ref`` → s on lane ``member`` of its group, level with it (through the
        group's rightmost lane; linear beyond the lanes' ends)."""
        root = self.along(ref, s)
        a, b = self.world.lanes.vptr[member], self.world.lanes.vptr[member + 1]
        table = self.root_s[a:b]
        own = self.world.lanes.key[a:b] - self.world.lanes.base[member]
        inside = np.clip(root, table[0], table[-1])
        return np.interp(inside, table, own) + (root - inside)


FOREIGN_TOLERANCE = 0.05
"""Overlap with another lane [m] a standing ego may have (a touching box is not inside)."""

_CACHE: "weakref.WeakKeyDictionary[World, Network]" = weakref.WeakKeyDictionary()


def network_of(world: World) -> Network:
    """The :class:`Network` of a world (built on first use, then cached)."""
    got = _CACHE.get(world)
    if got is None:
        got = _build(world)
        _CACHE[world] = got
    return got


# ------------------------------------------------------------------------------ groups


def _groups(world: World) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Group id (its rightmost lane), lateral offset [m] from the rightmost lane and whether it is
    an exact parallel offset of it, for every lane; and per vertex s [m] on the group's rightmost
    lane level with it. Groups: chains of lanes beside each other running the same way."""
    lanes = world.lanes
    n = len(lanes.lanes)
    group = np.arange(n)
    dlat = np.zeros(n)
    exact = np.ones(n, dtype=bool)
    owner = np.repeat(np.arange(n), np.diff(lanes.vptr))
    root_s = lanes.key - lanes.base[owner]
    for i in range(n):
        if lanes.right[i] >= 0:
            continue  # not the rightmost lane of its group
        a = lanes.lanes[i]
        tangent = np.stack([np.cos(a.heading), np.sin(a.heading)], axis=1)
        chain = [i]
        j = int(lanes.left[i])
        while j >= 0 and j not in chain:
            chain.append(j)
            j = int(lanes.left[j])
        for j in chain[1:]:
            group[j] = i
            b = lanes.lanes[j]
            lo, hi = lanes.vptr[j], lanes.vptr[j + 1]
            if len(b.points) == len(a.points) and np.max(np.abs(b.heading - a.heading)) <= 1e-9:
                rel = b.points - a.points
                along = np.einsum("kj,kj->k", rel, tangent)
                side = tangent[:, 0] * rel[:, 1] - tangent[:, 1] * rel[:, 0]
                if np.max(np.abs(along)) < 1e-6 and np.ptp(side) < 1e-6:
                    dlat[j] = float(side[0])
                    root_s[lo:hi] = a.s
                    continue
            s, lat = lanes.project(np.full(len(b.points), i), b.points)
            exact[j] = False
            dlat[j] = float(np.median(lat))
            root_s[lo:hi] = np.maximum.accumulate(s)
    return group, dlat, exact, root_s


# ------------------------------------------------------------------------------- cells


def _cells(world: World) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Cut every lane into convex cells (heading monotone, turning ≤ CELL_TURN, at most
    CELL_LENGTH long; cuts at vertices, a long straight interval split evenly; a polyline's
    corner — the heading jumping at one point — is a cell of its own, of zero length, turning by
    the jump; a kink — an interval running more than 45° off its ends' headings, as a lane offset
    to the inside of a sharp corner does — is a cell of its own marked :data:`KINK`): ptr (L+1,),
    s0, s1 [m] and the turn [rad] within each cell."""
    lane_of, s0, s1, turn = [], [], [], []

    def close(i: int, a: float, b: float, t: float) -> None:
        lane_of.append(i); s0.append(a); s1.append(b); turn.append(t)

    for i, lane in enumerate(world.lanes.lanes):
        s, h = lane.s, lane.heading
        start, lo, hi, sign = 0, h[0], h[0], 0.0
        pts = lane.points
        for k in range(1, len(s)):
            dh = h[k] - h[k - 1]
            d = pts[k] - pts[k - 1]
            chord = math.atan2(d[1], d[0])
            off = max(abs((chord - h[k - 1] + math.pi) % (2 * math.pi) - math.pi),
                      abs((chord - h[k] + math.pi) % (2 * math.pi) - math.pi))
            kink = s[k] - s[k - 1] > 1e-9 and off > math.pi / 4
            if (s[k] - s[k - 1] <= 1e-9 and abs(dh) > 1e-12) or kink:  # a corner
                if k - 1 > start:
                    close(i, s[start], s[k - 1], hi - lo)
                close(i, s[k - 1] if kink else s[k], s[k], KINK if kink else abs(dh))
                start, lo, hi, sign = k, h[k], h[k], 0.0
                continue
            sgn = math.copysign(1.0, dh) if abs(dh) > 1e-12 else 0.0
            nlo, nhi = min(lo, h[k]), max(hi, h[k])
            bad = nhi - nlo > CELL_TURN or (sgn * sign < 0) or s[k] - s[start] > CELL_LENGTH
            if bad and k - 1 > start:
                close(i, s[start], s[k - 1], hi - lo)
                start, lo, hi, sign = k - 1, min(h[k - 1], h[k]), max(h[k - 1], h[k]), sgn
            else:
                lo, hi, sign = nlo, nhi, sgn or sign
        if start < len(s) - 1 or not lane_of or lane_of[-1] != i:
            close(i, s[start], s[-1], hi - lo)
    lane_a, s0a, s1a, ta = np.array(lane_of), np.array(s0), np.array(s1), np.array(turn)
    parts = np.maximum(1, np.ceil((s1a - s0a) / CELL_LENGTH - 1e-9)).astype(int)
    rep = np.repeat(np.arange(len(s0a)), parts)
    k = np.arange(len(rep)) - np.repeat(np.cumsum(parts) - parts, parts)
    width = (s1a - s0a)[rep] / parts[rep]
    s0a, s1a = s0a[rep] + k * width, s0a[rep] + (k + 1) * width
    lane_a, ta = lane_a[rep], ta[rep]
    ptr = np.searchsorted(lane_a, np.arange(len(world.lanes.lanes) + 1), side="left")
    return ptr.astype(int), s0a, s1a, ta


# ------------------------------------------------------------------------------- lines


def _lines(world: World) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    kind = np.concatenate([np.full(len(world.stops.ids), STOP_SIGN), np.full(len(world.lights.ids), LIGHT)])
    index = np.concatenate([np.arange(len(world.stops.ids)), np.arange(len(world.lights.ids))])
    lane = np.concatenate([world.stops.lane, world.lights.lane]).astype(int)
    s = np.concatenate([world.stops.s, world.lights.s]).astype(float)
    return kind.astype(int), index.astype(int), lane, s


def _lane_limits(world: World) -> np.ndarray:
    """The largest speed limit in force anywhere on each lane [m/s]."""
    lim, lanes = world.limits, world.lanes
    out = np.empty(len(lanes.lanes))
    for i in range(len(lanes.lanes)):
        lo, hi = lanes.base[i] - 0.5, lanes.base[i] + lanes.length[i]
        inside = (lim.key >= lo) & (lim.key <= hi)
        first = lim.at(np.array([i]), np.array([0.0]))[0]
        out[i] = max([first] + list(lim.value[inside]))
    return out


# ------------------------------------------------------------------------------- trees


def _level(net_root: np.ndarray, world: World, ref: int, member: int) -> np.ndarray:
    """s [m] on lane ``ref`` level with each vertex of lane ``member`` (same group), through the
    group's rightmost lane."""
    ls = world.lanes
    table = np.maximum.accumulate(net_root[ls.vptr[ref]:ls.vptr[ref + 1]])
    return np.interp(net_root[ls.vptr[member]:ls.vptr[member + 1]], table, ls.lanes[ref].s)


def _members(group: np.ndarray, dlat: np.ndarray, change: bool) -> list[list[int]]:
    """The members of each lane as a node's ref, ordered by lateral offset ``dlat`` [m]: with lane
    changes its ``group``, else the lane alone."""
    if not change:
        return [[r] for r in range(len(group))]
    members_of = {g: sorted(np.flatnonzero(group == g).tolist(), key=lambda i: dlat[i]) for g in set(group.tolist())}
    return [members_of[group[r]] for r in range(len(group))]


def _ref_tables(world: World, mem_of: list[list[int]], dlat: np.ndarray, exact: np.ndarray, root_s: np.ndarray,
                limits: np.ndarray, lines: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                lane_kappa: np.ndarray) -> dict[str, np.ndarray]:
    """What a tree node holds depends on its ref lane only (its offset aside): per lane as a
    node's ref, its members and everything about them (padded as in :class:`LaneTrees`), whether
    it is a leaf, the largest limit, the stretch and shrink of its members, and the lines' path
    positions relative to the node's offset. Built once per lane, so a tree of many nodes costs
    no more than indexing these tables (``mem_of``: :func:`_members`)."""
    lanes = world.lanes.lanes
    n = len(lanes)
    m_max = max(len(m) for m in mem_of)
    _, _, line_lane, line_s = lines
    lines_on = {i: np.flatnonzero(line_lane == i) for i in range(n)}
    t = {"members": np.full((n, m_max), -1, dtype=int), "dlat": np.zeros((n, m_max)), "half": np.zeros((n, m_max)),
         "own": np.zeros((n, m_max), dtype=bool), "spread": np.zeros((n, m_max)), "kappa": lane_kappa.astype(float).copy(),
         "line": np.full((n, m_max, _MAX_LINES), -1, dtype=int), "line_x": np.full((n, m_max, _MAX_LINES), np.inf),
         "leaf": np.zeros(n, dtype=bool), "limit": np.zeros(n), "stretch": np.ones(n), "shrink": np.ones(n)}
    width = world.lanes.width
    for ref, mem in enumerate(mem_of):
        t["leaf"][ref] = not any(lanes[m].successors for m in mem)
        t["limit"][ref] = max(limits[m] for m in mem)
        for j, m in enumerate(mem):
            t["members"][ref, j] = m
            t["dlat"][ref, j] = dlat[m] - dlat[ref]
            t["half"][ref, j] = width[m] / 2
            q = lines_on[m][:_MAX_LINES]
            t["line"][ref, j, : len(q)] = q
            if m == ref or (exact[m] and exact[ref]):
                # a member's line at s on the member is at the same vertex fraction on the ref lane
                t["line_x"][ref, j, : len(q)] = np.interp(line_s[q], lanes[m].s, lanes[ref].s)
                level = lanes[ref].s
            else:
                level = _level(root_s, world, ref, m)
                t["own"][ref, j] = True
                t["kappa"][ref] = max(t["kappa"][ref], lane_kappa[m])
                t["line_x"][ref, j, : len(q)] = np.interp(line_s[q], lanes[m].s, level)
                # how far the member's band strays from dl ± half in the ref's frame (for bounding circles)
                _, lat = world.lanes.project(np.full(2 * len(lanes[m].s), ref),
                                             np.concatenate([lanes[m].left_bound, lanes[m].right_bound]))
                dl, half = t["dlat"][ref, j], t["half"][ref, j]
                t["spread"][ref, j] = max(float(lat.max()) - dl - half, dl - half - float(lat.min()), 0.0) + MAP_SLACK
            if m != ref:
                ratio = np.diff(level) / np.maximum(np.diff(lanes[m].s), 1e-12)
                ok = np.diff(lanes[m].s) > 1e-9
                if ok.any():
                    t["stretch"][ref] = max(t["stretch"][ref], float(ratio[ok].max()))
                    t["shrink"][ref] = min(t["shrink"][ref], float(ratio[ok].min()))
    return t


def _children(world: World, group: np.ndarray, mem_of: list[list[int]], change: bool
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The children of a node by its ref lane and whether the ref is the node's natural lane (a
    node's natural lane is its ref or none): CSR ``ptr`` (2L+1,) over rows ``2·ref + natural``,
    the children's ``ref`` and ``natural`` flag, in the order the trees list them (with lane
    changes one child per group reached, on the natural lane's successor where there is one)."""
    lanes = world.lanes.lanes
    ptr, ref, nat = [0], [], []
    for r, mem in enumerate(mem_of):
        for natural in (False, True):
            succ: dict[int, tuple[int, bool]] = {}  # child key → (ref, natural)
            for m in mem:
                for q in lanes[m].successors:
                    key = int(group[q]) if change else int(q)
                    nq = natural and m == r
                    if key not in succ or (nq and not succ[key][1]):
                        succ[key] = (int(q), nq)
            for q, nq in succ.values():
                ref.append(q)
                nat.append(nq)
            ptr.append(len(ref))
    return np.asarray(ptr, dtype=int), np.asarray(ref, dtype=int), np.asarray(nat, dtype=bool)


def _trees(world: World, group: np.ndarray, dlat: np.ndarray, exact: np.ndarray, root_s: np.ndarray, change: bool,
           limits: np.ndarray, lines: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
           lane_kappa: np.ndarray) -> LaneTrees:
    """Every lane's tree, grown breadth first for all lanes at once (one pass per depth): a node
    is expanded while its end lies within :data:`REACH` and its tree has fewer than
    :data:`MAX_NODES` nodes when the breadth-first queue reaches it."""
    n = len(world.lanes.lanes)
    length = world.lanes.length
    mem_of = _members(group, dlat, change)
    tab = _ref_tables(world, mem_of, dlat, exact, root_s, limits, lines, lane_kappa)
    cptr, cref, cnat = _children(world, group, mem_of, change)
    # one level: tree, ref, natural flag, offset, parent and position within the tree
    tree, ref, nat = np.arange(n), np.arange(n), np.ones(n, dtype=bool)
    off, parent, pos = np.zeros(n), np.full(n, -1), np.zeros(n, dtype=int)
    count = np.ones(n, dtype=int)  # nodes in each tree so far
    extent = np.full(n, np.inf)
    levels = []
    depth = 0
    while len(tree):
        levels.append((tree, ref, nat, off, parent, pos, np.full(len(tree), depth)))
        end = off + length[ref]
        row = 2 * ref + nat
        kids = np.where(end < REACH, cptr[row + 1] - cptr[row], 0)
        # nodes of the same tree are contiguous and in queue order: the count when each is reached
        first = np.flatnonzero(np.r_[True, tree[1:] != tree[:-1]])
        run = np.cumsum(kids) - kids
        before = count[tree] + run - np.repeat(run[first], np.diff(np.r_[first, len(tree)]))
        grow = (end < REACH) & (before < MAX_NODES)
        cut = ~grow & ~tab["leaf"][ref]
        np.minimum.at(extent, tree[cut], end[cut])
        kids = np.where(grow, kids, 0)
        np.add.at(count, tree, kids)
        k = np.repeat(np.arange(len(tree)), kids)
        at = np.arange(len(k)) - np.repeat(np.cumsum(kids) - kids, kids)
        child = cptr[row[k]] + at
        tree, ref, nat, off, parent, pos = tree[k], cref[child], cnat[child], end[k], pos[k], before[k] + at
        depth += 1
    cat = [np.concatenate(c) for c in zip(*levels)]
    order = np.lexsort((cat[5], cat[0]))  # by tree, then position: each tree's nodes in queue order
    tree, ref, nat, off, parent, _, dep = (c[order] for c in cat)
    ptr = np.searchsorted(tree, np.arange(n + 1))
    per_tree = lambda name, how: how.reduceat(tab[name][ref], ptr[:-1])  # noqa: E731 - every tree has its root
    line_x = off[:, None, None] + tab["line_x"][ref]
    return LaneTrees(ptr.astype(int), ref, np.where(nat, ref, -1), off, parent, dep, tab["leaf"][ref], tab["members"][ref],
                     tab["dlat"][ref], tab["line"][ref], line_x, per_tree("limit", np.maximum),
                     per_tree("stretch", np.maximum), per_tree("shrink", np.minimum), extent, tab["half"][ref],
                     tab["own"][ref], tab["spread"][ref], tab["kappa"][ref])


# ---------------------------------------------------------------------- conflict zones


def _behind_route(world: World, route_lanes: frozenset[int]) -> set[int]:
    """Lanes entered only from the route's lanes (or from lanes entered only so): a lane that
    branches off the route ahead of the ego. Whoever is on it came along the ego's lane, i.e.
    from behind the ego."""
    lanes = world.lanes.lanes
    preds: dict[int, set[int]] = {i: set() for i in range(len(lanes))}
    for ln in lanes:
        for q in ln.successors:
            preds[q].add(ln.index)
    inner = set(route_lanes)
    grew = True
    while grew:
        grew = False
        for i, p in preds.items():
            if i not in inner and p and p <= inner:
                inner.add(i)
                grew = True
    return inner - set(route_lanes)


def _foreign(world: World, route_lanes: frozenset[int], cells: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
             ) -> tuple[np.ndarray, np.ndarray]:
    """Quads covering every lane others may come along near the route — not the route's lanes, not
    lanes entered only from them (each cell's band, shrunk by :data:`FOREIGN_TOLERANCE`) — and
    their lane."""
    ptr, s0, s1, turn = cells
    lanes = world.lanes
    lane_of = np.repeat(np.arange(len(lanes.lanes)), np.diff(ptr))
    own = set(route_lanes) | _behind_route(world, route_lanes)
    other = ~np.isin(lane_of, list(own))
    idx = np.flatnonzero(other)
    if not len(idx):
        return np.zeros((0, 4, 2)), np.zeros(0, dtype=int)
    half = lanes.width[lane_of[idx]] / 2 - FOREIGN_TOLERANCE
    quads, _, centre, _, _ = band_pieces(lanes, lane_of[idx], s0[idx], s1[idx], -half, half, turn[idx])
    # near the route: within the route's reach (its points ± a margin)
    r = world.route
    near = np.zeros(len(idx), dtype=bool)
    step = 256
    pts = r.points[:: max(1, int(5.0 / max(r.spacing, 1e-3)))]
    for i in range(0, len(pts), step):  # route samples in blocks (precomputation, once per world)
        d = np.hypot(centre[:, None, 0] - pts[None, i:i + step, 0], centre[:, None, 1] - pts[None, i:i + step, 1])
        near |= d.min(axis=1) <= CELL_LENGTH + 20.0
    return quads[near], lane_of[idx][near]


def _zones(world: World, foreign: np.ndarray) -> np.ndarray:
    """Route intervals [s_in, s_out] [m] over which the ego's box centred on the route overlaps a
    foreign quad."""
    r = world.route
    if not len(foreign):
        return np.zeros((0, 2))
    s = np.arange(0.0, float(r.s[-1]) + 1e-9, 0.25)
    pts = r.position(s)
    psi = r.heading_at(s)
    boxes = box_corners(pts[:, 0], pts[:, 1], psi, world.ego.length, world.ego.width)
    hit = np.zeros(len(s), dtype=bool)
    for i in range(0, len(s), 128):
        b = boxes[i:i + 128]
        hit[i:i + 128] = overlaps(b[:, None], foreign[None]).any(axis=1)
    if not hit.any():
        return np.zeros((0, 2))
    edges = np.diff(np.concatenate([[0], hit.astype(int), [0]]))
    start, stop = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    lo = s[np.maximum(start - 1, 0)]
    hi = s[np.minimum(stop + 1, len(s) - 1)]
    return np.stack([lo, hi], axis=1)


def _build(world: World) -> Network:
    group, dlat, exact, root_s = _groups(world)
    cells = _cells(world)
    lines = _lines(world)
    limits = _lane_limits(world)
    near = _bends_near(world, cells)
    kappa = np.array([near[cells[0][i]:cells[0][i + 1]].max(initial=0.0) for i in range(len(world.lanes.lanes))])
    keep = _trees(world, group, dlat, exact, root_s, False, limits, lines, kappa)
    change = _trees(world, group, dlat, exact, root_s, True, limits, lines, kappa)
    route_lanes = frozenset(int(p[0]) for p in world.route.pieces)
    foreign, foreign_lane = _foreign(world, route_lanes, cells)
    zones = _zones(world, foreign)
    key = world.lanes.base[np.repeat(np.arange(len(cells[0]) - 1), np.diff(cells[0]))] + cells[1]
    return Network(world, group, dlat, exact, root_s, keep, change, *cells, key, near, kappa, *lines, route_lanes,
                   foreign, rect_axes(foreign), foreign.mean(axis=1), foreign_lane, zones)


def _bends_near(world: World, cells: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """The largest turning per metre [1/m] within :data:`BODY_REACH` of each cell: of the cells
    of its lane, and near the lane's ends of the lanes before and after it (with the jump of
    heading where they join, if any)."""
    ptr, s0, s1, turn = cells
    lanes = world.lanes.lanes
    rate = turn / np.maximum(s1 - s0, 1.0)
    near = np.zeros(len(s0))
    head, tail = np.zeros(len(lanes)), np.zeros(len(lanes))  # rates near each lane's start / end
    for i in range(len(lanes)):  # per lane: cells within a body's reach of each other
        a, b = ptr[i], ptr[i + 1]
        meet = (s0[None, a:b] <= s1[a:b, None] + BODY_REACH) & (s1[None, a:b] >= s0[a:b, None] - BODY_REACH)
        near[a:b] = np.where(meet, rate[None, a:b], 0.0).max(axis=1)
        head[i] = rate[a:b][s0[a:b] <= BODY_REACH].max(initial=0.0)
        tail[i] = rate[a:b][s1[a:b] >= lanes[i].length - BODY_REACH].max(initial=0.0)
    for ln in lanes:
        i = ln.index
        a, b = ptr[i], ptr[i + 1]
        for q in ln.successors:  # across the joint, both ways
            jump = abs((lanes[q].heading[0] - ln.heading[-1] + math.pi) % (2 * math.pi) - math.pi)
            end = s1[a:b] >= ln.length - BODY_REACH
            near[a:b] = np.where(end, np.maximum(near[a:b], max(head[q], jump)), near[a:b])
            qa, qb = ptr[q], ptr[q + 1]
            start = s0[qa:qb] <= BODY_REACH
            near[qa:qb] = np.where(start, np.maximum(near[qa:qb], max(tail[i], jump)), near[qa:qb])
    return near
