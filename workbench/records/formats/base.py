"""The record-format mechanism: :class:`RecordFormat`, :class:`RecordTable` and the registry.

A record format is a class that says which file extensions are its own, how to recognise
its files by their content (:meth:`RecordFormat.sniff_bytes`,
:meth:`RecordFormat.sniff_text`) and how to read one file into a :class:`RecordTable`
(:meth:`RecordFormat.read`). Registering it with :func:`register_format` is the only
registration: :func:`workbench.records.io.load_record` (``fmt=``),
:func:`workbench.records.io.detect_format`, the command line's ``--format`` choices and
the messages that list the formats all read the same registry.

Detection order (:func:`workbench.records.io.detect_format`)
------------------------------------------------------------
1. The file extension, if a registered format claims it (an extension belongs to one
   format only).
2. :meth:`RecordFormat.sniff_bytes` of every format on the file's bytes, before the file
   is decoded as text (C3D is binary).
3. :meth:`RecordFormat.sniff_text` of every format on the decoded lines.

   In steps 2 and 3 the specific formats are asked first, in registration order, and the
   generic ones (``generic = True``: CSV, which reads any text table with a header line)
   after all the others.
4. Nothing claims the file: an error that says so.

The built-in formats register in the order ``csv``, ``mot``, ``insole``, ``c3d``, so the
formats are listed in that order; a format registered later is listed, and asked, after
them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from workbench.errors import UsageError
from workbench.records.record import G_M_S2, FloatArray

__all__ = [
    "ARRAY_NAMES",
    "FORCE_UNITS",
    "RecordFormat",
    "RecordTable",
    "format_names",
    "record_format",
    "register_format",
    "registered_formats",
    "unregister_format",
]

#: The arrays a reader may return, by :class:`~workbench.records.record.Record` field, with
#: their units. ``time_s`` and ``grf_n`` are required.
ARRAY_NAMES: dict[str, str] = {
    "time_s": "s",
    "grf_n": "N",
    "grf_left_n": "N",
    "grf_right_n": "N",
    "ground_acc_m_s2": "m/s^2",
}

#: Force units :func:`~workbench.records.io.load_record` converts from, with their factor to
#: newtons. ``kgf`` uses the workbench's g = 9.81 m/s^2 so that a force given in
#: kilograms-force averages to the body mass times the same g the model uses.
FORCE_UNITS: dict[str, float] = {"N": 1.0, "kN": 1000.0, "kgf": G_M_S2}

# Accepted spellings of FORCE_UNITS (lower case) -> their key.
_FORCE_UNIT_NAMES = {"n": "N", "kn": "kN", "kgf": "kgf", "kg": "kgf"}

_NAME = re.compile(r"^[a-z][a-z0-9_]*$")
_EXTENSION = re.compile(r"^\.[a-z0-9][a-z0-9_.-]*$")


@dataclass
class RecordTable:
    """What a format reader found in one file, before the sidecar and keywords are merged.

    :func:`~workbench.records.io.load_record` turns it into a
    :class:`~workbench.records.record.Record`: it merges the JSON sidecar and the keyword
    arguments, converts ``--force-unit``, takes the mass and validates the record.

    Attributes
    ----------
    arrays : dict of str to ndarray
        One float array per :class:`~workbench.records.record.Record` field, all of the same
        length, one value per sample, in the units of :data:`ARRAY_NAMES`: ``time_s`` [s]
        and ``grf_n`` [N] (the total vertical force on the person, positive upwards) are
        required; ``grf_left_n``, ``grf_right_n`` [N] (per foot) and ``ground_acc_m_s2``
        [m/s^2] (vertical acceleration of the walking surface) are optional. Forces are in
        newtons as the file states them; ``--force-unit`` is applied afterwards.
    metadata : dict
        How the file was read, merged into ``Record.metadata`` over the sidecar's keys:
        ``columns`` (where each array came from, by field name, for messages) and, for a
        text file, ``file_lines`` (the file line of each sample, from
        :func:`workbench.records.text_table.line_runs`, so that validation can name lines).
        ``side_assignment`` says how ``grf_left_n`` and ``grf_right_n`` were assigned when
        the file does not say which foot is which.
    warnings : list of str
        Sentences about the file that do not stop the reading (e.g. a truncated file).
    mass_kg : float, optional
        The body mass [kg] the file states, used when neither ``mass_kg=`` (``--mass``) nor
        the sidecar gives one.
    mass_source : str, optional
        Where in the file ``mass_kg`` was found, in words (``metadata["mass_source"]``).
    """

    arrays: dict[str, FloatArray]
    metadata: dict[str, Any]
    warnings: list[str] = field(default_factory=list)
    mass_kg: float | None = None
    mass_source: str | None = None


class RecordFormat:
    """Base class of a record format: its name, extensions, recognition and reader.

    Subclasses set the class attributes ``name`` and ``extensions`` and implement
    :meth:`read`; they override :meth:`sniff_text` (or :meth:`sniff_bytes` for a binary
    format) to be recognised by content in files whose extension is not their own. See
    the guide page "Adding a record format" for a worked example.
    """

    #: The format's name: ``fmt=`` of :func:`~workbench.records.io.load_record` and
    #: ``--format`` on the command line (lower case, digits and ``_``).
    name: ClassVar[str] = ""
    #: File extensions that are this format's own, lower case with the dot (``(".mot",)``).
    extensions: ClassVar[tuple[str, ...]] = ()
    #: One line on what the format is, for listings.
    description: ClassVar[str] = ""
    #: A generic format (CSV) reads a wide family of files: content detection asks it only
    #: after every specific format has declined.
    generic: ClassVar[bool] = False
    #: The keys of :attr:`RecordTable.metadata` that describe the file read (beyond the
    #: common ``columns`` and ``file_lines``); ``save_record`` leaves them out of a new
    #: sidecar, where they would be false.
    file_keys: ClassVar[tuple[str, ...]] = ()

    def sniff_bytes(self, raw: bytes) -> bool:
        """Tell whether the bytes of a file are in this format (binary formats).

        Asked before the file is decoded as text, for a file whose extension no format
        claims. The default declines.

        Parameters
        ----------
        raw : bytes
            The whole file.

        Returns
        -------
        bool
        """
        return False

    def sniff_text(self, lines: list[str]) -> bool:
        """Tell whether a text file is in this format.

        Asked for a file whose extension no format claims, after every format's
        :meth:`sniff_bytes` has declined. Keep it cheap and specific: the first format that
        answers True reads the file. The default declines.

        Parameters
        ----------
        lines : list of str
            The file's lines (decoded as UTF-8, split at line ends only, as
            :func:`workbench.records.text_table.split_lines` does); at least one is not
            blank.

        Returns
        -------
        bool
        """
        return False

    def read(self, path: Path, source: str) -> RecordTable:
        """Read one file.

        Parameters
        ----------
        path : Path
            The file (it exists and is a regular file).
        source : str
            The path as the user gave it, for messages
            (:class:`~workbench.errors.InputError` takes it first).

        Returns
        -------
        RecordTable

        Raises
        ------
        InputError
            For any problem with the file, naming the place (``line N``) in one sentence.
        """
        raise NotImplementedError


_REGISTRY: dict[str, RecordFormat] = {}


def _validate_format_class(cls: type[RecordFormat]) -> None:
    where = f"register_format: {cls.__qualname__}"
    if not isinstance(cls.name, str) or not _NAME.match(cls.name):
        raise UsageError(
            f"{where}: name {cls.name!r} is not a lower-case identifier; set name = 'my_format'"
        )
    if isinstance(cls.extensions, str) or not all(
        isinstance(e, str) and _EXTENSION.match(e) for e in cls.extensions
    ):
        raise UsageError(
            f"{where}: extensions {cls.extensions!r} must be a tuple of lower-case "
            "extensions with the dot, e.g. ('.toy',)"
        )
    if cls.read is RecordFormat.read:
        raise UsageError(f"{where}: a record format must implement read(path, source)")
    for other in _REGISTRY.values():
        if other.name == cls.name:
            continue
        taken = sorted(set(cls.extensions) & set(other.extensions))
        if taken:
            raise UsageError(
                f"{where}: the extension {taken[0]} is already the '{other.name}' format's; "
                "an extension belongs to one format"
            )


def register_format(cls: type[RecordFormat]) -> type[RecordFormat]:
    """Class decorator: make a record format available by its ``name``.

    The format then appears in :func:`format_names` (after those registered before it),
    :func:`~workbench.records.io.load_record`'s ``fmt=``, the detection of
    :func:`~workbench.records.io.detect_format` and the command line's ``--format``.
    Re-registering the same class (same module and qualified name, e.g. after a reload)
    replaces the entry in its place; a different class with a taken name, or an extension
    another format claims, is a ``UsageError``.

    Parameters
    ----------
    cls : type
        A subclass of :class:`RecordFormat`.

    Returns
    -------
    type
        ``cls`` itself, so it works as a decorator.
    """
    if not (isinstance(cls, type) and issubclass(cls, RecordFormat)):
        raise UsageError(
            f"register_format: {cls!r} is not a subclass of RecordFormat; derive your format "
            "from workbench.records.formats.RecordFormat"
        )
    _validate_format_class(cls)
    existing = _REGISTRY.get(cls.name)
    if existing is not None:
        known = type(existing)
        if (known.__module__, known.__qualname__) != (cls.__module__, cls.__qualname__):
            raise UsageError(
                f"register_format: format name '{cls.name}' is already registered by "
                f"{known.__module__}.{known.__qualname__}; choose another name"
            )
    _REGISTRY[cls.name] = cls()
    return cls


def unregister_format(name: str) -> None:
    """Remove a record format from the registry (for tests and interactive sessions).

    Parameters
    ----------
    name : str
        Registered format name; unknown names are a ``UsageError``.
    """
    record_format(name)
    del _REGISTRY[name]


def format_names() -> tuple[str, ...]:
    """Names of all registered record formats, in registration order (built-ins first).

    Returns
    -------
    tuple of str
    """
    return tuple(_REGISTRY)


def registered_formats() -> tuple[RecordFormat, ...]:
    """All registered record formats, in registration order.

    Returns
    -------
    tuple of RecordFormat
    """
    return tuple(_REGISTRY.values())


def record_format(name: str) -> RecordFormat:
    """Return the registered format of a name.

    Parameters
    ----------
    name : str
        Format name, e.g. ``"mot"``.

    Returns
    -------
    RecordFormat
    """
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise UsageError(
            f"record format '{name}' is not known; use one of {', '.join(format_names())} or "
            "register your own with @register_format"
        ) from None
