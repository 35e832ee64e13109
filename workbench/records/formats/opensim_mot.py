"""The OpenSim storage format (``.mot``): a header up to ``endheader``, then a table.

OpenSim is y-up, so each plate's vertical force is its ``*_vy`` column; the rules are those
of the ``mot`` entry of :mod:`workbench.records.io` and docs/contracts.md.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np

from workbench.errors import InputError
from workbench.records.formats.base import RecordFormat, RecordTable, register_format
from workbench.records.record import FloatArray
from workbench.records.text_table import (
    line_runs,
    no_data_rows,
    parse_rows,
    quote,
    quote_list,
    read_text,
    split_lines,
)

__all__ = ["OpenSimFormat"]

#: Content detection looks for ``endheader`` among this many first non-blank lines.
_HEADER_SEARCH_LINES = 200

_SIDE_TOKENS = {"l": "left", "left": "left", "r": "right", "right": "right"}


@register_format
class OpenSimFormat(RecordFormat):
    """OpenSim storage (``.mot``): recognised by an ``endheader`` line near the top."""

    name = "mot"
    extensions = (".mot",)
    description = "OpenSim storage: header up to 'endheader', then columns with *_vy forces"
    file_keys = ("mot_header", "plates", "side_assignment")

    def sniff_text(self, lines: list[str]) -> bool:
        """Claim a file with an ``endheader`` line among its first 200 non-blank lines."""
        content = [s.strip() for s in lines if s.strip()]
        return any(s.lower() == "endheader" for s in content[:_HEADER_SEARCH_LINES])

    def read(self, path: Path, source: str) -> RecordTable:
        """Read the header, find the ``time`` and ``*_vy`` columns and sum the plates."""
        return _read_mot(path, source)


def _read_mot(path: Path, source: str) -> RecordTable:
    lines = split_lines(read_text(path, source))
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
            f"there is no 'time' column (columns found: {quote_list(names)})",
            "give the OpenSim column-name line starting with 'time'",
        )
    time_j = lower.index("time")
    vy = [j for j, n in enumerate(lower) if n.endswith("_vy")]
    if not vy:
        vz = [names[j] for j, n in enumerate(lower) if n.endswith("_vz")]
        problem = f"there is no vertical force column '*_vy' (columns found: {quote_list(names)})"
        if vz:
            problem += "; the '*_vz' columns suggest a z-up lab frame, but OpenSim files are y-up"
        raise InputError(
            source,
            f"line {names_line}",
            problem,
            "export the plate forces in the OpenSim y-up frame (ground_force_vy) or convert the "
            "record to CSV with 'time' and 'grf' columns",
        )
    labels = {j: f"column {quote(names[j])}" for j in [time_j, *vy]}
    columns, line_numbers = parse_rows(
        lines,
        names_index + 1,
        n_fields=len(names),
        columns=labels,
        source=source,
        count_error=lambda line, n: InputError(
            source,
            f"line {line}",
            f"the row has {n} values but the column-name line (line {names_line}) has {len(names)}",
            "repair or delete the row (the file may be truncated)",
        ),
        decimal_comma_hint=True,
    )
    if not line_numbers:
        raise no_data_rows(source, names_line)

    arrays: dict[str, FloatArray] = {"time_s": columns[time_j]}
    total = np.zeros_like(columns[time_j])
    for j in vy:
        total = total + columns[j]
    arrays["grf_n"] = total
    column_labels = {
        "time_s": labels[time_j],
        "grf_n": "columns " + " + ".join(quote(names[j]) for j in vy),
    }
    metadata: dict[str, Any] = {
        "mot_header": header,
        "plates": [names[j] for j in vy],
        "file_lines": line_runs(line_numbers),
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
    return RecordTable(arrays, metadata, warnings)


def _side_of(name: str) -> str | None:
    tokens = re.split(r"[_\W]+", name.lower())
    sides = {_SIDE_TOKENS[t] for t in tokens if t in _SIDE_TOKENS}
    return sides.pop() if len(sides) == 1 else None
