"""Batched rollouts (backends agree, boxes follow poses), actuation maps, parameter overrides."""

from __future__ import annotations

import signal

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from twolevel.models import actuation as act, fourwheel as fw
from twolevel.models.obb import box_corners
from twolevel.models.ops import NP
from twolevel.models.params import BicycleParams, InvalidParameterError, UnknownParameterError, VehicleParams
from twolevel.models import rollout as rollout_module
from twolevel.models.rollout import compiled_available, rollout, rollout_accel

P = VehicleParams()


def _controls(K: int, H: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.stack([rng.uniform(-0.3, 0.3, (K, H)), rng.uniform(-1, 1, (K, H))], axis=-1)


@pytest.mark.parametrize("backend", ["casadi", "casadi-vm"])
def test_casadi_backends_match_numpy(backend: str) -> None:
    x0 = fw.initial_state(v=12.0)
    u = _controls(5, 10)
    ref = rollout(x0, u, 0.1, P, backend="numpy")
    got = rollout(x0, u, 0.1, P, backend=backend)
    np.testing.assert_allclose(got.states, ref.states, atol=1e-9)
    ua = np.stack([u[..., 0], 4 * u[..., 1]], axis=-1)
    np.testing.assert_allclose(rollout_accel(x0, ua, 0.1, P, backend=backend).states,
                               rollout_accel(x0, ua, 0.1, P, backend="numpy").states, atol=1e-9)


def test_rollout_shapes_and_boxes() -> None:
    r = rollout(fw.initial_state(v=8.0), _controls(3, 10), 0.1, P)
    assert r.states.shape == (3, 11, fw.NX) and r.boxes.shape == (3, 11, 4, 2)
    np.testing.assert_allclose(r.states[:, 0], np.broadcast_to(fw.initial_state(v=8.0), (3, fw.NX)))
    s = r.states
    np.testing.assert_allclose(r.boxes, box_corners(s[..., 0], s[..., 1], s[..., 2], 4.22, 1.8))
    np.testing.assert_allclose(r.boxes.mean(axis=-2), s[..., :2], atol=1e-12)  # centred on the CoG


def test_rollout_rejects_bad_shapes() -> None:
    with pytest.raises(ValueError):
        rollout(np.zeros(4), _controls(1, 10), 0.1)
    with pytest.raises(ValueError):
        rollout(fw.initial_state(), np.zeros((2, 10, 3)), 0.1)


def test_compiled_backend_is_available_here() -> None:
    assert compiled_available()  # gcc is installed on the project's machines


def test_accel_round_trip_and_saturation() -> None:
    v = np.linspace(1.0, 30.0, 30)
    a = np.linspace(-8.5, 2.5, 30)  # inside what the car can do at every speed here
    np.testing.assert_allclose(act.accel_from_gamma(act.gamma_from_accel(a, v, P), v, P), a, atol=1e-9)
    assert np.all(act.gamma_from_accel(np.full(3, 50.0), np.array([1.0, 10.0, 30.0]), P) == 1.0)
    assert act.gamma_from_accel(-50.0, 10.0, P) == -1.0
    full_brake = act.accel_from_gamma(-1.0, 10.0, P)
    assert -0.97 * P.mu * 9.81 < full_brake < -0.9 * P.mu * 9.81


def test_closed_loop_acceleration_tracks_the_command() -> None:
    x0 = fw.initial_state(v=10.0)
    for a in (-6.0, -2.0, 1.0, 3.0):
        s = rollout_accel(x0, np.tile([0.0, a], (1, 10, 1)), 0.1, P).states[0]
        achieved = np.diff(s[3:, 3]) / 0.1  # after the first 0.2 s of load-transfer lag
        np.testing.assert_allclose(achieved, a, rtol=0.03, atol=0.03)


def test_wheel_torques_respect_friction_and_limits() -> None:
    fz = [3000.0, 3000.0, 2500.0, 2500.0]
    drive, brake = act.wheel_torques(1.0, 5.0, fz, P)
    assert drive[0] == 0.0 and drive[1] == 0.0  # rear-wheel drive
    assert all(d / P.R_w <= P.mu * act.tyre_grip(f, P) + 1e-9 for d, f in zip(drive, fz))
    drive, brake = act.wheel_torques(-1.0, 5.0, fz, P)
    assert all(d == 0.0 for d in drive)
    assert all(0.0 < b <= P.brake_torque_max for b in brake)
    assert all(b / P.R_w <= P.brake_friction_use * P.mu * act.tyre_grip(f, P) + 1e-9 for b, f in zip(brake, fz))


def test_overrides() -> None:
    p = P.with_overrides({"mu": 0.5, "m": 1500})
    assert p.mu == 0.5 and p.m == 1500.0 and P.mu == 1.0
    with pytest.raises(UnknownParameterError) as err:
        P.with_overrides({"muu": 0.5})
    assert err.value.suggestion == "mu" and "did you mean 'mu'" in str(err.value)
    with pytest.raises(InvalidParameterError):
        P.with_overrides({"m": -3})
    with pytest.raises(InvalidParameterError):
        P.with_overrides({"m": "heavy"})
    assert BicycleParams().with_overrides({"l_f": 2.5}).l_f == 2.5
    with pytest.raises(UnknownParameterError):
        BicycleParams().with_overrides({"wheelbase": 2.5})


def test_compiling_leaves_nothing_in_the_working_directory(tmp_path, monkeypatch) -> None:
    """casadi's JIT wrote jit_tmp*.c and tmp_casadi_compiler_shell*.so into the current folder
    (and so into the repository after `make run`) (regression)."""
    import subprocess
    import sys

    code = (
        "import numpy as np\n"
        "from twolevel.models import fourwheel as fw, rollout as r\n"
        "assert r.compiled_available()\n"
        "r.rollout(fw.initial_state(v=5.0), np.zeros((3, 10, 2)), 0.1, backend='casadi')\n"
    )
    subprocess.run([sys.executable, "-c", code], cwd=tmp_path, check=True)
    assert list(tmp_path.iterdir()) == []


def test_a_ctrl_c_while_the_compiler_runs_is_not_lost(tmp_path) -> None:
    """casadi's JIT ran the compiler with system(), which ignores SIGINT meanwhile: a Ctrl-C then
    was discarded and the run went on (regression). The signal is sent once the compiler runs."""
    import subprocess
    import sys

    code = (
        "import os, signal, threading, time\n"
        "from dataclasses import replace\n"
        "from twolevel import interruption\n"
        "from twolevel.models import rollout as r\n"
        "from twolevel.models.params import VehicleParams\n"
        "interruption.install()\n"
        "def children():\n"
        "    return [c for t in os.listdir('/proc/self/task') for c in open(f'/proc/self/task/{t}/children').read().split()]\n"
        "def interrupt():\n"
        "    while not children():\n"
        "        time.sleep(0.001)\n"
        "    os.kill(os.getpid(), signal.SIGINT)\n"
        "threading.Thread(target=interrupt, daemon=True).start()\n"
        "with interruption.deferred():\n"
        "    r._substep_function(replace(VehicleParams(), m=1234.5), 0.005, True)\n"
        "    print('received', interruption.received())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert out.stdout.split() == ["received", str(int(signal.SIGINT))], out.stderr


@settings(max_examples=200, deadline=None)
@given(a=st.lists(st.floats(-15.0, 0.0), min_size=1, max_size=8), v=st.floats(0.0, 40.0))
def test_the_braking_only_gamma_is_that_of_the_mixed_batch(a, v):
    """γ for decelerations only (a fail-safe's braking: the drive's grip is not computed) is, bit
    for bit, what the same entries get in a batch with an accelerating one (the general path)."""
    p = VehicleParams()
    acc, speed = np.array(a), np.full(len(a), v)
    assume(np.all(act.effective_mass(p) * acc + act.resistance_force(speed, p) < 0))  # braking throughout
    alone = act.gamma_from_accel(acc, speed, p)
    mixed = act.gamma_from_accel(np.append(acc, 2.0), np.append(speed, v), p)
    assert np.array_equal(alone, mixed[:-1])


@settings(max_examples=200, deadline=None)
@given(gamma=st.lists(st.floats(-1.2, 1.2), min_size=1, max_size=12), v=st.lists(st.floats(0.0, 45.0), min_size=1,
                                                                                     max_size=12))
def test_the_acceleration_stopped_at_its_fixed_point_is_that_of_all_iterations(gamma, v):
    """The quasi-static acceleration's fixed-point iteration stops once an iterate repeats bit for
    bit: the same as all 25 iterations (numpy's functions through the casadi-style namespace, which
    always runs them), and at once when every entry brakes."""
    p = VehicleParams()
    n = min(len(gamma), len(v))
    g, speed = np.array(gamma[:n]), np.array(v[:n])
    assert np.array_equal(act.accel_from_gamma(g, speed, p), act.accel_from_gamma(g, speed, p, NP))


@settings(max_examples=40, deadline=None)
@given(K=st.integers(1, 6), H=st.integers(1, 12), accel=st.booleans(), seed=st.integers(0, 2**16),
       v=st.floats(0.0, 40.0), dt=st.sampled_from([0.05, 0.1, 0.2]))
def test_the_fused_compiled_step_is_the_substep_loop_bit_for_bit(K, H, accel, seed, v, dt):
    """One compiled control step (its internal steps looped in C, called through a buffer) gives,
    bit for bit, the states of casadi's virtual machine calling the compiled internal step once
    per substep (the reference), from varied states under varied commands; both agree with numpy."""
    rng = np.random.default_rng(seed)
    x0 = np.array([fw.initial_state(v=v + w) for w in rng.uniform(0.0, 3.0, K)])
    x0[:, 2] = rng.uniform(-np.pi, np.pi, K)
    u = np.stack([rng.uniform(-0.4, 0.4, (K, H)), rng.uniform(-9.0, 3.0, (K, H)) if accel
                  else rng.uniform(-1.0, 1.0, (K, H))], axis=-1)
    fused = rollout_accel(x0, u, dt, P) if accel else rollout(x0, u, dt, P)
    ref = rollout_module._simulate(x0, u, dt, P, "casadi", accel, fused=False)
    assert np.array_equal(fused.states, ref.states)
    if K * H <= 6:  # the numpy backend loops in Python: a few only
        np.testing.assert_allclose(fused.states, rollout_module._simulate(x0, u, dt, P, "numpy", accel).states,
                                   rtol=1e-9, atol=1e-9)
