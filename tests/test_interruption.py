"""SIGINT, SIGTERM and SIGHUP handled alike, deferred to checkpoints, never lost
(:mod:`twolevel.interruption`), in this process with its handlers restored afterwards; real
``twolevel`` processes are interrupted in ``tests/sim/test_interruptions.py``."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import pytest

from twolevel import interruption


@pytest.fixture
def installed():
    saved = {s: signal.getsignal(s) for s in interruption.SIGNALS}
    interruption._state.installed = False
    interruption.clear()
    assert interruption.install()
    yield
    for s, h in saved.items():
        signal.signal(s, h)
    interruption._state.installed = False
    interruption.clear()


@pytest.mark.parametrize("signum", interruption.SIGNALS)
def test_a_signal_outside_any_block_raises_at_once(installed, signum: int) -> None:
    with pytest.raises(interruption.Interrupted) as err:
        os.kill(os.getpid(), signum)
        signal.pthread_sigmask(signal.SIG_BLOCK, [])  # a bytecode boundary for the handler to run at
    assert err.value.signum == signum and isinstance(err.value, KeyboardInterrupt)


def test_a_deferred_signal_raises_at_every_checkpoint_until_cleared(installed) -> None:
    with interruption.deferred():
        os.kill(os.getpid(), signal.SIGTERM)
        total = sum(range(1000))  # work goes on: the signal is only recorded
        assert total == 499500 and interruption.received() == signal.SIGTERM
        for _ in range(2):  # one swallowed by compiled code is raised again at the next checkpoint
            with pytest.raises(interruption.Interrupted, match="SIGTERM"):
                interruption.checkpoint()
    interruption.clear()
    interruption.checkpoint()


def test_a_second_signal_while_deferred_raises_at_once(installed) -> None:
    with interruption.deferred():
        os.kill(os.getpid(), signal.SIGHUP)
        with pytest.raises(interruption.Interrupted) as err:
            os.kill(os.getpid(), signal.SIGINT)
            signal.pthread_sigmask(signal.SIG_BLOCK, [])
    assert err.value.signum == signal.SIGINT  # the one that raised


def test_a_first_signal_raises_at_once_inside_prompt_even_when_deferred(installed) -> None:
    with interruption.deferred():
        with pytest.raises(interruption.Interrupted) as err:
            with interruption.prompt():
                os.kill(os.getpid(), signal.SIGTERM)
                signal.pthread_sigmask(signal.SIG_BLOCK, [])
                pytest.fail("the signal was held")
        assert err.value.signum == signal.SIGTERM
        with pytest.raises(interruption.Interrupted):  # recorded too: the next checkpoint raises again
            interruption.checkpoint()
        with pytest.raises(interruption.Interrupted):  # one received before the block raises at its start
            with interruption.prompt():
                pytest.fail("entered the block after a signal")
    interruption.clear()
    with interruption.deferred(), interruption.prompt(), interruption.shielded():
        os.kill(os.getpid(), signal.SIGINT)  # a shield inside still holds it
        signal.pthread_sigmask(signal.SIG_BLOCK, [])
    assert interruption.received() == signal.SIGINT


def test_nothing_raises_inside_a_shield(installed) -> None:
    with interruption.shielded():
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)
        interruption.checkpoint()  # a no-op inside the shield
    with pytest.raises(interruption.Interrupted, match="Ctrl-C"):
        interruption.checkpoint()


def test_descriptions_and_exit_codes() -> None:
    assert interruption.describe(None) == interruption.describe(signal.SIGINT) == "interrupted by the user (Ctrl-C)"
    assert interruption.describe(signal.SIGTERM) == "interrupted by SIGTERM"
    assert [interruption.exit_code(s) for s in (None, signal.SIGTERM, signal.SIGHUP)] == [130, 143, 129]


def test_without_install_checkpoints_never_raise() -> None:
    out = subprocess.run([sys.executable, "-c", "from twolevel import interruption as i; i.checkpoint(); print('ok')"],
                         capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "ok"
