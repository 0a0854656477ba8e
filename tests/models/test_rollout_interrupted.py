"""A signal raised inside a casadi call is swallowed by casadi's overload dispatch, which then
tries the symbolic overloads and returns a symbolic matrix (regression: a sweep worker signalled
during the low level's warm-up crashed on "Implicit conversion of symbolic CasADi type" instead of
recording the interruption). The rollout turns such a result into the interruption it is."""

from __future__ import annotations

import signal

import casadi as ca
import numpy as np
import pytest

from twolevel import interruption
from twolevel.models import rollout
from twolevel.models.params import VehicleParams


def test_a_symbolic_result_after_a_signal_is_the_interruption(monkeypatch: pytest.MonkeyPatch) -> None:
    x, u = ca.SX.sym("x", 12), ca.SX.sym("u", 2)
    monkeypatch.setattr(rollout, "_batch_function", lambda *a: (lambda *_: ca.SX.zeros(12, 1) * x[0] * u[0]))
    monkeypatch.setattr(interruption._state, "signum", int(signal.SIGTERM))
    try:
        with pytest.raises(interruption.Interrupted):
            rollout.rollout(np.zeros(12), np.zeros((1, 1, 2)), 0.1, VehicleParams(), "casadi-vm")
    finally:
        interruption.clear()
    with pytest.raises(RuntimeError, match="symbolic"):  # no signal: an error, never a symbolic state
        rollout.rollout(np.zeros(12), np.zeros((1, 1, 2)), 0.1, VehicleParams(), "casadi-vm")
