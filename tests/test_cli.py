"""The ``workbench`` command as a new user meets it: real records, bad input, JSON contract."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from workbench.cli import main
from workbench.datasets import embedded_path

G = 9.81
INSPECT_KEYS = {
    "duration_s",
    "sample_rate_hz",
    "mass_kg",
    "pacing_hz",
    "steps",
    "mean_grf_n",
    "static_balance",
    "warnings",
}


def walking_grf(duration_s=12.0, fs=200.0, mass=70.0, pacing=1.8):
    """A smooth analytic walking-like GRF: M g plus the first three step harmonics."""
    t = np.arange(0.0, duration_s, 1.0 / fs)
    w = 2 * np.pi * pacing * t
    grf = mass * G * (1 + 0.35 * np.sin(w) + 0.1 * np.sin(2 * w + 1.0) + 0.05 * np.sin(3 * w + 2))
    return t, grf


def write_csv(path: Path, t, grf, *, mass=70.0, header="time,grf", sidecar=True, rows=None):
    lines = [header]
    if rows is None:
        rows = [f"{float(a)!r},{float(b)!r}" for a, b in zip(t, grf, strict=True)]
    lines += rows
    path.write_text("\n".join(lines) + "\n")
    if sidecar:
        path.with_suffix(".json").write_text(json.dumps({"mass_kg": mass}))
    return path


def run_cli(argv, capsys):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# --------------------------------------------------------------------------------------------
# the real records
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def treadmill_json():
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "workbench",
            "inspect",
            str(embedded_path("treadmill")),
            "--mass",
            "77.3",
            "--json",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(out.stdout)


def test_inspect_treadmill_contract_and_values(treadmill_json):
    r = treadmill_json
    assert INSPECT_KEYS <= r.keys()
    assert r["mass_kg"] == pytest.approx(77.3)
    assert r["sample_rate_hz"] == pytest.approx(200.0, rel=1e-6)
    assert r["duration_s"] == pytest.approx(143.05, abs=0.1)
    # Independent count: heel strikes on the two belts (see tests/test_steps.py).
    from tests.test_steps import TREADMILL_HEEL_STRIKES

    assert abs(r["steps"] - TREADMILL_HEEL_STRIKES) <= 0.05 * TREADMILL_HEEL_STRIKES
    assert 1.3 < r["pacing_hz"] < 2.3
    assert r["static_balance"] == pytest.approx(1.0, abs=0.02)
    # The trial changes speed: the per-step series must show it and a warning must say so.
    assert r["pacing"]["varies"] is True
    assert r["pacing"]["instantaneous_p90_hz"] - r["pacing"]["instantaneous_p10_hz"] > 0.3
    assert any("changes along the record" in w for w in r["warnings"])


def test_inspect_insole_warns_about_static_balance(capsys):
    code, out, err = run_cli(["inspect", embedded_path("insole"), "--mass", "83", "--json"], capsys)
    assert code == 0, err
    r = json.loads(out)
    from tests.test_steps import INSOLE_HEEL_STRIKES

    assert abs(r["steps"] - INSOLE_HEEL_STRIKES) <= 0.05 * INSOLE_HEEL_STRIKES
    assert r["static_balance"] == pytest.approx(1.33, abs=0.03)
    assert any("rescale-to-mass" in w and "mass" in w for w in r["warnings"])
    assert 0.8 < r["pacing_hz"] < 2.5


def test_rescale_to_mass_brings_balance_to_one(capsys):
    code, out, err = run_cli(
        ["inspect", embedded_path("insole"), "--mass", "83", "--rescale-to-mass", "--json"],
        capsys,
    )
    assert code == 0, err
    r = json.loads(out)
    assert r["static_balance"] == pytest.approx(1.0, abs=2e-3)
    assert r["static_balance_raw"] == pytest.approx(1.33, abs=0.03)
    assert r["grf_scale_factor"] == pytest.approx(1 / r["static_balance_raw"], rel=1e-3)


def test_inspect_human_text_and_report(tmp_path, capsys):
    t, grf = walking_grf()
    path = write_csv(tmp_path / "walk.csv", t, grf)
    code, out, err = run_cli(["inspect", path, "--out", tmp_path / "rep"], capsys)
    assert code == 0, err
    assert "static balance" in out and "steps" in out
    assert (tmp_path / "rep" / "index.html").exists()
    assert (tmp_path / "rep" / "report.md").exists()
    pngs = list((tmp_path / "rep" / "figures").glob("*.png"))
    assert len(pngs) == 4


def test_inspect_recovers_pacing_of_analytic_walk(tmp_path, capsys):
    t, grf = walking_grf(duration_s=20.0, pacing=1.93)
    path = write_csv(tmp_path / "walk.csv", t, grf)
    code, out, err = run_cli(["inspect", path, "--json"], capsys)
    assert code == 0, err
    r = json.loads(out)
    assert r["pacing_hz"] == pytest.approx(1.93, rel=0.01)
    assert r["static_balance"] == pytest.approx(1.0, abs=0.01)
    assert r["warnings"] == []


# --------------------------------------------------------------------------------------------
# bad input: one clear sentence naming the file and the place, exit 2, never a traceback
# --------------------------------------------------------------------------------------------
def _bad_inputs(tmp: Path):
    t, grf = walking_grf()
    ok_rows = [f"{float(a)!r},{float(b)!r}" for a, b in zip(t, grf, strict=True)]
    cases = {}

    cases["missing file"] = ([tmp / "nope.csv", "--mass", "70"], ["nope.csv"])
    (tmp / "empty.csv").write_text("")
    cases["empty file"] = ([tmp / "empty.csv", "--mass", "70"], ["empty"])
    write_csv(tmp / "header_only.csv", t, grf, rows=[])
    cases["header only"] = ([tmp / "header_only.csv"], ["header_only.csv"])
    write_csv(tmp / "nogrf.csv", t, grf, header="time,force")
    cases["misnamed column"] = ([tmp / "nogrf.csv"], ["grf"])
    write_csv(tmp / "notime.csv", t, grf, rows=[f"{b!r}" for b in grf], header="grf")
    cases["missing column"] = ([tmp / "notime.csv"], ["time"])
    rows = list(ok_rows)
    rows[100] = f"{float(t[100])!r},abc"
    write_csv(tmp / "text.csv", t, grf, rows=rows)
    cases["non-numeric"] = ([tmp / "text.csv"], ["abc"])
    rows = list(ok_rows)
    rows[50] = f"{float(t[50])!r},nan"
    write_csv(tmp / "nan.csv", t, grf, rows=rows)
    cases["nan"] = ([tmp / "nan.csv"], ["grf"])
    rows = list(ok_rows)
    rows[200], rows[201] = rows[201], rows[200]
    write_csv(tmp / "backwards.csv", t, grf, rows=rows)
    cases["non-monotonic time"] = ([tmp / "backwards.csv"], ["time"])
    rows = list(ok_rows)
    rows[300] = f"{float(t[299])!r},{float(grf[300])!r}"
    write_csv(tmp / "dup.csv", t, grf, rows=rows)
    cases["duplicate time"] = ([tmp / "dup.csv"], ["time"])
    t_irr = t + np.where(np.arange(t.size) % 7 == 3, 0.002, 0.0)
    write_csv(tmp / "irregular.csv", t_irr, grf)
    cases["irregular sampling"] = ([tmp / "irregular.csv"], ["--resample"])
    write_csv(tmp / "nomass.csv", t, grf, sidecar=False)
    cases["no mass"] = ([tmp / "nomass.csv"], ["--mass"])
    write_csv(tmp / "tiny.csv", t, grf)
    cases["mass out of range"] = ([tmp / "tiny.csv", "--mass", "7"], ["mass"])
    write_csv(tmp / "kg.csv", t, grf / G)
    cases["force in kg"] = ([tmp / "kg.csv"], ["9.81"])
    write_csv(tmp / "kn.csv", t, grf / 1000)
    cases["force in kN"] = ([tmp / "kn.csv"], ["1000"])
    t_short, grf_short = walking_grf(duration_s=2.4, pacing=1.0)
    write_csv(tmp / "short.csv", t_short, grf_short)
    cases["too short for three steps"] = ([tmp / "short.csv"], ["step"])
    rng = np.random.default_rng(0)
    write_csv(tmp / "standing.csv", t, 70 * G + rng.normal(0, 5.0, t.size))
    cases["no walking (sensor noise only)"] = ([tmp / "standing.csv"], ["walking"])
    write_csv(tmp / "slow_sine.csv", t, 70 * G * (1 + 0.3 * np.sin(2 * np.pi * 0.6 * t)))
    cases["periodic but not walking"] = ([tmp / "slow_sine.csv"], ["0.6", "walking"])
    write_csv(tmp / "uplift.csv", t, 70 * G * (1 + 1.5 * np.sin(2 * np.pi * 1.8 * t)))
    cases["force pulls the person down"] = ([tmp / "uplift.csv"], ["push"])
    off = grf.copy()
    off[-400:] = 0.0
    write_csv(tmp / "stepped_off.csv", t, off)
    cases["stepped off the plate"] = ([tmp / "stepped_off.csv"], ["cut the record"])
    write_csv(tmp / "fine.csv", t, grf)
    cases["absurd high-pass"] = ([tmp / "fine.csv", "--highpass-hz", "1e-9"], ["--highpass-hz"])
    cases["high-pass eating the pacing"] = ([tmp / "fine.csv", "--highpass-hz", "1.5"], ["0.6"])
    (tmp / "folder.csv").mkdir()
    cases["a folder, not a file"] = ([tmp / "folder.csv"], ["folder.csv"])
    write_csv(tmp / "badside.csv", t, grf)
    (tmp / "badside.json").write_text("{mass_kg: 70")
    cases["invalid JSON sidecar"] = ([tmp / "badside.csv"], ["badside.json", "line 1"])
    return cases


BAD_CASES = [
    "missing file",
    "empty file",
    "header only",
    "misnamed column",
    "missing column",
    "non-numeric",
    "nan",
    "non-monotonic time",
    "duplicate time",
    "irregular sampling",
    "no mass",
    "mass out of range",
    "force in kg",
    "force in kN",
    "too short for three steps",
    "no walking (sensor noise only)",
    "periodic but not walking",
    "force pulls the person down",
    "stepped off the plate",
    "absurd high-pass",
    "high-pass eating the pacing",
    "a folder, not a file",
    "invalid JSON sidecar",
]


@pytest.mark.parametrize("case", BAD_CASES)
def test_bad_input_gives_one_sentence_and_exit_2(case, tmp_path, capsys):
    cases = _bad_inputs(tmp_path)
    argv, must_mention = cases[case]
    code, out, err = run_cli(["inspect", *argv], capsys)
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    message = lines[0]
    assert message.startswith("workbench: error: ")
    if "high-pass" not in case and "sidecar" not in case:
        assert Path(argv[0]).name in message
    for word in must_mention:
        assert word.lower() in message.lower(), message
    assert "Traceback" not in err


def test_bad_input_json_mode_prints_error_object(tmp_path, capsys):
    code, out, err = run_cli(["inspect", tmp_path / "absent.csv", "--mass", "70", "--json"], capsys)
    assert code == 2
    assert "absent.csv" in err
    assert "absent.csv" in json.loads(out)["error"]


def test_resample_opt_in_fixes_irregular_sampling(tmp_path, capsys):
    cases = _bad_inputs(tmp_path)
    argv, _ = cases["irregular sampling"]
    code, out, err = run_cli(["inspect", *argv, "--resample", "--json"], capsys)
    assert code == 0, err
    r = json.loads(out)
    assert r["pacing_hz"] == pytest.approx(1.8, rel=0.01)
    assert any("interpolated linearly onto a uniform" in w for w in r["warnings"])


def test_bad_input_from_a_real_shell(tmp_path):
    """The installed entry point, run as a user would, exits non-zero with one sentence."""
    (tmp_path / "empty.csv").write_text("")
    proc = subprocess.run(
        [sys.executable, "-m", "workbench", "inspect", str(tmp_path / "empty.csv"), "--mass", "70"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_unknown_format_is_a_usage_error(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "workbench", "inspect", "x.csv", "--format", "xlsx"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "invalid choice" in proc.stderr


def test_argument_errors_honour_json(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["inspect", "x.csv", "--mass", "70kg", "--json"])
    assert exc.value.code == 2
    out, _ = capsys.readouterr()
    assert "70kg" in json.loads(out)["error"]


def test_unwritable_output_is_a_user_error(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code = main(["simulate", "--out", str(blocker / "walk.csv")])
    err = capsys.readouterr().err
    assert code == 2
    assert "--out" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1


def test_written_files_have_ordinary_permissions(tmp_path, capsys):
    assert main(["simulate", "--out", str(tmp_path / "walk.csv")]) == 0
    capsys.readouterr()
    for name in ("walk.csv", "walk.json", "walk.truth.json"):
        assert (tmp_path / name).stat().st_mode & 0o044 == 0o044, name


def test_inspect_json_carries_the_instantaneous_pacing_series():
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "workbench",
            "inspect",
            str(embedded_path("treadmill")),
            "--mass",
            "77.3",
            "--json",
        ],
        capture_output=True,
        text=True,
        check=True,
    )
    r = json.loads(out.stdout)
    t = np.asarray(r["pacing"]["times_s"])
    f = np.asarray(r["pacing"]["instantaneous_hz"])
    assert t.size == f.size == r["steps"]
    # The trial speeds up and slows down: slow start, fast middle, medium end.
    start, middle, end = (
        np.median(f[t < 30]),
        np.median(f[(t > 75) & (t < 100)]),
        np.median(f[t > 115]),
    )
    assert start < 1.45 and middle > 2.05 and 1.45 < end < 1.8
