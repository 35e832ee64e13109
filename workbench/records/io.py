"""Reading and writing GRF records: CSV + JSON sidecar, OpenSim .mot, PhysioNet insole, C3D.

Formats (docs/contracts.md)
-----------------------
``csv``
    A header line, then one row per sample. Columns ``time`` [s] and ``grf`` [N] (total
    vertical force on the person, positive up); optional ``grf_left``, ``grf_right`` [N] and
    ``ground_acc`` [m/s^2]. Separated by commas, semicolons, tabs or runs of spaces (taken from
    the header line). Names are case- and whitespace-insensitive; a unit in brackets is allowed
    if it is the expected one (``time [s]``, ``grf (N)``, ``ground_acc [m/s^2]``). Accepted
    aliases, recorded in ``metadata["column_aliases"]``, are only the unambiguous ones:
    :data:`COLUMN_ALIASES` (``t``, ``time_s``, ``grf_n``, ``grf_left_n``, ``grf_right_n``,
    ``ground_acc_m_s2``). Anything else (``Force``, ``Fz``, ``GRF [kN]``) is an error that lists
    the columns found, never a guess. If ``grf`` is absent but ``grf_left`` and ``grf_right``
    are present, the total is their sum (recorded in ``metadata["grf_from"]``). Other columns
    are ignored and listed in ``metadata["ignored_columns"]``. Blank lines and lines starting
    with ``#`` are skipped. Metadata come from the JSON sidecar ``NAME.json`` beside the data
    file (``mass_kg``, ``pacing_hz``, ``subject``, ``notes``; any other key is kept in
    ``Record.metadata``); keyword arguments override it. The sidecar is read for every format.
``mot``
    OpenSim storage: header lines up to ``endheader``, a line of column names, then
    whitespace-separated numbers. OpenSim is y-up, so the vertical force of each plate is its
    ``*_vy`` column; the total is their sum. With two plates they become ``grf_left_n`` and
    ``grf_right_n`` -- by ``l``/``r`` in the column names if present, otherwise in file order,
    and ``metadata["side_assignment"]`` says that the file does not state which belt is under
    which foot. A file with ``*_vz`` but no ``*_vy`` columns is refused (it is in a z-up lab
    frame; we do not guess the vertical axis).
``insole``
    PhysioNet gaitpdb text: no header, 19 whitespace-separated columns, time in column 1,
    total left and right foot force [N] in columns 18 and 19 (1-based); GRF = 18 + 19.
``c3d``
    Needs the optional extra ``ezc3d`` (``pip install workbench[c3d]``). The vertical force is
    the z component (ezc3d assumes z up) of every force platform, summed, on the analog time
    base. Force platforms report the force the person exerts on the plate in some labs and
    the reaction in others, so a negative mean is flipped and the flip recorded in
    ``metadata["warnings"]``.

Places in error messages are file line numbers (1-based, every line counted, including
header, comment and blank lines), written ``line N``.

Writing (:func:`save_record`) produces the CSV format above plus its sidecar, each written
atomically (temporary file in the same folder, then :func:`os.replace`), with floats in their
shortest exact text form so that reading back gives identical arrays.
"""

from __future__ import annotations

import csv
import json
import math
import numbers
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from workbench.errors import InputError, UsageError
from workbench.fileutil import atomic_write_text
from workbench.records.record import G_M_S2, FloatArray, Record
from workbench.records.validation import mass_problem, pacing_problem, validate_record

__all__ = [
    "COLUMN_ALIASES",
    "CSV_COLUMNS",
    "FORCE_UNITS",
    "FORMATS",
    "ManifestEntry",
    "detect_format",
    "load_manifest",
    "load_record",
    "save_record",
]

#: Formats :func:`load_record` reads.
FORMATS: tuple[str, ...] = ("csv", "mot", "insole", "c3d")

#: CSV column name -> Record field.
CSV_COLUMNS: dict[str, str] = {
    "time": "time_s",
    "grf": "grf_n",
    "grf_left": "grf_left_n",
    "grf_right": "grf_right_n",
    "ground_acc": "ground_acc_m_s2",
}

#: Accepted alternative CSV column names (after lower-casing and joining words with ``_``).
#: They name the quantity and its unit unambiguously; ``force``, ``fz`` and the like do not.
COLUMN_ALIASES: dict[str, str] = {
    "t": "time",
    "time_s": "time",
    "grf_n": "grf",
    "grf_left_n": "grf_left",
    "grf_right_n": "grf_right",
    "ground_acc_m_s2": "ground_acc",
}

#: Force units :func:`load_record` converts from, with their factor to newtons. ``kgf`` uses
#: the workbench's g = 9.81 m/s^2 so that a force given in kilograms-force averages to the
#: body mass times the same g the model uses.
FORCE_UNITS: dict[str, float] = {"N": 1.0, "kN": 1000.0, "kgf": G_M_S2}

_FORCE_UNIT_NAMES = {"n": "N", "kn": "kN", "kgf": "kgf", "kg": "kgf"}

# Units allowed in brackets after a CSV column name (lower case, spaces removed).
_COLUMN_UNITS: dict[str, tuple[str, ...]] = {
    "time": ("s",),
    "grf": ("n",),
    "grf_left": ("n",),
    "grf_right": ("n",),
    "ground_acc": ("m/s^2", "m/s2", "m/s²", "ms^-2", "ms-2", "m.s-2", "m.s^-2"),
}

#: How the accepted units are written in messages.
_DISPLAY_UNITS = {"time": "s", "grf": "N", "grf_left": "N", "grf_right": "N", "ground_acc": "m/s^2"}

_EXTENSIONS = {".csv": "csv", ".tsv": "csv", ".mot": "mot", ".c3d": "c3d"}
_INSOLE_COLUMNS = 19

# Metadata that describe how one particular file was read; save_record does not copy them
# into a new sidecar because they would be false for the file it writes.
_LOADER_KEYS = frozenset(
    {
        "format",
        "columns",
        "column_aliases",
        "ignored_columns",
        "grf_from",
        "delimiter",
        "file_lines",
        "mass_source",
        "sidecar",
        "mot_header",
        "plates",
        "side_assignment",
        "force_unit",
        "c3d",
    }
)
_SIDECAR_FIELDS = ("mass_kg", "pacing_hz", "subject", "notes")


# --------------------------------------------------------------------------------------
# Public API


def detect_format(path: str | os.PathLike[str]) -> str:
    """Tell which record format a file is in.

    The extension decides first (``.csv``/``.tsv`` -> ``"csv"``, ``.mot`` -> ``"mot"``,
    ``.c3d`` -> ``"c3d"``); otherwise (``.txt``, ``.dat``, no extension ...) the content:
    a C3D binary header, an ``endheader`` line (OpenSim), a headerless numeric table with 19
    columns (PhysioNet insole), or a text table whose first line is a header (CSV, e.g. a
    ``.txt`` with tab-separated ``time`` and ``grf`` columns). Pass ``fmt=`` to
    :func:`load_record` to override.

    Parameters
    ----------
    path : str or path-like
        The record file.

    Returns
    -------
    str
        One of :data:`FORMATS`.

    Raises
    ------
    InputError
        If the file is missing, empty, binary or not recognisable.
    """
    p = Path(path)
    source = str(path)
    _require_file(p, source)
    by_extension = _EXTENSIONS.get(p.suffix.lower())
    if by_extension is not None:
        return by_extension
    raw = _read_bytes(p, source)
    if len(raw) >= 512 and raw[1] == 0x50 and b"\x00" in raw[:512]:
        # C3D: byte 2 of the binary header block is the fixed key 0x50.
        return "c3d"
    text = _decode(raw, source)
    lines = _split_lines(text)
    content = [(i, s.strip()) for i, s in enumerate(lines) if s.strip()]
    if not content:
        raise _empty_file(source)
    if any(s.lower() == "endheader" for _, s in content[:200]):
        return "mot"
    first_index, first = next(((i, s) for i, s in content if not s.startswith("#")), content[0])
    tokens = first.split()
    if tokens and all(_parse_number(tok) is not None for tok in tokens):
        if len(tokens) == _INSOLE_COLUMNS:
            return "insole"
        raise InputError(
            source,
            f"line {first_index + 1}",
            f"the file is a table of numbers without a header, with {len(tokens)} columns "
            f"(the PhysioNet insole format has {_INSOLE_COLUMNS})",
            "add a header line naming the columns 'time' and 'grf' to read it as CSV, or pass "
            "the format with --format (fmt=... in Python)",
        )
    return "csv"


def load_record(
    path: str | os.PathLike[str],
    *,
    fmt: str | None = None,
    mass_kg: float | None = None,
    pacing_hz: float | None = None,
    subject: str | None = None,
    resample: bool = False,
    irregular_tolerance: float = 0.01,
    validate: bool = True,
    force_unit: str = "N",
    allow_negative_force: bool = False,
) -> Record:
    """Read a GRF record from a file, with its metadata, and validate it.

    Parameters
    ----------
    path : str or path-like
        The record file; ``Record.source`` is this path as given.
    fmt : {"csv", "mot", "insole", "c3d"}, optional
        The format; detected by :func:`detect_format` if not given.
    mass_kg : float, optional
        Body mass [kg]; overrides ``mass_kg`` in the JSON sidecar. For the embedded real
        records the mass from :data:`workbench.datasets.EMBEDDED` is used if none is given.
    pacing_hz : float, optional
        Stated pacing (step) frequency [Hz]; overrides the sidecar.
    subject : str, optional
        Subject identifier; overrides the sidecar.
    resample : bool, optional
        Interpolate irregularly sampled records onto a uniform grid (see
        :func:`~workbench.records.validation.validate_record`).
    irregular_tolerance : float, optional
        Accepted relative deviation of a sample interval from the median (default 1 %).
    validate : bool, optional
        Run :func:`~workbench.records.validation.validate_record` (default). Parsing errors
        (missing file, bad cells, missing columns) are raised either way.
    force_unit : {"N", "kN", "kgf"}, optional
        Unit of the force columns in the file; forces are converted to newtons and the
        conversion recorded in ``metadata["force_unit"]``.
    allow_negative_force : bool, optional
        Accept total-force samples below zero with a warning instead of refusing the record
        (see :func:`~workbench.records.validation.validate_record`); for synthetic benchmark
        forces that dip below zero. Default False.

    Returns
    -------
    Record
        With ``metadata["format"]``, ``metadata["columns"]`` (where each field was read),
        ``metadata["file_lines"]`` (file line of each sample, run-length coded),
        ``metadata["mass_source"]`` when a mass is known, ``metadata["warnings"]`` and any
        extra sidecar keys.

    Raises
    ------
    InputError
        For any problem with the file, its sidecar or the data, in one sentence.
    UsageError
        For a bad argument (unknown ``fmt`` or ``force_unit``, a non-numeric mass) or, for
        C3D, when ``ezc3d`` is not installed.
    """
    p = Path(path)
    source = str(path)
    mass_arg = _number_argument(mass_kg, "mass_kg")
    pacing_arg = _number_argument(pacing_hz, "pacing_hz")
    unit = _FORCE_UNIT_NAMES.get(str(force_unit).strip().lower())
    if unit is None:
        raise UsageError(f"force_unit must be one of {', '.join(FORCE_UNITS)}, got {force_unit!r}")
    _require_file(p, source)
    if fmt is None:
        fmt = detect_format(p)
    elif str(fmt).lower() in FORMATS:
        fmt = str(fmt).lower()
    else:
        raise UsageError(f"fmt must be one of {', '.join(FORMATS)}, got {fmt!r}")

    readers: dict[str, Callable[[Path, str], _Table]] = {
        "csv": _read_csv,
        "mot": _read_mot,
        "insole": _read_insole,
        "c3d": _read_c3d,
    }
    table = readers[fmt](p, source)
    arrays = table.arrays
    metadata: dict[str, Any] = {}

    sidecar, sidecar_path = _read_sidecar(p)
    for key, value in sidecar.items():
        # Loader keys in a sidecar describe some other file (e.g. a hand-copied sidecar);
        # this file's own reading fills them in below.
        if key not in _SIDECAR_FIELDS and key not in _LOADER_KEYS:
            metadata[key] = value
    warnings = [str(w) for w in metadata.pop("warnings", None) or []]
    metadata.update(table.metadata)
    warnings.extend(w for w in table.warnings if w not in warnings)
    metadata["format"] = fmt
    if sidecar_path is not None:
        metadata["sidecar"] = str(sidecar_path)

    if unit != "N":
        factor = FORCE_UNITS[unit]
        for name in ("grf_n", "grf_left_n", "grf_right_n"):
            if arrays.get(name) is not None:
                arrays[name] = arrays[name] * factor
        metadata["force_unit"] = {"unit": unit, "factor_to_n": factor}

    mass = sidecar.get("mass_kg")
    mass_source = f'"mass_kg" in {sidecar_path.name}' if sidecar_path and mass is not None else None
    if mass_arg is not None:
        mass, mass_source = mass_arg, "given as --mass or mass_kg"
    if mass is None:
        embedded = _embedded_entry(p)
        if embedded is not None:
            mass, mass_source = embedded.mass_kg, "embedded dataset table"
            metadata.setdefault("attribution", embedded.attribution)
    if mass_source is not None:
        metadata["mass_source"] = mass_source
    pacing = pacing_arg if pacing_arg is not None else sidecar.get("pacing_hz")
    subject_value = subject if subject is not None else sidecar.get("subject")
    metadata["warnings"] = warnings

    record = Record(
        time_s=arrays["time_s"],
        grf_n=arrays["grf_n"],
        mass_kg=mass,
        grf_left_n=arrays.get("grf_left_n"),
        grf_right_n=arrays.get("grf_right_n"),
        ground_acc_m_s2=arrays.get("ground_acc_m_s2"),
        pacing_hz=pacing,
        subject=None if subject_value is None else str(subject_value),
        source=source,
        notes=str(sidecar.get("notes", "")),
        metadata=metadata,
    )
    if validate:
        record = validate_record(
            record,
            irregular_tolerance=irregular_tolerance,
            resample=resample,
            allow_negative_force=allow_negative_force,
        )
    return record


def save_record(
    record: Record,
    path: str | os.PathLike[str],
    *,
    extra_metadata: Mapping[str, Any] | None = None,
) -> tuple[Path, Path]:
    """Write a record as CSV plus JSON sidecar, each file atomically.

    Only the columns the record has are written (``time``, ``grf`` and whichever of
    ``grf_left``, ``grf_right``, ``ground_acc`` are present), every value in its shortest
    exact decimal form, so ``load_record(save_record(r, p)[0])`` gives identical arrays. The
    sidecar holds ``mass_kg``, ``pacing_hz``, ``subject``, ``notes`` (when set), the record's
    other metadata except the keys that describe how its original file was read (format,
    column names, line numbers, mass source ...), then ``extra_metadata``.

    Each file is written to a temporary file in the same folder and moved into place with
    :func:`os.replace`, so a reader never sees a half-written file; the sidecar is replaced
    first, so an existing CSV always has its sidecar.

    Parameters
    ----------
    record : Record
        The record to write.
    path : str or path-like
        The CSV path (must end in ``.csv``); the sidecar is the same path with ``.json``.
        Missing folders are created.
    extra_metadata : mapping, optional
        More JSON-serialisable keys for the sidecar (e.g. ``{"truth": {...}}``).

    Returns
    -------
    tuple of Path
        ``(csv_path, json_path)``.

    Raises
    ------
    UsageError
        If the path does not end in ``.csv``, ``extra_metadata`` tries to set a record field,
        or a metadata value cannot be written as JSON.
    """
    csv_path = Path(path)
    if csv_path.suffix.lower() != ".csv":
        raise UsageError(f"save_record writes CSV; give a path ending in .csv, not {str(path)!r}")
    json_path = csv_path.with_suffix(".json")

    sidecar: dict[str, Any] = {}
    if record.mass_kg is not None:
        sidecar["mass_kg"] = record.mass_kg
    if record.pacing_hz is not None:
        sidecar["pacing_hz"] = record.pacing_hz
    if record.subject is not None:
        sidecar["subject"] = record.subject
    if record.notes:
        sidecar["notes"] = record.notes
    for key, value in record.metadata.items():
        if key in _LOADER_KEYS or key in _SIDECAR_FIELDS:
            continue
        if key == "warnings" and not value:
            continue
        sidecar[str(key)] = _jsonable(value, f"metadata[{key!r}]")
    for key, value in (extra_metadata or {}).items():
        if key in _SIDECAR_FIELDS:
            raise UsageError(
                f"extra_metadata cannot set {key!r}; set it on the record with "
                f"record.replace({key}=...)"
            )
        sidecar[str(key)] = _jsonable(value, f"extra_metadata[{key!r}]")
    json_text = json.dumps(sidecar, indent=2, sort_keys=False) + "\n"

    names = ["time", "grf"]
    columns: list[list[float]] = [record.time_s.tolist(), record.grf_n.tolist()]
    for column, name in (
        ("grf_left", "grf_left_n"),
        ("grf_right", "grf_right_n"),
        ("ground_acc", "ground_acc_m_s2"),
    ):
        values = getattr(record, name)
        if values is not None:
            names.append(column)
            columns.append(values.tolist())
    # repr of a Python float is its shortest decimal form that reads back bit for bit.
    rows = (",".join(map(repr, row)) for row in zip(*columns, strict=True))
    csv_text = ",".join(names) + "\n" + "".join(f"{row}\n" for row in rows)

    csv_path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(json_path, json_text)
    atomic_write_text(csv_path, csv_text)
    return csv_path, json_path


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


def load_manifest(path: str | os.PathLike[str]) -> list[ManifestEntry]:
    """Read a batch manifest: a CSV with a ``path`` column and optional metadata columns.

    Columns: ``path`` (required; relative to the manifest's folder), ``mass_kg``,
    ``pacing_hz``, ``subject`` (optional; empty cells mean "not given"). Separators as for
    record CSV files; quoted cells are allowed (paths with commas). Other columns are refused
    so that a misspelt ``mass`` column is not silently ignored. Whether each record file exists
    is not checked here: a batch reports a missing record as a failure of that record.

    Parameters
    ----------
    path : str or path-like
        The manifest file.

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
    lines = _split_lines(text)
    header_index = _first_content_line(lines)
    if header_index is None:
        raise _empty_file(source)
    header_line = lines[header_index]
    delimiter = _detect_delimiter(header_line)
    names = _split_fields(header_line, delimiter)
    index_of: dict[str, int] = {}
    for i, raw in enumerate(names):
        name, unit = _normalise_name(raw)
        if name not in _MANIFEST_COLUMNS:
            raise InputError(
                source,
                f"line {header_index + 1}, column {_show(raw)}",
                "this column is not part of a manifest",
                f"use only the columns {', '.join(_MANIFEST_COLUMNS)} (path is required)",
            )
        expected_unit = {"mass_kg": "kg", "pacing_hz": "hz"}.get(name)
        if unit is not None and unit != expected_unit:
            raise InputError(
                source,
                f"line {header_index + 1}, column {_show(raw)}",
                f"the unit {unit!r} does not match the column {name!r}",
                "give masses in kg and pacing frequencies in Hz and drop the bracketed unit",
            )
        if name in index_of:
            raise InputError(
                source,
                f"line {header_index + 1}, column {_show(raw)}",
                f"the column {name!r} appears twice",
                "keep one of them",
            )
        index_of[name] = i
    if "path" not in index_of:
        raise InputError(
            source,
            f"line {header_index + 1}",
            f"there is no 'path' column (columns found: {_show_list(names)})",
            "name the column with the record files 'path' (optional: "
            f"{', '.join(_MANIFEST_COLUMNS[1:])})",
        )

    entries: list[ManifestEntry] = []
    seen: dict[str, int] = {}
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
                f"the record {_show(file_text)} is already listed on line {seen[file_text]}",
                "list every record once",
            )
        seen[file_text] = number
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
        entries.append(ManifestEntry(record_path, mass, pacing, subject, number))
    if not entries:
        raise InputError(
            source,
            f"line {header_index + 1}",
            "the manifest has a header but no records",
            "add one row per record file",
        )
    return entries


# --------------------------------------------------------------------------------------
# Reading text


@dataclass
class _Table:
    """What a format reader found, before sidecar and keyword metadata are merged."""

    arrays: dict[str, FloatArray]
    metadata: dict[str, Any]
    warnings: list[str] = field(default_factory=list)


def _require_file(p: Path, source: str) -> None:
    if not p.exists():
        raise InputError(
            source,
            "whole file",
            "the file does not exist",
            "check the path (relative paths start from the current folder)",
        )
    if p.is_dir():
        raise InputError(source, "whole file", "this is a folder, not a file", "give a record file")


def _read_bytes(p: Path, source: str) -> bytes:
    _require_file(p, source)
    try:
        return p.read_bytes()
    except OSError as exc:
        raise InputError(
            source,
            "whole file",
            f"the file cannot be read ({exc.strerror or type(exc).__name__})",
            "check its permissions",
        ) from None


def _empty_file(source: str) -> InputError:
    return InputError(
        source, "whole file", "the file is empty", "give a file with a header and data rows"
    )


def _decode(raw: bytes, source: str) -> str:
    if not raw.strip():
        raise _empty_file(source)
    if raw.startswith(b"PK\x03\x04"):
        raise InputError(
            source,
            "whole file",
            "this is a ZIP archive (an Excel .xlsx workbook?), not a text table",
            "export the sheet as CSV",
        )
    if b"\x00" in raw:
        raise InputError(
            source,
            "whole file",
            "the file contains binary data (NUL bytes), not a text table",
            "give a text file (CSV, OpenSim .mot or PhysioNet insole text) or pass --format c3d "
            "for a C3D file",
        )
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise InputError(
            source,
            f"line {line}",
            f"the byte 0x{raw[exc.start]:02x} is not UTF-8 text",
            "save the file as UTF-8 (plain text CSV)",
        ) from None


def _split_lines(text: str) -> list[str]:
    # Only CR, LF and CRLF end lines, as in any CSV reader and text editor; str.splitlines
    # would also split at form feeds and Unicode separators and shift the line numbers.
    lines = re.split(r"\r\n|\r|\n", text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def _first_content_line(lines: Sequence[str]) -> int | None:
    for i, line in enumerate(lines):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            return i
    return None


def _parse_number(cell: str) -> float | None:
    """Strict decimal number (also nan/inf, which validation reports) or None."""
    text = cell.strip()
    # float() would also take '1_000' and non-ASCII digits; neither is a number in a data file.
    if not text or not text.isascii() or "_" in text:
        return None
    try:
        return float(text)
    except ValueError:
        return None


def _show(text: str, limit: int = 40) -> str:
    """Quote a piece of the user's file for a message, on one line and not too long."""
    if len(text) > limit:
        return repr(text[:limit]) + "..."
    return repr(text)


def _show_list(names: Sequence[str], limit: int = 12) -> str:
    shown = ", ".join(_show(n) for n in names[:limit])
    return shown + (f" and {len(names) - limit} more" if len(names) > limit else "")


def _delimiter_name(delimiter: str | None) -> str:
    return {",": "commas", ";": "semicolons", "\t": "tabs", None: "spaces"}[delimiter]


def _detect_delimiter(header: str) -> str | None:
    counts = {d: header.count(d) for d in ("\t", ";", ",")}
    best = max(counts, key=lambda d: counts[d])  # ties keep the order tab, semicolon, comma
    if counts[best] > 0:
        return best
    return None if len(header.split()) > 1 else ","


def _split_fields(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    if '"' in line:
        try:
            return next(csv.reader([line], delimiter=delimiter), [])
        except csv.Error:
            return line.split(delimiter)
    return line.split(delimiter)


def _normalise_name(raw: str) -> tuple[str, str | None]:
    """Column name -> (lower-case name with words joined by '_', unit in brackets or None)."""
    text = raw.strip().strip("\"'").strip()
    unit = None
    match = re.fullmatch(r"(.*?)\s*[\[(]\s*([^\])]*?)\s*[\])]", text)
    if match:
        text, unit = match.group(1), re.sub(r"\s+", "", match.group(2)).lower()
    name = re.sub(r"[\s\-]+", "_", text.strip().lower())
    return name, unit


def _field_count_error(
    source: str, line: int, found: int, header_line: int, expected: int, delimiter: str | None
) -> InputError:
    return InputError(
        source,
        f"line {line}",
        f"the row has {found} fields but the header (line {header_line}) has {expected}",
        f"separate the values with {_delimiter_name(delimiter)} as in the header and give one "
        "value per column",
    )


def _parse_rows(
    lines: Sequence[str],
    first: int,
    split: Callable[[str], list[str]],
    n_fields: int,
    wanted: Sequence[int],
    labels: Mapping[int, str],
    source: str,
    count_error: Callable[[int, int], InputError],
    decimal_comma_hint: bool,
) -> tuple[dict[int, FloatArray], list[int]]:
    """Parse the numeric cells of columns ``wanted`` from ``lines[first:]``.

    Returns the columns by index and the 1-based file line of each parsed row.
    """
    values: dict[int, list[float]] = {j: [] for j in wanted}
    line_numbers: list[int] = []
    for i in range(first, len(lines)):
        line = lines[i]
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = split(line)
        if len(fields) != n_fields:
            raise count_error(i + 1, len(fields))
        for j in wanted:
            cell = fields[j]
            number = _parse_number(cell)
            if number is None:
                raise _bad_cell(source, i + 1, labels[j], cell, decimal_comma_hint)
            values[j].append(number)
        line_numbers.append(i + 1)
    return {j: np.asarray(v, dtype=np.float64) for j, v in values.items()}, line_numbers


def _bad_cell(
    source: str, line: int, label: str, cell: str, decimal_comma_hint: bool
) -> InputError:
    where = f"line {line}, {label}"
    if not cell.strip():
        return InputError(source, where, "the cell is empty", "fill in the value or delete the row")
    hint = ""
    if decimal_comma_hint and re.fullmatch(r"\s*[+-]?\d*,\d+\s*", cell):
        hint = " (write decimals with a point, not a comma)"
    return InputError(
        source,
        where,
        f"the value {_show(cell)} is not a number",
        f"correct the value or delete the row{hint}",
    )


def _line_runs(line_numbers: Sequence[int]) -> dict[str, Any]:
    """Run-length code of sample index -> file line (JSON-friendly, small)."""
    runs: list[list[int]] = []
    previous = None
    for index, line in enumerate(line_numbers):
        if previous is None or line != previous + 1:
            runs.append([index, line])
        previous = line
    return {"n_samples": len(line_numbers), "runs": runs}


def _no_data_rows(source: str, header_line: int) -> InputError:
    return InputError(
        source,
        f"line {header_line}",
        "the file has a header but no data rows",
        "add the measured samples below the header",
    )


# --------------------------------------------------------------------------------------
# Format readers


def _read_csv(p: Path, source: str) -> _Table:
    text = _decode(_read_bytes(p, source), source)
    lines = _split_lines(text)
    header_index = _first_content_line(lines)
    if header_index is None:
        raise _empty_file(source)
    header_line = header_index + 1
    delimiter = _detect_delimiter(lines[header_index])
    names = _split_fields(lines[header_index], delimiter)
    expected = (
        "name the columns 'time' [s] and 'grf' [N] (optional 'grf_left', 'grf_right' [N], "
        "'ground_acc' [m/s^2]; also accepted: " + ", ".join(COLUMN_ALIASES) + ")"
    )
    if all(_parse_number(n) is not None for n in names):
        raise InputError(
            source,
            f"line {header_line}",
            f"the first line {_show(lines[header_index])} is data, not a header",
            f"add a header line and {expected}",
        )

    found: dict[str, tuple[int, str]] = {}
    aliases: dict[str, str] = {}
    ignored: list[str] = []
    for j, raw in enumerate(names):
        name, unit = _normalise_name(raw)
        canonical = name if name in CSV_COLUMNS else COLUMN_ALIASES.get(name)
        if canonical is None:
            ignored.append(raw)
            continue
        if unit is not None and unit not in _COLUMN_UNITS[canonical]:
            raise InputError(
                source,
                f"line {header_line}, column {_show(raw)}",
                f"the unit {unit!r} is not the one the workbench reads "
                f"({_DISPLAY_UNITS[canonical]})",
                f"convert the column to {_DISPLAY_UNITS[canonical]} and name it "
                f"'{canonical}' (for forces in kN or kgf you may instead name it '{canonical}' "
                "and pass --force-unit)",
            )
        if canonical in found:
            raise InputError(
                source,
                f"line {header_line}, column {_show(raw)}",
                f"this column and column {_show(found[canonical][1])} both mean '{canonical}'",
                "keep one of them",
            )
        found[canonical] = (j, raw)
        if name != canonical:
            aliases[raw] = canonical

    grf_from = None
    if "time" not in found or "grf" not in found:
        if "time" in found and "grf_left" in found and "grf_right" in found:
            grf_from = "grf_left + grf_right"
        else:
            missing = [c for c in ("time", "grf") if c not in found]
            raise InputError(
                source,
                f"line {header_line} (header)",
                f"there is no {' or '.join(repr(m) for m in missing)} column (columns found: "
                f"{_show_list(names)})",
                expected,
            )

    labels = {j: f"column {_show(raw)}" for _, (j, raw) in found.items()}
    columns, line_numbers = _parse_rows(
        lines,
        header_index + 1,
        lambda line: _split_fields(line, delimiter),
        len(names),
        [j for j, _ in found.values()],
        labels,
        source,
        lambda line, n: _field_count_error(source, line, n, header_line, len(names), delimiter),
        decimal_comma_hint=delimiter != ",",
    )
    if not line_numbers:
        raise _no_data_rows(source, header_line)

    arrays: dict[str, FloatArray] = {}
    column_labels: dict[str, str] = {}
    for canonical, (j, _raw) in found.items():
        arrays[CSV_COLUMNS[canonical]] = columns[j]
        column_labels[CSV_COLUMNS[canonical]] = labels[j]
    metadata: dict[str, Any] = {}
    warnings: list[str] = []
    if grf_from is not None:
        arrays["grf_n"] = arrays["grf_left_n"] + arrays["grf_right_n"]
        column_labels["grf_n"] = (
            f"columns {_show(found['grf_left'][1])} + {_show(found['grf_right'][1])}"
        )
        metadata["grf_from"] = grf_from
    metadata["columns"] = column_labels
    metadata["delimiter"] = _delimiter_name(delimiter)
    metadata["file_lines"] = _line_runs(line_numbers)
    if aliases:
        metadata["column_aliases"] = aliases
    if ignored:
        metadata["ignored_columns"] = ignored
        suspicious = [
            n for n in ignored if _normalise_name(n)[0].startswith(("time", "grf", "ground"))
        ]
        if suspicious:
            warnings.append(
                f"The columns {_show_list(suspicious)} look like workbench columns but do not "
                "match any expected name, so they were ignored."
            )
    return _Table(arrays, metadata, warnings)


_SIDE_TOKENS = {"l": "left", "left": "left", "r": "right", "right": "right"}


def _read_mot(p: Path, source: str) -> _Table:
    text = _decode(_read_bytes(p, source), source)
    lines = _split_lines(text)
    end = next((i for i, line in enumerate(lines) if line.strip().lower() == "endheader"), None)
    if end is None:
        raise InputError(
            source,
            "header",
            "there is no 'endheader' line, so this is not an OpenSim .mot file",
            "check the file or pass the right format (--format csv for a table with a header line)",
        )
    header: dict[str, str] = {}
    for line in lines[:end]:
        if "=" in line:
            key, _, value = line.partition("=")
            header[key.strip()] = value.strip()
    names_index = next((i for i in range(end + 1, len(lines)) if lines[i].strip()), None)
    if names_index is None:
        raise InputError(
            source,
            f"line {end + 1}",
            "nothing follows 'endheader' (no column names, no data)",
            "give the column-name line and the data rows",
        )
    names_line = names_index + 1
    names = (
        lines[names_index].split("\t") if "\t" in lines[names_index] else lines[names_index].split()
    )
    names = [n.strip() for n in names]
    lower = [n.lower() for n in names]
    if "time" not in lower:
        raise InputError(
            source,
            f"line {names_line}",
            f"there is no 'time' column (columns found: {_show_list(names)})",
            "give the OpenSim column-name line starting with 'time'",
        )
    time_j = lower.index("time")
    vy = [j for j, n in enumerate(lower) if n.endswith("_vy")]
    if not vy:
        vz = [names[j] for j, n in enumerate(lower) if n.endswith("_vz")]
        problem = f"there is no vertical force column '*_vy' (columns found: {_show_list(names)})"
        if vz:
            problem += "; the '*_vz' columns suggest a z-up lab frame, but OpenSim files are y-up"
        raise InputError(
            source,
            f"line {names_line}",
            problem,
            "export the plate forces in the OpenSim y-up frame (ground_force_vy) or convert the "
            "record to CSV with 'time' and 'grf' columns",
        )
    labels = {j: f"column {_show(names[j])}" for j in [time_j, *vy]}
    columns, line_numbers = _parse_rows(
        lines,
        names_index + 1,
        str.split,
        len(names),
        [time_j, *vy],
        labels,
        source,
        lambda line, n: InputError(
            source,
            f"line {line}",
            f"the row has {n} values but the column-name line (line {names_line}) has {len(names)}",
            "repair or delete the row (the file may be truncated)",
        ),
        decimal_comma_hint=True,
    )
    if not line_numbers:
        raise _no_data_rows(source, names_line)

    arrays: dict[str, FloatArray] = {"time_s": columns[time_j]}
    total = np.zeros_like(columns[time_j])
    for j in vy:
        total = total + columns[j]
    arrays["grf_n"] = total
    column_labels = {
        "time_s": labels[time_j],
        "grf_n": "columns " + " + ".join(_show(names[j]) for j in vy),
    }
    metadata: dict[str, Any] = {
        "mot_header": header,
        "plates": [names[j] for j in vy],
        "file_lines": _line_runs(line_numbers),
    }
    warnings: list[str] = []
    if len(vy) == 2:
        sides = [_side_of(names[j]) for j in vy]
        if sorted(s or "" for s in sides) == ["left", "right"]:
            left_j, right_j = (vy[0], vy[1]) if sides[0] == "left" else (vy[1], vy[0])
            assignment = "from the column names"
        else:
            left_j, right_j = vy
            assignment = (
                f"grf_left_n is {names[left_j]} and grf_right_n is {names[right_j]} in file "
                "order; the file does not state which plate or belt is under which foot"
            )
        arrays["grf_left_n"] = columns[left_j]
        arrays["grf_right_n"] = columns[right_j]
        column_labels["grf_left_n"] = labels[left_j]
        column_labels["grf_right_n"] = labels[right_j]
        metadata["side_assignment"] = assignment
    metadata["columns"] = column_labels
    stated_rows = header.get("nRows")
    if stated_rows is not None and stated_rows.strip().isdigit():
        if int(stated_rows) != len(line_numbers):
            warnings.append(
                f"The header states nRows={stated_rows} but {len(line_numbers)} data rows were "
                "read; the file may be truncated."
            )
    return _Table(arrays, metadata, warnings)


def _side_of(name: str) -> str | None:
    tokens = re.split(r"[_\W]+", name.lower())
    sides = {_SIDE_TOKENS[t] for t in tokens if t in _SIDE_TOKENS}
    return sides.pop() if len(sides) == 1 else None


def _read_insole(p: Path, source: str) -> _Table:
    text = _decode(_read_bytes(p, source), source)
    lines = _split_lines(text)
    first = _first_content_line(lines)
    if first is None:
        raise _empty_file(source)
    labels = {0: "column 1 (time)", 17: "column 18 (total left)", 18: "column 19 (total right)"}
    columns, line_numbers = _parse_rows(
        lines,
        first,
        str.split,
        _INSOLE_COLUMNS,
        [0, 17, 18],
        labels,
        source,
        lambda line, n: InputError(
            source,
            f"line {line}",
            f"the row has {n} values but the PhysioNet insole format has {_INSOLE_COLUMNS}",
            "repair or delete the row, or pass the right format (--format csv for a table "
            "with a header line)",
        ),
        decimal_comma_hint=True,
    )
    left, right = columns[17], columns[18]
    arrays = {"time_s": columns[0], "grf_n": left + right, "grf_left_n": left, "grf_right_n": right}
    metadata: dict[str, Any] = {
        "columns": {
            "time_s": labels[0],
            "grf_n": "columns 18 + 19 (total left + total right)",
            "grf_left_n": labels[17],
            "grf_right_n": labels[18],
        },
        "file_lines": _line_runs(line_numbers),
    }
    return _Table(arrays, metadata)


def _read_c3d(p: Path, source: str) -> _Table:
    try:
        import ezc3d  # optional extra, imported only when a C3D file is read
    except ImportError:
        raise UsageError(
            f"reading the C3D file {source} needs the optional package ezc3d; install it with "
            "pip install 'workbench[c3d]'"
        ) from None
    try:
        c3d = ezc3d.c3d(str(p), extract_forceplat_data=True)
        platforms = list(c3d["data"]["platform"])
        analog_rate = float(c3d["header"]["analogs"]["frame_rate"])
        point_rate = float(c3d["header"]["points"]["frame_rate"])
        first_frame = int(c3d["header"]["points"]["first_frame"])
    except Exception as exc:  # ezc3d raises plain RuntimeErrors for damaged files
        raise InputError(
            source,
            "whole file",
            f"ezc3d could not read the force platforms ({type(exc).__name__})",
            "check that this is a C3D file with force platform data",
        ) from None
    if not platforms:
        raise InputError(
            source,
            "force platforms",
            "the C3D file has no force platform data",
            "give a trial recorded with force platforms",
        )
    if not (math.isfinite(analog_rate) and analog_rate > 0):
        raise InputError(
            source, "header", f"the analog rate {analog_rate!r} Hz is not valid", "repair the file"
        )
    vertical: list[FloatArray] = []
    for k, platform in enumerate(platforms, start=1):
        force = np.asarray(platform["force"], dtype=np.float64)
        unit = str(platform.get("unit_force", "N")).strip()
        factor = FORCE_UNITS.get(_FORCE_UNIT_NAMES.get(unit.lower(), ""), None)
        if factor is None:
            raise InputError(
                source,
                f"force platform {k}",
                f"the force unit {unit!r} is not one the workbench converts",
                f"export the forces in {', '.join(FORCE_UNITS)}",
            )
        if force.ndim != 2 or force.shape[0] < 3:
            raise InputError(
                source,
                f"force platform {k}",
                f"the force data have shape {force.shape}, not 3 x samples",
                "check the force platform parameters of the file",
            )
        vertical.append(force[2] * factor)
    lengths = {v.size for v in vertical}
    if len(lengths) != 1:
        raise InputError(
            source,
            "force platforms",
            f"the platforms have different numbers of samples ({sorted(lengths)})",
            "check the analog channels of the file",
        )
    n = vertical[0].size
    # Analog samples run at analog_rate from the first point frame: one common time base.
    time_s = first_frame / point_rate + np.arange(n, dtype=np.float64) / analog_rate
    total = np.sum(vertical, axis=0)
    warnings: list[str] = []
    sign = 1.0
    if n and float(np.mean(total)) < 0.0:
        sign = -1.0
        warnings.append(
            "The C3D platforms report the force on the plate (negative upwards), so its sign "
            "was flipped to the force on the person."
        )
    arrays: dict[str, FloatArray] = {"time_s": time_s, "grf_n": sign * total}
    column_labels = {"time_s": "analog time base", "grf_n": "sum of platform Fz"}
    metadata: dict[str, Any] = {
        "c3d": {
            "platforms": len(platforms),
            "analog_rate_hz": analog_rate,
            "point_rate_hz": point_rate,
            "first_frame": first_frame,
            "vertical_sign": sign,
        }
    }
    if len(vertical) == 2:
        arrays["grf_left_n"] = sign * vertical[0]
        arrays["grf_right_n"] = sign * vertical[1]
        column_labels["grf_left_n"] = "platform 1 Fz"
        column_labels["grf_right_n"] = "platform 2 Fz"
        metadata["side_assignment"] = (
            "grf_left_n is platform 1 and grf_right_n is platform 2 in file order; the file "
            "does not state which platform is under which foot"
        )
    metadata["columns"] = column_labels
    return _Table(arrays, metadata, warnings)


# --------------------------------------------------------------------------------------
# Metadata


def _read_sidecar(p: Path) -> tuple[dict[str, Any], Path | None]:
    side = p.with_suffix(".json")
    if side == p or not side.is_file():
        return {}, None
    source = str(side)
    raw = _read_bytes(side, source)
    try:
        data = json.loads(raw.decode("utf-8-sig"))
    except UnicodeDecodeError:
        raise InputError(
            source, "whole file", "the sidecar is not UTF-8 text", "save it as UTF-8 JSON"
        ) from None
    except json.JSONDecodeError as exc:
        raise InputError(
            source,
            f"line {exc.lineno}, column {exc.colno}",
            f"the sidecar is not valid JSON ({exc.msg})",
            'fix the JSON syntax, e.g. {"mass_kg": 72.5, "subject": "S01"}',
        ) from None
    except RecursionError:
        raise InputError(
            source, "whole file", "the JSON is nested too deeply", "simplify it"
        ) from None
    if not isinstance(data, dict):
        raise InputError(
            source,
            "whole file",
            f"the sidecar holds a JSON {type(data).__name__}, not an object",
            'write an object such as {"mass_kg": 72.5}',
        )
    for key in ("mass_kg", "pacing_hz"):
        value = data.get(key)
        if value is not None and (isinstance(value, bool) or not isinstance(value, int | float)):
            unit = "kilograms" if key == "mass_kg" else "hertz"
            raise InputError(
                source,
                f"key {key!r}",
                f"the value {_show(json.dumps(value))} is not a number",
                f'write it as a plain number in {unit}, e.g. "{key}": '
                f"{72.5 if key == 'mass_kg' else 1.8}",
            )
        if value is not None:
            data[key] = float(value)
    subject = data.get("subject")
    if subject is not None and (isinstance(subject, bool) or not isinstance(subject, str | int)):
        raise InputError(
            source,
            "key 'subject'",
            "the subject is not a text or a number",
            'write it as text, e.g. "subject": "S01"',
        )
    notes = data.get("notes")
    if notes is not None and not isinstance(notes, str):
        raise InputError(
            source, "key 'notes'", "the notes are not text", "write them as one JSON string"
        )
    if notes is None:
        data.pop("notes", None)
    warnings = data.get("warnings")
    if warnings is not None and not (
        isinstance(warnings, list) and all(isinstance(w, str) for w in warnings)
    ):
        raise InputError(
            source,
            "key 'warnings'",
            "the warnings are not a list of texts",
            "fix or remove the key",
        )
    return data, side


def _number_argument(value: Any, name: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise UsageError(f"{name} must be a number, got {value!r}")
    return float(value)


def _embedded_entry(p: Path) -> Any:
    from workbench.datasets.catalogue import EMBEDDED, embedded_path

    try:
        resolved = p.resolve()
        for key, entry in EMBEDDED.items():
            if embedded_path(key).resolve() == resolved:
                return entry
    except OSError:
        return None
    return None


def _manifest_number(cell: str, source: str, line: int, column: str) -> float | None:
    if not cell:
        return None
    value = _parse_number(cell)
    if value is None or not math.isfinite(value):
        raise InputError(
            source,
            f"line {line}, column {column!r}",
            f"the value {_show(cell)} is not a number",
            "write a plain number or leave the cell empty",
        )
    return value


def _jsonable(value: Any, name: str) -> Any:
    """Convert a metadata value to plain JSON types, or raise naming the key."""
    if value is None or isinstance(value, str | bool | int | float):
        return value
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v, f"{name}[{k!r}]") for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v, name) for v in value]
    raise UsageError(
        f"{name} is a {type(value).__name__}, which cannot be written to the JSON sidecar; "
        "convert it to numbers, text, lists or dicts"
    )
