"""One executor abstraction for every campaign: ``submit(fn, *args) -> Future``, ``map``,
``shutdown``, usable as a context manager (the ``concurrent.futures.Executor`` interface).

* local (the default): a pool of worker processes on this machine, started with ``spawn`` (no
  state inherited from the parent); each worker pins its BLAS/OpenMP threads to one before it
  imports numpy, so N workers use N cores;
* ``tcp://HOST:PORT``: a Dask distributed cluster (``pip install twolevel[dask]``, imported
  only then) through its ``concurrent.futures`` executor; the workers are asked to pin their
  BLAS threads to one as well (a Dask nanny already starts them with one).

Tasks are module-level functions of picklable arguments, so results are the same wherever they
run: a campaign's table does not depend on the executor.

Interruptions (local): each worker leaves the terminal's process group (a Ctrl-C reaches only the
parent) and handles SIGINT, SIGTERM and SIGHUP as one deferred request
(:mod:`twolevel.interruption`). :meth:`LocalExecutor.interrupt` (the parent, on its signal)
cancels what has not started, forwards the signal to every worker — a running simulation stops
at its next checkpoint and records the interruption in its ``run.json``; a case taken after it
ends at once — waits for them to exit (a second signal to the parent, or ``grace`` seconds, and
they are killed) and leaves no process behind.
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
import time
from typing import Any, Callable

__all__ = ["Executor", "LocalExecutor", "make_executor", "pin_threads", "worker_threads", "THREAD_VARIABLES",
           "ExecutorError"]

#: Environment variables that size the BLAS and OpenMP thread pools.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")

Executor = cf.Executor


class ExecutorError(Exception):
    """The executor cannot be made (an unknown scheduler, dask not installed, no cluster there);
    the message says what to do."""


def pin_threads() -> dict[str, str]:
    """Pin this process's BLAS/OpenMP threads to one: the environment for libraries not yet
    loaded, and threadpoolctl (when installed) for those that are. Returns the variables."""
    for name in THREAD_VARIABLES:
        os.environ[name] = "1"
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        pass
    else:
        threadpool_limits(1)
    return {name: os.environ[name] for name in THREAD_VARIABLES}


def _start_worker() -> None:
    """A local worker's start: one BLAS thread, its own process group, signals deferred."""
    from twolevel import interruption

    pin_threads()
    os.setpgid(0, 0)  # the terminal's Ctrl-C goes to the parent alone, which forwards it once
    interruption.install(deferring=True)


class LocalExecutor(cf.ProcessPoolExecutor):
    """Worker processes on this machine (``spawn``), which an interruption stops cleanly."""

    def __init__(self, workers: int) -> None:
        super().__init__(max_workers=workers, mp_context=multiprocessing.get_context("spawn"),
                         initializer=_start_worker)

    def interrupt(self, signum: int, grace: float = 60.0) -> None:
        """Stop on the signal ``signum``: cancel the cases not started, forward ``signum`` to
        every worker and wait until they have exited (killing those still running after
        ``grace`` [s] or a second signal to this process)."""
        from twolevel import interruption

        processes = list((self._processes or {}).values())  # the pool's own table of its workers
        self.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            if p.is_alive():
                try:
                    os.kill(p.pid, signum)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + grace
        while any(p.is_alive() for p in processes) and time.monotonic() < deadline and not interruption.insisted():
            time.sleep(0.05)
        for p in processes:
            if p.is_alive():
                p.kill()
            p.join(5)


class _DaskExecutor(cf.Executor):
    """A Dask client's executor that also closes the client when shut down."""

    def __init__(self, address: str) -> None:
        try:
            from distributed import Client
        except ImportError:
            raise ExecutorError("--scheduler needs Dask: pip install 'twolevel[dask]'") from None
        try:
            self.client = Client(address, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise ExecutorError(f"no Dask scheduler at {address}: {exc}") from None
        self.client.run(pin_threads)
        self._inner = self.client.get_executor(pure=False)

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> cf.Future:
        return self._inner.submit(fn, *args, **kwargs)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        self._inner.shutdown(wait=wait)
        self.client.close()


def make_executor(scheduler: str | None = None, workers: int | None = None) -> cf.Executor:
    """The executor for a campaign: local processes (``workers``, default one per usable core)
    or, with ``scheduler`` = ``tcp://HOST:PORT``, a Dask cluster. Raises :class:`ExecutorError`
    with a message for the user when it cannot be made."""
    if scheduler:
        if not scheduler.startswith(("tcp://", "tls://", "inproc://", "ucx://")):
            raise ExecutorError(f"--scheduler must be an address such as tcp://HOST:PORT, got '{scheduler}'")
        return _DaskExecutor(scheduler)
    if workers is not None and workers < 1:
        raise ExecutorError(f"--jobs must be at least 1, got {workers}")
    from twolevel.sim.provenance import cpus  # the one count of usable cores

    return LocalExecutor(workers or cpus())


def worker_threads() -> dict[str, str | None]:
    """The thread settings of the process this runs in (to check what a worker was given)."""
    return {name: os.environ.get(name) for name in THREAD_VARIABLES}
