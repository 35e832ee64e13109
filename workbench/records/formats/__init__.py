"""Record formats: the registry and the built-in readers (CSV, OpenSim .mot, insole, C3D).

A format is a :class:`RecordFormat` subclass registered with :func:`register_format`; each
reader turns one file into a :class:`RecordTable` (arrays named like the
:class:`~workbench.records.record.Record` fields, in SI units, the metadata of how the file
was read, and warnings), before :func:`workbench.records.io.load_record` merges the sidecar
and keyword metadata and validates the record. The mechanism and the detection order are in
:mod:`workbench.records.formats.base`; the guide page "Adding a record format" shows a new
format end to end.

The built-in formats, one module each, register here in the order ``csv``, ``mot``,
``insole``, ``c3d`` (the order :func:`format_names` lists them in):
:mod:`~workbench.records.formats.csv_table`, :mod:`~workbench.records.formats.opensim_mot`,
:mod:`~workbench.records.formats.physionet_insole` and
:mod:`~workbench.records.formats.c3d_platforms`.
"""

from workbench.records.formats.base import (
    ARRAY_NAMES,
    FORCE_UNITS,
    RecordFormat,
    RecordTable,
    format_names,
    record_format,
    register_format,
    registered_formats,
    unregister_format,
)

# Importing a built-in module registers its format. The order of these imports is the order
# of format_names() and of content detection, so keep it (not alphabetical).
# isort: off
from workbench.records.formats.csv_table import COLUMN_ALIASES, CSV_COLUMNS
from workbench.records.formats import opensim_mot  # noqa: F401
from workbench.records.formats import physionet_insole  # noqa: F401
from workbench.records.formats import c3d_platforms  # noqa: F401

# isort: on

__all__ = [
    "ARRAY_NAMES",
    "COLUMN_ALIASES",
    "CSV_COLUMNS",
    "FORCE_UNITS",
    "FORMATS",
    "RecordFormat",
    "RecordTable",
    "format_names",
    "record_format",
    "register_format",
    "registered_formats",
    "unregister_format",
]

#: The built-in formats, in registration order. Formats registered later are not here:
#: :func:`format_names` lists every registered one.
FORMATS: tuple[str, ...] = ("csv", "mot", "insole", "c3d")
