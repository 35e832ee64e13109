"""The PhysioNet insole text format (gaitpdb): 19 columns, no header.

Time in column 1, the total left and right foot forces [N] in columns 18 and 19 (1-based);
the ``insole`` entry of :mod:`workbench.records.io` and docs/contracts.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from workbench.errors import InputError
from workbench.records.formats.base import RecordFormat, RecordTable, register_format
from workbench.records.text_table import (
    empty_file,
    first_content_line,
    line_runs,
    parse_number,
    parse_rows,
    read_text,
    split_lines,
)

__all__ = ["INSOLE_COLUMNS", "InsoleFormat"]

#: Columns of a PhysioNet insole file.
INSOLE_COLUMNS = 19


@register_format
class InsoleFormat(RecordFormat):
    """PhysioNet insole text: recognised by a first line of exactly 19 numbers.

    It has no extension of its own (the files end in ``.txt``).
    """

    name = "insole"
    extensions = ()
    description = "PhysioNet insole text: no header, 19 columns, feet totals in 18 and 19"

    def sniff_text(self, lines: list[str]) -> bool:
        """Claim a file whose first non-comment line is 19 numbers."""
        first = first_content_line(lines)
        if first is None:
            return False
        tokens = lines[first].split()
        return len(tokens) == INSOLE_COLUMNS and all(
            parse_number(tok) is not None for tok in tokens
        )

    def read(self, path: Path, source: str) -> RecordTable:
        """Read time and the two feet's totals; the GRF is their sum."""
        return _read_insole(path, source)


def _read_insole(path: Path, source: str) -> RecordTable:
    lines = split_lines(read_text(path, source))
    first = first_content_line(lines)
    if first is None:
        raise empty_file(source)
    labels = {0: "column 1 (time)", 17: "column 18 (total left)", 18: "column 19 (total right)"}
    columns, line_numbers = parse_rows(
        lines,
        first,
        n_fields=INSOLE_COLUMNS,
        columns=labels,
        source=source,
        count_error=lambda line, n: InputError(
            source,
            f"line {line}",
            f"the row has {n} values but the PhysioNet insole format has {INSOLE_COLUMNS}",
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
        "file_lines": line_runs(line_numbers),
    }
    return RecordTable(arrays, metadata)
