"""A batch's folder and the record files it reads, before any identification.

- the folder's lock (:func:`batch_lock`): one run at a time, held for the run's life;
- names from the manifest's folder (:func:`as_in_manifest`, :func:`manifest_from_folder`), so
  that a batch's files do not depend on the folder it was started from;
- record files checked before they are read (:func:`check_record_file`: a pipe, a device, a
  missing file or one over the per-record budget fails its own row) and seeded from their
  bytes (:func:`record_seed`, :func:`file_seed`), so that any number of workers gives the
  same numbers.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
from collections.abc import Iterator
from pathlib import Path

from workbench.errors import InputError, OutputError, UsageError
from workbench.records.text_table import FILE_MISSING, file_problem

__all__ = [
    "LOCK_NAME",
    "as_in_manifest",
    "batch_lock",
    "check_record_file",
    "file_seed",
    "manifest_from_folder",
    "record_seed",
]


def record_seed(base_seed: int, path: str, content: bytes | None) -> int:
    """Seed of one record: SHA-256 of the batch seed, the manifest path and the file bytes.

    Parameters
    ----------
    base_seed : int
        The batch seed (``--seed``).
    path : str
        The record's path as written in the manifest.
    content : bytes or None
        The file's bytes (None when it cannot be read; the record then fails anyway).

    Returns
    -------
    int
        A seed in ``[0, 2**32)``.
    """
    h = hashlib.sha256()
    h.update(str(int(base_seed)).encode())
    h.update(b"\0")
    h.update(path.encode("utf-8"))
    h.update(b"\0")
    h.update(content if content is not None else b"<unreadable>")
    return int.from_bytes(h.digest()[:4], "little")


#: The lock file of a batch folder (:func:`batch_lock`).
LOCK_NAME = ".batch.lock"


@contextlib.contextmanager
def batch_lock(out: Path) -> Iterator[None]:
    """Hold an exclusive lock on the batch folder ``out`` (created if needed) while in the block.

    The lock is the system's (``flock``) on ``out/.batch.lock``, so it is released when the
    run ends in any way, a kill -9 included, and a stale lock file locks nothing. On systems
    without ``fcntl`` (Windows) no lock is taken.

    Raises
    ------
    UsageError
        When another run holds the folder.
    """
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not on POSIX
        yield
        return
    out.mkdir(parents=True, exist_ok=True)
    path = out / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as err:
        raise OutputError(path, err) from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise UsageError(
                f"the output folder {out} is in use by another batch that is still running; "
                "wait until it ends, or choose another folder"
            ) from None
        yield
    finally:
        os.close(fd)  # releases the lock


def manifest_from_folder(out: Path, manifest: str | os.PathLike[str]) -> str:
    """Return the manifest's path from the output folder (the same from any current folder)."""
    try:
        return Path(os.path.relpath(Path(manifest).absolute(), out.absolute())).as_posix()
    except ValueError:  # another drive (Windows)
        return Path(manifest).absolute().as_posix()


def as_in_manifest(text: str, folder: str, path: str) -> str:
    """Name the record's files in ``text`` as the manifest does, from the manifest's folder.

    The loader names the file it opened, which starts with the manifest's folder as typed on
    the command line (``../study/``, an absolute path ...); the batch's files must not depend
    on where it was started from.
    """
    if not folder or folder == "." or Path(path).is_absolute():
        return text
    for sep in sorted({os.sep, "/"}):
        # Only where a path starts (after a space, a quote or a bracket), so that a
        # folder of the same name deeper in a path is kept.
        prefix = re.escape(folder.rstrip(sep) + sep)
        text = re.sub(rf"(?<![^\s'\"(]){prefix}", "", text)
    return text


def check_record_file(path: str, file: str, max_rows: int | None, budget: str) -> None:
    """Refuse a record that cannot be read, or is too long to identify, before reading it.

    A pipe would hang the worker and ``/dev/zero`` would fill its memory; a record of
    millions of rows would take the worker's memory and hours. Its rows are counted by
    streaming the file (nothing held), and the identification's memory is estimated from
    them as ``workbench identify`` estimates it from the samples.
    """
    problem = file_problem(file)
    if problem == FILE_MISSING:
        # The loader's own message would send the user to the current folder.
        raise InputError(
            path,
            "whole file",
            "the record file does not exist",
            "check the manifest's path column (relative paths start from the manifest's folder)",
        )
    if problem is not None:
        raise InputError(
            path, "whole file", problem, "list a record file saved on disk in the manifest"
        )
    if max_rows is None:
        return
    rows = _count_lines(file, stop_after=max_rows)
    if rows > max_rows:
        raise InputError(
            path,
            "whole file",
            f"the record has more than {max_rows:,} lines, more than the batch "
            f"identifies within its per-record budget of {budget}",
            "split it into shorter records, or run the batch with --no-limits",
        )


def _count_lines(path: str, *, stop_after: int) -> int:
    """Count the lines of a file in 1 MiB chunks, stopping once past ``stop_after``."""
    lines = 0
    with open(path, "rb") as handle:
        while chunk := handle.read(1 << 20):
            lines += chunk.count(b"\n")
            if lines > stop_after:
                break
    return lines


def file_seed(base_seed: int, path: str, file: Path) -> int:
    """:func:`record_seed` of a record file, read in chunks; only regular files are read."""
    if file_problem(file) is not None:
        return record_seed(base_seed, path, None)
    h = hashlib.sha256()
    h.update(str(int(base_seed)).encode())
    h.update(b"\0")
    h.update(path.encode("utf-8"))
    h.update(b"\0")
    try:
        with open(file, "rb") as handle:
            while chunk := handle.read(1 << 20):
                h.update(chunk)
    except OSError:
        return record_seed(base_seed, path, None)
    return int.from_bytes(h.digest()[:4], "little")
