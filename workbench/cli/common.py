"""What every ``workbench`` subcommand shares: options, record loading, output, settings.

Command modules import this module and nothing else from :mod:`workbench.cli`, so the
command line has no import cycle: :mod:`workbench.cli.main` imports the command modules,
they import this one, and this one imports only the library.

The work budgets live in :mod:`workbench.cli.budgets` and the method's flags in
:mod:`workbench.cli.settings_flags`; this module re-exports them, so that a command module still
needs only this one.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import tempfile
from pathlib import Path
from typing import Any, NoReturn

from workbench.cli.budgets import (
    IDENTIFY_BASE_BYTES,
    IDENTIFY_BYTES_PER_SAMPLE,
    IDENTIFY_SECONDS_PER_SAMPLE,
    MEMORY_BUDGET_GB,
    TIME_BUDGET_MIN,
    add_no_limits,
    check_budget,
    check_particles,
    check_record_size,
)
from workbench.cli.output import emit, emit_after_writing
from workbench.cli.settings_flags import (
    CROSSCHECK_FILTER,
    add_method_flag,
    harmonics_help,
    obs_noise_help,
    particles_help,
    prior_help,
    state_noise_help,
    warn_ignored_method_flags,
)

__all__ = [
    "CROSSCHECK_FILTER",
    "CURRENT_ARGV",
    "EXIT_RECORDS_FAILED",
    "IDENTIFY_BASE_BYTES",
    "IDENTIFY_BYTES_PER_SAMPLE",
    "IDENTIFY_SECONDS_PER_SAMPLE",
    "MEMORY_BUDGET_GB",
    "TIME_BUDGET_MIN",
    "Parser",
    "add_allow_negative_force",
    "add_allow_outside_paths",
    "add_method_flag",
    "add_no_limits",
    "add_rigid_floor_flag",
    "check_budget",
    "check_highpass",
    "check_out",
    "check_particles",
    "check_record_size",
    "emit",
    "emit_after_writing",
    "floats",
    "harmonics_help",
    "identify_settings",
    "load",
    "obs_noise_help",
    "output_options",
    "particles_help",
    "positive_int",
    "prior_help",
    "record_options",
    "safe_key",
    "seed_int",
    "state_noise_help",
    "surface_choice",
    "warn_accepted_negative_force",
    "warn_ignored_method_flags",
    "warn_many_workers",
    "whole_number",
]


#: Exit status of a batch that finished but could not identify every record (their reasons
#: are in failures.csv); distinct from 2, a batch that did not run at all.
EXIT_RECORDS_FAILED = 4

#: The arguments of the running :func:`workbench.cli.main` call (``--json`` usage errors).
CURRENT_ARGV: list[str] = []

#: What argparse should read as a (negative) value rather than an option: a number (also
#: ``-inf``, judged by the option's own check) or a comma-separated list of numbers, so
#: that ``--blf -0.4,0.1`` passes ``-0.4,0.1`` to the option instead of failing with
#: "expected one argument". Argparse's own pattern knows only single numbers.
_NEGATIVE_VALUE = re.compile(
    r"^-((\d+\.?\d*|\.\d+)(e[-+]?\d+)?|inf|infinity|nan)(,.*)?$", re.IGNORECASE
)


class Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors honour ``--json`` (one JSON object on stdout).

    It also reads negative lists of numbers (``-0.4,0.1``) as values (:data:`_NEGATIVE_VALUE`).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        # Argparse's private hook, present in every supported Python; no option of the
        # workbench looks like a negative number, so widening it cannot hide an option.
        self._negative_number_matcher = _NEGATIVE_VALUE

    def error(self, message: str) -> NoReturn:  # argparse's hook for usage errors
        """Print the usage error (also as JSON under ``--json``) and exit with status 2.

        Parameters
        ----------
        message : str
            Argparse's description of the error.
        """
        if "--json" in sys.argv[1:] or "--json" in CURRENT_ARGV:
            print(json.dumps({"error": f"{self.prog}: {message}"}))
        super().error(message)


def output_options() -> Parser:
    """Parent parser of every subcommand: ``--json``.

    Returns
    -------
    Parser
    """
    p = Parser(add_help=False)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    return p


def add_allow_negative_force(group: Any) -> None:
    """Add ``--allow-negative-force`` to a parser or argument group.

    Parameters
    ----------
    group : argparse.ArgumentParser or argument group
    """
    group.add_argument(
        "--allow-negative-force",
        action="store_true",
        help="accept a total force that dips below zero (a synthetic benchmark force such as "
        "the seed study's numerical example) with a warning instead of refusing the record",
    )


def add_allow_outside_paths(group: Any) -> None:
    """Add ``--allow-outside-paths`` (manifest paths outside the manifest's folder).

    Parameters
    ----------
    group : argparse.ArgumentParser or argument group
    """
    group.add_argument(
        "--allow-outside-paths",
        action="store_true",
        help="read manifest paths outside the manifest's folder (absolute or with ..); "
        "refused by default so that a manifest cannot open any file of the machine",
    )


def check_out(path: str | os.PathLike[str], *, is_file: bool = False, flag: str = "--out") -> None:
    """Refuse an ``--out`` (or other output path) that cannot be written, before any work.

    Otherwise a write failure shows only after the work is done. The check has no side
    effect: it finds the nearest existing folder of the output and creates and removes an
    empty hidden file there; the writers create the missing folders later.

    Parameters
    ----------
    path : path-like
        The ``--out`` value.
    is_file : bool, default False
        The output is one file (``simulate``, ``sample``), not a folder.
    flag : str, default "--out"
        The option that gave the path (``hsi --records`` is an output folder too).

    Raises
    ------
    UsageError
        In one sentence naming the flag and the folder in the way.
    """
    from workbench.errors import UsageError

    if not str(path).strip():
        # Path("") is the current folder: the outputs would land among the user's files.
        example = "a file name, e.g. walk.csv" if is_file else "a folder, e.g. results"
        raise UsageError(
            f"{flag} is empty, which would write into the current folder; give {example}"
        )
    target = Path(path)
    fix = "choose a folder you can write to"
    try:
        if is_file and target.is_dir():
            raise UsageError(f"{flag} {path}: this is a folder; give a file name in it")
        if not is_file and target.exists() and not target.is_dir():
            raise UsageError(f"{flag} {path}: this is a file, not a folder; {fix}")
        existing = (target.parent if is_file else target).absolute()
        while not existing.exists():
            existing = existing.parent
    except OSError as err:
        raise UsageError(f"{flag} {path}: {err.strerror or err}; {fix}") from None
    if not existing.is_dir():
        raise UsageError(
            f"{flag} {path}: {existing} is a file, so no folder can be made in it; {fix}"
        )
    try:  # the system's answer, which permission bits alone do not give (read-only mounts)
        with tempfile.NamedTemporaryFile(dir=existing, prefix=".workbench-check-"):
            pass
    except OSError as err:
        raise UsageError(
            f"{flag} {path}: cannot write in {existing} ({err.strerror or err}); {fix}"
        ) from None


def warn_many_workers(workers: int) -> None:
    """Warn on stderr when more local workers are asked for than this computer has cores.

    They would share the cores, run no faster and multiply the memory; the command still
    runs as asked (a user may know better, e.g. on a shared machine's cgroup limits).

    Parameters
    ----------
    workers : int
        The ``--workers`` value.
    """
    try:
        cores = len(os.sched_getaffinity(0))  # the cores this process may use
    except AttributeError:  # not on every platform
        cores = os.cpu_count() or 1
    if workers > cores:
        print(
            f"workbench: warning: --workers {workers} is more than the {cores} cores this "
            f"computer lets the workbench use, so the workers share them and run no faster; "
            f"give --workers {cores} or fewer",
            file=sys.stderr,
        )


def record_options() -> Parser:
    """Parent parser of the subcommands that read one record: mass, pacing, format, ...

    Returns
    -------
    Parser
    """
    from workbench.records.formats import format_names

    p = Parser(add_help=False)
    g = p.add_argument_group("record")
    g.add_argument("--mass", type=float, metavar="KG", help="body mass [kg] (overrides sidecar)")
    g.add_argument("--pacing", type=float, metavar="HZ", help="stated pacing frequency [Hz]")
    g.add_argument("--subject", help="subject identifier")
    g.add_argument(
        "--format",
        dest="fmt",
        choices=format_names(),  # the registry when the parser is built, registered ones too
        help="file format (detected from the file when omitted)",
    )
    g.add_argument(
        "--force-unit",
        choices=["N", "kN", "kgf"],
        default="N",
        help="unit of the force columns in the file; converted to N on loading (default N)",
    )
    g.add_argument(
        "--resample",
        action="store_true",
        help="interpolate irregularly sampled records onto a uniform grid at the median rate",
    )
    g.add_argument(
        "--rescale-to-mass",
        action="store_true",
        help="scale the GRF so its mean over whole steps equals M g (assumes a sensor gain error)",
    )
    g.add_argument(
        "--highpass-hz",
        type=float,
        default=None,
        metavar="F",
        help="high-pass cut-off for the COM response [Hz]; 0 switches it off (default 0.15)",
    )
    add_allow_negative_force(g)
    return p


def load(args: argparse.Namespace) -> Any:
    """Load ``args.record`` with the record options.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed arguments of a subcommand with :func:`record_options`.

    Returns
    -------
    Record
    """
    from workbench import datasets
    from workbench.records.io import load_record

    datasets.require_record(args.record)  # a mistyped name gets the list of names
    reader: Any = load_record if datasets.named(args.record) is None else datasets.load
    record = reader(
        args.record,
        fmt=args.fmt,
        mass_kg=args.mass,
        pacing_hz=args.pacing,
        subject=args.subject,
        resample=args.resample,
        force_unit=args.force_unit,
        allow_negative_force=getattr(args, "allow_negative_force", False),
    )
    warn_accepted_negative_force(record)
    return record


def warn_accepted_negative_force(record: Any) -> None:
    """Say on stderr that a record's force below zero was accepted (``--allow-negative-force``).

    Commands whose JSON does not carry the record's warnings (identify, diagnose, ...) would
    otherwise accept such a record silently.

    Parameters
    ----------
    record : Record
        A loaded record; its ``metadata["warnings"]`` are searched.
    """
    from workbench.records.validation import NEGATIVE_FORCE_ACCEPTED

    for warning in record.metadata.get("warnings", []):
        if NEGATIVE_FORCE_ACCEPTED in str(warning):
            print(f"workbench: warning: {warning}", file=sys.stderr)


def safe_key(name: str) -> str:
    """Make a file-name-safe key of a record name.

    Parameters
    ----------
    name : str

    Returns
    -------
    str
        ``name`` with every character other than letters, digits, ``-`` and ``_`` replaced
        by ``_`` (``"record"`` if empty).
    """
    return "".join(c if c.isalnum() or c in "-_" else "_" for c in name) or "record"


def identify_settings(args: argparse.Namespace) -> Any:
    """Build the identification settings from a subcommand's flags (flags win over ``--config``).

    Subcommands that identify (``identify``, ``sensitivity``, ...) share these flags; a flag a
    subcommand does not offer counts as not given.

    Parameters
    ----------
    args : argparse.Namespace

    Returns
    -------
    IdentifySettings
    """
    from workbench import datasets
    from workbench.inference.pipeline import IdentifySettings

    def flag(name: str) -> Any:
        return getattr(args, name, None)

    overrides = {
        "method": flag("method"),
        "particles": flag("particles"),
        "harmonics": flag("harmonics"),
        "pacing_hz": flag("pacing"),
        "highpass_hz": flag("highpass_hz"),
        "obs_noise": flag("obs_noise"),
        "time_basis": flag("time_basis"),
        "pieces": flag("pieces"),
        "prior": flag("prior"),
        "seed": flag("seed"),
        "state_noise_fraction": flag("state_noise"),
        "observe": flag("observe"),
        "force_proposal": flag("force_proposal"),
        "force_check": False if flag("no_force_check") else None,
        "effects": flag("effects"),
        "rescale_to_mass": True if flag("rescale_to_mass") else None,
        "surface": surface_choice(args),
    }
    if flag("config"):
        settings = IdentifySettings.from_toml(args.config, **overrides)
    elif (name := datasets.named(flag("record"))) is not None:  # its own force model, flags win
        settings = datasets.settings(name, **{k: v for k, v in overrides.items() if v is not None})
    else:
        settings = IdentifySettings().replace(**overrides)
    check_particles(args, settings)
    warn_ignored_method_flags(args, settings.method.name)
    return settings


def add_rigid_floor_flag(parser: Any) -> None:
    """Add ``--rigid-floor`` and ``--surface MODEL`` (how a measured surface motion enters)."""
    parser.add_argument(
        "--rigid-floor",
        action="store_true",
        help="ignore the record's ground_acc column: identify as on a rigid floor instead of "
        "letting the measured surface motion act through K and C (the default), to see "
        "what the surface adds; the same as --surface rigid",
    )
    parser.add_argument(
        "--surface",
        choices=("coupled", "joint", "rigid"),
        default=None,
        help="how the record's ground_acc enters: coupled (default; C and K from the deck's "
        "transmissibility, the force given them), joint (C, K and the force from the time "
        "history together, in every method), rigid (ignored)",
    )


def surface_choice(args: argparse.Namespace) -> str | None:
    """Return the surface model asked for by ``--surface`` / ``--rigid-floor`` (None: default).

    Parameters
    ----------
    args : argparse.Namespace

    Returns
    -------
    str or None
    """
    surface = getattr(args, "surface", None)
    if getattr(args, "rigid_floor", False):
        if surface not in (None, "rigid"):
            from workbench.errors import UsageError

            raise UsageError(f"--rigid-floor contradicts --surface {surface}; give one of them")
        return "rigid"
    return surface


def floats(text: str) -> tuple[float, ...]:
    """Argparse type: a comma-separated list of numbers.

    Parameters
    ----------
    text : str

    Returns
    -------
    tuple of float
    """
    try:
        return tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a comma-separated list of numbers"
        ) from None


def check_highpass(value: float) -> None:
    """Refuse a ``--highpass-hz`` outside the range every command takes, before any work.

    The library checks the same range where it filters, but identification's settings
    refuse a negative value first with other words; checked here, every command says the
    same, before a record is loaded.

    Parameters
    ----------
    value : float
        The ``--highpass-hz`` value (0 switches the filter off).

    Raises
    ------
    UsageError
    """
    from workbench.errors import UsageError
    from workbench.records.preprocess import MAX_HIGHPASS_HZ, MIN_HIGHPASS_HZ

    if value != 0 and not MIN_HIGHPASS_HZ <= value <= MAX_HIGHPASS_HZ:
        raise UsageError(
            f"--highpass-hz {value:g} is outside {MIN_HIGHPASS_HZ:g}-{MAX_HIGHPASS_HZ:g} Hz: "
            "lower cut-offs need minutes of padding and let the integrals drift, higher ones "
            "remove part of the walking fundamental (1-3 Hz); use 0.15 (the seed's) or 0 to "
            "switch the filter off"
        )


def seed_int(text: str) -> int:
    """Argparse type: a random seed, a whole number of 0 or more.

    Checked here, once for every command, so that a negative seed is refused before any work
    (numpy's generators refuse it only when they are built, deep inside a computation).

    Parameters
    ----------
    text : str

    Returns
    -------
    int
    """
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a seed; give a whole number of 0 or more"
        ) from None
    if value < 0:
        raise argparse.ArgumentTypeError(
            f"{text!r} is negative; a seed is a whole number of 0 or more"
        )
    return value


def whole_number(text: str) -> int:
    """Argparse type: a whole number, also written with an exponent (``1e6``).

    Parameters
    ----------
    text : str

    Returns
    -------
    int
    """
    try:
        return int(text)
    except ValueError:
        pass
    # Counts are often written as 1e6; a whole number so written is one.
    try:
        number = float(text)
    except ValueError:
        number = math.nan
    if not (math.isfinite(number) and number.is_integer()):
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    return int(number)


def positive_int(text: str) -> int:
    """Argparse type: a whole number of at least 1 (:func:`whole_number`).

    Parameters
    ----------
    text : str

    Returns
    -------
    int
    """
    value = whole_number(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be at least 1")
    return value
