"""A batch folder: one run at a time, and bytes that do not depend on the current folder."""

import json
import os
from pathlib import Path

import pytest

from workbench.cli import main
from workbench.population.batch_folder import LOCK_NAME, batch_lock

fcntl = pytest.importorskip("fcntl")  # the lock is the system's flock


def _study(root: Path) -> Path:
    """A manifest whose rows all fail cheaply, before identification, in different ways."""
    records = root / "study" / "records"
    records.mkdir(parents=True)
    (records / "corrupt.csv").write_bytes(bytes(range(1, 256)) * 2)
    (records / "nan.csv").write_text("time,grf\n0,700\n0.01,nan\n0.02,700\n")
    (records / "badside.csv").write_text("time,grf\n0,700\n0.01,700\n")
    (records / "badside.json").write_text("{not json")
    manifest = root / "study" / "manifest.csv"
    rows = ["records/corrupt.csv", "records/nan.csv", "records/badside.csv", "records/gone.csv"]
    manifest.write_text("path,mass_kg\n" + "".join(f"{r},70\n" for r in rows))
    return manifest


def _outputs(out: Path) -> dict[str, bytes]:
    names = ["failures.csv", "results.csv", "batch.json"]
    names += sorted(f"records/{p.name}" for p in (out / "records").glob("*.json"))
    return {name: (out / name).read_bytes() for name in names}


def test_the_same_batch_from_another_folder_writes_the_same_bytes(tmp_path, monkeypatch):
    manifest = _study(tmp_path)
    runs = {}
    # The manifest typed relative from its folder, absolute, and with ../ from a sibling.
    for label, cwd, typed, out in [
        ("relative", manifest.parent, "manifest.csv", "../out-relative"),
        ("absolute", tmp_path, str(manifest), str(tmp_path / "out-absolute")),
        ("dotdot", tmp_path / "elsewhere", "../study/manifest.csv", "../out-dotdot"),
    ]:
        cwd.mkdir(exist_ok=True)
        monkeypatch.chdir(cwd)
        assert main(["batch", typed, "--out", out, "--json"]) == 4
        runs[label] = _outputs((cwd / out).resolve())
    reference = runs["relative"]
    assert len(reference) == 3 + 4  # three tables and one file per record
    for label, files in runs.items():
        assert files == reference, label
    reasons = (tmp_path / "out-relative" / "failures.csv").read_text()
    # Named as in the manifest, the sidecar beside its record, no trace of how it was typed.
    assert "records/badside.json, line 1" in reasons
    assert "records/corrupt.csv, " in reasons and "study/" not in reasons
    meta = json.loads(runs["dotdot"]["batch.json"])
    assert meta["manifest"] == "../study/manifest.csv"  # from the output folder


def test_a_second_run_on_a_folder_in_use_is_refused_and_touches_nothing(tmp_path, capsys):
    manifest = _study(tmp_path)
    out = tmp_path / "out"
    assert main(["batch", str(manifest), "--out", str(out), "--json"]) == 4
    capsys.readouterr()
    live_temporary = out / "records" / ".x.json.abc123.tmp"  # a live run's file being written
    live_temporary.write_text("{")
    with batch_lock(out):  # the other run, still going
        code = main(["batch", str(manifest), "--out", str(out), "--resume"])
        assert code == 2
        (line,) = capsys.readouterr().err.strip().splitlines()
        assert line == (
            f"workbench: error: the output folder {out} is in use by another batch that is "
            "still running; wait until it ends, or choose another folder"
        )
        assert live_temporary.exists()
    # Once the other run has ended, the lock is free and its leftovers are cleaned up.
    assert main(["batch", str(manifest), "--out", str(out), "--resume", "--json"]) == 4
    assert not live_temporary.exists()
    assert (out / LOCK_NAME).exists()


def test_the_lock_is_the_systems_and_outlives_no_run(tmp_path):
    out = tmp_path / "out"
    with batch_lock(out):
        fd = os.open(out / LOCK_NAME, os.O_RDWR)
        try:
            with pytest.raises(BlockingIOError):
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        finally:
            os.close(fd)
    fd = os.open(out / LOCK_NAME, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)  # released: taken at once
    finally:
        os.close(fd)
