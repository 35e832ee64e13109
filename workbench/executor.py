"""The study executor: run tasks in this process, a local pool or a Dask cluster.

Batch identification, sensitivity studies and other study-scale jobs hand it a picklable
function and a list of tasks; it yields the results as they finish. Determinism is the
caller's part: every task carries its own seed (derived from the task, never from its
position or from the worker that runs it), so the results do not depend on the number of
workers or the order in which they finish; callers sort what they collect.

- one worker: in this process, in order;
- several: a local ``ProcessPoolExecutor`` with the ``spawn`` start method (no state of the
  parent leaks into the workers, and the same code runs on every platform; scripts that start
  several workers need the ``if __name__ == "__main__":`` guard); each worker watches its
  parent and ends when the parent is gone, killed outright (kill -9) included;
- ``scheduler``: a Dask distributed cluster at that address (``pip install 'workbench[dask]'``),
  with one named task per item so the cluster's dashboard says what runs.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

from workbench.errors import UsageError

__all__ = ["run_tasks"]

T = TypeVar("T")
R = TypeVar("R")


def _serial(fn: Callable[[T], R], tasks: Sequence[T]) -> Iterator[R]:
    for task in tasks:
        yield fn(task)


def _pool(fn: Callable[[T], R], tasks: Sequence[T], workers: int) -> Iterator[R]:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    ctx = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=ctx,
        initializer=_exit_with_parent,
        initargs=(os.getpid(), _PARENT_POLL_S),
    )
    try:
        futures = [pool.submit(fn, t) for t in tasks]
        for fut in as_completed(futures):
            yield fut.result()
    except BaseException:
        # Interrupted (Ctrl-C, SIGTERM turned into KeyboardInterrupt by the command line) or
        # abandoned: the pool's own exit would wait for every running task, and a killed
        # parent would leave its workers running re-parented. Stop them now instead.
        _stop_workers(pool)
        raise
    else:
        pool.shutdown(wait=True)


#: How often a pool worker looks whether its parent is still there [s].
_PARENT_POLL_S = 0.5


def _exit_with_parent(parent_pid: int, poll_s: float) -> None:
    """Pool worker initializer: end this worker as soon as the process that started it is gone.

    A parent killed outright (kill -9, the out-of-memory killer) cannot stop its workers;
    they would wait for tasks for ever, holding memory and the resource tracker. The
    parent's death re-parents the worker, so a daemon thread that sees its parent id change
    ends the worker (and the tracker, once no worker holds it, ends too).

    Parameters
    ----------
    parent_pid : int
        The process id of the parent.
    poll_s : float
        Seconds between looks.
    """
    import threading

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(poll_s)
        os._exit(1)  # no clean-up to wait for: the parent that would collect results is gone

    threading.Thread(target=watch, name="workbench-parent-watch", daemon=True).start()


def _stop_workers(pool: Any) -> None:
    """Cancel the queued tasks and terminate the pool's processes, waiting until they are gone."""
    # The executor offers no public way to terminate before Python 3.14
    # (``terminate_workers``); its process table is the documented-in-source way in.
    procs = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in procs:
        if proc.is_alive():
            proc.terminate()
    for proc in procs:
        proc.join(timeout=10)
        if proc.is_alive():  # ignored SIGTERM: no choice left
            proc.kill()
            proc.join(timeout=5)


def _dask(
    fn: Callable[[T], R], tasks: Sequence[T], address: str, keys: Sequence[str]
) -> Iterator[R]:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise UsageError(
            "'scheduler' needs Dask distributed; install it with pip install 'workbench[dask]'",
            parameter="scheduler",
        ) from None
    try:
        client = Client(address, timeout="20s")
    except (OSError, TimeoutError) as err:
        raise UsageError(
            f"'scheduler' {address}: cannot reach a Dask scheduler there ({err}); start one "
            "(dask scheduler) or check the address",
            parameter="scheduler",
        ) from None
    try:
        futures = client.map(fn, list(tasks), key=list(keys))
        for fut in as_completed(futures):
            yield fut.result()
    finally:
        client.close()


def run_tasks(
    fn: Callable[[T], R],
    tasks: Sequence[T],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    keys: Sequence[str] | None = None,
    label: str = "workbench",
) -> Iterator[R]:
    """Yield ``fn(task)`` for every task as the runs finish (module docstring).

    Parameters
    ----------
    fn : callable
        A module-level (picklable) function of one task.
    tasks : sequence
        Picklable tasks.
    workers : int, default 1
        Local processes; 1 runs in this process, in order.
    scheduler : str, optional
        Address of a Dask scheduler (overrides ``workers``).
    keys : sequence of str, optional
        Unique Dask task names, one per task (default ``label-i``).
    label : str
        Prefix of the default Dask task names.

    Returns
    -------
    iterator
        The results, in the order the runs finish.
    """
    if isinstance(workers, bool) or int(workers) != workers or workers < 1:
        raise UsageError(
            f"'workers' must be a whole number of at least 1, got {workers!r}", parameter="workers"
        )
    if scheduler:
        names = list(keys) if keys is not None else [f"{label}-{i}" for i in range(len(tasks))]
        return _dask(fn, tasks, scheduler, names)
    if workers > 1 and len(tasks) > 1:
        return _pool(fn, tasks, int(workers))
    return _serial(fn, tasks)
