"""Errors the workbench reports to its users.

Every problem a user can cause (a bad file, a wrong flag, a record that cannot hold steps)
is raised as a :class:`WorkbenchError` whose message is one plain sentence naming the file,
the place in it and the fix. The command line prints that sentence and exits non-zero; it
never shows a traceback for these.
"""

from __future__ import annotations

import errno
from os import PathLike


class WorkbenchError(ValueError):
    """A problem the user can fix; ``str(err)`` is the one sentence to show them.

    It is a :class:`ValueError` (a bad value reached the workbench), so code that guards a
    call with ``except ValueError`` catches it as it would numpy's or pandas' own.
    """

    exit_code: int = 2


class InputError(WorkbenchError):
    """Bad input data: a file, a column, a row or a value that the workbench cannot use.

    Parameters
    ----------
    source : str or path-like
        The file (or other origin, for example ``"--mass"``) the problem is in.
    where : str
        The place inside it: ``"column 'grf'"``, ``"row 17"``, ``"whole file"``.
    problem : str
        What is wrong, in plain words, without a trailing full stop.
    fix : str
        What the user should do about it, without a trailing full stop.
    """

    def __init__(self, source: str | PathLike[str], where: str, problem: str, fix: str):
        self.source = str(source)
        self.where = where
        self.problem = problem
        self.fix = fix
        super().__init__(f"{self.source}, {where}: {problem}; {fix}.")


class UsageError(WorkbenchError):
    """An API argument or command-line option that does not make sense (not tied to a file).

    Library code names the parameter in its own words and quotes: ``"'highpass_hz' must
    be ..."``; with ``parameter="highpass_hz"`` the command line, which knows its flags,
    can say ``--highpass-hz`` instead (:meth:`naming`).

    Parameters
    ----------
    message : str
        The one sentence.
    parameter : str, optional
        The parameter the sentence is about, as quoted in it.
    """

    def __init__(self, message: str, *, parameter: str | None = None) -> None:
        super().__init__(message)
        self.parameter = parameter

    def naming(self, flags: dict[str, str]) -> str:
        """Return the sentence with the quoted parameter replaced by its flag, if known.

        Parameters
        ----------
        flags : dict
            Parameter name -> command-line flag (``{"highpass_hz": "--highpass-hz"}``).

        Returns
        -------
        str
        """
        text = str(self)
        flag = flags.get(self.parameter or "")
        if flag is None:
            return text
        return text.replace(f"'{self.parameter}'", flag, 1)


class OutputError(WorkbenchError):
    """A result file that could not be written (a full disk, a folder turned read-only).

    Raised by the atomic writers (:mod:`workbench.fileutil`), which leave the target as it
    was, so the sentence can say that nothing half-written is left.

    Parameters
    ----------
    target : str or path-like
        The file that was to be written (never its temporary name).
    error : OSError or str
        What the system said, or why the workbench refused to write there.
    """

    def __init__(self, target: str | PathLike[str], error: OSError | str) -> None:
        self.target = str(target)
        #: Set when the command printed its result before this error (the command line
        #: then prints no second JSON object for the error).
        self.result_printed = False
        self.errno = error.errno if isinstance(error, OSError) else None
        if isinstance(error, str):
            reason, fix = error, "give another file name"
        elif error.errno in _DISK_FULL:
            reason = "the disk is full"
            fix = "free space on that disk or write to another folder"
        else:
            reason = (error.strerror or str(error)).rstrip(".").lower()
            fix = "write to a folder you can write to"
        super().__init__(
            f"could not write {self.target} ({reason}) and left no half-written file; {fix}"
        )


#: errno values of a full disk or an exhausted quota.
_DISK_FULL = {errno.ENOSPC, getattr(errno, "EDQUOT", errno.ENOSPC), errno.EFBIG}


def check_seed(seed: object, where: str = "") -> int:
    """Return ``seed`` as an ``int``, or refuse it in one sentence if it is not a seed.

    The one check of the public functions that take a ``seed``: numpy's generators refuse a
    negative seed only when they are built, deep inside a computation, with a bare
    ``ValueError: expected non-negative integer``.

    Parameters
    ----------
    seed : object
        The value given; a whole number of 0 or more (``int`` or a numpy integer).
    where : str, optional
        The function, put before the sentence (``"sample_pedestrians"``).

    Returns
    -------
    int

    Raises
    ------
    UsageError
        Naming ``'seed'`` (``parameter="seed"``, so that the command line can say
        ``--seed``).
    """
    from operator import index

    try:  # index() takes int and numpy integers, refuses floats and strings
        value = index(seed)  # type: ignore[arg-type]
    except TypeError:
        value = -1
    if isinstance(seed, bool) or value < 0:
        prefix = f"{where}: " if where else ""
        raise UsageError(
            f"{prefix}'seed' must be a whole number of 0 or more, got {seed!r}; pass for "
            "example seed=1",
            parameter="seed",
        )
    return value
