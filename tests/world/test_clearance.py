"""The lateral clearance a passed road user is owed (twolevel/world/clearance.py): a vehicle
0.5 m, a cyclist or pedestrian 1.5 m at urban limits and 2 m above (StVO §5(4)); and the MPC's
reference lays a pass of a cyclist out with it, which does not fit in the ego's lane."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from helpers.world_files import load_world
from twolevel.control.high_level.reference import reference
from twolevel.control.high_level.settings import MPCSettings
from twolevel.models.params import BicycleParams
from twolevel.world.assumptions import CYCLIST, PEDESTRIAN, VEHICLE
from twolevel.world.clearance import URBAN_LIMIT, passing_clearance

ROOT = Path(__file__).resolve().parents[2]


@settings(max_examples=200, deadline=None)
@given(users=st.lists(st.sampled_from([VEHICLE, CYCLIST, PEDESTRIAN]), min_size=1, max_size=6),
       limit=st.floats(1.0, 40.0))
def test_the_clearance_by_road_user_and_limit(users, limit):
    """Element by element as the scalar call gives it; vulnerable users get more than vehicles
    and more out of town than in it."""
    got = passing_clearance(np.array(users), limit)
    for u, g in zip(users, got):
        assert g == passing_clearance(u, limit)
        if u == VEHICLE:
            assert g == 0.5
        else:
            assert g == (1.5 if limit <= URBAN_LIMIT else 2.0)
            assert g > passing_clearance(VEHICLE, limit)


def _reference_behind_the_cyclist(user: int):
    """The MPC's reference for the ego 20 m behind the cyclist of cyclist_ahead (near the right
    edge of its lane, 5 m/s) at its pace, the cyclist predicted as road user ``user``."""
    w = load_world(ROOT / "scenarios" / "everyday" / "cyclist_ahead.yaml")
    ids = list(w.parts.ids)
    bike = ids.index("cyclist")
    w = dataclasses.replace(w, parts=dataclasses.replace(
        w.parts, user=np.where(np.arange(len(ids)) == bike, user, w.parts.user)))
    x0 = np.array([float(w.traffic0.x[bike]) - 20.0, -1.75, 0.0, 5.0])
    return w, bike, reference(w, x0, 0.0, w.traffic0, MPCSettings(), BicycleParams())


def test_a_cyclist_is_not_passed_within_the_lane() -> None:
    """Regression: the reference laid the pass of a cyclist out 0.5 m beside it, which fits in the
    ego's 3.5 m lane, so the MPC planned to squeeze past (and the safety layer refuted it). Owed
    1.5 m, the pass does not fit within the lane; as a vehicle of its size it would."""
    w, bike, ref = _reference_behind_the_cyclist(CYCLIST)
    assert ref.front is not None and ref.front.index == bike
    half = 0.5 * (w.ego.width + float(w.parts.width[bike]))
    inside = 1.75 - w.ego.width / 2  # the farthest left the ego's centre may be with its body in the lane
    assert ref.lateral >= half + 1.5
    assert ref.front.e + half + 1.5 > inside  # it does not fit in the lane
    assert not ref.sides[0] or ref.oncoming  # passed over the oncoming lane or not at all
    w, bike, ref = _reference_behind_the_cyclist(VEHICLE)
    assert ref.lateral == pytest.approx(half + 0.5) and ref.sides[0] and not ref.oncoming
