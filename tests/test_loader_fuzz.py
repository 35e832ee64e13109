"""Property tests: the loaders either return a valid record or raise WorkbenchError.

Malformed inputs (random bytes, random text tables, random column names, NaN, shuffled or
duplicated times, blank lines, wrong separators, wrong units, odd sidecars) must never escape
as a bare Python/numpy exception or a warning, and anything that loads must be usable.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from workbench.errors import WorkbenchError
from workbench.records.io import load_manifest, load_record, save_record
from workbench.records.record import G_M_S2, Record
from workbench.records.validation import (
    BODY_WEIGHT_RATIO_RANGE,
    MASS_RANGE_KG,
    MIN_DURATION_S,
    MIN_SAMPLE_RATE_HZ,
)

FUZZ = settings(
    max_examples=120,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)


def load_or_error(path: Path, **kwargs: Any) -> Record | None:
    """Load; a WorkbenchError is fine (one line), a returned record must be valid."""
    try:
        rec = load_record(path, **kwargs)
    except WorkbenchError as err:
        msg = str(err)
        assert msg and "\n" not in msg and "\r" not in msg, msg
        return None
    assert_valid(rec)
    return rec


def assert_valid(rec: Record) -> None:
    for name in ("time_s", "grf_n", "grf_left_n", "grf_right_n", "ground_acc_m_s2"):
        values = getattr(rec, name)
        if values is not None:
            assert values.dtype == np.float64 and values.shape == rec.time_s.shape
            assert np.all(np.isfinite(values)), name
    assert np.all(np.diff(rec.time_s) > 0)
    assert rec.mass_kg is not None and MASS_RANGE_KG[0] <= rec.mass_kg <= MASS_RANGE_KG[1]
    assert rec.sample_rate_hz >= MIN_SAMPLE_RATE_HZ * (1 - 1e-9)
    assert rec.duration_s >= MIN_DURATION_S * (1 - 1e-9)
    ratio = float(np.mean(rec.grf_n)) / rec.weight_n
    assert BODY_WEIGHT_RATIO_RANGE[0] <= ratio <= BODY_WEIGHT_RATIO_RANGE[1]
    assert isinstance(rec.metadata["warnings"], list)


# --------------------------------------------------------------------------------------
# random bytes and random text


@FUZZ
@given(
    content=st.binary(max_size=3000),
    suffix=st.sampled_from([".csv", ".txt", ".mot", ".dat", ".c3d", ""]),
)
def test_random_bytes(content: bytes, suffix: str) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"rec{suffix}"
        path.write_bytes(content)
        load_or_error(path, mass_kg=70.0)


NAMES = ["time", "grf", "grf_left", "grf_right", "ground_acc", "t", "GRF_N", "Force", "Fz", ""]
cells = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**6), 10**6).map(str),
    st.text(alphabet="0123456789.-+eE,;nainfNA _\t\"'", max_size=8),
    st.just(""),
)


@FUZZ
@given(
    header=st.lists(st.one_of(st.sampled_from(NAMES), st.text(max_size=6)), min_size=0, max_size=5),
    rows=st.lists(st.lists(cells, min_size=0, max_size=6), max_size=30),
    sep=st.sampled_from([",", ";", "\t", " ", "|"]),
    newline=st.sampled_from(["\n", "\r\n", "\r"]),
    suffix=st.sampled_from([".csv", ".txt"]),
)
def test_random_text_tables(
    header: list[str], rows: list[list[str]], sep: str, newline: str, suffix: str
) -> None:
    text = newline.join(sep.join(r) for r in [header, *rows]) + newline
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / f"rec{suffix}"
        path.write_text(text, encoding="utf-8", newline="")
        load_or_error(path, mass_kg=70.0)
        load_or_error(path, mass_kg=70.0, resample=True)


# --------------------------------------------------------------------------------------
# valid tables with mutations

# (name, benign): benign mutations must still load.
MUTATIONS = [
    ("swap_rows", False),
    ("duplicate_row", False),
    ("nan_cell", False),
    ("inf_cell", False),
    ("empty_cell", False),
    ("text_cell", False),
    ("decimal_comma", False),
    ("blank_lines", True),
    ("comment_lines", True),
    ("other_separator_line", False),
    ("drop_cell", False),
    ("jitter_time", False),
    ("gap", False),
    ("truncate", False),
    ("scale_kgf", False),
    ("scale_kn", False),
    ("negate", False),
    ("calibration_133", True),
    ("header_case", True),
    ("rename_column", False),
    ("crlf", True),
]


@st.composite
def mutated_tables(draw: st.DrawFn) -> tuple[str, bool, dict[str, np.ndarray]]:
    rate = draw(st.sampled_from([50.0, 100.0, 200.0, 250.0]))
    seconds = draw(st.floats(2.2, 4.0))
    mass = draw(st.floats(40.0, 120.0))
    n = int(seconds * rate)
    t = np.arange(n) / rate
    pacing = draw(st.floats(1.4, 2.4))
    grf = mass * G_M_S2 * (1.0 + 0.3 * np.sin(2 * np.pi * pacing * t))
    columns: dict[str, np.ndarray] = {"time": t, "grf": grf}
    if draw(st.booleans()):
        left = 0.5 * grf * (1 + 0.2 * np.sin(2 * np.pi * 0.5 * pacing * t))
        columns["grf_left"], columns["grf_right"] = left, grf - left
    if draw(st.booleans()):
        columns["ground_acc"] = 0.05 * np.sin(2 * np.pi * 1.9 * t)
    chosen = draw(st.lists(st.sampled_from(MUTATIONS), max_size=3, unique=True))
    sep = draw(st.sampled_from([",", ";", "\t"]))
    names = list(columns)
    table = [[repr(float(v)) for v in row] for row in zip(*columns.values(), strict=True)]
    lines_before: list[str] = []
    newline = "\n"

    width = len(names)

    def pick(min_rows: int = 1) -> int | None:
        """A row that still holds one text cell per column, or None."""
        rows = [i for i, r in enumerate(table) if len(r) == width and not r[0].startswith("#")]
        return draw(st.sampled_from(rows)) if len(rows) >= min_rows else None

    def number(cell: str) -> float | None:
        try:
            return float(cell)
        except ValueError:
            return None

    for name, _ in chosen:
        col = draw(st.integers(0, width - 1))
        i = pick()
        if i is None:
            break
        if name == "swap_rows" and i + 1 < len(table):
            table[i], table[i + 1] = table[i + 1], table[i]
        elif name == "duplicate_row":
            table.insert(i, list(table[i]))
        elif name in ("nan_cell", "inf_cell", "empty_cell", "text_cell"):
            bad = {"nan_cell": "nan", "inf_cell": "-inf", "empty_cell": "", "text_cell": "abc"}
            table[i][col] = bad[name]
        elif name == "decimal_comma":
            table[i][col] = table[i][col].replace(".", ",")
        elif name == "blank_lines":
            for _ in range(draw(st.integers(1, 4))):
                table.insert(draw(st.integers(0, len(table))), [])
        elif name == "comment_lines":
            lines_before.append("# exported by the lab system")
            table.insert(draw(st.integers(0, len(table))), ["# pause"])
        elif name == "other_separator_line":
            table[i] = [(";" if sep != ";" else ",").join(table[i])]
        elif name == "drop_cell":
            del table[i][col]
        elif name == "jitter_time":
            value = number(table[i][0])
            if value is not None:
                table[i][0] = repr(value + draw(st.floats(-0.6, 0.6)) / rate)
        elif name == "gap":
            del table[i : i + draw(st.integers(1, 25))]
        elif name == "truncate":
            del table[i:]
        elif name in ("scale_kgf", "scale_kn", "negate", "calibration_133"):
            factor = {"scale_kgf": 1 / G_M_S2, "scale_kn": 1e-3, "negate": -1.0}.get(name, 1.33)
            force_cols = [j for j, c in enumerate(columns) if c.startswith("grf")]
            for row in table:
                for j in force_cols:
                    value = number(row[j]) if len(row) == width else None
                    if value is not None:
                        row[j] = repr(value * factor)
        elif name == "header_case":
            names = [f" {c.upper()} " for c in names]
        elif name == "rename_column":
            names[col] = draw(
                st.sampled_from(["Force", "Fz", "grf_x", "Time (ms)", "", "GRF [kN]"])
            )
        elif name == "crlf":
            newline = "\r\n"
    body = [sep.join(row) for row in table]
    text = newline.join([*lines_before, sep.join(names), *body]) + newline
    benign = all(ok for _, ok in chosen)
    return text, benign, columns


@FUZZ
@given(case=mutated_tables(), resample=st.booleans())
def test_mutated_valid_tables(
    case: tuple[str, bool, dict[str, np.ndarray]], resample: bool
) -> None:
    text, benign, columns = case
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "rec.csv"
        path.write_text(text, encoding="utf-8", newline="")
        mass = float(np.mean(columns["grf"])) / G_M_S2
        rec = load_or_error(path, mass_kg=mass, resample=resample)
        if benign:
            assert rec is not None, "a valid table with only harmless changes must load"
            np.testing.assert_array_equal(rec.time_s, columns["time"])


# --------------------------------------------------------------------------------------
# random column names, sidecars and manifests


@FUZZ
@given(
    names=st.lists(
        st.one_of(
            st.sampled_from(["time", "grf", "Time", " GRF ", "t", "grf_n", "time [s]", "grf (N)"]),
            st.text(alphabet=st.characters(exclude_categories=["Cs"]), max_size=8),
        ),
        min_size=2,
        max_size=2,
    )
)
def test_random_column_names(names: list[str]) -> None:
    t = np.arange(300) / 100.0
    grf = 700.0 * (1 + 0.2 * np.sin(2 * np.pi * 2 * t))
    rows = "".join(f"{a!r},{b!r}\n" for a, b in zip(t.tolist(), grf.tolist(), strict=True))
    header = ",".join(names)
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "rec.csv"
        path.write_text(header + "\n" + rows, encoding="utf-8", newline="")
        rec = load_or_error(path, mass_kg=700.0 / G_M_S2)
        canonical = [n.strip().lower() for n in names]
        if canonical in (["time", "grf"], ["t", "grf_n"], ["time [s]", "grf (n)"]):
            assert rec is not None
            np.testing.assert_array_equal(rec.grf_n, grf)


json_values = st.recursive(
    st.none() | st.booleans() | st.floats() | st.integers() | st.text(max_size=5),
    lambda inner: (
        st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=8,
)


def _walk_csv(folder: str) -> tuple[Path, np.ndarray]:
    t = np.arange(300) / 100.0
    grf = 700.0 * (1 + 0.2 * np.sin(2 * np.pi * 2 * t))
    rows = "".join(f"{a!r},{b!r}\n" for a, b in zip(t.tolist(), grf.tolist(), strict=True))
    path = Path(folder) / "rec.csv"
    path.write_text("time,grf\n" + rows)
    return path, grf


@FUZZ
@given(
    sidecar=st.fixed_dictionaries(
        {"mass_kg": st.one_of(st.floats(36.0, 140.0), json_values)},
        optional={
            key: json_values
            for key in (
                "pacing_hz",
                "subject",
                "notes",
                "warnings",
                "truth",
                "format",
                "columns",
                "file_lines",
            )
        },
    ),
)
def test_random_sidecars(sidecar: dict[str, Any]) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path, grf = _walk_csv(folder)
        path.with_suffix(".json").write_text(json.dumps(sidecar), encoding="utf-8")
        rec = load_or_error(path)
        if rec is not None:
            np.testing.assert_array_equal(rec.grf_n, grf)
            # what loaded can be written back and read again unchanged
            csv_path, _ = save_record(rec, Path(folder) / "again.csv")
            again = load_record(csv_path)
            np.testing.assert_array_equal(again.grf_n, rec.grf_n)
            assert (again.mass_kg, again.pacing_hz, again.subject, again.notes) == (
                rec.mass_kg,
                rec.pacing_hz,
                rec.subject,
                rec.notes,
            )


@FUZZ
@given(raw=st.one_of(json_values.map(json.dumps), st.text(max_size=40)))
def test_random_sidecar_text(raw: str) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path, _ = _walk_csv(folder)
        path.with_suffix(".json").write_text(raw, encoding="utf-8")
        load_or_error(path, mass_kg=70.0)


@FUZZ
@given(
    header=st.lists(
        st.sampled_from(["path", "mass_kg", "pacing_hz", "subject", "mass", ""]), max_size=4
    ),
    rows=st.lists(
        st.lists(st.one_of(cells, st.sampled_from(["a.csv", "b c.csv", '"x,y"'])), max_size=4),
        max_size=6,
    ),
    sep=st.sampled_from([",", ";", "\t"]),
)
def test_random_manifests(header: list[str], rows: list[list[str]], sep: str) -> None:
    text = "\n".join(sep.join(r) for r in [header, *rows]) + "\n"
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "manifest.csv"
        path.write_text(text, encoding="utf-8")
        try:
            entries = load_manifest(path)
        except WorkbenchError as err:
            assert "\n" not in str(err)
            return
        assert entries
        for entry in entries:
            assert entry.path.is_absolute() or entry.path.parent == Path(folder)
            if entry.mass_kg is not None:
                assert MASS_RANGE_KG[0] <= entry.mass_kg <= MASS_RANGE_KG[1]
