"""The ``workbench`` command: the parser, the dispatch and the exit statuses.

One entry point with subcommands (docs/contracts.md). Every subcommand accepts ``--json`` to print
one JSON object on stdout instead of human text, and writes files only under ``--out``.
Problems the user can fix are reported as one sentence on stderr with exit status 2; an
unexpected internal failure prints one sentence too (exit 3) and shows the traceback only when
``WORKBENCH_DEBUG=1`` is set.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import json
import os
import re
import signal
import stat
import sys
import threading
import traceback
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any

from workbench.cli import (
    criticism,
    crosscheck,
    demo,
    hsi,
    identify,
    population,
    records,
    recovery,
    sensitivity,
    simulate,
)
from workbench.cli.common import (
    CURRENT_ARGV,
    EXIT_RECORDS_FAILED,
    Parser,
    check_highpass,
    check_out,
    output_options,
)
from workbench.errors import UsageError, WorkbenchError

__all__ = [
    "EXIT_INTERNAL_ERROR",
    "EXIT_RECORDS_FAILED",
    "EXIT_USER_ERROR",
    "build_parser",
    "main",
]

#: Exit status of a problem the user can fix.
EXIT_USER_ERROR = 2
#: Exit status of an unexpected internal failure.
EXIT_INTERNAL_ERROR = 3

Handler = Callable[[argparse.Namespace], int]


def build_parser() -> argparse.ArgumentParser:
    """Build the argument parser of the ``workbench`` command.

    Returns
    -------
    argparse.ArgumentParser
        With one subparser per subcommand; each sets ``handler`` to the function that runs it.
    """
    parser = Parser(
        prog="workbench",
        description="Identify, criticise and simulate spring-mass-damper pedestrian models "
        "from vertical ground reaction force records.",
    )
    from workbench import __version__

    parser.add_argument("--version", action="version", version=f"workbench {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    out_opts = output_options()
    records.add_records_parser(sub, out_opts)
    identify.add_identify_parser(sub, out_opts)
    simulate.add_simulate_parser(sub, out_opts)
    sensitivity.add_sensitivity_parser(sub, out_opts)
    hsi.add_hsi_parser(sub, out_opts)
    population.add_population_parser(sub, out_opts)
    recovery.add_recovery_parser(sub, out_opts)
    criticism.add_criticism_parser(sub, out_opts)
    crosscheck.add_crosscheck_parser(sub, out_opts)
    demo.add_demo_parser(sub, out_opts)
    return parser


#: The flag that sets each library parameter, for error messages.
FLAG_FOR_PARAMETER = {
    "method": "--method",
    "particles": "--particles",
    "n_particles": "--particles",
    "harmonics": "--harmonics",
    "pacing_hz": "--pacing",
    "highpass_hz": "--highpass-hz",
    "obs_noise": "--obs-noise",
    "state_noise_fraction": "--state-noise",
    "time_basis": "--time-basis",
    "pieces": "--pieces",
    "prior": "--prior",
    "observe": "--observe",
    "force_proposal": "--force-proposal",
    "seed": "--seed",
    "workers": "--workers",
    "scheduler": "--scheduler",
    "resume": "--resume",
    "factors": "--factors",
    "levels": "--levels",
    "design": "--design",
    "replicates": "--replicates",
    "mode": "--mode",
    "effects": "--effects",
    "surface": "--surface",
    "keep_not_identified": "--keep-not-identified",
}


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``workbench`` command and return its exit status.

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments after the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 for a problem the user can fix, 3 for an internal error, 4 for a
        batch that could not identify every record, 130 when interrupted.
    """
    parser = build_parser()
    CURRENT_ARGV[:] = list(argv) if argv is not None else []
    args = parser.parse_args(argv)
    handler: Handler = args.handler
    with _sigterm_interrupts():
        return _run(args, handler)


@contextlib.contextmanager
def _sigterm_interrupts() -> Iterator[None]:
    """Treat SIGTERM like Ctrl-C while a command runs.

    Python dies on SIGTERM without unwinding, so a batch's pool workers would be left
    running; as a KeyboardInterrupt it unwinds, the executor stops its workers and the
    command exits with status 130. Outside the main thread signals cannot be handled.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _run(args: argparse.Namespace, handler: Handler) -> int:
    """Run a parsed command and turn its errors into messages and exit statuses."""
    try:
        # Options shared by many commands, checked once here before any work.
        if getattr(args, "highpass_hz", None) is not None:
            check_highpass(args.highpass_hz)
        if getattr(args, "out", None) is not None:
            check_out(args.out, is_file=getattr(args, "out_is_file", False))
        _refuse_special_inputs(args)
        if getattr(args, "out", None):
            _check_free_space(args.out)
        return handler(args)
    except UsageError as err:
        # Library messages name their parameters; here the user typed flags.
        _report_error(args, err.naming(FLAG_FOR_PARAMETER))
        return err.exit_code
    except WorkbenchError as err:
        # A result printed before its files failed already carries the error in its JSON.
        _report_error(args, str(err), as_json=not getattr(err, "result_printed", False))
        return err.exit_code
    except OSError as err:
        _report_error(args, _file_error_sentence(args, err))
        return EXIT_USER_ERROR
    except MemoryError:
        _report_error(
            args,
            "ran out of memory; the record or the requested output is too large for this "
            "machine, so cut the record or lower the sample rate or duration",
        )
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("workbench: interrupted", file=sys.stderr)
        return 130
    except Exception as err:  # the user must never see a bare traceback
        if os.environ.get("WORKBENCH_DEBUG"):
            traceback.print_exc()
        _report_error(
            args,
            f"internal error ({type(err).__name__}: {err}); this is a bug in the workbench, "
            "please report it with the command you ran (set WORKBENCH_DEBUG=1 to see the "
            "traceback).",
        )
        return EXIT_INTERNAL_ERROR


#: The temporary name under which a file is written before its atomic rename
#: (:func:`workbench.fileutil.atomic_path`): ``.NAME.RANDOM.tmp``.
_TEMPORARY_NAME = re.compile(r"^\.(?P<name>.+)\.[^.]+\.tmp$")


def _written_name(filename: str | os.PathLike[str]) -> str:
    """Name the file the user asked for, not the temporary file it is written through."""
    path = Path(filename)
    match = _TEMPORARY_NAME.match(path.name)
    return str(path.with_name(match["name"])) if match else str(filename)


def _refuse_special_inputs(args: argparse.Namespace) -> None:
    """Refuse an input given as a pipe, a device, a socket or a symbolic link loop, up front.

    Reading a named pipe waits for a writer for ever and a device such as ``/dev/zero``
    never ends; the record and manifest readers refuse them, and this check does the same
    for every other path a command reads (settings, laws, results, structures), before
    any work. Folders and files that do not exist are left to the commands, which say what
    they expected.
    """
    from workbench.errors import InputError
    from workbench.records.text_table import LINK_LOOP, SPECIAL_FILES, file_problem

    out = getattr(args, "out", None)
    if out:
        # Written by renaming over it: over /dev/null that would replace the device itself.
        with contextlib.suppress(OSError):
            mode = os.lstat(out).st_mode
            if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode) or stat.S_ISLNK(mode)):
                raise UsageError(
                    f"--out {out}: this is a device, a pipe or a socket, not a file or a "
                    "folder; give the name of a file or folder to write"
                )
    for name, value in vars(args).items():
        if name == "out":
            continue
        for item in value if isinstance(value, list) else [value]:
            if not isinstance(item, str | os.PathLike) or not os.path.lexists(item):
                continue
            problem = file_problem(item)
            if problem not in SPECIAL_FILES:
                continue  # a folder, a missing or unreadable file: the command says more
            fix = (
                "point the link at the file itself"
                if problem == LINK_LOOP
                else "give a file saved on disk"
            )
            raise InputError(item, "whole file", problem, fix)


#: Free space an --out disk must have before a command starts [bytes]: a nearly full disk is
#: refused before the computation, whose result a write failing at the end would lose. A
#: larger output that still meets a full disk ends in the atomic writer's sentence.
MIN_FREE_BYTES = 1 << 20


def _check_free_space(out: str | os.PathLike[str]) -> None:
    """Refuse an --out on a disk with less than :data:`MIN_FREE_BYTES` free, before any work."""
    import shutil

    folder = Path(out).absolute()
    while not folder.is_dir() and folder != folder.parent:
        folder = folder.parent
    try:
        free = shutil.disk_usage(folder).free
    except OSError:  # not measurable here: the writers will say if the disk is full
        return
    if free < MIN_FREE_BYTES:
        raise UsageError(
            f"--out {out}: its disk has only {free / 1024:.0f} kB free, less than the "
            f"{MIN_FREE_BYTES >> 20} MB the workbench asks for before it starts; free space "
            "there or choose a folder on another disk"
        )


def _file_error_sentence(args: argparse.Namespace, err: OSError) -> str:
    """Say which file the system refused, whether it was being read or written, and why.

    Outputs are written by :mod:`workbench.fileutil`, which names its files itself; what
    reaches here is mostly an input (a --config, a --laws file) or the making of an output
    folder, so an error is blamed on --out only when the disk refused a write or a folder
    of the output could not be made.
    """
    reason = _SYSTEM_REASONS.get(err.errno or 0) or (err.strerror or str(err)).lower()
    out = getattr(args, "out", None)
    if not err.filename:
        where = f"under --out {out}" if out else "a file"
        return f"could not read or write {where} ({reason}); check the paths and free space"
    name = _written_name(err.filename)
    # A file being made: the disk refused it, or it lies under --out and is not there yet
    # (a folder of the output); an existing file, even under --out, was an input.
    writing = err.errno in _WRITE_REFUSALS or (
        out is not None and _lies_under(name, out) and not os.path.lexists(name)
    )
    if writing and err.errno != errno.ENOENT:
        return (
            f"could not write {name} ({reason}); free space there or choose a folder you can "
            "write to with --out"
        )
    return f"could not read {name} ({reason}); check the path"


#: What the system says only about writing: a full disk or quota, a read-only file system.
_WRITE_REFUSALS = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC), errno.EROFS, errno.EFBIG}

#: The system's reasons in the words of the sentences (its own text names no file).
_SYSTEM_REASONS = {
    errno.ELOOP: "it is a loop of symbolic links that point at each other",
    errno.ENOENT: "it does not exist",
    errno.ENOSPC: "the disk is full",
    errno.EROFS: "the file system is read-only",
    errno.EACCES: "permission denied",
    errno.ENOTDIR: "a part of the path before it is a file, not a folder",
}


def _lies_under(name: str | os.PathLike[str], out: str | os.PathLike[str]) -> bool:
    path, folder = Path(name).absolute(), Path(out).absolute()
    return path == folder or folder in path.parents


def _report_error(args: argparse.Namespace, message: str, *, as_json: bool = True) -> None:
    print(f"workbench: error: {message}", file=sys.stderr)
    if as_json and getattr(args, "json", False):
        print(json.dumps({"error": message}))


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
