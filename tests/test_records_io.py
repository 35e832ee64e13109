"""Record loaders: the embedded real records, CSV + sidecar, round trip, manifests, C3D."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from workbench.datasets import EMBEDDED, embedded_path
from workbench.errors import InputError, UsageError, WorkbenchError
from workbench.records.io import (
    ManifestEntry,
    detect_format,
    load_manifest,
    load_record,
    save_record,
)
from workbench.records.record import G_M_S2, Record

# --------------------------------------------------------------------------------------
# helpers


def walking(mass_kg: float = 70.0, rate_hz: float = 100.0, duration_s: float = 4.0) -> Record:
    """A periodic GRF whose mean over whole periods is exactly M g."""
    t = np.arange(round(duration_s * rate_hz)) / rate_hz
    weight = mass_kg * G_M_S2
    grf = weight * (1.0 + 0.3 * np.sin(2 * np.pi * 2.0 * t) + 0.1 * np.cos(2 * np.pi * 4.0 * t))
    left = 0.5 * grf + 40.0 * np.sin(2 * np.pi * 1.0 * t)
    return Record(
        time_s=t,
        grf_n=grf,
        grf_left_n=left,
        grf_right_n=grf - left,
        ground_acc_m_s2=0.05 * np.sin(2 * np.pi * 1.9 * t),
        mass_kg=mass_kg,
        pacing_hz=2.0,
        subject="S07",
        notes="synthetic",
    )


def req(values: np.ndarray | None) -> np.ndarray:
    """The array of an optional record field that the test knows is present."""
    assert values is not None
    return values


def write_csv(path: Path, header: str, rows: list[list[float]], sep: str = ",") -> Path:
    text = header + "\n" + "".join(sep.join(repr(float(v)) for v in row) + "\n" for row in rows)
    path.write_text(text, encoding="utf-8")
    return path


def simple_rows(mass_kg: float = 70.0, rate_hz: float = 100.0, n: int = 400) -> list[list[float]]:
    t = np.arange(n) / rate_hz
    grf = mass_kg * G_M_S2 * (1.0 + 0.3 * np.sin(2 * np.pi * 2.0 * t))
    return [[float(a), float(b)] for a, b in zip(t, grf, strict=True)]


# --------------------------------------------------------------------------------------
# embedded real records


@pytest.fixture(scope="module")
def treadmill() -> Record:
    return load_record(embedded_path("treadmill"), mass_kg=77.3)


@pytest.fixture(scope="module")
def insole() -> Record:
    return load_record(embedded_path("insole"), mass_kg=83.0)


def _raw_rows(path: Path, skip_until: str | None) -> list[list[float]]:
    """Independent plain parse of a whitespace table (after a marker line, if given)."""
    lines = path.read_text().splitlines()
    if skip_until is not None:
        lines = lines[[s.strip() for s in lines].index(skip_until) + 2 :]
    return [[float(x) for x in line.split()] for line in lines if line.strip()]


def test_treadmill_shape_rate_and_balance(treadmill: Record) -> None:
    assert detect_format(embedded_path("treadmill")) == "mot"
    assert treadmill.metadata["format"] == "mot"
    assert treadmill.n_samples == 28611
    assert treadmill.sample_rate_hz == pytest.approx(200.0, rel=1e-9)
    assert treadmill.duration_s == pytest.approx(143.055, abs=1e-9)
    assert treadmill.time_s[0] == 0.005
    ratio = float(np.mean(treadmill.grf_n)) / (77.3 * G_M_S2)
    assert ratio == pytest.approx(0.9994, abs=5e-4)
    assert treadmill.metadata["warnings"] == []
    assert "does not state" in treadmill.metadata["side_assignment"]
    assert treadmill.source == str(embedded_path("treadmill"))


def test_treadmill_grf_is_sum_of_plate_vy(treadmill: Record) -> None:
    rows = _raw_rows(embedded_path("treadmill"), "endheader")
    assert len(rows) == treadmill.n_samples
    # columns: time, plate 1 vx vy vz ..., plate 2 vx vy vz ... (vy at 1-based 3 and 12)
    for k in (0, 1, 777, 14305, 28610):
        assert treadmill.time_s[k] == rows[k][0]
        assert treadmill.grf_n[k] == rows[k][2] + rows[k][11]
        assert treadmill.grf_left_n is not None and treadmill.grf_right_n is not None
        assert treadmill.grf_left_n[k] == rows[k][2]
        assert treadmill.grf_right_n[k] == rows[k][11]


def test_insole_shape_rate_and_balance(insole: Record) -> None:
    assert detect_format(embedded_path("insole")) == "insole"
    assert insole.metadata["format"] == "insole"
    assert insole.n_samples == 12119
    assert insole.sample_rate_hz == pytest.approx(100.0, rel=1e-9)
    assert insole.duration_s == pytest.approx(121.1815, abs=1e-9)
    ratio = float(np.mean(insole.grf_n)) / (83.0 * G_M_S2)
    # the known 33 % calibration error passes validation (static balance is checked later)
    assert ratio == pytest.approx(1.3313, abs=1e-3)


def test_insole_grf_is_sum_of_columns_18_and_19(insole: Record) -> None:
    rows = _raw_rows(embedded_path("insole"), None)
    assert len(rows) == insole.n_samples
    assert all(len(r) == 19 for r in rows[:50])
    for k in (0, 3, 5000, 12118):
        assert insole.time_s[k] == rows[k][0]
        assert insole.grf_n[k] == rows[k][17] + rows[k][18]
        assert insole.grf_left_n is not None and insole.grf_right_n is not None
        assert insole.grf_left_n[k] == rows[k][17]
        assert insole.grf_right_n[k] == rows[k][18]


def test_embedded_records_get_their_tabulated_mass() -> None:
    rec = load_record(embedded_path("insole"))
    assert rec.mass_kg == EMBEDDED["insole"].mass_kg == 83.0
    assert rec.metadata["mass_source"] == "embedded dataset table"
    assert "PhysioNet" in rec.metadata["attribution"]
    # an explicit mass wins
    assert load_record(embedded_path("insole"), mass_kg=80.0).mass_kg == 80.0


def test_insole_copy_elsewhere_reads_with_txt_sniffing(tmp_path: Path) -> None:
    src = embedded_path("insole").read_text().splitlines()[:500]
    path = tmp_path / "walk.dat"
    path.write_text("\n".join(src) + "\n")
    assert detect_format(path) == "insole"
    rec = load_record(path, mass_kg=83.0)
    assert rec.n_samples == 500
    with pytest.raises(InputError, match="no body mass"):
        load_record(path)


# --------------------------------------------------------------------------------------
# format detection


def test_detect_format_by_extension_and_content(tmp_path: Path) -> None:
    rows = simple_rows()
    assert detect_format(write_csv(tmp_path / "a.csv", "time,grf", rows)) == "csv"
    assert detect_format(write_csv(tmp_path / "b.tsv", "time\tgrf", rows, "\t")) == "csv"
    tabbed = write_csv(tmp_path / "c.txt", "Time\tGRF", rows, "\t")
    assert detect_format(tabbed) == "csv"
    assert load_record(tabbed, mass_kg=70.0).n_samples == len(rows)
    mot = tmp_path / "d.txt"
    mot.write_text("name\nendheader\ntime\tground_force_vy\n0\t1\n")
    assert detect_format(mot) == "mot"
    (tmp_path / "e.c3d").write_bytes(b"\x02\x50" + bytes(510))
    assert detect_format(tmp_path / "e.c3d") == "c3d"
    (tmp_path / "f.bin").write_bytes(b"\x02\x50" + bytes(510))
    assert detect_format(tmp_path / "f.bin") == "c3d"


def test_detect_format_headerless_table_with_wrong_width(tmp_path: Path) -> None:
    path = tmp_path / "x.txt"
    path.write_text("0.0 700.0 1.0\n0.01 701.0 1.0\n")
    with pytest.raises(InputError) as err:
        detect_format(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}, line 1: ") and "3 columns" in msg and "\n" not in msg


def test_format_override(tmp_path: Path) -> None:
    rows = simple_rows()
    path = write_csv(tmp_path / "rec.mot", "time,grf", rows)  # wrong extension
    with pytest.raises(InputError, match="endheader"):
        load_record(path, mass_kg=70.0)
    assert load_record(path, fmt="csv", mass_kg=70.0).metadata["format"] == "csv"
    with pytest.raises(UsageError, match="fmt must be one of"):
        load_record(path, fmt="xlsx", mass_kg=70.0)


# --------------------------------------------------------------------------------------
# CSV variants


@pytest.mark.parametrize(
    ("header", "sep"),
    [
        ("time,grf", ","),
        ("time;grf", ";"),
        ("time\tgrf", "\t"),
        ("time   grf", "   "),
        (" Time , GRF ", ","),
        ('"time","grf"', ","),
        ("time [s],grf (N)", ","),
    ],
)
def test_csv_separators_and_header_spelling(tmp_path: Path, header: str, sep: str) -> None:
    rows = simple_rows()
    rec = load_record(write_csv(tmp_path / "r.csv", header, rows, sep), mass_kg=70.0)
    np.testing.assert_array_equal(rec.time_s, [r[0] for r in rows])
    np.testing.assert_array_equal(rec.grf_n, [r[1] for r in rows])
    assert "column_aliases" not in rec.metadata


def test_csv_aliases_are_recorded(tmp_path: Path) -> None:
    rows = simple_rows()
    rec = load_record(write_csv(tmp_path / "r.csv", "t,GRF_N", rows), mass_kg=70.0)
    assert rec.metadata["column_aliases"] == {"t": "time", "GRF_N": "grf"}
    assert rec.n_samples == len(rows)


def test_csv_optional_columns_and_ignored_columns(tmp_path: Path) -> None:
    rec0 = walking()
    rows = [
        [a, b, c, d, e, 1.0]
        for a, b, c, d, e in zip(
            rec0.time_s,
            rec0.grf_n,
            req(rec0.grf_left_n),
            req(rec0.grf_right_n),
            req(rec0.ground_acc_m_s2),
            strict=True,
        )
    ]
    path = write_csv(tmp_path / "r.csv", "time,grf,grf_left,grf_right,ground_acc,cop_x", rows)
    rec = load_record(path, mass_kg=70.0)
    np.testing.assert_array_equal(rec.grf_left_n, req(rec0.grf_left_n))
    np.testing.assert_array_equal(rec.ground_acc_m_s2, req(rec0.ground_acc_m_s2))
    assert rec.metadata["ignored_columns"] == ["cop_x"]
    assert rec.metadata["warnings"] == []


def test_csv_total_from_left_plus_right(tmp_path: Path) -> None:
    rec0 = walking()
    rows = [
        [a, b, c]
        for a, b, c in zip(rec0.time_s, req(rec0.grf_left_n), req(rec0.grf_right_n), strict=True)
    ]
    rec = load_record(write_csv(tmp_path / "r.csv", "time,grf_left,grf_right", rows), mass_kg=70)
    np.testing.assert_array_equal(rec.grf_n, req(rec0.grf_left_n) + req(rec0.grf_right_n))
    assert rec.metadata["grf_from"] == "grf_left + grf_right"


def test_csv_comments_blank_lines_and_line_numbers(tmp_path: Path) -> None:
    rows = simple_rows()
    body = [",".join(map(repr, r)) for r in rows]
    body[10] = body[10] + "\n"  # a blank line after data row 11
    text = "# exported by a lab system\n\ntime,grf\n" + "\n".join(body) + "\n"
    path = tmp_path / "r.csv"
    path.write_text(text)
    rec = load_record(path, mass_kg=70.0)
    assert rec.n_samples == len(rows)
    # data row k (0-based) is on line 4 + k, plus one after the blank line
    assert rec.metadata["file_lines"] == {"n_samples": len(rows), "runs": [[0, 4], [11, 16]]}


def test_force_unit_conversion(tmp_path: Path) -> None:
    rows = [[t, f / 1000.0] for t, f in simple_rows()]
    path = write_csv(tmp_path / "r.csv", "time,grf", rows)
    rec = load_record(path, mass_kg=70.0, force_unit="kN")
    np.testing.assert_allclose(rec.grf_n, [r[1] * 1000.0 for r in rows], rtol=1e-15)
    assert rec.metadata["force_unit"] == {"unit": "kN", "factor_to_n": 1000.0}
    with pytest.raises(UsageError, match="force_unit"):
        load_record(path, mass_kg=70.0, force_unit="lbf")


# --------------------------------------------------------------------------------------
# sidecar and keyword overrides, round trip


def test_round_trip_identical_arrays_and_metadata(tmp_path: Path) -> None:
    rec = walking()
    rec = rec.replace(metadata={"truth": {"stiffness_n_per_m": 15000.0}, "seed": 3})
    csv_path, json_path = save_record(
        rec, tmp_path / "sub" / "rec.csv", extra_metadata={"simulator": "unit-test"}
    )
    assert csv_path == tmp_path / "sub" / "rec.csv" and json_path == tmp_path / "sub" / "rec.json"
    back = load_record(csv_path)
    for name in ("time_s", "grf_n", "grf_left_n", "grf_right_n", "ground_acc_m_s2"):
        np.testing.assert_array_equal(getattr(back, name), getattr(rec, name), err_msg=name)
    assert (back.mass_kg, back.pacing_hz, back.subject, back.notes) == (
        70.0,
        2.0,
        "S07",
        "synthetic",
    )
    assert back.metadata["truth"] == {"stiffness_n_per_m": 15000.0}
    assert back.metadata["seed"] == 3 and back.metadata["simulator"] == "unit-test"
    assert back.metadata["mass_source"] == '"mass_kg" in rec.json'
    assert back.source == str(csv_path)
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["rec.csv", "rec.json"]


def test_round_trip_of_loaded_record_drops_loader_keys(tmp_path: Path) -> None:
    rec = load_record(embedded_path("insole"))
    rec = rec.slice(0.0, 10.0)
    csv_path, json_path = save_record(rec, tmp_path / "insole.csv")
    side = json.loads(json_path.read_text())
    assert side["mass_kg"] == 83.0
    assert "file_lines" not in side and "columns" not in side and "format" not in side
    assert "PhysioNet" in side["attribution"]
    back = load_record(csv_path)
    np.testing.assert_array_equal(back.grf_n, rec.grf_n)
    np.testing.assert_array_equal(back.grf_left_n, rec.grf_left_n)
    assert back.metadata["format"] == "csv"


def test_save_replaces_atomically_and_leaves_old_file_on_failure(tmp_path: Path) -> None:
    rec = walking()
    csv_path, _ = save_record(rec, tmp_path / "r.csv")
    before = csv_path.read_bytes()
    bad = rec.replace(metadata={"thing": object()})
    with pytest.raises(UsageError, match=r"metadata\['thing'\]"):
        save_record(bad, csv_path)
    assert csv_path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv", "r.json"]
    with pytest.raises(UsageError, match=r"\.csv"):
        save_record(rec, tmp_path / "r.txt")
    with pytest.raises(UsageError, match="mass_kg"):
        save_record(rec, tmp_path / "r.csv", extra_metadata={"mass_kg": 3})


def test_keyword_arguments_override_sidecar(tmp_path: Path) -> None:
    path = write_csv(tmp_path / "r.csv", "time,grf", simple_rows(mass_kg=70.0))
    (tmp_path / "r.json").write_text(
        json.dumps({"mass_kg": 71.0, "pacing_hz": 1.8, "subject": 12, "notes": "n", "truth": 1})
    )
    rec = load_record(path)
    assert (rec.mass_kg, rec.pacing_hz, rec.subject, rec.notes) == (71.0, 1.8, "12", "n")
    assert rec.metadata["truth"] == 1
    rec = load_record(path, mass_kg=69.0, pacing_hz=2.1, subject="S2")
    assert (rec.mass_kg, rec.pacing_hz, rec.subject) == (69.0, 2.1, "S2")
    assert rec.metadata["mass_source"] == "given as --mass or mass_kg"
    with pytest.raises(UsageError, match="mass_kg must be a number"):
        load_record(path, mass_kg="70")  # type: ignore[arg-type]


def test_sidecar_nulls_mean_not_given(tmp_path: Path) -> None:
    path = write_csv(tmp_path / "r.csv", "time,grf", simple_rows())
    (tmp_path / "r.json").write_text(
        '{"mass_kg": 70, "pacing_hz": null, "subject": null, "notes": null, "warnings": null}'
    )
    rec = load_record(path)
    assert (rec.mass_kg, rec.pacing_hz, rec.subject, rec.notes) == (70.0, None, None, "")
    assert rec.metadata["warnings"] == []


def test_sidecar_loader_keys_are_ignored(tmp_path: Path) -> None:
    rows = simple_rows()
    rows[5][0] = rows[4][0]  # duplicate time on line 7
    path = write_csv(tmp_path / "r.csv", "time,grf", rows)
    (tmp_path / "r.json").write_text(
        '{"mass_kg": 70, "file_lines": {"n_samples": 400, "runs": [["x"]]}, "format": "mot"}'
    )
    with pytest.raises(InputError, match=r"r\.csv, line 7, column 'time': .*duplicate"):
        load_record(path)
    rec = load_record(path, validate=False)
    assert rec.metadata["format"] == "csv"


@pytest.mark.parametrize(
    ("text", "where", "what"),
    [
        ('{"mass_kg": 70,}', "line 1, column 16", "not valid JSON"),
        ('{"mass_kg": "70 kg"}', "key 'mass_kg'", "not a number"),
        ('{"pacing_hz": true}', "key 'pacing_hz'", "not a number"),
        ("[70]", "whole file", "not an object"),
        ('{"mass_kg": 70, "notes": 5}', "key 'notes'", "not text"),
    ],
)
def test_bad_sidecar(tmp_path: Path, text: str, where: str, what: str) -> None:
    path = write_csv(tmp_path / "r.csv", "time,grf", simple_rows())
    side = tmp_path / "r.json"
    side.write_text(text)
    with pytest.raises(InputError) as err:
        load_record(path)
    msg = str(err.value)
    assert msg.startswith(f"{side}, {where}: ") and what in msg
    assert "\n" not in msg and msg.endswith(".")


# --------------------------------------------------------------------------------------
# OpenSim variants


def _mot(path: Path, names: list[str], rows: np.ndarray, n_rows: int | None = None) -> Path:
    head = f"name\nversion=1\nnRows={len(rows) if n_rows is None else n_rows}\nendheader\n"
    body = "".join("\t".join(repr(float(v)) for v in row) + "\n" for row in rows)
    path.write_text(head + "\t".join(names) + "\n" + body)
    return path


def test_mot_single_plate_and_named_sides(tmp_path: Path) -> None:
    rec0 = walking()
    one = np.column_stack([rec0.time_s, 1.0 + 0 * rec0.time_s, rec0.grf_n])
    path = _mot(tmp_path / "a.mot", ["time", "ground_force_vx", "ground_force_vy"], one)
    rec = load_record(path, mass_kg=70.0)
    np.testing.assert_array_equal(rec.grf_n, rec0.grf_n)
    assert rec.grf_left_n is None

    two = np.column_stack([rec0.time_s, req(rec0.grf_right_n), req(rec0.grf_left_n)])
    path = _mot(tmp_path / "b.mot", ["time", "r_ground_force_vy", "l_ground_force_vy"], two, 7)
    rec = load_record(path, mass_kg=70.0)
    np.testing.assert_array_equal(rec.grf_left_n, req(rec0.grf_left_n))
    np.testing.assert_array_equal(rec.grf_right_n, req(rec0.grf_right_n))
    assert rec.metadata["side_assignment"] == "from the column names"
    assert any("nRows=7" in w for w in rec.metadata["warnings"])


def test_mot_without_vy_is_refused(tmp_path: Path) -> None:
    rec0 = walking()
    rows = np.column_stack([rec0.time_s, rec0.grf_n])
    path = _mot(tmp_path / "z.mot", ["time", "ground_force_vz"], rows)
    with pytest.raises(InputError) as err:
        load_record(path, mass_kg=70.0)
    msg = str(err.value)
    assert msg.startswith(f"{path}, line 5: ") and "z-up" in msg and "\n" not in msg


# --------------------------------------------------------------------------------------
# C3D


def test_c3d_without_ezc3d_says_how_to_install(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "ezc3d", None)  # makes `import ezc3d` fail
    path = tmp_path / "trial.c3d"
    path.write_bytes(b"\x02\x50" + bytes(510))
    with pytest.raises(UsageError) as err:
        load_record(path, mass_kg=70.0)
    assert "pip install 'workbench[c3d]'" in str(err.value)
    assert isinstance(err.value, WorkbenchError)


# The reader on real two-plate files written with ezc3d: tests/test_c3d.py.


# --------------------------------------------------------------------------------------
# manifests


def test_manifest_loading(tmp_path: Path) -> None:
    (tmp_path / "data").mkdir()
    manifest = tmp_path / "data" / "batch.csv"
    manifest.write_text(
        "path,mass_kg,pacing_hz,subject\n"
        "a.csv,70,1.8,S1\n"
        "\n"
        '"sub dir/b, c.csv",,,\n'
        f"{tmp_path / 'abs.csv'},82.5,,S3\n"
    )
    entries = load_manifest(manifest, allow_outside_paths=True)
    assert entries == [
        ManifestEntry(tmp_path / "data" / "a.csv", 70.0, 1.8, "S1", 2),
        ManifestEntry(tmp_path / "data" / "sub dir" / "b, c.csv", None, None, None, 4),
        ManifestEntry(tmp_path / "abs.csv", 82.5, None, "S3", 5),
    ]
    # The absolute path leaves the manifest's folder: refused unless allowed.
    with pytest.raises(InputError, match=r"line 5, column 'path'.*--allow-outside-paths"):
        load_manifest(manifest)


def test_manifest_semicolon_and_path_only(tmp_path: Path) -> None:
    manifest = tmp_path / "m.csv"
    manifest.write_text("Path\nx.csv\ny.csv\n")
    assert [e.path.name for e in load_manifest(manifest)] == ["x.csv", "y.csv"]
    manifest.write_text("path;Mass_kg [kg]\nx.csv;70\n")
    assert load_manifest(manifest)[0].mass_kg == 70.0


@pytest.mark.parametrize(
    ("text", "where", "what"),
    [
        ("file,mass_kg\na.csv,70\n", "line 1, column 'file'", "not part of a manifest"),
        ("mass_kg\n70\n", "line 1", "no 'path' column"),
        ("path,mass\na.csv,70\n", "line 1, column 'mass'", "not part of a manifest"),
        ("path,mass_kg\na.csv,70\nb.csv,7O\n", "line 3, column 'mass_kg'", "'7O' is not a number"),
        ("path,mass_kg\na.csv,700\n", "line 2, column 'mass_kg'", "outside"),
        ("path,pacing_hz\na.csv,110\n", "line 2, column 'pacing_hz'", "steps per minute"),
        ("path,mass_kg\na.csv,70\na.csv,71\n", "line 3, column 'path'", "already listed on line 2"),
        ("path,mass_kg\n,70\n", "line 2, column 'path'", "empty"),
        ("path,mass_kg\na.csv;70\n", "line 2", "1 fields but the header (line 1) has 2"),
        ("path,mass_kg\n", "line 1", "no records"),
        ("path,mass_kg [lb]\na.csv,170\n", "line 1, column 'mass_kg [lb]'", "unit 'lb'"),
        ("", "whole file", "empty"),
    ],
)
def test_manifest_errors_name_the_row(tmp_path: Path, text: str, where: str, what: str) -> None:
    manifest = tmp_path / "m.csv"
    manifest.write_text(text)
    with pytest.raises(InputError) as err:
        load_manifest(manifest)
    msg = str(err.value)
    assert msg.startswith(f"{manifest}, {where}: "), msg
    assert what in msg and "\n" not in msg and msg.endswith(".")


def test_manifest_missing_file(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="does not exist"):
        load_manifest(tmp_path / "nope.csv")
