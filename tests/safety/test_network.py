"""The road network view and the polygons: lane groups, trees through junctions, conflict zones,
and the containment and separation the prediction and the checks rely on."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers.safety_worlds import world
from twolevel.safety.network import network_of
from twolevel.safety.polygons import OCTAGON_NORMALS, band_pieces, disc_hull_octagons, lane_point


def lane_ids(w, idx):
    return sorted(w.lanes.lanes[i].id for i in idx if i >= 0)


def test_lanes_of_a_road_in_one_direction_form_a_group():
    w = world("lanes3")
    net = network_of(w)
    assert len(set(net.group.tolist())) == 1
    assert sorted(net.dlat.tolist()) == [0.0, 3.5, 7.0]
    w2 = world("left_turn")
    net2 = network_of(w2)
    i, j = (next(ln.index for ln in w2.lanes.lanes if ln.id == name) for name in ("in_e", "out_w"))
    assert net2.group[i] != net2.group[j]  # opposite directions never


def test_a_lane_tree_follows_every_branch():
    w = world("left_turn")
    net = network_of(w)
    i = next(ln.index for ln in w.lanes.lanes if ln.id == "in_e")
    tr = net.keep
    nodes = range(tr.ptr[i], tr.ptr[i + 1])
    assert lane_ids(w, [tr.ref[n] for n in nodes]) == ["in_e", "left_n", "out_e", "out_n", "thru_e"]
    by_lane = {w.lanes.lanes[tr.ref[n]].id: tr.offset[n] for n in nodes}
    assert by_lane["thru_e"] == by_lane["left_n"] == 90.0 and by_lane["out_e"] == 110.0


def test_conflict_zones_and_other_lanes_of_a_route():
    """The crossing route's zone is where the ego's body meets the crossing lane; a lane that
    only branches off the route (the straight-on lane beside a left turn) is not another lane."""
    w = world("crossing_scn")
    net = network_of(w)
    (z_in, z_out), = net.zones
    assert 100.0 - 80.0 - w.ego.length / 2 - 0.5 <= z_in <= 100.0 - 80.0 - w.ego.length / 2 + 0.5
    assert 103.5 - 80.0 + w.ego.length / 2 - 0.5 <= z_out <= 103.5 - 80.0 + w.ego.length / 2 + 0.5
    w2 = world("left_turn")
    assert lane_ids(w2, set(network_of(w2).foreign_lane.tolist())) == ["in_w", "out_w", "thru_w"]


curved = st.sampled_from([("scenarios/comparison.yaml", "east"), ("scenarios/comparison.yaml", "west"),
                          ("sound_bends", "inner"), ("sound_bends", "outer"), ("left_turn", "left_n")])


@settings(max_examples=80, deadline=None)
@given(curved, st.floats(0, 1), st.floats(0, 1), st.floats(-4, 4), st.floats(0, 4), st.integers(0, 2**31 - 1))
def test_a_band_piece_contains_its_band(which, pick_cell, frac, lat_lo, width, seed):
    """Points of the lane at any s in [a, b] within one cell and any λ in [lo, hi] lie in the
    quad (the centre line continued straight beyond the lane's ends, too)."""
    name, lane_id = which
    w = world(name)
    net = network_of(w)
    li = next(ln.index for ln in w.lanes.lanes if ln.id == lane_id)
    c = net.cell_ptr[li] + int(pick_cell * (net.cell_ptr[li + 1] - net.cell_ptr[li] - 1e-9))
    s0, s1 = net.cell_s0[c], net.cell_s1[c]
    a = s0 + frac * (s1 - s0) * 0.5 - (3.0 if c == net.cell_ptr[li] else 0.0)
    b = s1 + (3.0 if c == net.cell_ptr[li + 1] - 1 else 0.0)
    lo, hi = lat_lo, lat_lo + width
    quad, axes, centre, radius, extent = band_pieces(w.lanes, np.array([li]), np.array([a]), np.array([b]),
                                                      np.array([lo]), np.array([hi]), np.array([net.cell_turn[c]]))
    rng = np.random.default_rng(seed)
    s = rng.uniform(a, b, 200)
    lat = rng.uniform(lo, hi, 200)
    pts, _ = lane_point(w.lanes, np.full(200, li), s, lat)
    proj = np.einsum("ad,pd->pa", axes[0], pts)
    box = np.einsum("ad,vd->va", axes[0], quad[0])
    assert np.all((proj >= box.min(0) - 1e-6) & (proj <= box.max(0) + 1e-6))
    assert np.all(np.hypot(*(pts - centre[0]).T) <= radius[0] + 1e-6)
    assert np.all(np.abs(pts - centre[0]) <= extent[0] + 1e-6)


@settings(max_examples=200, deadline=None)
@given(st.floats(-20, 20), st.floats(-20, 20), st.floats(0, 10), st.floats(-20, 20), st.floats(-20, 20),
       st.floats(0, 10))
def test_an_octagon_contains_the_hull_of_its_two_discs(x0, y0, r0, x1, y1, r1):
    octa, centre, radius = disc_hull_octagons(np.array([x0, y0]), np.array(r0), np.array([x1, y1]), np.array(r1))
    ang = np.linspace(0, 2 * np.pi, 64)
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    lam = np.linspace(0, 1, 5)[:, None, None]
    pts = ((1 - lam) * (np.array([x0, y0]) + r0 * ring) + lam * (np.array([x1, y1]) + r1 * ring)).reshape(-1, 2)
    support = np.einsum("kd,vd->kv", OCTAGON_NORMALS, octa).max(axis=1)
    assert np.all(pts @ OCTAGON_NORMALS.T <= support + 1e-6)
    assert np.all(np.hypot(*(octa - centre).T) <= radius + 1e-6)
