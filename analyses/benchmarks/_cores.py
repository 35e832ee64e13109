"""Pin a benchmark to a number of CPUs before numpy starts its thread pools.

Both sides of a benchmark must get the same hardware. Left alone, numpy's BLAS pool starts
one thread per CPU in every process and small matrix products then fight over the cores:
measured with ``pf_throughput.py`` at 2000 particles on a two-core machine, the ``particles``
library's filter took 6.56 s with the default pools and 2.00 s with one thread, while the
workbench's took 1.25 s and 1.31 s, so an unpinned run reported a 5.2x speedup that a pinned
one shows to be 1.5x. Import this module, and call :func:`pin_cores`, before numpy.
"""

from __future__ import annotations

import os


def pin_cores(argv: list[str]) -> int:
    """Pin this process to ``--cores N`` CPUs from ``argv`` (default 1); return N.

    Sets the thread counts of the OpenMP, OpenBLAS and MKL pools to N and the process's CPU
    affinity to the first N allowed CPUs (Linux; elsewhere only the pools are sized).
    """
    cores = 1
    if "--cores" in argv[:-1]:
        cores = max(1, int(argv[argv.index("--cores") + 1]))
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(cores)
    if hasattr(os, "sched_setaffinity"):
        allowed = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, set(allowed[:cores]))
    return cores


def affinity() -> list[int] | None:
    """CPUs this process may run on (None where the platform does not say)."""
    return sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else None
