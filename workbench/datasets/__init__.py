"""Embedded default data: two real walking records and a small synthetic set.

``load(name)`` returns one as a :class:`~workbench.records.record.Record`, with its body
mass::

    import workbench as wb
    rec = wb.datasets.load("treadmill")        # real: instrumented treadmill, 143 s
    rec = wb.datasets.load("seed_individual")  # synthetic, with a JSON sidecar of its truth

See ``README.md`` in this folder for provenance and licences; keep that attribution in any
copy.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from workbench.errors import InputError, UsageError
from workbench.records.embedded import (
    EMBEDDED,
    EmbeddedRecord,
    benchmark_paths,
    dataset_options,
    dataset_path,
    embedded_path,
    names,
    synthetic_paths,
)
from workbench.records.io import load_record
from workbench.records.record import Record

__all__ = [
    "EMBEDDED",
    "EmbeddedRecord",
    "benchmark_paths",
    "dataset_options",
    "dataset_path",
    "embedded_path",
    "load",
    "named",
    "names",
    "require_record",
    "settings",
    "synthetic_paths",
]


def load(name: str, **options: Any) -> Record:
    """Load an embedded record by name.

    Parameters
    ----------
    name : str
        ``"treadmill"`` or ``"insole"`` (real records), the name of a synthetic walk
        (``"seed_individual"``, ``"seed_individual_deck"``, ...) or of a benchmark
        (``"seed_numerical_example"``); :func:`names` lists them.
    **options
        Passed to :func:`~workbench.records.io.load_record` (``mass_kg=...``,
        ``allow_negative_force=...``), over the record's own loader options.

    Returns
    -------
    Record
    """
    path = dataset_path(name)
    if path is None:
        raise UsageError(
            f"no embedded record is called {name!r}; choose one of {', '.join(names())}"
        )
    own, _ = dataset_options(name)
    merged = {**own, **options}
    # A permission the record needs is not taken back by a caller's default of False.
    merged["allow_negative_force"] = bool(own.get("allow_negative_force")) or bool(
        options.get("allow_negative_force")
    )
    record = load_record(path, **merged)
    # Named from the package, not from wherever it is installed.
    return record.replace(source=f"workbench/datasets/{path.parent.name}/{path.name}")


def named(argument: object) -> str | None:
    """Return the embedded record a record argument names, or None when it is a path.

    A file of that name in the current folder wins, so a user's ``treadmill`` file is
    never shadowed by the embedded one; anything but a single string or path is None.
    """
    if not isinstance(argument, str | os.PathLike):
        return None
    text = os.fspath(argument)
    if not isinstance(text, str) or Path(text).exists() or dataset_path(text) is None:
        return None
    return text


def require_record(argument: str | os.PathLike[str]) -> None:
    """Refuse a record argument that is neither a file nor an embedded record's name.

    A bare word (no folder, no extension) that is no file is most likely a mistyped
    embedded name, so the sentence lists the names; a path keeps the loader's own
    "does not exist" sentence, which names the file.

    Raises
    ------
    InputError
        For a bare word that is no file and no embedded record.
    """
    path = Path(os.fspath(argument))
    if path.exists() or named(argument) is not None or path.suffix or len(path.parts) != 1:
        return
    raise InputError(
        str(argument),
        "record",
        "there is no file and no embedded record of that name",
        f"give a record file, or one of the embedded records: {', '.join(names())}",
    )


def settings(name: str, **overrides: Any) -> Any:
    """Return the identification settings an embedded record was made for.

    Parameters
    ----------
    name : str
        An embedded record (:func:`names`).
    **overrides
        Flat settings (``method="exact"``) over the record's own.

    Returns
    -------
    IdentifySettings
        The defaults for a walk, the force model it was simulated with for a benchmark
        (the seed's numerical example: ten harmonics of 0.5 Hz on absolute time, one piece,
        no high-pass).
    """
    from workbench.inference.pipeline import IdentifySettings

    if dataset_path(name) is None:
        raise UsageError(
            f"no embedded record is called {name!r}; choose one of {', '.join(names())}"
        )
    _, own = dataset_options(name)
    return IdentifySettings.from_flat(**{**own, **overrides})
