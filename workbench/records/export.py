"""Write records in the other formats the loaders read (OpenSim ``.mot``).

CSV with its JSON sidecar is written by :func:`workbench.records.io.save_record`; this module
adds the OpenSim motion format so simulated records can go through the same path as the
treadmill data. A simulated SMD has one vertical force, so the ``.mot`` holds it on plate 1
(``ground_force_1_vy``) with the other force components zero; when the record has left and
right forces they go on plates 1 and 2 instead.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from workbench.errors import UsageError
from workbench.fileutil import atomic_write_texts
from workbench.records.record import Record

__all__ = ["mot_texts", "write_mot"]

_COMPONENTS = ("vx", "vy", "vz", "px", "py", "pz")


def write_mot(
    record: Record, path: str | os.PathLike[str], *, sidecar: dict[str, Any] | None = None
) -> Path:
    """Write a record as an OpenSim ``.mot`` file (and optionally a JSON sidecar).

    Both files are written, or neither (:func:`mot_texts`,
    :func:`workbench.fileutil.atomic_write_texts`).

    Parameters
    ----------
    record : Record
        The record.
    path : path-like
        Target path ending in ``.mot``.
    sidecar : dict, optional
        Metadata written to the same path with ``.json`` (mass, truth, ...).

    Returns
    -------
    Path
        The ``.mot`` path.
    """
    atomic_write_texts(mot_texts(record, path, sidecar=sidecar))
    return Path(path)


def mot_texts(
    record: Record, path: str | os.PathLike[str], *, sidecar: dict[str, Any] | None = None
) -> dict[Path, str]:
    """Return the files :func:`write_mot` writes: the sidecar (if any), then the ``.mot``.

    Parameters
    ----------
    record : Record
        The record.
    path : path-like
        Target path ending in ``.mot``.
    sidecar : dict, optional
        Metadata written atomically to the same path with ``.json`` (mass, truth, ...).

    Returns
    -------
    dict
        Path -> text, in the order the files are moved into place.
    """
    path = Path(path)
    if path.suffix.lower() != ".mot":
        raise UsageError(
            f"write_mot writes OpenSim motion files; give a path ending in .mot, not {str(path)!r}"
        )
    if record.grf_left_n is not None and record.grf_right_n is not None:
        plates = [record.grf_left_n, record.grf_right_n]
    else:
        plates = [record.grf_n]
    names = ["time"]
    columns = [record.time_s]
    zeros = np.zeros_like(record.time_s)
    for k, vy in enumerate(plates, start=1):
        for comp in _COMPONENTS:
            names.append(f"ground_force_{k}_{comp}")
            columns.append(vy if comp == "vy" else zeros)
    table = np.column_stack(columns)
    header = [
        path.name,
        "version=1",
        f"nRows={table.shape[0]}",
        f"nColumns={table.shape[1]}",
        "inDegrees=no",
        "endheader",
        "\t".join(names),
    ]
    body = "\n".join("\t".join(repr(float(x)) for x in row) for row in table)
    files = {}
    if sidecar is not None:
        files[path.with_suffix(".json")] = json.dumps(sidecar, indent=2) + "\n"
    files[path] = "\n".join(header) + "\n" + body + "\n"
    return files
