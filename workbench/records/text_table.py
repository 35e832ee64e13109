"""Shared text-table parsing for the record and manifest readers.

Holds what every text format needs before its own column rules apply: checking that the
file exists and reading its bytes, decoding UTF-8 (refusing ZIP archives and binary data),
splitting lines at CR/LF only so that line numbers in messages match a text editor,
finding the header, detecting the delimiter, normalising column names with a bracketed
unit, parsing cells as strict decimal numbers and quoting pieces of the file for messages.
Places in messages are 1-based file line numbers (``line N``).

The public functions are the small set a new record format's reader needs (the guide page
"Adding a record format"): :func:`read_text`, :func:`split_lines`,
:func:`first_content_line`, :func:`parse_number`, :func:`parse_rows`, :func:`line_runs`,
:func:`quote`, :func:`quote_list`, :func:`empty_file` and :func:`no_data_rows`. They keep
their behaviour, since the built-in readers' messages depend on it.
"""

from __future__ import annotations

import csv
import errno
import os
import re
import stat
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from workbench.errors import InputError
from workbench.records.record import FloatArray

__all__ = [
    "FILE_MISSING",
    "LINK_LOOP",
    "SPECIAL_FILES",
    "empty_file",
    "file_problem",
    "first_content_line",
    "line_runs",
    "no_data_rows",
    "parse_number",
    "parse_rows",
    "quote",
    "quote_list",
    "read_text",
    "split_lines",
]

#: What a path is when it is not a regular file: each would hang (a FIFO waits for a writer)
#: or never end (``/dev/zero``) if it were read as a record.
_FILE_KINDS = (
    (stat.S_ISDIR, "this is a folder, not a file"),
    (stat.S_ISFIFO, "this is a named pipe (FIFO), not a regular file"),
    (stat.S_ISCHR, "this is a character device (such as /dev/zero), not a regular file"),
    (stat.S_ISBLK, "this is a block device, not a regular file"),
    (stat.S_ISSOCK, "this is a socket, not a regular file"),
)

#: :func:`file_problem`'s words for a path where nothing is.
FILE_MISSING = "the file does not exist"

#: :func:`file_problem`'s words for a symbolic link that leads back to itself.
LINK_LOOP = "the path is a loop of symbolic links that point at each other"

#: :func:`file_problem`'s sentences for the paths whose reading would hang or never end:
#: pipes, devices, sockets and symbolic link loops (not folders or missing files).
SPECIAL_FILES = frozenset(
    [*(problem for _, problem in _FILE_KINDS[1:]), "this is not a regular file", LINK_LOOP]
)

#: What to do about a path that is not a regular file.
_NOT_REGULAR_FIX = "give a file saved on disk"


def file_problem(p: str | os.PathLike[str]) -> str | None:
    """Say why ``p`` cannot be read as a data file, or return None if it can.

    Only the path's status is asked (``os.stat``, following symbolic links), nothing is
    opened, so a named pipe or a device is refused before anything waits on it or reads it
    without end.

    Parameters
    ----------
    p : path-like
        The file.

    Returns
    -------
    str or None
        The problem in plain words, without a trailing full stop: ``"the file does not
        exist"``, a symbolic link loop, a folder, a pipe, a device, a socket, or the
        system's reason it cannot be looked at.
    """
    try:
        mode = os.stat(p).st_mode
    except FileNotFoundError:
        return FILE_MISSING
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return LINK_LOOP
        if exc.errno == errno.ENOTDIR:
            return "a part of the path before the file name is a file, not a folder"
        return f"the file cannot be looked at ({exc.strerror or type(exc).__name__})"
    except ValueError:  # an embedded NUL byte
        return "the path contains a NUL character"
    if stat.S_ISREG(mode):
        return None
    for is_kind, problem in _FILE_KINDS:
        if is_kind(mode):
            return problem
    return "this is not a regular file"


def _require_file(p: Path, source: str) -> None:
    problem = file_problem(p)
    if problem is None:
        return
    if problem == FILE_MISSING:
        fix = "check the path (relative paths start from the current folder)"
    elif problem.startswith("this is a folder"):
        fix = "give a record file"
    elif problem == LINK_LOOP:
        fix = "point the link at the file itself"
    elif problem.startswith("the file cannot be looked at"):
        fix = "check its permissions and those of its folders"
    else:
        fix = _NOT_REGULAR_FIX
    raise InputError(source, "whole file", problem, fix)


def _read_bytes(p: Path, source: str) -> bytes:
    _require_file(p, source)
    try:
        # Non-blocking, so that a file swapped for a pipe after the check cannot hang the
        # open; the check is then repeated on what was actually opened. O_BINARY: Windows
        # would otherwise translate line ends in the bytes read (neither flag exists on
        # every platform).
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0))
    except OSError as exc:
        raise InputError(
            source,
            "whole file",
            f"the file cannot be read ({exc.strerror or type(exc).__name__})",
            "check its permissions",
        ) from None
    with os.fdopen(fd, "rb") as handle:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise InputError(source, "whole file", "this is not a regular file", _NOT_REGULAR_FIX)
        try:
            return handle.read()
        except OSError as exc:
            raise InputError(
                source,
                "whole file",
                f"the file cannot be read ({exc.strerror or type(exc).__name__})",
                "check its permissions",
            ) from None


def read_text(p: Path, source: str) -> str:
    """Read a text file whole, refusing what is not a text table, in one sentence.

    A missing file, a folder, a pipe or a device, an empty file, a ZIP archive (an Excel
    workbook), binary data and bytes that are not UTF-8 are each an
    :class:`~workbench.errors.InputError` naming the file. A UTF-8 byte-order mark is
    dropped.

    Parameters
    ----------
    p : Path
        The file.
    source : str
        The path as the user gave it, for messages.

    Returns
    -------
    str
    """
    return _decode(_read_bytes(p, source), source)


def empty_file(source: str) -> InputError:
    """Return the error for a file with nothing in it, to raise.

    Parameters
    ----------
    source : str
        The path as the user gave it.

    Returns
    -------
    InputError
    """
    return InputError(
        source, "whole file", "the file is empty", "give a file with a header and data rows"
    )


def _decode(raw: bytes, source: str) -> str:
    if not raw.strip():
        raise empty_file(source)
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
            "give a text file (CSV, OpenSim .mot or PhysioNet insole text) or, for a C3D file, "
            'pass fmt="c3d" (--format c3d on the command line)',
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


def split_lines(text: str) -> list[str]:
    """Split text into lines at CR, LF and CRLF only, so line numbers match a text editor.

    Parameters
    ----------
    text : str

    Returns
    -------
    list of str
        Without line ends; a final line end adds no empty line. ``lines[i]`` is file line
        ``i + 1``.
    """
    # Only CR, LF and CRLF end lines, as in any CSV reader and text editor; str.splitlines
    # would also split at form feeds and Unicode separators and shift the line numbers.
    lines = re.split(r"\r\n|\r|\n", text)
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def first_content_line(lines: Sequence[str]) -> int | None:
    """Index of the first line that is neither blank nor a ``#`` comment.

    Parameters
    ----------
    lines : sequence of str

    Returns
    -------
    int or None
        None when every line is blank or a comment.
    """
    for i, line in enumerate(lines):
        stripped = line.strip()
        if stripped and not stripped.startswith("#"):
            return i
    return None


def parse_number(cell: str) -> float | None:
    """Read a cell as a strict decimal number, or None if it is not one.

    ``nan`` and ``inf`` are numbers here (validation reports them with their place);
    ``1_000``, non-ASCII digits, decimal commas and empty cells are not.

    Parameters
    ----------
    cell : str

    Returns
    -------
    float or None
    """
    text = cell.strip()
    # float() would also take '1_000' and non-ASCII digits; neither is a number in a data file.
    if not text or not text.isascii() or "_" in text:
        return None
    try:
        return float(text)
    except ValueError:
        return None


def quote(text: str, limit: int = 40) -> str:
    """Quote a piece of the user's file for a message, on one line and not too long.

    Parameters
    ----------
    text : str
    limit : int, optional
        Characters shown before ``...`` (default 40).

    Returns
    -------
    str
    """
    if len(text) > limit:
        return repr(text[:limit]) + "..."
    return repr(text)


def quote_list(names: Sequence[str], limit: int = 12) -> str:
    """Quote names (columns found, say) for a message: ``'a', 'b' and 3 more``.

    Parameters
    ----------
    names : sequence of str
    limit : int, optional
        Names shown (default 12).

    Returns
    -------
    str
    """
    shown = ", ".join(quote(n) for n in names[:limit])
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


def parse_rows(
    lines: Sequence[str],
    first: int,
    *,
    n_fields: int,
    columns: Mapping[int, str],
    source: str,
    split: Callable[[str], list[str]] = str.split,
    count_error: Callable[[int, int], InputError] | None = None,
    decimal_comma_hint: bool = True,
) -> tuple[dict[int, FloatArray], list[int]]:
    """Parse the numeric cells of some columns of a table's rows.

    Blank lines and ``#`` comments are skipped. Every other line from ``lines[first]`` on
    must have ``n_fields`` fields, and each cell of the wanted columns must be a number
    (:func:`parse_number`); the first row that is not is an
    :class:`~workbench.errors.InputError` naming its line and column.

    Parameters
    ----------
    lines : sequence of str
        The file's lines (:func:`split_lines`).
    first : int
        Index of the first data line.
    n_fields : int
        Fields every data row has.
    columns : mapping of int to str
        The wanted columns: 0-based field index -> how messages name it (e.g.
        ``"column 'grf'"``), in the order each row's cells are checked.
    source : str
        The path as the user gave it, for messages.
    split : callable, optional
        Splits a line into fields (default: at runs of whitespace).
    count_error : callable, optional
        ``count_error(line_number, fields_found)`` returns the error for a row with the
        wrong number of fields; by default one that names both counts.
    decimal_comma_hint : bool, optional
        Suggest writing decimals with a point when a bad cell looks like ``1,5`` (default
        True; False where commas separate the fields).

    Returns
    -------
    columns : dict of int to ndarray
        The parsed columns by field index.
    line_numbers : list of int
        The 1-based file line of each row, for :func:`line_runs`.
    """
    wanted = list(columns)
    if count_error is None:
        count_error = _default_count_error(source, n_fields)
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
            number = parse_number(cell)
            if number is None:
                raise _bad_cell(source, i + 1, columns[j], cell, decimal_comma_hint)
            values[j].append(number)
        line_numbers.append(i + 1)
    return {j: np.asarray(v, dtype=np.float64) for j, v in values.items()}, line_numbers


def _default_count_error(source: str, n_fields: int) -> Callable[[int, int], InputError]:
    def error(line: int, found: int) -> InputError:
        return InputError(
            source,
            f"line {line}",
            f"the row has {found} values but the format has {n_fields}",
            "repair or delete the row (the file may be truncated)",
        )

    return error


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
        f"the value {quote(cell)} is not a number",
        f"correct the value or delete the row{hint}",
    )


def line_runs(line_numbers: Sequence[int]) -> dict[str, Any]:
    """Run-length code of sample index -> file line (JSON-friendly, small).

    Put it in a reader's ``metadata["file_lines"]``: validation then names the file line
    of a bad sample.

    Parameters
    ----------
    line_numbers : sequence of int
        The 1-based file line of each sample, in sample order.

    Returns
    -------
    dict
        ``{"n_samples": N, "runs": [[first_sample, its_line], ...]}``, one run per block
        of consecutive lines.
    """
    runs: list[list[int]] = []
    previous = None
    for index, line in enumerate(line_numbers):
        if previous is None or line != previous + 1:
            runs.append([index, line])
        previous = line
    return {"n_samples": len(line_numbers), "runs": runs}


def no_data_rows(source: str, header_line: int) -> InputError:
    """Return the error for a file with a header but no data rows, to raise.

    Parameters
    ----------
    source : str
        The path as the user gave it.
    header_line : int
        The header's 1-based file line.

    Returns
    -------
    InputError
    """
    return InputError(
        source,
        f"line {header_line}",
        "the file has a header but no data rows",
        "add the measured samples below the header",
    )
