"""The JSON sidecar beside a record file: reading and checking it, and writing values to it.

``NAME.json`` beside a data file holds ``mass_kg``, ``pacing_hz``, ``subject``, ``notes``
and any further keys, which are kept in ``Record.metadata``. This module reads and checks
a sidecar (``_read_sidecar``), converts metadata values to plain JSON types for writing
(``_jsonable``), and names the sidecar fields and the loader keys, which describe how one
particular file was read and so are never copied into a new sidecar.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from workbench.errors import InputError, UsageError
from workbench.records.text_table import (
    _NOT_REGULAR_FIX,
    FILE_MISSING,
    _read_bytes,
    file_problem,
    quote,
)

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


def _read_sidecar(p: Path) -> tuple[dict[str, Any], Path | None]:
    side = p.with_suffix(".json")
    if side == p or not os.path.lexists(side) or side.is_dir():
        return {}, None
    problem = file_problem(side)
    if problem is not None and problem != FILE_MISSING:
        # A pipe or a device where the sidecar belongs: ignoring it would drop the mass
        # without a word, reading it would hang.
        raise InputError(
            side, "whole file", f"the sidecar of {p.name}: {problem}", _NOT_REGULAR_FIX
        )
    if problem == FILE_MISSING:  # a dangling link: no sidecar, as before
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
                f"the value {quote(json.dumps(value))} is not a number",
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
