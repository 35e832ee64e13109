"""The record-format registry: a format registered once is read, detected and offered everywhere."""

from __future__ import annotations

import argparse
import json
import re
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from workbench import datasets
from workbench.cli.main import build_parser, main
from workbench.errors import InputError, UsageError
from workbench.records.formats import (
    FORMATS,
    RecordFormat,
    RecordTable,
    format_names,
    record_format,
    register_format,
    registered_formats,
    unregister_format,
)
from workbench.records.io import detect_format, load_record, save_record
from workbench.records.text_table import (
    first_content_line,
    line_runs,
    parse_rows,
    read_text,
    split_lines,
)

ROOT = Path(__file__).resolve().parents[1]

#: The toy format's first line: a magic word and the body mass in kilograms.
TOY_MAGIC = "TOYGRF"


class ToyFormat(RecordFormat):
    """A whitespace table of time [s] and vertical GRF [N] after a ``TOYGRF <mass>`` line."""

    name = "toy"
    extensions = (".toy",)
    description = "toy test format"

    def sniff_text(self, lines: list[str]) -> bool:
        first = first_content_line(lines)
        return first is not None and lines[first].split()[0] == TOY_MAGIC

    def read(self, path: Path, source: str) -> RecordTable:
        lines = split_lines(read_text(path, source))
        first = first_content_line(lines)
        assert first is not None  # read_text refuses an empty file
        mass_kg = float(lines[first].split()[1])
        labels = {0: "column 1 (time)", 1: "column 2 (grf)"}
        columns, line_numbers = parse_rows(
            lines, first + 1, n_fields=2, columns=labels, source=source
        )
        return RecordTable(
            arrays={"time_s": columns[0], "grf_n": columns[1]},
            metadata={
                "columns": {"time_s": "column 1", "grf_n": "column 2"},
                "file_lines": line_runs(line_numbers),
            },
            mass_kg=mass_kg,
            mass_source=f"the {TOY_MAGIC} line",
        )


@pytest.fixture
def toy_format() -> Iterator[type[RecordFormat]]:
    register_format(ToyFormat)
    try:
        yield ToyFormat
    finally:
        unregister_format("toy")
    assert "toy" not in format_names()


def write_toy(path: Path, time_s: np.ndarray, grf_n: np.ndarray, mass_kg: float) -> Path:
    rows = "".join(f"{t!r} {f!r}\n" for t, f in zip(time_s.tolist(), grf_n.tolist(), strict=True))
    path.write_text(f"# a toy record\n{TOY_MAGIC} {mass_kg!r}\n{rows}", encoding="utf-8")
    return path


def format_choices() -> list[str]:
    """The ``--format`` choices of ``workbench inspect``, from a freshly built parser."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    inspect = sub.choices["inspect"]
    action = next(a for a in inspect._actions if "--format" in a.option_strings)
    assert action.choices is not None
    return list(action.choices)


# -- the built-in formats -------------------------------------------------------------------
def test_the_built_in_formats_are_registered_in_their_order() -> None:
    assert format_names() == FORMATS == ("csv", "mot", "insole", "c3d")
    assert format_choices() == list(FORMATS)
    assert {f.name: f.extensions for f in registered_formats()} == {
        "csv": (".csv", ".tsv"),
        "mot": (".mot",),
        "insole": (),
        "c3d": (".c3d",),
    }
    assert [f.name for f in registered_formats() if f.generic] == ["csv"]
    assert record_format("mot").name == "mot"
    with pytest.raises(UsageError, match="'wobble' is not known; use one of csv, mot, insole, c3d"):
        record_format("wobble")


def test_contracts_list_every_registered_format_with_its_extensions() -> None:
    """docs/contracts.md's table of formats is the registry's: names, order and extensions."""
    text = (ROOT / "docs" / "contracts.md").read_text(encoding="utf-8")
    rows = re.findall(r"^\| `(\w+)` \| ([^|]*) \|", text, re.M)
    table = {name: tuple(re.findall(r"`(\.\w+)`", ext)) for name, ext in rows if name in FORMATS}
    assert list(table) == list(FORMATS)
    assert table == {f.name: f.extensions for f in registered_formats()}
    assert f"`--format {'|'.join(FORMATS)}`" in text


# -- a registered format appears everywhere -------------------------------------------------
def test_a_registered_format_is_offered_detected_loaded_and_inspected(
    toy_format: type[RecordFormat], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    walk = datasets.load("seed_individual")
    assert walk.mass_kg is not None
    toy = write_toy(tmp_path / "walk.toy", walk.time_s, walk.grf_n, walk.mass_kg)

    assert format_names()[-1] == "toy"
    assert "toy" in format_choices()
    assert detect_format(toy) == "toy"
    # By content: the specific toy format is asked before the generic CSV, which would
    # otherwise take the magic line for a header.
    as_text = toy.with_suffix(".txt")
    as_text.write_bytes(toy.read_bytes())
    assert detect_format(as_text) == "toy"

    record = load_record(toy)
    np.testing.assert_array_equal(record.time_s, walk.time_s)
    np.testing.assert_array_equal(record.grf_n, walk.grf_n)
    assert record.mass_kg == walk.mass_kg
    assert record.metadata["format"] == "toy"
    assert record.metadata["mass_source"] == "the TOYGRF line"
    assert load_record(as_text, fmt="TOY").metadata["format"] == "toy"
    with pytest.raises(UsageError, match="fmt must be one of csv, mot, insole, c3d, toy, got"):
        load_record(toy, fmt="wobble")

    # A bad cell is reported at its file line by the shared row parser.
    broken = tmp_path / "broken.toy"
    broken.write_text(f"{TOY_MAGIC} 70\n0.0 700\n0.01 7OO\n", encoding="utf-8")
    with pytest.raises(InputError, match=r"line 3, column 2 \(grf\).*'7OO' is not a number"):
        load_record(broken)

    # The command line reads it as it reads the same samples from CSV.
    csv_path, _ = save_record(walk.replace(metadata={}), tmp_path / "walk.csv")
    assert main(["inspect", str(toy), "--json"]) == 0
    from_toy = json.loads(capsys.readouterr().out)
    assert main(["inspect", str(csv_path), "--json"]) == 0
    from_csv = json.loads(capsys.readouterr().out)
    assert from_toy.pop("format") == "toy" and from_csv.pop("format") == "csv"
    assert from_toy.pop("source") == str(toy)
    from_csv.pop("source")
    assert from_toy["steps"] > 10
    assert from_toy == from_csv


def test_an_unregistered_format_is_gone_everywhere(tmp_path: Path) -> None:
    register_format(ToyFormat)
    unregister_format("toy")
    toy = write_toy(tmp_path / "walk.toy", np.arange(3) / 100, np.full(3, 700.0), 70.0)
    assert "toy" not in format_choices()
    assert detect_format(toy) == "csv"  # no extension claims .toy; the header-like line
    with pytest.raises(UsageError, match="fmt must be one of csv, mot, insole, c3d, got 'toy'"):
        load_record(toy, fmt="toy")
    with pytest.raises(UsageError, match="'toy' is not known"):
        unregister_format("toy")


# -- what the registry refuses --------------------------------------------------------------
def test_registering_the_same_class_again_keeps_its_place(toy_format: type[RecordFormat]) -> None:
    register_format(toy_format)
    assert format_names() == (*FORMATS, "toy")


@pytest.mark.parametrize(
    ("attributes", "words"),
    [
        ({"name": "toy"}, "format name 'toy' is already registered by"),
        ({"name": "Toy Format"}, "is not a lower-case identifier"),
        ({"name": "other", "extensions": (".CSV",)}, "must be a tuple of lower-case extensions"),
        ({"name": "other", "extensions": ".oth"}, "must be a tuple of lower-case extensions"),
        ({"name": "other", "extensions": (".tsv",)}, "the extension .tsv is already the 'csv'"),
        ({"name": "other", "extensions": (".toy",)}, "the extension .toy is already the 'toy'"),
        ({"name": "other", "read": RecordFormat.read}, "must implement read(path, source)"),
    ],
)
def test_a_bad_format_class_is_refused_with_a_reason(
    toy_format: type[RecordFormat], attributes: dict[str, object], words: str
) -> None:
    bad = type("BadFormat", (ToyFormat,), attributes)
    with pytest.raises(UsageError, match=re.escape(words)):
        register_format(bad)
    assert format_names() == (*FORMATS, "toy")
    with pytest.raises(UsageError, match="is not a subclass of RecordFormat"):
        register_format(dict)  # type: ignore[arg-type]


def test_a_reader_that_returns_no_grf_is_named(tmp_path: Path) -> None:
    class NoGrf(ToyFormat):
        name = "no_grf"
        extensions = (".nogrf",)

        def read(self, path: Path, source: str) -> RecordTable:
            return RecordTable(arrays={"time_s": np.arange(3.0), "force": np.ones(3)}, metadata={})

    register_format(NoGrf)
    try:
        path = tmp_path / "a.nogrf"
        path.write_text("x\n", encoding="utf-8")
        with pytest.raises(UsageError, match="format 'no_grf' returned the arrays force, time_s"):
            load_record(path)
    finally:
        unregister_format("no_grf")


# -- detection order ------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("time,grf\n0,700\n", "csv"),
        ("# only a comment\n", "csv"),
        ("name=x\nendheader\ntime\tg_vy\n0\t700\n", "mot"),
        ("time,grf\nendheader\n", "mot"),  # OpenSim is asked before the generic CSV
        ("# c\n" + " ".join(["1"] * 19) + "\n", "insole"),
    ],
)
def test_content_detection_asks_the_specific_formats_before_csv(
    tmp_path: Path, text: str, expected: str
) -> None:
    path = tmp_path / "record.txt"
    path.write_text(text, encoding="utf-8")
    assert detect_format(path) == expected


def test_a_headerless_table_no_format_claims_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "record.dat"
    path.write_text("\n0 700 1\n", encoding="utf-8")
    with pytest.raises(InputError, match="line 2: the file is a table of numbers without a header"):
        detect_format(path)


def test_a_text_file_no_format_claims_is_refused_naming_the_formats(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Without the generic CSV, a table with a header line is claimed by no format."""
    from workbench.records.formats import base

    without_csv = {name: f for name, f in base._REGISTRY.items() if name != "csv"}
    monkeypatch.setattr(base, "_REGISTRY", without_csv)
    path = tmp_path / "record.txt"
    path.write_text("time grf\n0 700\n", encoding="utf-8")
    with pytest.raises(InputError, match="the content is in none of the formats mot, insole, c3d"):
        detect_format(path)
