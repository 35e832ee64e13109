"""A record or a manifest of records: what study-scale commands take as their input."""

from __future__ import annotations

import os
from pathlib import Path

from workbench.errors import InputError
from workbench.records.record import Record

__all__ = ["is_manifest", "load_study_records"]


def is_manifest(path: str | os.PathLike[str]) -> bool:
    """Tell a batch manifest (a CSV with a ``path`` column) from a CSV record.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    bool
        True if the file is a CSV whose first non-blank line names a ``path`` column and
        no ``grf`` column.
    """
    p = Path(path)
    if p.suffix.lower() != ".csv" or not p.is_file():
        return False
    try:
        with p.open(encoding="utf-8", errors="replace") as fh:
            for line in fh:
                if line.strip():
                    cells = [
                        c.strip().strip('"').lower() for c in line.replace(";", ",").split(",")
                    ]
                    return "path" in cells and "grf" not in cells
    except OSError:
        return False
    return False


def _rescaled(record: Record, rescale_to_mass: bool) -> Record:
    from workbench.records.inspection import inspect_record

    # Inspected before the study, as identify inspects before it identifies: a record
    # without walking (a constant force, a machine's sine) is refused here, once, instead
    # of failing every run of the study. The study identifies the rescaled record, as
    # 'identify --rescale-to-mass' would.
    return inspect_record(record, rescale=rescale_to_mass).record


def load_study_records(
    path: str | os.PathLike[str],
    *,
    mass_kg: float | None = None,
    pacing_hz: float | None = None,
    subject: str | None = None,
    rescale_to_mass: bool = False,
    allow_negative_force: bool = False,
    allow_outside_paths: bool = False,
) -> list[tuple[str, Record]]:
    """Load a record, or every record of a manifest, as ``(key, Record)`` pairs.

    Parameters
    ----------
    path : path-like
        A record file or a batch manifest (:func:`is_manifest`).
    mass_kg, pacing_hz : float, optional
        Body mass [kg] and stated pacing [Hz]; a manifest's own values win for its rows.
    subject : str, optional
        Subject of a single record (a manifest row names its own).
    rescale_to_mass : bool, optional
        Scale each record's GRF so its mean over whole steps equals M g.
    allow_negative_force : bool, optional
        Accept force samples below zero with a warning (synthetic benchmarks); see
        :func:`~workbench.records.validation.validate_record`.
    allow_outside_paths : bool, optional
        Accept manifest paths outside the manifest's folder
        (:func:`~workbench.records.manifest.load_manifest`).

    Returns
    -------
    list of (str, Record)
        A single record keyed by its file name; manifest rows keyed by their path relative
        to the manifest's folder (so seeds derived from the keys do not depend on where the
        manifest lies), in manifest order.

    Raises
    ------
    InputError
        If the path does not exist, a record cannot be loaded or the manifest is empty.
    """
    from workbench.records.io import load_manifest, load_record

    p = Path(path)
    if not p.exists():
        raise InputError(p, "whole file", "the record or manifest does not exist", "check the path")
    if not is_manifest(p):
        rec = load_record(
            p,
            mass_kg=mass_kg,
            pacing_hz=pacing_hz,
            subject=subject,
            allow_negative_force=allow_negative_force,
        )
        return [(p.name, _rescaled(rec, rescale_to_mass))]
    out = []
    for entry in load_manifest(p, allow_outside_paths=allow_outside_paths):
        file = entry.path  # already joined to the manifest's folder by load_manifest
        rec = load_record(
            file,
            mass_kg=entry.mass_kg if entry.mass_kg is not None else mass_kg,
            pacing_hz=entry.pacing_hz if entry.pacing_hz is not None else pacing_hz,
            subject=entry.subject,
            allow_negative_force=allow_negative_force,
        )
        try:
            key = file.resolve().relative_to(p.parent.resolve()).as_posix()
        except ValueError:
            key = str(entry.path)
        out.append((key, _rescaled(rec, rescale_to_mass)))
    if not out:
        raise InputError(p, "whole file", "the manifest lists no records", "add rows")
    return out
