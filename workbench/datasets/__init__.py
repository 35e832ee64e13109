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

from workbench.datasets.catalogue import (
    EMBEDDED,
    EmbeddedRecord,
    embedded_path,
    names,
    synthetic_paths,
)
from workbench.errors import UsageError
from workbench.records.io import load_record
from workbench.records.record import Record

__all__ = ["EMBEDDED", "EmbeddedRecord", "embedded_path", "load", "names", "synthetic_paths"]


def load(name: str, **options: object) -> Record:
    """Load an embedded record by name.

    Parameters
    ----------
    name : str
        ``"treadmill"`` or ``"insole"`` (real records) or the name of a synthetic record
        (``"seed_individual"``, ...); :func:`names` lists them.
    **options
        Passed to :func:`~workbench.records.io.load_record` (``mass_kg=...``,
        ``allow_negative_force=...``).

    Returns
    -------
    Record
    """
    if name in EMBEDDED:
        path = embedded_path(name)
    else:
        path = next((p for p in synthetic_paths() if p.stem == name), None)  # type: ignore[assignment]
        if path is None:
            raise UsageError(
                f"no embedded record is called {name!r}; choose one of {', '.join(names())}"
            )
    record = load_record(path, **options)  # type: ignore[arg-type]
    # Named from the package, not from wherever it is installed.
    return record.replace(source=f"workbench/datasets/{path.parent.name}/{path.name}")
