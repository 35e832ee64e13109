"""The CSV record format: a text table with a header line, plus its JSON sidecar.

The columns, their aliases and units are those of docs/contracts.md ("CSV with a JSON
sidecar") and the ``csv`` entry of :mod:`workbench.records.io`; :data:`CSV_COLUMNS` and
:data:`COLUMN_ALIASES` name them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from workbench.errors import InputError
from workbench.records.formats.base import RecordFormat, RecordTable, register_format
from workbench.records.record import FloatArray
from workbench.records.text_table import (
    _delimiter_name,
    _detect_delimiter,
    _field_count_error,
    _normalise_name,
    _split_fields,
    empty_file,
    first_content_line,
    line_runs,
    no_data_rows,
    parse_number,
    parse_rows,
    quote,
    quote_list,
    read_text,
    split_lines,
)

__all__ = ["COLUMN_ALIASES", "CSV_COLUMNS", "CsvFormat"]

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


@register_format
class CsvFormat(RecordFormat):
    """A text table whose first line names the columns (``time``, ``grf`` ...).

    Generic: content detection gives it any text file whose first line that is neither
    blank nor a comment is not all numbers, once every other format has declined.
    """

    name = "csv"
    extensions = (".csv", ".tsv")
    description = "text table with a header line (time [s], grf [N], ...) and a JSON sidecar"
    generic = True
    file_keys = ("column_aliases", "ignored_columns", "grf_from", "delimiter")

    def sniff_text(self, lines: list[str]) -> bool:
        """Claim a text file whose first non-comment line is not all numbers (a header)."""
        first = first_content_line(lines)
        if first is None:
            # Only comments: the reader says the file is empty.
            return True
        tokens = lines[first].split()
        return not all(parse_number(tok) is not None for tok in tokens)

    def read(self, path: Path, source: str) -> RecordTable:
        """Read the header, match the columns and parse the rows (module docstring)."""
        return _read_csv(path, source)


def _read_csv(path: Path, source: str) -> RecordTable:
    lines = split_lines(read_text(path, source))
    header_index = first_content_line(lines)
    if header_index is None:
        raise empty_file(source)
    header_line = header_index + 1
    delimiter = _detect_delimiter(lines[header_index])
    names = _split_fields(lines[header_index], delimiter)
    expected = (
        "name the columns 'time' [s] and 'grf' [N] (optional 'grf_left', 'grf_right' [N], "
        "'ground_acc' [m/s^2]; also accepted: " + ", ".join(COLUMN_ALIASES) + ")"
    )
    if all(parse_number(n) is not None for n in names):
        raise InputError(
            source,
            f"line {header_line}",
            f"the first line {quote(lines[header_index])} is data, not a header",
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
                f"line {header_line}, column {quote(raw)}",
                f"the unit {unit!r} is not the one the workbench reads "
                f"({_DISPLAY_UNITS[canonical]})",
                f"convert the column to {_DISPLAY_UNITS[canonical]} and name it "
                f"'{canonical}' (for forces in kN or kgf you may instead name it '{canonical}' "
                "and pass force_unit=..., or --force-unit on the command line)",
            )
        if canonical in found:
            raise InputError(
                source,
                f"line {header_line}, column {quote(raw)}",
                f"this column and column {quote(found[canonical][1])} both mean '{canonical}'",
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
                f"{quote_list(names)})",
                expected,
            )

    labels = {j: f"column {quote(raw)}" for _, (j, raw) in found.items()}
    columns, line_numbers = parse_rows(
        lines,
        header_index + 1,
        n_fields=len(names),
        columns={j: labels[j] for j, _ in found.values()},
        source=source,
        split=lambda line: _split_fields(line, delimiter),
        count_error=lambda line, n: _field_count_error(
            source, line, n, header_line, len(names), delimiter
        ),
        decimal_comma_hint=delimiter != ",",
    )
    if not line_numbers:
        raise no_data_rows(source, header_line)

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
            f"columns {quote(found['grf_left'][1])} + {quote(found['grf_right'][1])}"
        )
        metadata["grf_from"] = grf_from
    metadata["columns"] = column_labels
    metadata["delimiter"] = _delimiter_name(delimiter)
    metadata["file_lines"] = line_runs(line_numbers)
    if aliases:
        metadata["column_aliases"] = aliases
    if ignored:
        metadata["ignored_columns"] = ignored
        suspicious = [
            n for n in ignored if _normalise_name(n)[0].startswith(("time", "grf", "ground"))
        ]
        if suspicious:
            warnings.append(
                f"The columns {quote_list(suspicious)} look like workbench columns but do not "
                "match any expected name, so they were ignored."
            )
    return RecordTable(arrays, metadata, warnings)
