"""Input validation: every bad input gives one InputError sentence naming file, place and fix."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from workbench.errors import InputError, UsageError
from workbench.records.io import load_record
from workbench.records.record import G_M_S2, Record
from workbench.records.validation import (
    MASS_RANGE_KG,
    MIN_SAMPLE_RATE_HZ,
    validate_record,
)

MASS = 70.0
RATE = 100.0
N = 400  # 4 s


def table(n: int = N, rate_hz: float = RATE, mass_kg: float = MASS) -> dict[str, np.ndarray]:
    t = np.arange(n) / rate_hz
    grf = mass_kg * G_M_S2 * (1.0 + 0.3 * np.sin(2 * np.pi * 2.0 * t))
    return {"time": t, "grf": grf}


def write(path: Path, columns: dict[str, np.ndarray | list[str]], sep: str = ",") -> Path:
    """Write columns as CSV; cells may be given as text to inject bad values."""
    names = list(columns)
    cells = [[c if isinstance(c, str) else repr(float(c)) for c in columns[n]] for n in names]
    rows = [sep.join(row) for row in zip(*cells, strict=True)]
    path.write_text(sep.join(names) + "\n" + "\n".join(rows) + "\n", encoding="utf-8")
    return path


def as_text(values: np.ndarray) -> list[str]:
    return [repr(float(v)) for v in values]


def check_message(msg: str, source: str | Path, place: str, *words: str) -> None:
    """One sentence: 'SOURCE, PLACE: problem; fix.' with no line break and no second sentence."""
    assert msg.startswith(f"{source}, {place}: "), msg
    assert "\n" not in msg and msg.endswith("."), msg
    assert "; " in msg, msg
    assert re.search(r"\.\s+[A-Z]", msg) is None, msg
    for word in words:
        assert word in msg, (word, msg)


def expect(path: Path, place: str, *words: str, **kwargs: object) -> str:
    kwargs.setdefault("mass_kg", MASS)
    with pytest.raises(InputError) as err:
        load_record(path, **kwargs)  # type: ignore[arg-type]
    msg = str(err.value)
    check_message(msg, path, place, *words)
    return msg


# --------------------------------------------------------------------------------------
# files and columns


def test_missing_file(tmp_path: Path) -> None:
    expect(tmp_path / "nope.csv", "whole file", "does not exist")


@pytest.mark.parametrize("content", [b"", b"   \n\n", b"\xef\xbb\xbf\n"])
def test_empty_file(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "r.csv"
    path.write_bytes(content)
    expect(path, "whole file", "empty")


def test_header_only(tmp_path: Path) -> None:
    path = tmp_path / "r.csv"
    path.write_text("time,grf\n\n")
    expect(path, "line 1", "header but no data rows")


@pytest.mark.parametrize(
    ("header", "missing"),
    [("time,Force", "'grf'"), ("Zeit,grf", "'time'"), ("t_ms,Fz", "'time' or 'grf'")],
)
def test_misnamed_columns_list_found_and_expected(
    tmp_path: Path, header: str, missing: str
) -> None:
    data = table()
    a, b = header.split(",")
    path = write(tmp_path / "r.csv", {a: data["time"], b: data["grf"]})
    msg = expect(path, "line 1 (header)", f"no {missing} column", repr(a), repr(b))
    assert "name the columns 'time' [s] and 'grf' [N]" in msg


def test_wrong_unit_in_column_name(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "GRF [kN]": data["grf"] / 1000})
    expect(path, "line 1, column 'GRF [kN]'", "unit 'kn'", "--force-unit")


def test_duplicate_meaning_columns(tmp_path: Path) -> None:
    data = table()
    path = write(
        tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"], "GRF_N": data["grf"]}
    )
    expect(path, "line 1, column 'GRF_N'", "both mean 'grf'")


def test_first_line_is_data(tmp_path: Path) -> None:
    path = tmp_path / "r.csv"
    path.write_text("0.0,686.7\n0.01,690.1\n")
    expect(path, "line 1", "is data, not a header")


def test_non_numeric_cell_names_row_column_and_value(tmp_path: Path) -> None:
    data = table()
    grf = as_text(data["grf"])
    grf[36] = "12..5"
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": grf})
    expect(path, "line 38, column 'grf'", "'12..5' is not a number")


def test_decimal_comma_hint(tmp_path: Path) -> None:
    path = tmp_path / "r.csv"
    path.write_text("time;grf\n0,00;686,7\n0,01;690,1\n")
    expect(path, "line 2, column 'time'", "'0,00' is not a number", "point, not a comma")


def test_empty_cell(tmp_path: Path) -> None:
    data = table()
    grf = as_text(data["grf"])
    grf[9] = ""
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": grf})
    expect(path, "line 11, column 'grf'", "the cell is empty")


def test_wrong_number_of_fields(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"]})
    lines = path.read_text().splitlines()
    lines[5] = lines[5].replace(",", ";")
    path.write_text("\n".join(lines) + "\n")
    expect(path, "line 6", "1 fields but the header (line 1) has 2", "commas")


@pytest.mark.parametrize(
    ("content", "words"),
    [
        (b"PK\x03\x04" + bytes(100), ("ZIP archive", "export the sheet as CSV")),
        (b"time,grf\n0,\x00\x01\n", ("binary data",)),
        (b"time,grf\n0,1\n\xff\xfe1,2\n", ("0xff is not UTF-8",)),
    ],
)
def test_binary_or_non_utf8(tmp_path: Path, content: bytes, words: tuple[str, ...]) -> None:
    path = tmp_path / "r.csv"
    path.write_bytes(content)
    place = "line 3" if b"\xff" in content else "whole file"
    expect(path, place, *words)


# --------------------------------------------------------------------------------------
# values and time base


@pytest.mark.parametrize(
    ("text", "kind"), [("nan", "NaN"), ("-inf", "infinite"), ("Infinity", "infinite")]
)
def test_nan_and_inf_first_row(tmp_path: Path, text: str, kind: str) -> None:
    data = table()
    grf = as_text(data["grf"])
    grf[49] = text
    grf[80] = "nan"
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": grf})
    expect(path, "line 51, column 'grf'", kind)


def test_time_goes_back(tmp_path: Path) -> None:
    data = table()
    t = data["time"].copy()
    t[[100, 101]] = t[[101, 100]]
    path = write(tmp_path / "r.csv", {"time": t, "grf": data["grf"]})
    expect(path, "line 103, column 'time'", "goes back from 1.01 s to 1.0 s", "sort the rows")


def test_duplicate_time(tmp_path: Path) -> None:
    data = table()
    t = data["time"].copy()
    t[200] = t[199]
    path = write(tmp_path / "r.csv", {"time": t, "grf": data["grf"]})
    expect(path, "line 202, column 'time'", "duplicate", "remove the duplicated row")


def test_irregular_sampling_points_to_resample(tmp_path: Path) -> None:
    data = table()
    t = data["time"].copy()
    t[150] += 0.3 / RATE
    path = write(tmp_path / "r.csv", {"time": t, "grf": data["grf"]})
    msg = expect(path, "line 152, column 'time'", "irregular", "30 % off", "--resample")
    assert "tolerance 1 %" in msg
    # a looser tolerance accepts it as it is
    rec = load_record(path, mass_kg=MASS, irregular_tolerance=0.35)
    np.testing.assert_array_equal(rec.time_s, t)


def test_resample_interpolates_onto_uniform_grid(tmp_path: Path) -> None:
    t = np.arange(N) / RATE
    t[1:-1] += np.random.default_rng(4).uniform(-0.2, 0.2, N - 2) / RATE
    # a force linear in time is interpolated exactly, so the resampled values are known
    grf = MASS * G_M_S2 * (1.0 + 0.05 * (t - 2.0))
    path = write(tmp_path / "r.csv", {"time": t, "grf": grf})
    with pytest.raises(InputError, match="--resample"):
        load_record(path, mass_kg=MASS)
    rec = load_record(path, mass_kg=MASS, resample=True)
    dt = float(np.median(np.diff(t)))
    assert rec.n_samples == int(np.floor((t[-1] - t[0]) / dt * (1 + 1e-12))) + 1
    np.testing.assert_allclose(np.diff(rec.time_s), dt, rtol=1e-9)
    np.testing.assert_allclose(
        rec.grf_n, MASS * G_M_S2 * (1.0 + 0.05 * (rec.time_s - 2.0)), rtol=1e-12
    )
    info = rec.metadata["resampled"]
    assert info["method"] == "linear" and info["n_samples_before"] == N
    assert info["sample_rate_hz"] == pytest.approx(1 / dt)
    assert "file_lines" not in rec.metadata
    assert (
        len(rec.metadata["warnings"]) == 1
        and "interpolated linearly" in rec.metadata["warnings"][0]
    )


def test_resample_refuses_long_gaps(tmp_path: Path) -> None:
    data = table()
    keep = np.r_[0:100, 110:N]
    path = write(tmp_path / "r.csv", {"time": data["time"][keep], "grf": data["grf"][keep]})
    expect(path, "line 102, column 'time'", "gap of 0.11 s", "split the record", resample=True)


def test_insole_jitter_at_exactly_the_tolerance_passes(tmp_path: Path) -> None:
    # time stamps printed to 0.1 ms: one 0.0099 s interval is exactly 1 % off
    t = np.round(np.arange(N) / RATE, 4)
    t[200:] -= 0.0001
    data = table()
    path = write(tmp_path / "r.csv", {"time": t, "grf": data["grf"]})
    assert load_record(path, mass_kg=MASS).n_samples == N
    expect(path, "line 202, column 'time'", "irregular", irregular_tolerance=0.009)


def test_sample_rate_too_low(tmp_path: Path) -> None:
    data = table(n=100, rate_hz=25.0)
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"]})
    expect(path, "column 'time'", "25 Hz", f"{MIN_SAMPLE_RATE_HZ:g} Hz")


def test_time_in_milliseconds(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"] * 1000.0, "grf": data["grf"]})
    expect(path, "column 'time'", "0.1 Hz", "milliseconds")


def test_too_short(tmp_path: Path) -> None:
    data = table(n=150)
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"]})
    expect(path, "whole file", "1.5 s", "too short")


def test_single_row(tmp_path: Path) -> None:
    path = tmp_path / "r.csv"
    path.write_text("time,grf\n0,700\n")
    expect(path, "whole file", "single data row")


# --------------------------------------------------------------------------------------
# mass, units, signs


def test_no_mass(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"]})
    expect(path, "metadata", "no body mass", "--mass", mass_kg=None)


@pytest.mark.parametrize(
    ("mass", "word"),
    [(700.0, "outside"), (7.0, "outside"), (70000.0, "grams"), (float("nan"), "finite")],
)
def test_mass_out_of_range_from_argument(tmp_path: Path, mass: float, word: str) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"]})
    expect(path, "body mass (given as --mass or mass_kg)", word, "kilograms", mass_kg=mass)


def test_mass_out_of_range_from_sidecar(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"]})
    (tmp_path / "r.json").write_text('{"mass_kg": 154}')
    # 154 kg is a valid mass; the same number in pounds is a typical slip caught by the force level
    msg = expect(path, "column 'grf'", "far from 1", mass_kg=None)
    assert "0.455 times" in msg
    (tmp_path / "r.json").write_text('{"mass_kg": 0.07}')
    expect(path, 'body mass ("mass_kg" in r.json)', "0.07 kg is outside", mass_kg=None)
    assert MASS_RANGE_KG == (20.0, 300.0)


def test_forces_in_kilograms_force(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"] / G_M_S2})
    expect(path, "column 'grf'", "kilograms-force", "multiply the force columns by 9.81")
    rec = load_record(path, mass_kg=MASS, force_unit="kgf")
    assert float(np.mean(rec.grf_n)) / (MASS * G_M_S2) == pytest.approx(1.0, abs=1e-9)


def test_forces_in_kilonewtons(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"] / 1000.0})
    expect(path, "column 'grf'", "kilonewtons", "by 1000")


def test_calibration_error_of_33_percent_passes(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": 1.33 * data["grf"]})
    rec = load_record(path, mass_kg=MASS)
    assert float(np.mean(rec.grf_n)) / rec.weight_n == pytest.approx(1.33, abs=1e-9)
    assert rec.metadata["warnings"] == []


def test_negative_force_is_a_sign_error(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": -data["grf"]})
    expect(path, "column 'grf'", "negative", "multiply the force columns by -1")


def test_negative_side_channel(tmp_path: Path) -> None:
    data = table()
    left = 0.5 * data["grf"]
    path = write(
        tmp_path / "r.csv",
        {"time": data["time"], "grf": data["grf"], "grf_left": -left, "grf_right": left},
    )
    expect(path, "column 'grf_left'", "wrong sign")


def test_side_sum_mismatch_is_a_warning(tmp_path: Path) -> None:
    data = table()
    left = 0.5 * data["grf"]
    path = write(
        tmp_path / "r.csv",
        {"time": data["time"], "grf": data["grf"], "grf_left": left, "grf_right": 0.8 * left},
    )
    rec = load_record(path, mass_kg=MASS)
    assert len(rec.metadata["warnings"]) == 1
    assert "10 % of its mean" in rec.metadata["warnings"][0]


def test_pacing_in_steps_per_minute(tmp_path: Path) -> None:
    data = table()
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"]})
    expect(path, "pacing frequency", "steps per minute", "divide it by 60", pacing_hz=110.0)
    expect(path, "pacing frequency", "outside the walking range", pacing_hz=9.0)


def test_ground_acceleration_with_gravity(tmp_path: Path) -> None:
    data = table()
    acc = -G_M_S2 + 0.1 * np.sin(2 * np.pi * 1.7 * data["time"])
    path = write(tmp_path / "r.csv", {"time": data["time"], "grf": data["grf"], "ground_acc": acc})
    expect(path, "column 'ground_acc'", "contains gravity", "-9.81")


# --------------------------------------------------------------------------------------
# other formats and in-memory records


def test_mot_bad_cell_names_line_and_column(tmp_path: Path) -> None:
    data = table()
    path = tmp_path / "r.mot"
    rows = [
        f"{t!r}\t{f!r}" for t, f in zip(data["time"].tolist(), data["grf"].tolist(), strict=True)
    ]
    rows[3] = rows[3].split("\t")[0] + "\tn/a"
    path.write_text("x\nnRows=400\nendheader\ntime\tground_force_vy\n" + "\n".join(rows) + "\n")
    expect(path, "line 8, column 'ground_force_vy'", "'n/a' is not a number")


def test_mot_without_endheader(tmp_path: Path) -> None:
    path = tmp_path / "r.mot"
    path.write_text("time\tground_force_vy\n0\t700\n")
    expect(path, "header", "no 'endheader' line")


def test_insole_row_with_wrong_width(tmp_path: Path) -> None:
    data = table()
    rows = [
        "\t".join([repr(t)] + ["1.0"] * 16 + [repr(f / 2), repr(f / 2)])
        for t, f in zip(data["time"].tolist(), data["grf"].tolist(), strict=True)
    ]
    rows[20] = rows[20].rsplit("\t", 1)[0]
    path = tmp_path / "r.txt"
    path.write_text("\n".join(rows) + "\n")
    expect(path, "line 21", "18 values", "19", fmt="insole")


def test_in_memory_record_names_samples() -> None:
    data = table()
    grf = data["grf"].copy()
    grf[7] = np.nan
    rec = Record(time_s=data["time"], grf_n=grf, mass_kg=MASS)
    with pytest.raises(InputError) as err:
        validate_record(rec)
    check_message(str(err.value), "<memory>", "sample 8, field grf_n", "NaN")


def test_in_memory_without_mass_when_not_required() -> None:
    data = table()
    rec = validate_record(Record(time_s=data["time"], grf_n=data["grf"]), require_mass=False)
    assert rec.metadata["warnings"] == []
    with pytest.raises(InputError, match="no body mass"):
        validate_record(rec)


def test_sliced_record_does_not_use_stale_line_numbers(tmp_path: Path) -> None:
    data = table()
    t = data["time"].copy()
    t[300] = t[299]
    path = write(tmp_path / "r.csv", {"time": t, "grf": data["grf"]})
    rec = load_record(path, mass_kg=MASS, validate=False)
    with pytest.raises(InputError) as err:
        validate_record(rec.slice(1.0, 4.0))
    check_message(str(err.value), path, "sample 201, column 'time'", "duplicate")


def test_validation_returns_new_record_and_keeps_input() -> None:
    data = table()
    rec = Record(time_s=data["time"], grf_n=data["grf"], mass_kg=MASS, metadata={"k": 1})
    out = validate_record(rec)
    assert out is not rec and dict(rec.metadata) == {"k": 1}
    assert out.metadata == {"k": 1, "warnings": []}


def test_bad_tolerance_is_a_usage_error() -> None:
    data = table()
    rec = Record(time_s=data["time"], grf_n=data["grf"], mass_kg=MASS)
    with pytest.raises(UsageError, match="irregular_tolerance"):
        validate_record(rec, irregular_tolerance=-0.1)
