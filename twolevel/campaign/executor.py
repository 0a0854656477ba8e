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
"""

from __future__ import annotations

import concurrent.futures as cf
import multiprocessing
import os
from typing import Any, Callable

__all__ = ["Executor", "make_executor", "pin_threads", "worker_threads", "THREAD_VARIABLES", "ExecutorError"]

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

    n = workers or cpus()
    return cf.ProcessPoolExecutor(max_workers=n, mp_context=multiprocessing.get_context("spawn"), initializer=pin_threads)


def worker_threads() -> dict[str, str | None]:
    """The thread settings of the process this runs in (to check what a worker was given)."""
    return {name: os.environ.get(name) for name in THREAD_VARIABLES}
