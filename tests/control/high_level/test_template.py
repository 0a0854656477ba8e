"""Value-only refresh of a step model (twolevel.control.high_level.template): on a shape hit the refreshed
model equals a model built afresh with the same structure, and the controller's plans do not
depend on whether the refresh is used."""

from __future__ import annotations

import numpy as np

from helpers.mpc_worlds import advance, make_world, rules
from twolevel.control.high_level.controller import HighLevelController
from twolevel.control.high_level.settings import MPCSettings
from twolevel.control.high_level.problem import assemble
from twolevel.models import bicycle

EGO = "{start: {lane: middle, s: 20}, speed: 12.0, desired_speed: 13.0}"
ROUTE = "{start: {lane: middle, s: 20}, goal: {lane: middle, s: 900}, stop_at_goal: false}"
TRAFFIC = ("[{id: slow, behaviour: constant_velocity, start: {lane: middle, s: 45}, speed: 6.0},"
           " {id: a, behaviour: constant_velocity, start: {lane: left, s: 24}, speed: 12.5},"
           " {id: b, behaviour: constant_velocity, start: {lane: right, s: 30}, speed: 11.8},"
           " {id: c, behaviour: constant_velocity, start: {lane: left, s: 40}, speed: 12.2}]")
RULES = """input float v
input float v_max
input float d_lead
input float e
speed_limit = always[0:1] (v <= v_max + 0.5);
no_collision = always[0:1] collision_free(1.0);
keep_gap = always[0:1] (d_lead >= 1.0 + 0.5 * v);
on_road = always[0:1] ((e <= 4.5) and (e >= -4.5));
"""


def _fresh(ctrl: HighLevelController, step, past, P, keep):
    return assemble(step, ctrl.step_rules(past, P), ctrl.settings, ctrl.params, stable=True, keep=keep)


def test_refreshed_model_equals_a_fresh_build(tmp_path) -> None:
    w = make_world(tmp_path, "highway.yaml", EGO, ROUTE, TRAFFIC, "controller: {r_near: 40}")
    ctrl = HighLevelController(w, [rules(tmp_path, RULES)], MPCSettings(time_limit=None, monitor=False))
    e = w.ego
    x = np.array([e.x, e.y, e.psi, e.v])
    tr = w.traffic0
    hits = compared = 0
    for k in range(25):
        h0 = ctrl.templates.hits
        step, past, P = ctrl.prepare(x, 0.1 * k, tr, None)
        asm = ctrl.build(step, past, P)
        if ctrl.templates.hits > h0:
            hits += 1
            ref = _fresh(ctrl, step, past, P, ctrl.templates.holding(asm).codes).model
            m = asm.model
            assert m.A.shape == ref.A.shape and m.A.nnz == ref.A.nnz
            assert np.array_equal(m.A.indptr, ref.A.indptr) and np.array_equal(m.A.indices, ref.A.indices)
            np.testing.assert_allclose(m.A.data, ref.A.data, rtol=0, atol=1e-12)
            for a, b in ((m.row_lo, ref.row_lo), (m.row_hi, ref.row_hi), (m.lb, ref.lb), (m.ub, ref.ub), (m.q, ref.q)):
                np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)
            assert abs(m.c0 - ref.c0) <= 1e-12 * max(1.0, abs(ref.c0))
            assert (m.P != ref.P).nnz == 0
            assert [(d.cover_row, d.binaries.tolist()) for d in m.disjunctions] == \
                   [(d.cover_row, d.binaries.tolist()) for d in ref.disjunctions]
            compared += 1
        r = ctrl.solve(x, 0.1 * k, tr, None)
        assert r.ok, r.message
        x = bicycle.step(x, r.controls[0], 0.1, ctrl.params)
        tr = advance(tr, 0.1)
    assert compared >= 10 and hits == compared  # the structure lasts several steps


def test_plans_do_not_depend_on_the_refresh(tmp_path) -> None:
    w = make_world(tmp_path, "highway.yaml", EGO, ROUTE, TRAFFIC, "controller: {r_near: 40}")
    rs = [rules(tmp_path, RULES)]
    ctl = {f: HighLevelController(w, rs, MPCSettings(time_limit=None, monitor=False, refresh=f)) for f in (True, False)}
    e = w.ego
    x = np.array([e.x, e.y, e.psi, e.v])
    tr = w.traffic0
    for k in range(12):
        res = {}
        carry = ctl[True].carry
        for f, c in ctl.items():
            c.carry = carry
            res[f] = c.solve(x, 0.1 * k, tr, None)
        assert res[True].ok and res[False].ok
        # B&B to completion on both: the same optimum (the refreshed model only keeps redundant rows)
        assert abs(res[True].cost - res[False].cost) <= 1e-5 * max(1.0, abs(res[False].cost))
        x = bicycle.step(x, res[True].controls[0], 0.1, ctl[True].params)
        tr = advance(tr, 0.1)
    assert ctl[True].templates.hits > 0
