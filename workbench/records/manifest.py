"""Batch manifests: a CSV listing record files with optional per-record metadata.

Holds :class:`ManifestEntry` (one row) and :func:`load_manifest`, which reads a manifest
with the shared text-table parsing of the record readers and checks every cell, naming
the line and column of any problem.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from workbench.errors import InputError
from workbench.records.text_table import (
    _decode,
    _detect_delimiter,
    _field_count_error,
    _normalise_name,
    _read_bytes,
    _require_file,
    _split_fields,
    empty_file,
    first_content_line,
    parse_number,
    quote,
    quote_list,
    split_lines,
)
from workbench.records.validation import mass_problem, pacing_problem

__all__ = ["ManifestEntry", "load_manifest"]


@dataclass(frozen=True)
class ManifestEntry:
    """One row of a batch manifest.

    Parameters
    ----------
    path : Path
        The record file (relative paths in the manifest are taken from the manifest's folder).
    mass_kg : float or None
        Body mass [kg] from the manifest, if given.
    pacing_hz : float or None
        Pacing frequency [Hz] from the manifest, if given.
    subject : str or None
        Subject identifier from the manifest, if given.
    row : int
        Line number of this row in the manifest file (1-based; the header is line 1).
    """

    path: Path
    mass_kg: float | None = None
    pacing_hz: float | None = None
    subject: str | None = None
    row: int = 0


_MANIFEST_COLUMNS = ("path", "mass_kg", "pacing_hz", "subject")


def load_manifest(
    path: str | os.PathLike[str], *, allow_outside_paths: bool = False
) -> list[ManifestEntry]:
    """Read a batch manifest: a CSV with a ``path`` column and optional metadata columns.

    Columns: ``path`` (required; relative to the manifest's folder), ``mass_kg``,
    ``pacing_hz``, ``subject`` (optional; empty cells mean "not given"). Separators as for
    record CSV files; quoted cells are allowed (paths with commas). Other columns are refused
    so that a misspelt ``mass`` column is not silently ignored. Whether each record file exists
    is not checked here: a batch reports a missing record as a failure of that record.

    Record paths must lie in the manifest's folder or below it, unless
    ``allow_outside_paths``: a manifest from elsewhere must not make the workbench open (and
    quote, in a failure's reason) any file of the machine. The check is on the written path
    (``..`` and absolute paths), not on where symbolic links lead, so a link placed in the
    folder on purpose still works.

    Parameters
    ----------
    path : str or path-like
        The manifest file.
    allow_outside_paths : bool, default False
        Accept absolute paths and paths that climb out of the manifest's folder.

    Returns
    -------
    list of ManifestEntry
        In file order.

    Raises
    ------
    InputError
        For a problem in the manifest, naming its line and column.
    """
    p = Path(path)
    source = str(path)
    _require_file(p, source)
    text = _decode(_read_bytes(p, source), source)
    lines = split_lines(text)
    header_index = first_content_line(lines)
    if header_index is None:
        raise empty_file(source)
    header_line = lines[header_index]
    delimiter = _detect_delimiter(header_line)
    names = _split_fields(header_line, delimiter)
    index_of: dict[str, int] = {}
    for i, raw in enumerate(names):
        name, unit = _normalise_name(raw)
        if name not in _MANIFEST_COLUMNS:
            raise InputError(
                source,
                f"line {header_index + 1}, column {quote(raw)}",
                "this column is not part of a manifest",
                f"use only the columns {', '.join(_MANIFEST_COLUMNS)} (path is required)",
            )
        expected_unit = {"mass_kg": "kg", "pacing_hz": "hz"}.get(name)
        if unit is not None and unit != expected_unit:
            raise InputError(
                source,
                f"line {header_index + 1}, column {quote(raw)}",
                f"the unit {unit!r} does not match the column {name!r}",
                "give masses in kg and pacing frequencies in Hz and drop the bracketed unit",
            )
        if name in index_of:
            raise InputError(
                source,
                f"line {header_index + 1}, column {quote(raw)}",
                f"the column {name!r} appears twice",
                "keep one of them",
            )
        index_of[name] = i
    if "path" not in index_of:
        raise InputError(
            source,
            f"line {header_index + 1}",
            f"there is no 'path' column (columns found: {quote_list(names)})",
            "name the column with the record files 'path' (optional: "
            f"{', '.join(_MANIFEST_COLUMNS[1:])})",
        )

    entries: list[ManifestEntry] = []
    seen: dict[str, int] = {}
    files: dict[object, tuple[str, int]] = {}  # the file each row names, however spelt
    folder = p.parent
    for i in range(header_index + 1, len(lines)):
        line = lines[i]
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        number = i + 1
        fields = _split_fields(line, delimiter)
        if len(fields) != len(names):
            raise _field_count_error(
                source, number, len(fields), header_index + 1, len(names), delimiter
            )
        cells = {name: fields[j].strip() for name, j in index_of.items()}
        file_text = cells["path"]
        if not file_text:
            raise InputError(
                source, f"line {number}, column 'path'", "the path is empty", "give the record file"
            )
        if file_text in seen:
            raise InputError(
                source,
                f"line {number}, column 'path'",
                f"the record {quote(file_text)} is already listed on line {seen[file_text]}",
                "list every record once",
            )
        seen[file_text] = number
        identity = _file_identity(
            Path(file_text) if Path(file_text).is_absolute() else folder / file_text
        )
        if identity in files:
            first, first_line = files[identity]
            raise InputError(
                source,
                f"line {number}, column 'path'",
                f"the record {quote(file_text)} is the file {quote(first)} of line {first_line} "
                "under another spelling, so it would be identified twice and count twice",
                "list every record once",
            )
        files[identity] = (file_text, number)
        mass = _manifest_number(cells.get("mass_kg", ""), source, number, "mass_kg")
        if mass is not None:
            problem = mass_problem(mass)
            if problem is not None:
                raise InputError(
                    source,
                    f"line {number}, column 'mass_kg'",
                    problem,
                    "give the body mass in kilograms",
                )
        pacing = _manifest_number(cells.get("pacing_hz", ""), source, number, "pacing_hz")
        if pacing is not None:
            found = pacing_problem(pacing)
            if found is not None:
                raise InputError(source, f"line {number}, column 'pacing_hz'", *found)
        subject = cells.get("subject") or None
        record_path = Path(file_text)
        if not record_path.is_absolute():
            record_path = folder / record_path
        if not allow_outside_paths and not _inside(record_path, folder):
            raise InputError(
                source,
                f"line {number}, column 'path'",
                f"the record {quote(file_text)} lies outside the manifest's folder",
                "move it into that folder or below it (paths start from the manifest's "
                "folder), or pass --allow-outside-paths to read it where it is",
            )
        entries.append(ManifestEntry(record_path, mass, pacing, subject, number))
    if not entries:
        raise InputError(
            source,
            f"line {header_index + 1}",
            "the manifest has a header but no records",
            "add one row per record file",
        )
    return entries


def _file_identity(record_path: Path) -> object:
    """Return what is the same for every spelling of one file, and differs between files.

    ``r1.csv``, ``./r1.csv`` and a path through a link to the same folder are one record.
    """
    try:
        info = os.stat(record_path)  # follows links; a hard link is the same file too
    except (OSError, ValueError):  # missing (a failure of its row later) or unreadable name
        return os.path.realpath(record_path)
    return (info.st_dev, info.st_ino)


def _inside(record_path: Path, folder: Path) -> bool:
    """Whether a record path, ``..`` resolved on the text, lies in ``folder`` or below it."""
    record = os.path.normpath(os.path.abspath(record_path))
    root = os.path.normpath(os.path.abspath(folder))
    try:
        return os.path.commonpath([record, root]) == root
    except ValueError:  # another drive (Windows)
        return False


def _manifest_number(cell: str, source: str, line: int, column: str) -> float | None:
    if not cell:
        return None
    value = parse_number(cell)
    if value is None or not math.isfinite(value):
        raise InputError(
            source,
            f"line {line}, column {column!r}",
            f"the value {quote(cell)} is not a number",
            "write a plain number or leave the cell empty",
        )
    return value
