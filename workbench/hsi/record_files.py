"""Walker records on disk: a folder of records, their truth and a batch manifest.

The records of :mod:`workbench.hsi.records` are written into a folder as::

    manifest.csv                          path, mass_kg, pacing_hz, subject (for batch)
    truth.csv                             one row per record: path and its true parameters
    records/crossingCCCC_walkerWWW.csv    time, grf, ground_acc
    records/crossingCCCC_walkerWWW.json   sidecar: mass_kg, pacing_hz, subject, notes, truth
    records/crossingCCCC_walkerWWW.truth.json   the truth alone (as `workbench simulate`)

(a record's subject is its file stem, except a cohort member's, which is the person:
``walker007``, so that one walker's crossings group in a population fit)

every file atomically, the manifest last, so a manifest always lists complete records;
the CSV and sidecar are those of :func:`workbench.records.io.save_record`, so
:func:`workbench.load_record` and ``workbench batch manifest.csv`` read them.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from workbench.errors import InputError, UsageError
from workbench.hsi.records import crossing_records, record_name
from workbench.records.record import Record

__all__ = [
    "RecordsWritten",
    "check_records_folder",
    "write_crossing_records",
    "write_walker_records",
]


def check_records_folder(folder: str | os.PathLike[str]) -> Path:
    """Create the records folder if needed and make sure files can be written there.

    Called before a simulation so that a bad folder costs nothing.

    Parameters
    ----------
    folder : path-like
        Where :func:`write_walker_records` will write.

    Returns
    -------
    Path

    Raises
    ------
    UsageError
        If it is a file, lies inside a file, or cannot be written (``parameter="folder"``).
    """
    path = Path(folder)
    if path.exists() and not path.is_dir():
        raise UsageError(
            f"'folder' {str(path)!r} is a file; give a folder for the walker records (it is "
            "created if missing)",
            parameter="folder",
        )
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError as err:
        raise UsageError(
            f"'folder' {str(path)!r} cannot be written ({err.strerror or err}); give a folder "
            "you can write to",
            parameter="folder",
        ) from None
    return path


@dataclass(frozen=True)
class RecordsWritten:
    """What :func:`write_walker_records` wrote.

    Attributes
    ----------
    folder : Path
    manifest : Path or None
        ``folder/manifest.csv``; None when no record could be written.
    records : list of Path
        The record CSV files, in manifest order.
    skipped : list of dict
        ``{"record": name, "reason": ...}`` for records the loaders would refuse (a walker
        on the deck for less than 2 s, for example).
    """

    folder: Path
    manifest: Path | None
    records: list[Path] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """JSON description (paths as strings)."""
        return {
            "folder": str(self.folder),
            "manifest": None if self.manifest is None else str(self.manifest),
            "records": len(self.records),
            "files": [str(p) for p in self.records],
            "skipped": list(self.skipped),
        }


def write_walker_records(
    records: Sequence[Record], folder: str | os.PathLike[str]
) -> RecordsWritten:
    """Write walker records, their truth and a batch manifest into a folder.

    Layout in the module docstring. Each record is checked as the loaders check it
    (:func:`~workbench.records.validation.validate_record`) and skipped, with the reason,
    if they would refuse it. The manifest (``path, mass_kg, pacing_hz, subject``, exact
    floats) lists exactly the records written by this call, and is written last.

    Parameters
    ----------
    records : sequence of Record
        From :func:`~workbench.hsi.records.walker_records` (named by their ``subject``).
    folder : path-like
        Created if missing; files of an earlier run are overwritten where names agree.

    Returns
    -------
    RecordsWritten
    """
    from workbench.fileutil import atomic_path, atomic_write_json, atomic_write_text
    from workbench.records.io import save_record
    from workbench.records.validation import validate_record

    names = [_file_stem(r) for r in records]
    for i, name in enumerate(names):
        if not name or names.index(name) != i:
            # The stem names the files: a repeat would overwrite a record.
            what = "a record without a subject" if not name else f"the record {name!r} twice"
            raise UsageError(
                f"'records' has {what}; give each record its own subject (walker_records "
                "names them by crossing and walker, so pass distinct crossing_ids)",
                parameter="records",
            )
    out = check_records_folder(folder)
    rows, truths, written, skipped = [], [], [], []
    for record, name in zip(records, names, strict=True):
        rel = f"records/{name}.csv"
        try:
            validate_record(record.replace(source=rel))
        except InputError as err:
            skipped.append({"record": name, "reason": err.problem})
            continue
        csv_path, _ = save_record(record, out / rel)
        truth = dict(record.metadata.get("truth") or {})
        if truth:
            atomic_write_json(out / f"records/{name}.truth.json", truth)
        written.append(csv_path)
        subject = record.subject or name
        rows.append([rel, repr(record.mass_kg), repr(record.pacing_hz), subject])
        truths.append({"path": rel, "subject": subject, **_truth_row(truth)})
    if not rows:
        # An earlier run's manifest would list records this run did not write.
        for stale in ("manifest.csv", "truth.csv"):
            (out / stale).unlink(missing_ok=True)
        return RecordsWritten(out, None, [], skipped)
    with atomic_path(out / "truth.csv") as tmp:
        pd.DataFrame(truths).to_csv(tmp, index=False, lineterminator="\n")
    manifest = out / "manifest.csv"
    text = "path,mass_kg,pacing_hz,subject\n" + "".join(",".join(r) + "\n" for r in rows)
    atomic_write_text(manifest, text)
    return RecordsWritten(out, manifest, written, skipped)


def _file_stem(record: Record) -> str:
    """Name a record's files by its crossing and walker, else by its subject.

    A cohort member's records share their subject (the person), so the subject cannot name
    the files of several crossings; the crossing and the walker's place in it can.
    """
    truth = record.metadata.get("truth") or {}
    if "walker_id" in truth and "crossing" in truth and "walker" in truth:
        return record_name(int(truth["crossing"]), int(truth["walker"]))
    return record.subject or ""


#: Scalar truth entries that go into ``truth.csv``, in column order.
_TRUTH_COLUMNS = (
    "crossing",
    "walker",
    "mass_kg",
    "pacing_hz",
    "speed_m_s",
    "entry_time_s",
    "exit_time_s",
    "natural_frequency_hz",
    "damping_ratio",
    "stiffness_n_per_m",
    "damping_ns_per_m",
)


def _truth_row(truth: Mapping[str, Any]) -> dict[str, Any]:
    row = {k: truth.get(k) for k in _TRUTH_COLUMNS}
    if "walker_id" in truth:  # a cohort's member (workbench.population.cohort)
        row["walker_id"] = truth["walker_id"]
    for i, value in enumerate(truth.get("blf") or [], start=1):
        row[f"blf{i}"] = value
    return row


def write_crossing_records(
    spec: Any, seed: int, folder: str | os.PathLike[str], *, crossings: int = 1
) -> RecordsWritten:
    """Write the walker records of the first ``crossings`` Monte Carlo crossings.

    Crossings are integrated one at a time
    (:func:`~workbench.hsi.records.crossing_records`), so the memory held
    is one crossing's walker histories whatever ``crossings`` is.

    Parameters
    ----------
    spec : CrossingSpec
        What a crossing is.
    seed : int
        The Monte Carlo's seed.
    folder : path-like
        As :func:`write_walker_records`.
    crossings : int
        How many crossings, from crossing 0.

    Returns
    -------
    RecordsWritten
    """
    if int(crossings) != crossings or crossings < 1:
        raise UsageError(
            f"'crossings' must be a positive whole number, got {crossings!r}",
            parameter="crossings",
        )
    check_records_folder(folder)
    records = [r for i in range(int(crossings)) for r in crossing_records(spec, seed, i)]
    return write_walker_records(records, folder)
