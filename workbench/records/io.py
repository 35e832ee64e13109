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
    the laboratory's z component of every force platform (ezc3d turns each platform's force
    into the laboratory frame with its corners; a file whose z axis carries less force than
    x or y is refused), each platform turned to the force on the person (force platforms
    report the force the person exerts on the plate in some labs and the reaction in others:
    a platform whose largest load is negative is flipped and the flip recorded in
    ``metadata["warnings"]``), summed, on the analog clock from the first point frame. The
    mass is ``--mass``, else the sidecar's, else the file's ``PROCESSING:Bodymass``. The
    force unit is the one ``ANALOG:UNITS`` states for a platform's Fz channel (platform types
    2 and 4), else ezc3d's (``POINT:FORCE_UNITS``, N when absent); ``--force-unit`` converts
    on top of it, for a file whose stated unit is wrong.

Places in error messages are file line numbers (1-based, every line counted, including
header, comment and blank lines), written ``line N``.

Writing (:func:`save_record`) produces the CSV format above plus its sidecar, each written
atomically (temporary file in the same folder, then :func:`os.replace`), with floats in their
shortest exact text form so that reading back gives identical arrays.

This module keeps :func:`detect_format`, :func:`load_record` and :func:`save_record`. The
formats are a registry (:mod:`workbench.records.formats`: one module per format with its
reader and column names, and :func:`~workbench.records.formats.register_format` to add
one; the guide page "Adding a record format"), the shared
text-table parsing in :mod:`workbench.records.text_table`, the sidecar in
:mod:`workbench.records.sidecar` and batch manifests in :mod:`workbench.records.manifest`;
the public names among them are re-exported here.
"""

from __future__ import annotations

import json
import numbers
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from workbench.errors import InputError, UsageError
from workbench.fileutil import atomic_write_texts
from workbench.records.embedded import EMBEDDED, EmbeddedRecord, embedded_path
from workbench.records.formats import (
    ARRAY_NAMES,
    COLUMN_ALIASES,
    CSV_COLUMNS,
    FORCE_UNITS,
    FORMATS,
    RecordTable,
    format_names,
    record_format,
    registered_formats,
)
from workbench.records.formats.base import _FORCE_UNIT_NAMES
from workbench.records.formats.physionet_insole import INSOLE_COLUMNS
from workbench.records.manifest import (
    ManifestEntry,
    load_manifest,
)
from workbench.records.record import Record
from workbench.records.sidecar import (
    _LOADER_KEYS,
    _SIDECAR_FIELDS,
    _jsonable,
    _read_sidecar,
)
from workbench.records.text_table import (
    _decode,
    _read_bytes,
    _require_file,
    empty_file,
    first_content_line,
    parse_number,
    split_lines,
)
from workbench.records.validation import validate_record

__all__ = [
    "COLUMN_ALIASES",
    "CSV_COLUMNS",
    "FORCE_UNITS",
    "FORMATS",
    "ManifestEntry",
    "detect_format",
    "load_manifest",
    "load_record",
    "record_texts",
    "save_record",
]


# --------------------------------------------------------------------------------------
# Public API


def detect_format(path: str | os.PathLike[str]) -> str:
    """Tell which record format a file is in.

    The extension decides first, if a registered format claims it (``.csv``/``.tsv`` ->
    ``"csv"``, ``.mot`` -> ``"mot"``, ``.c3d`` -> ``"c3d"``); otherwise (``.txt``, ``.dat``,
    no extension ...) the content, each registered format asked in turn (the order of
    :mod:`workbench.records.formats.base`): a C3D binary header, an ``endheader`` line
    (OpenSim), a headerless numeric table with 19 columns (PhysioNet insole), or, asked
    last, a text table whose first line is a header (CSV, e.g. a ``.txt`` with
    tab-separated ``time`` and ``grf`` columns). Pass ``fmt=`` to :func:`load_record` to
    override.

    Parameters
    ----------
    path : str or path-like
        The record file.

    Returns
    -------
    str
        One of :func:`~workbench.records.formats.format_names`.

    Raises
    ------
    InputError
        If the file is missing, empty, binary or not recognisable.
    """
    p = Path(path)
    source = str(path)
    _require_file(p, source)
    formats = registered_formats()
    extension = p.suffix.lower()
    for candidate in formats:
        if extension in candidate.extensions:
            return candidate.name
    raw = _read_bytes(p, source)
    # Specific formats are asked before generic ones (CSV takes any table with a header).
    in_order = [f for f in formats if not f.generic] + [f for f in formats if f.generic]
    for candidate in in_order:
        if candidate.sniff_bytes(raw):
            return candidate.name
    lines = split_lines(_decode(raw, source))
    if not any(line.strip() for line in lines):
        raise empty_file(source)
    for candidate in in_order:
        if candidate.sniff_text(lines):
            return candidate.name
    first_index = first_content_line(lines)
    tokens = [] if first_index is None else lines[first_index].split()
    if first_index is not None and all(parse_number(tok) is not None for tok in tokens):
        raise InputError(
            source,
            f"line {first_index + 1}",
            f"the file is a table of numbers without a header, with {len(tokens)} columns "
            f"(the PhysioNet insole format has {INSOLE_COLUMNS})",
            "add a header line naming the columns 'time' and 'grf' to read it as CSV, or pass "
            "the format as fmt=... (--format on the command line)",
        )
    raise InputError(
        source,
        "whole file",
        f"the content is in none of the formats {', '.join(format_names())}",
        "pass the format as fmt=... (--format on the command line)",
    )


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
    fmt : str, optional
        A registered format (:func:`~workbench.records.formats.format_names`: ``"csv"``,
        ``"mot"``, ``"insole"``, ``"c3d"`` and any registered since); detected by
        :func:`detect_format` if not given.
    mass_kg : float, optional
        Body mass [kg]; overrides ``mass_kg`` in the JSON sidecar. For the embedded real
        records the mass from :data:`workbench.records.embedded.EMBEDDED` is used if none is given.
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
    elif str(fmt).lower() in format_names():
        fmt = str(fmt).lower()
    else:
        raise UsageError(f"fmt must be one of {', '.join(format_names())}, got {fmt!r}")

    table = record_format(fmt).read(p, source)
    _check_table(table, fmt)
    arrays = table.arrays
    metadata: dict[str, Any] = {}

    sidecar, sidecar_path = _read_sidecar(p)
    file_keys = _file_keys()
    for key, value in sidecar.items():
        # Loader keys in a sidecar describe some other file (e.g. a hand-copied sidecar);
        # this file's own reading fills them in below.
        if key not in _SIDECAR_FIELDS and key not in file_keys:
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
    if mass is None and table.mass_kg is not None:
        mass, mass_source = table.mass_kg, table.mass_source or f"the {fmt} file"
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
    """Write a record as CSV plus JSON sidecar, both or neither (:func:`record_texts`).

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
        As :func:`record_texts`.
    OutputError
        When a file cannot be written (a full disk); neither file is then changed.
    """
    files = record_texts(record, path, extra_metadata=extra_metadata)
    json_path, csv_path = atomic_write_texts(files)
    return csv_path, json_path


def record_texts(
    record: Record,
    path: str | os.PathLike[str],
    *,
    extra_metadata: Mapping[str, Any] | None = None,
) -> dict[Path, str]:
    """Return the files :func:`save_record` writes: the JSON sidecar, then the CSV.

    Only the columns the record has are written (``time``, ``grf`` and whichever of
    ``grf_left``, ``grf_right``, ``ground_acc`` are present), every value in its shortest
    exact decimal form, so ``load_record(save_record(r, p)[0])`` gives identical arrays. The
    sidecar holds ``mass_kg``, ``pacing_hz``, ``subject``, ``notes`` (when set), the record's
    other metadata except the keys that describe how its original file was read (format,
    column names, line numbers, mass source ...), then ``extra_metadata``.

    Written with :func:`workbench.fileutil.atomic_write_texts`, each file goes to a
    temporary file in the same folder and both are moved into place with :func:`os.replace`
    only once both are on disk, so a reader never sees a half-written file or a sidecar
    without its data (a full disk leaves neither); the sidecar is replaced first, so an
    existing CSV always has its sidecar.

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
    dict
        ``{json_path: text, csv_path: text}``, in the order they are moved into place.

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

    file_keys = _file_keys()
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
        if key in file_keys or key in _SIDECAR_FIELDS:
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

    return {json_path: json_text, csv_path: csv_text}


def _check_table(table: RecordTable, fmt: str) -> None:
    """Refuse a reader's result that is not a RecordTable with time and GRF arrays.

    The built-in readers always pass; this names the format whose reader is wrong instead
    of failing later on a missing key.
    """
    if not isinstance(table, RecordTable):
        raise UsageError(
            f"the reader of the record format '{fmt}' returned {type(table).__name__}, "
            "not a RecordTable"
        )
    missing = [name for name in ("time_s", "grf_n") if name not in table.arrays]
    unknown = sorted(set(table.arrays) - set(ARRAY_NAMES))
    if missing or unknown:
        raise UsageError(
            f"the reader of the record format '{fmt}' returned the arrays "
            f"{', '.join(sorted(table.arrays)) or '(none)'}; it must return time_s and grf_n "
            f"and only the record fields {', '.join(ARRAY_NAMES)}"
        )


def _file_keys() -> frozenset[str]:
    """Return the metadata keys that describe how a file was read, for every format."""
    return _LOADER_KEYS.union(*(f.file_keys for f in registered_formats()))


def _number_argument(value: Any, name: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise UsageError(f"{name} must be a number, got {value!r}")
    return float(value)


def _embedded_entry(p: Path) -> EmbeddedRecord | None:
    try:
        resolved = p.resolve()
        for key, entry in EMBEDDED.items():
            if embedded_path(key).resolve() == resolved:
                return entry
    except OSError:
        return None
    return None
