"""Work budgets of a command: memory and time estimated from its inputs, checked before any work.

A runaway input (a record of millions of samples, ``--particles 2e9``, a sensitivity study of
a billion runs) gets one sentence before anything is allocated instead of minutes of silence
or an exhausted memory; ``--no-limits`` lifts the budgets. Command modules reach these names
through :mod:`workbench.cli.common`.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = [
    "IDENTIFY_BASE_BYTES",
    "IDENTIFY_BYTES_PER_SAMPLE",
    "IDENTIFY_SECONDS_PER_SAMPLE",
    "MEMORY_BUDGET_GB",
    "PARTICLE_NUMBERS",
    "TIME_BUDGET_MIN",
    "add_no_limits",
    "check_budget",
    "check_particles",
    "check_record_size",
]

#: Work budgets of one command, checked against estimates before any long computation
#: (:func:`check_budget`): what a modest laptop gives one command without swapping or a wait
#: that looks like a hang. Each command estimates its memory and time from its inputs with
#: coefficients measured on small runs (see the command's estimate); ``--no-limits`` lifts both.
MEMORY_BUDGET_GB = 2.0
TIME_BUDGET_MIN = 30.0

#: Peak memory of identifying a record [bytes]: the interpreter, its libraries and the
#: compiled filter, then the problem, the filter's per-step clouds and the result per record
#: sample; measured as the peak resident size of the default identification (RBPF, 256
#: particles) of simulated 200 Hz walks of 12 000 (0.210 GB) and 48 000 samples (0.395 GB),
#: a straight line through both (10 M samples: 51 GB; the run that found it had reached 4.4
#: GB in 150 s). Every command that identifies, inspects or criticises one record checks it.
IDENTIFY_BASE_BYTES = 150e6
IDENTIFY_BYTES_PER_SAMPLE = 5100.0
#: Computing time of one identification per record sample [s]: the exact default took
#: about 4.5 s of one core (beyond the interpreter's start) on seed_individual's 6000
#: samples; the filters take longer, so for them it is a lower bound.
IDENTIFY_SECONDS_PER_SAMPLE = 7.5e-4
#: Least memory of one particle of a filter [bytes]: its force coefficients (2 n + 1), C, K
#: and the state's mean and covariance (six numbers), in three copies (the cloud, its
#: resampled copy and the proposal); the filters hold more, so this is a lower bound.
PARTICLE_NUMBERS = 7


def add_no_limits(group: Any) -> None:
    """Add ``--no-limits``, which lifts the memory and time budgets of :func:`check_budget`.

    Parameters
    ----------
    group : argparse.ArgumentParser or argument group
    """
    group.add_argument(
        "--no-limits",
        action="store_true",
        help=f"run even when the estimated memory is over {MEMORY_BUDGET_GB:g} GB or the "
        f"estimated time over {TIME_BUDGET_MIN:g} min (refused by default, before any work)",
    )


def check_budget(
    args: argparse.Namespace, what: str, fix: str, *, memory_gb: float = 0.0, minutes: float = 0.0
) -> None:
    """Refuse work whose estimated memory or time is over the budget, unless ``--no-limits``.

    Called before the long computation, so that a runaway input gets one sentence instead of
    minutes of silence or an exhausted memory. Work of a minute or more that goes ahead is
    announced on stderr with its estimate (not under ``--json``), so that it says something
    from its start.

    Parameters
    ----------
    args : argparse.Namespace
        The command's arguments (``no_limits``).
    what : str
        The work, in the user's words (``"hsi with 1000 modes and 20 crossings"``).
    fix : str
        How to make it smaller, without a trailing full stop.
    memory_gb, minutes : float
        The command's estimates.

    Raises
    ------
    UsageError
        The estimate, the budget, the fix and ``--no-limits``, in one sentence.
    """
    from workbench.errors import UsageError

    over = None
    if memory_gb > MEMORY_BUDGET_GB:
        over = f"about {memory_gb:.3g} GB of memory, over the {MEMORY_BUDGET_GB:g} GB budget"
    elif minutes > TIME_BUDGET_MIN:
        over = f"{_duration(minutes)} of computing, over the {TIME_BUDGET_MIN:g} min budget"
    if over is not None and not getattr(args, "no_limits", False):
        # A command without --no-limits (batch's shared settings) must not offer it.
        lift = ", or add --no-limits to run it anyway" if hasattr(args, "no_limits") else ""
        raise UsageError(f"{what} needs {over}; {fix}{lift}")
    if minutes >= 1 and not getattr(args, "json", False):
        # A progress bar may first move only after a long first chunk: say what to expect.
        print(f"workbench: {what}: {_duration(minutes)} estimated", file=sys.stderr)


def check_record_size(args: argparse.Namespace, record: Any, command: str) -> None:
    """Refuse a record too long to identify, inspect or criticise, before any work.

    Parameters
    ----------
    args : argparse.Namespace
    record : Record
        The loaded record (its sample count).
    command : str
        The command's name, for the sentence.
    """
    check_budget(
        args,
        f"{command} on {record.name} ({record.n_samples} samples)",
        f"{command} shorter parts of it (split the file) or resample it to a lower rate",
        memory_gb=(IDENTIFY_BASE_BYTES + IDENTIFY_BYTES_PER_SAMPLE * record.n_samples) / 1e9,
    )


def check_particles(args: argparse.Namespace, settings: Any) -> None:
    """Refuse a particle count whose cloud alone is over the memory budget, before any work."""
    n = getattr(settings.method, "n_particles", None)
    if not n:
        return
    numbers = 3 * (2 * settings.model.harmonics + 1 + PARTICLE_NUMBERS)
    check_budget(
        args,
        f"--particles {n}",
        "give fewer particles (the rbpf needs a few hundred, the pf a few thousand)",
        memory_gb=8.0 * numbers * n / 1e9,
    )


def _duration(minutes: float) -> str:
    if minutes < 1:
        return "under a minute"
    return f"about {minutes:.0f} min" if minutes < 120 else f"about {minutes / 60:.3g} h"
