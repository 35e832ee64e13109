"""Atomic file output: a result is either fully written or not there at all.

Batch and report jobs may be interrupted; writing to a temporary file in the same folder,
flushing it to disk and renaming it over the target (``os.replace`` is atomic on POSIX and
Windows) means a crash never leaves a half-written file that a later ``--resume`` would
mistake for a finished one.

Every file a command writes goes through here. Files that belong together (a record, its
sidecar and its truth) are written with :func:`atomic_paths` / :func:`atomic_write_texts`:
all to temporary files first, renamed only once all are on disk. A write the system refuses
(a full disk) raises :class:`~workbench.errors.OutputError`, one sentence naming the file
asked for, never its temporary name, and leaves no temporary file behind.
"""

from __future__ import annotations

import contextlib
import json
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from workbench.errors import OutputError

__all__ = [
    "atomic_path",
    "atomic_paths",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "atomic_write_texts",
    "strict_json",
]


def _default_mode(target: Path) -> int:
    """Mode a plain ``open(..., "w")`` would give: the existing file's, else 0666 & ~umask."""
    if target.exists():
        return target.stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``target``; on success move it over ``target``.

    Parameters
    ----------
    target : path-like
        Final file name. Its folder is created if needed.

    Yields
    ------
    Path
        Where the caller writes. Removed again if the body raises.

    Raises
    ------
    OutputError
        When the system refuses a write (a full disk, for one), naming ``target``; the
        target is left as it was.
    """
    with atomic_paths(target) as (tmp,):
        yield tmp


@contextlib.contextmanager
def atomic_paths(*targets: str | os.PathLike[str]) -> Iterator[tuple[Path, ...]]:
    """Yield temporary paths beside ``targets``; when all are written, move them into place.

    For files that belong together (a record and its sidecar): every file is written and
    flushed to disk first, and only then are they renamed, in the order given, so a full disk
    leaves none of them rather than a sidecar without its data. Temporary files are removed
    on any failure.

    Parameters
    ----------
    *targets : path-like
        Final file names, in the order they are moved into place. Their folders are created
        if needed.

    Yields
    ------
    tuple of Path
        Where the caller writes each file.

    Raises
    ------
    OutputError
        When the system refuses a write, naming the target being written.
    """
    finals = [Path(target) for target in targets]
    temporaries: list[Path] = []
    current = finals[0]
    for final in finals:
        _refuse_special_target(final)
    try:
        for final in finals:
            current = final
            final.parent.mkdir(parents=True, exist_ok=True)
            fd, name = tempfile.mkstemp(prefix=f".{final.name}.", suffix=".tmp", dir=final.parent)
            os.close(fd)
            temporaries.append(Path(name))
        current = finals[0]
        yield tuple(temporaries)
        for final, tmp in zip(finals, temporaries, strict=True):
            current = final
            # mkstemp creates 0600 files; give the result the mode a normal write would have.
            os.chmod(tmp, _default_mode(final))
            with open(tmp, "rb") as handle:
                os.fsync(handle.fileno())
        for final, tmp in zip(finals, temporaries, strict=True):
            current = final
            os.replace(tmp, final)
    except OSError as err:
        raise OutputError(_named_target(err, finals, current), err) from None
    finally:
        for tmp in temporaries:
            with contextlib.suppress(FileNotFoundError):
                tmp.unlink()


def _refuse_special_target(final: Path) -> None:
    """Refuse to rename over a device, a pipe or a socket (``--out /dev/null``, say).

    A rename replaces the name, not what it names: over ``/dev/null`` it would put a regular
    file in the device's place. A symbolic link is replaced by the file, leaving the file it
    pointed to alone, as a rename over a regular file does.
    """
    try:
        mode = os.lstat(final).st_mode
    except OSError:  # absent (the usual case) or unreadable: the write itself will say
        return
    if stat.S_ISREG(mode) or stat.S_ISLNK(mode):
        return
    kind = "a folder" if stat.S_ISDIR(mode) else "a device, a pipe or a socket"
    raise OutputError(final, f"it is {kind}, not a regular file")


def _named_target(err: OSError, finals: list[Path], current: Path) -> Path:
    """Return the target a failed write was for: the one whose temporary file it names."""
    if err.filename:
        name = Path(os.fsdecode(err.filename)).name
        for final in finals:
            if name == final.name or name.startswith(f".{final.name}."):
                return final
    return current


def atomic_write_text(target: str | os.PathLike[str], text: str) -> Path:
    """Write UTF-8 text with Unix line ends to ``target`` atomically; return the path."""
    with atomic_path(target) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
    return Path(target)


def atomic_write_bytes(target: str | os.PathLike[str], data: bytes) -> Path:
    """Write ``data`` to ``target`` atomically; return the path."""
    with atomic_path(target) as tmp:
        with open(tmp, "wb") as handle:
            handle.write(data)
    return Path(target)


def atomic_write_texts(files: dict[Path, str]) -> list[Path]:
    """Write UTF-8 texts that belong together: all of them, or none (:func:`atomic_paths`).

    Parameters
    ----------
    files : dict
        Target path -> text, in the order the files are moved into place.

    Returns
    -------
    list of Path
        The targets.
    """
    targets = list(files)
    with atomic_paths(*targets) as temporaries:
        for target, tmp, text in zip(targets, temporaries, files.values(), strict=True):
            try:
                with open(tmp, "w", encoding="utf-8", newline="\n") as handle:
                    handle.write(text)
            except OSError as err:  # a full disk's error names no file: name this one
                raise OutputError(target, err) from None
    return targets


def atomic_write_json(target: str | os.PathLike[str], obj: Any) -> Path:
    """Write ``obj`` as indented, strictly valid JSON to ``target`` atomically.

    Non-finite numbers are written as ``null`` (:func:`strict_json`).
    """
    text = json.dumps(strict_json(obj), indent=2, allow_nan=False)
    return atomic_write_text(target, text + "\n")


def strict_json(obj: Any) -> Any:
    """Return ``obj`` as strict JSON holds it: NaN and infinities ``None``, numpy as Python.

    Python's :func:`json.dumps` writes a bare ``NaN`` or ``Infinity``, which is not JSON
    (``jq`` and browsers refuse the whole document); a number that does not exist is
    ``null`` in every JSON the workbench writes or prints.

    Parameters
    ----------
    obj : object
        Dicts, lists, tuples, numbers, numpy scalars and arrays, paths, strings.

    Returns
    -------
    object
        The same structure with every non-finite float replaced by ``None``, numpy scalars
        and arrays turned into Python numbers and lists, and paths into strings.
    """
    import math

    import numpy as np

    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    elif isinstance(obj, np.generic):
        obj = obj.item()
    elif isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k if isinstance(k, str) else str(k): strict_json(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [strict_json(v) for v in obj]
    return obj
