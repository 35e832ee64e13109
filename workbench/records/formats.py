"""The per-format record readers: CSV, OpenSim .mot, PhysioNet insole text and C3D.

Each reader turns one file into a ``_Table`` (arrays named like the
:class:`~workbench.records.record.Record` fields, the metadata of how the file was read,
and warnings), before :func:`workbench.records.io.load_record` merges the sidecar and
keyword metadata and validates the record. The module also holds the format names, the
CSV column names and their accepted aliases and units, and the force units converted to
newtons. The formats themselves are described in :mod:`workbench.records.io`.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from workbench.errors import InputError, UsageError
from workbench.records.record import G_M_S2, FloatArray
from workbench.records.text_table import (
    _decode,
    _delimiter_name,
    _detect_delimiter,
    _empty_file,
    _field_count_error,
    _first_content_line,
    _line_runs,
    _no_data_rows,
    _normalise_name,
    _parse_number,
    _parse_rows,
    _read_bytes,
    _show,
    _show_list,
    _split_fields,
    _split_lines,
    _Table,
)

__all__ = [
    "COLUMN_ALIASES",
    "CSV_COLUMNS",
    "FORCE_UNITS",
    "FORMATS",
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
                "and pass force_unit=..., or --force-unit on the command line)",
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


def _plate_sign(vertical: FloatArray) -> float:
    """+1 or -1: the sign that makes a platform's vertical force the force on the person.

    Platforms report the force the person exerts on the plate (pointing down) in some labs
    and the reaction (pointing up) in others, and a platform whose corners are listed the
    other way round has its axes turned over. The person pushes down, so the force on the
    person points up at the platform's largest load: its sign there decides.
    """
    if vertical.size == 0 or not np.any(vertical):
        return 1.0
    peak = vertical[int(np.argmax(np.abs(vertical)))]
    return -1.0 if peak < 0.0 else 1.0


def _read_c3d(p: Path, source: str) -> _Table:
    """Read the force platforms of a C3D file (docs/contracts.md, "C3D").

    The vertical GRF is the global z component of every platform's force (ezc3d turns each
    platform's force into the laboratory's frame with the platform's corners), each platform
    turned to the force on the person (:func:`_plate_sign`), summed, on the analog clock.
    """
    try:
        import ezc3d  # noqa: F401 - optional extra, imported only when a C3D file is read
    except ImportError:
        raise UsageError(
            f"reading the C3D file {source} needs the optional package ezc3d; install it with "
            "pip install 'workbench[c3d]'"
        ) from None
    from workbench.records.c3d_file import read_force_platforms

    read = read_force_platforms(str(p), source)
    platforms: list[FloatArray] = read["forces"]
    analog_rate, point_rate = read["analog_rate"], read["point_rate"]
    first_frame = read["first_frame"]
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
    if not (math.isfinite(point_rate) and point_rate > 0):
        raise InputError(
            source, "header", f"the point rate {point_rate!r} Hz is not valid", "repair the file"
        )
    forces: list[FloatArray] = []
    units: list[str] = []
    for k, (force, stated, labelled) in enumerate(
        zip(platforms, read["channel_units"], read["unit_force"], strict=True), start=1
    ):
        # The Fz channel's own unit when it names a force unit; else ezc3d's label.
        known = stated is not None and _FORCE_UNIT_NAMES.get(stated.lower()) is not None
        unit = stated if known else labelled.strip()
        units.append(unit)
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
        forces.append(force[:3] * factor)
    lengths = {f.shape[1] for f in forces}
    if len(lengths) != 1:
        raise InputError(
            source,
            "force platforms",
            f"the platforms have different numbers of samples ({sorted(lengths)})",
            "check the analog channels of the file",
        )
    # The body's weight is carried by the vertical axis: z must carry more force than x or y
    # (a file in a y-up frame would otherwise give a horizontal force as the GRF).
    carried = np.sum([np.mean(np.abs(f), axis=1) for f in forces], axis=0)
    if np.all(np.isfinite(carried)) and carried[2] < np.max(carried):
        axis = "xyz"[int(np.argmax(carried))]
        raise InputError(
            source,
            "force platforms",
            f"the platforms' z axis carries less force than their {axis} axis, so z is not "
            "vertical in this file's frame (the workbench reads the laboratory's z as vertical)",
            "export the trial with the laboratory's z axis pointing up",
        )
    signs = [_plate_sign(f[2]) for f in forces]
    vertical = [sign * f[2] for sign, f in zip(signs, forces, strict=True)]
    n = vertical[0].size
    # Analog samples run at analog_rate from the first point frame (ezc3d counts frames from
    # 0): one common time base, frame 0 at 0 s.
    time_s = first_frame / point_rate + np.arange(n, dtype=np.float64) / analog_rate
    total = np.sum(vertical, axis=0)
    warnings: list[str] = []
    flipped = [k for k, sign in enumerate(signs, start=1) if sign < 0]
    if flipped:
        which = (
            "The C3D platforms report"
            if len(flipped) == len(signs)
            else f"C3D platform{'s' if len(flipped) > 1 else ''} "
            f"{', '.join(str(k) for k in flipped)} of {len(signs)} report"
        )
        warnings.append(
            f"{which} the force on the plate (negative upwards), so its sign was flipped to "
            "the force on the person."
        )
    arrays: dict[str, FloatArray] = {"time_s": time_s, "grf_n": total}
    column_labels = {"time_s": "analog time base", "grf_n": "sum of platform Fz"}
    metadata: dict[str, Any] = {
        "c3d": {
            "platforms": len(platforms),
            "analog_rate_hz": analog_rate,
            "point_rate_hz": point_rate,
            "first_frame": first_frame,
            "vertical_axis": "z",
            "force_units": units,
            "vertical_sign": signs[0] if len(set(signs)) == 1 else None,
            "vertical_signs": signs,
            "body_mass_kg": read["body_mass_kg"],
        }
    }
    if len(vertical) == 2:
        arrays["grf_left_n"] = vertical[0]
        arrays["grf_right_n"] = vertical[1]
        column_labels["grf_left_n"] = "platform 1 Fz"
        column_labels["grf_right_n"] = "platform 2 Fz"
        metadata["side_assignment"] = (
            "grf_left_n is platform 1 and grf_right_n is platform 2 in file order; the file "
            "does not state which platform is under which foot"
        )
    metadata["columns"] = column_labels
    return _Table(arrays, metadata, warnings)
