"""The lane trees of a large imported map: grown for every lane at once, they are exactly the
trees a plain breadth-first search from each lane gives (the oracle below), and building them
costs work per lane, not per node (the 476-lane SUMO grid has some 200 000 nodes)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from helpers.safety_worlds import world
from twolevel.safety import network
from twolevel.world.geometry import LaneSet
from twolevel.world.loader import load_scenario
from twolevel.world.world import World, build_world

ROOT = Path(__file__).resolve().parents[2]


def _grid_world(tmp_path: Path) -> World:
    """The 5x5 SUMO grid's import (a plain twolevel map: no SUMO needed), the ego on one lane."""
    path = tmp_path / "grid5.yaml"
    path.write_text(f"""kind: scenario
map: {ROOT / 'examples/sumo/grid5.yaml'}
ego: {{start: {{lane: A0B0_0, s: 20}}, speed: 8}}
route: {{start: {{lane: A0B0_0, s: 20}}, goal: {{lane: B0C0_0, s: 100}}}}
""")
    scn, diags = load_scenario(path)
    assert scn is not None, diags
    return build_world(scn)


def _oracle(w: World, net: network.Network, change: bool) -> list[list[tuple[int, int, float, int, int]]]:
    """Each lane's tree by a breadth-first queue per root: (ref, natural, offset, parent, depth)
    per node, expanded while the node ends within REACH and the tree has fewer than MAX_NODES;
    with lane changes one child per group reached, on the natural lane's successor if any."""
    lanes = w.lanes.lanes
    members = {g: sorted(np.flatnonzero(net.group == g).tolist(), key=lambda i: net.dlat[i])
               for g in set(net.group.tolist())}
    out = []
    for root in range(len(lanes)):
        nodes = [(root, root, 0.0, -1, 0)]
        k = 0
        while k < len(nodes):
            ref, nat, off, _, depth = nodes[k]
            end = off + lanes[ref].length
            if end < network.REACH and len(nodes) < network.MAX_NODES:
                succ: dict[int, tuple[int, int]] = {}
                for m in (members[net.group[ref]] if change else [ref]):
                    for q in lanes[m].successors:
                        key = int(net.group[q]) if change else int(q)
                        natural = int(q) if (nat >= 0 and m == nat) else -1
                        if key not in succ or (natural >= 0 and succ[key][1] < 0):
                            succ[key] = (int(q), natural)
                nodes += [(q, natural, end, k, depth + 1) for q, natural in succ.values()]
            k += 1
        out.append(nodes)
    return out


@pytest.mark.parametrize("change", [False, True])
def test_trees_of_a_large_grid_are_each_lanes_breadth_first_search(tmp_path: Path, change: bool) -> None:
    w = _grid_world(tmp_path)
    net = network.network_of(w)
    trees = net.trees(change)
    expected = _oracle(w, net, change)
    assert len(trees.ptr) == len(w.lanes.lanes) + 1
    assert int(trees.ptr[-1]) > 50_000  # deep trees: many are cut at MAX_NODES
    for root, nodes in enumerate(expected):
        a, b = trees.ptr[root], trees.ptr[root + 1]
        got = list(zip(trees.ref[a:b].tolist(), trees.natural[a:b].tolist(), trees.offset[a:b].tolist(),
                       trees.parent[a:b].tolist(), trees.depth[a:b].tolist()))
        assert got == [(r, n, pytest.approx(o), p, d) for r, n, o, p, d in nodes]


@pytest.mark.parametrize("name", ["lanes3", "left_turn"])
def test_trees_of_small_worlds_are_each_lanes_breadth_first_search(name: str) -> None:
    w = world(name)
    net = network.network_of(w)
    for change in (False, True):
        trees = net.trees(change)
        for root, nodes in enumerate(_oracle(w, net, change)):
            a, b = trees.ptr[root], trees.ptr[root + 1]
            assert trees.ref[a:b].tolist() == [n[0] for n in nodes]
            assert trees.natural[a:b].tolist() == [n[1] for n in nodes]
            assert trees.parent[a:b].tolist() == [n[3] for n in nodes]
            assert np.allclose(trees.offset[a:b], [n[2] for n in nodes])


@pytest.mark.parametrize("where", ["grid", "town"])
def test_building_a_network_costs_work_per_lane_pair_not_per_tree_node(where: str, tmp_path: Path,
                                                                       monkeypatch: pytest.MonkeyPatch) -> None:
    """The per-member work of the trees (interpolating lines and levels, projecting a member's
    boundaries onto the ref lane) is done once per pair of lanes of a group, not once per tree
    node: a node-by-node build called np.interp 275 000 times on the SUMO grid and projected
    16 000 times on the Town-like map; the whole build now stays within a few calls per pair."""
    if where == "grid":
        w = _grid_world(tmp_path)
    else:
        scn, diags = load_scenario(ROOT / "examples/town/safety.yaml")
        assert scn is not None, diags
        w = build_world(scn)
    calls = {"interp": 0, "project": 0}
    interp, project = np.interp, LaneSet.project

    def counted_interp(*args, **kwargs):  # the real functions, counted
        calls["interp"] += 1
        return interp(*args, **kwargs)

    def counted_project(self: LaneSet, *args, **kwargs):
        calls["project"] += 1
        return project(self, *args, **kwargs)

    monkeypatch.setattr(np, "interp", counted_interp)
    monkeypatch.setattr(LaneSet, "project", counted_project)
    net = network._build(w)
    pairs = sum(int((net.group == net.group[i]).sum()) for i in range(len(w.lanes.lanes)))
    assert int(net.keep.ptr[-1]) + int(net.change.ptr[-1]) > 20 * pairs  # many more nodes than pairs
    assert calls["interp"] <= 4 * pairs
    assert calls["project"] <= pairs
