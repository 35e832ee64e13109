"""Atomic file output: a result is either fully written or not there at all.

Batch and report jobs may be interrupted; writing to a temporary file in the same folder,
flushing it to disk and renaming it over the target (``os.replace`` is atomic on POSIX and
Windows) means a crash never leaves a half-written file that a later ``--resume`` would
mistake for a finished one.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["atomic_path", "atomic_write_json", "atomic_write_text", "strict_json"]


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
    """
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        # mkstemp creates 0600 files; give the result the mode a normal write would have.
        os.chmod(tmp_path, _default_mode(target))
        with open(tmp_path, "rb") as handle:
            os.fsync(handle.fileno())
        os.replace(tmp_path, target)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()


def atomic_write_text(target: str | os.PathLike[str], text: str) -> Path:
    """Write UTF-8 text with Unix line ends to ``target`` atomically; return the path."""
    with atomic_path(target) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="\n") as handle:
            handle.write(text)
    return Path(target)


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
