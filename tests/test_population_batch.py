"""Batch engine: faults, kill and resume, worker count, Dask (issue: population)."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from workbench.cli import main
from workbench.cli.main import EXIT_RECORDS_FAILED
from workbench.population.batch import RESULT_COLUMNS, TIMING_COLUMNS, record_seed
from workbench.population.study import StudyDesign, study_plan, write_study

pytestmark = pytest.mark.slow

SETTINGS_TOML = """method = "rbpf"
harmonics = 3
pieces = "whole"
time_basis = "absolute"
highpass_hz = 0.0
observe = "acc"
force_check = false
particles = 32
"""
N_GOOD = 5
BAD = ("records/missing.csv", "records/corrupt.csv", "records/withnan.csv")


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    root = tmp_path_factory.mktemp("study")
    design = StudyDesign(n_male=1, n_female=1, n_records=None, duration_s=3.0)
    plan = study_plan(design, seed=11).iloc[:N_GOOD]
    manifest = write_study(plan, root, design)
    good = manifest.read_text().splitlines()
    (root / "records" / "corrupt.csv").write_bytes(bytes(range(256)) * 2)
    first = root / "records" / f"{plan.record.iloc[0]}.csv"
    lines = first.read_text().splitlines()
    lines[40] = lines[40].split(",")[0] + ",nan"
    (root / "records" / "withnan.csv").write_text("\n".join(lines) + "\n")
    (root / "records" / "withnan.json").write_text(json.dumps({"mass_kg": 70.0}))
    # Bad records in the middle, so a run killed half-way has both kinds still to do.
    rows = [good[0], *good[1:3], f"{BAD[0]},70,1.5,X", f"{BAD[1]},70,1.5,X", f"{BAD[2]},,,"]
    rows += good[3:]
    (root / "manifest.csv").write_text("\n".join(rows) + "\n")
    (root / "study.toml").write_text(SETTINGS_TOML)
    return root


def _batch(study, out, *extra):
    argv = ["batch", str(study / "manifest.csv"), "--out", str(out), "--config"]
    return main([*argv, str(study / "study.toml"), "--json", *extra])


def _assert_same_outputs(out: Path, ref: Path) -> None:
    """Results, failures and every record file byte for byte; only timings.csv may differ."""
    for name in ("results.csv", "failures.csv"):
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    records = sorted(p.name for p in (ref / "records").glob("*.json"))
    assert sorted(p.name for p in (out / "records").glob("*.json")) == records
    for name in records:
        assert (out / "records" / name).read_bytes() == (ref / "records" / name).read_bytes()
    timings = pd.read_csv(out / "timings.csv")
    assert tuple(timings.columns) == TIMING_COLUMNS
    assert list(timings.path) == sorted(pd.read_csv(ref / "timings.csv").path)
    assert (timings.elapsed_s >= 0).all()


@pytest.fixture(scope="module")
def reference(study, tmp_path_factory):
    out = tmp_path_factory.mktemp("ref")
    import contextlib
    import io

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        # Three records fail: the batch finishes them all and says so in its exit status.
        assert _batch(study, out) == EXIT_RECORDS_FAILED
    return out, json.loads(buf.getvalue())


def test_faults_reported_and_rest_complete(study, reference):
    out, summary = reference
    assert (summary["done"], summary["failed"], summary["skipped"]) == (N_GOOD, 3, 0)
    failures = pd.read_csv(out / "failures.csv")
    assert list(failures.columns) == ["path", "reason"]
    assert sorted(failures.path) == sorted(BAD)
    reasons = dict(zip(failures.path, failures.reason, strict=True))
    assert "does not exist" in reasons[BAD[0]]
    assert "binary data" in reasons[BAD[1]]
    assert "NaN" in reasons[BAD[2]]
    assert "paths start from the manifest's folder" in reasons[BAD[0]]
    results = pd.read_csv(out / "results.csv")
    assert tuple(results.columns) == RESULT_COLUMNS and "elapsed_s" not in results.columns
    timings = pd.read_csv(out / "timings.csv")
    assert sorted(timings.path) == sorted([*BAD, *results.path])
    assert dict(zip(timings.path, timings.status, strict=True))[BAD[0]] == "failed"
    assert len(results) == N_GOOD and results.path.is_monotonic_increasing
    truth = pd.read_csv(study / "truth.csv")
    truth["path"] = "records/" + truth.record + ".csv"
    merged = results.merge(truth, on="path", suffixes=("", "_true"))
    assert len(merged) == N_GOOD
    # In the model class the records come from, the posterior bands hold the truth
    # (4 sd: five records, two parameters each).
    for col in ("natural_frequency_hz", "damping_ratio"):
        z = (merged[col] - merged[f"{col}_true"]) / merged[f"{col}_sd"]
        assert (z.abs() < 4).all(), (col, z.tolist())
    assert (merged.identifiability == "well identified").all()
    # Seeds come from path and content, not position.
    p = merged.path.iloc[0]
    content = (study / p).read_bytes()
    assert merged.seed.iloc[0] == record_seed(0, p, content)
    assert record_seed(0, p, content) != record_seed(0, p, content + b" ")


def test_two_workers_give_identical_results(study, reference, tmp_path, capsys):
    assert _batch(study, tmp_path, "--workers", "2") == EXIT_RECORDS_FAILED
    ref, _ = reference
    _assert_same_outputs(tmp_path, ref)


def test_kill_and_resume_equals_uninterrupted(study, reference, tmp_path, capsys):
    cmd = [sys.executable, "-m", "workbench", "batch", str(study / "manifest.csv")]
    cmd += ["--out", str(tmp_path), "--config", str(study / "study.toml"), "--json"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    rec = tmp_path / "records"
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline:
            if rec.exists() and len(list(rec.glob("*.json"))) >= 2:
                break
            if proc.poll() is not None:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the batch ended before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait()
    finished = len(list(rec.glob("*.json")))
    assert 2 <= finished < N_GOOD + 3
    assert not (tmp_path / "results.csv").exists()
    # Without --resume the folder is refused rather than overwritten.
    assert _batch(study, tmp_path) == 2
    capsys.readouterr()
    assert _batch(study, tmp_path, "--resume") == EXIT_RECORDS_FAILED
    summary = json.loads(capsys.readouterr().out)
    assert summary["done"] + summary["failed"] + summary["skipped"] == N_GOOD + 3
    assert summary["skipped"] >= 1 and summary["failed"] == 3
    ref, _ = reference
    _assert_same_outputs(tmp_path, ref)
    # A second resume has nothing left to identify; other settings are refused.
    assert _batch(study, tmp_path, "--resume") == EXIT_RECORDS_FAILED
    again = json.loads(capsys.readouterr().out)
    assert (again["done"], again["skipped"]) == (0, N_GOOD)
    assert _batch(study, tmp_path, "--resume", "--particles", "40") == 2


def test_a_run_stopped_between_a_records_two_files_keeps_every_time(
    study, reference, tmp_path, monkeypatch, capsys
):
    # The kill test above lands wherever the process happens to be; this one stops the run
    # exactly between a record's timing file and its result file, the window in which a
    # record could once be kept as done without its time (a NaN in timings.csv).
    import workbench.population.batch as batch_module

    real_write = batch_module.atomic_write_json
    files_written: dict[str, int] = {}

    def write_then_stop(path, payload):
        # A record writes two files of one name (its result and its time); stop after the
        # first file of the third record identified, whichever of the two comes first.
        if Path(path).parent.name in ("records", "timings") and payload["status"] == "done":
            finished = sum(n == 2 for n in files_written.values())
            if finished == 2 and files_written.get(Path(path).name) == 1:
                raise KeyboardInterrupt
            files_written[Path(path).name] = files_written.get(Path(path).name, 0) + 1
        real_write(path, payload)

    monkeypatch.setattr(batch_module, "atomic_write_json", write_then_stop)
    assert _batch(study, tmp_path) == 130  # the command's exit status when interrupted
    monkeypatch.setattr(batch_module, "atomic_write_json", real_write)
    capsys.readouterr()
    assert _batch(study, tmp_path, "--resume") == EXIT_RECORDS_FAILED
    summary = json.loads(capsys.readouterr().out)
    assert summary["skipped"] == 2
    ref, _ = reference
    _assert_same_outputs(tmp_path, ref)


def test_dask_local_cluster(study, reference, tmp_path, capsys):
    distributed = pytest.importorskip("distributed")
    with (
        distributed.LocalCluster(
            n_workers=1,
            threads_per_worker=1,
            processes=False,
            protocol="tcp",
            dashboard_address=None,
        ) as cluster,
    ):
        code = _batch(study, tmp_path, "--scheduler", cluster.scheduler_address)
    assert code == EXIT_RECORDS_FAILED
    summary = json.loads(capsys.readouterr().out)
    assert (summary["done"], summary["failed"]) == (N_GOOD, 3)
    ref, _ = reference
    _assert_same_outputs(tmp_path, ref)


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_signal_to_the_main_process_stops_the_workers(study, tmp_path, signum):
    psutil = pytest.importorskip("psutil")
    # Slow records (many particles, the force check on), so that the batch is still running
    # when the signal arrives on a loaded machine: with the study's fast settings it could
    # finish its eight records between the workers' start and the signal.
    slow = tmp_path / "slow.toml"
    slow.write_text(SETTINGS_TOML.replace("particles = 32", "particles = 5000"))
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "workbench", "batch", str(study / "manifest.csv")]
    cmd += ["--out", str(out), "--config", str(slow), "--workers", "2"]
    # A process started with SIGINT ignored keeps ignoring it (Python installs its Ctrl-C
    # handler only over the default), and a test runner's worker may ignore it; start the
    # batch as a terminal would, with the default.
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    main_process = psutil.Process(proc.pid)
    deadline = time.monotonic() + 120
    try:
        # Wait until both pool workers run (the spawn start method imports the package).
        while time.monotonic() < deadline and proc.poll() is None:
            workers = [
                p
                for p in main_process.children(recursive=True)
                if "spawn_main" in " ".join(p.cmdline())
            ]
            if len(workers) >= 2:
                break
            time.sleep(0.05)
        assert proc.poll() is None, "the batch ended before the signal could be sent"
        descendants = main_process.children(recursive=True)
        os.kill(proc.pid, signum)  # to the main process only, as a service manager does
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1] == "workbench: interrupted"
    _, alive = psutil.wait_procs(descendants, timeout=10)
    assert alive == [], [p.cmdline() for p in alive]
    # The finished records stay, so --resume continues where the signal stopped the batch.
    assert not (out / "results.csv").exists()
