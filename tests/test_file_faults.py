"""Files that are not files: pipes, devices, symbolic link loops and runaway records.

A named pipe read as a record waits for a writer for ever and ``/dev/zero`` never ends; both
must be refused by their status, before anything opens them, in one sentence naming the
file (exit 2), and in a batch only their own row fails.
"""

import json
import os
from pathlib import Path

import pandas as pd
import pytest

from workbench.cli import main
from workbench.errors import InputError
from workbench.population.batch_folder import file_seed, record_seed
from workbench.records.io import load_manifest, load_record

needs_fifo = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
needs_dev_zero = pytest.mark.skipif(not Path("/dev/zero").exists(), reason="no /dev/zero here")


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _loop(folder: Path) -> Path:
    (folder / "a.csv").symlink_to(folder / "b.csv")
    (folder / "b.csv").symlink_to(folder / "a.csv")
    return folder / "a.csv"


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err  # one sentence, no traceback
    return err[0]


@needs_fifo
def test_a_named_pipe_as_a_record_is_refused_without_waiting(tmp_path, capsys):
    pipe = _fifo(tmp_path / "walk.csv")
    with pytest.raises(InputError, match="named pipe"):
        load_record(pipe)
    assert main(["inspect", str(pipe)]) == 2
    line = _error_line(capsys)
    assert str(pipe) in line and "named pipe (FIFO)" in line and "saved on disk" in line


@needs_dev_zero
def test_a_device_as_a_record_is_refused_without_reading_it(tmp_path, capsys):
    link = tmp_path / "walk.csv"
    link.symlink_to("/dev/zero")
    assert main(["inspect", str(link)]) == 2
    line = _error_line(capsys)
    assert str(link) in line and "character device" in line


def test_a_symbolic_link_loop_is_called_a_loop_not_missing(tmp_path, capsys):
    loop = _loop(tmp_path)
    assert main(["inspect", str(loop)]) == 2
    line = _error_line(capsys)
    assert "loop of symbolic links" in line and "does not exist" not in line


@needs_fifo
def test_a_named_pipe_as_a_manifest_is_refused(tmp_path, capsys):
    pipe = _fifo(tmp_path / "manifest.csv")
    with pytest.raises(InputError, match="named pipe"):
        load_manifest(pipe)
    assert main(["batch", str(pipe), "--out", str(tmp_path / "out")]) == 2
    assert "named pipe" in _error_line(capsys)
    assert not (tmp_path / "out" / "batch.json").exists()


@needs_fifo
@needs_dev_zero
def test_bad_rows_fail_alone_and_name_their_file(tmp_path):
    _fifo(tmp_path / "pipe.csv")
    (tmp_path / "zero.csv").symlink_to("/dev/zero")
    _loop(tmp_path)
    rows = ["pipe.csv", "zero.csv", "a.csv", "missing.csv"]
    (tmp_path / "manifest.csv").write_text("path,mass_kg\n" + "".join(f"{r},70\n" for r in rows))
    out = tmp_path / "out"
    assert main(["batch", str(tmp_path / "manifest.csv"), "--out", str(out), "--json"]) == 4
    failures = pd.read_csv(out / "failures.csv").set_index("path").reason
    assert sorted(failures.index) == sorted(rows)
    assert "named pipe" in failures["pipe.csv"]
    assert "character device" in failures["zero.csv"]
    assert "loop of symbolic links" in failures["a.csv"]
    assert "does not exist" in failures["missing.csv"]
    for path, reason in failures.items():
        assert reason.startswith(f"{path}, whole file: ")


def test_a_record_over_the_per_record_budget_fails_its_row_before_it_is_read(tmp_path):
    from workbench.cli.population import BATCH_RECORD_LINES

    # Just over the budget: one line per sample, as the row estimate counts them.
    lines = BATCH_RECORD_LINES + 10
    body = "".join(f"{i / 1000:.3f},700\n" for i in range(lines))
    (tmp_path / "long.csv").write_text("time,grf\n" + body)
    (tmp_path / "manifest.csv").write_text("path,mass_kg\nlong.csv,70\n")
    out = tmp_path / "out"
    assert main(["batch", str(tmp_path / "manifest.csv"), "--out", str(out), "--json"]) == 4
    (reason,) = pd.read_csv(out / "failures.csv").reason
    assert reason.startswith("long.csv, whole file: the record has more than ")
    assert f"{BATCH_RECORD_LINES:,} lines" in reason and "--no-limits" in reason
    stored = json.loads(next((out / "records").glob("*.json")).read_text())
    assert stored["status"] == "failed"


def test_the_streamed_seed_equals_the_seed_of_the_bytes(tmp_path):
    # A record's seed is hashed from its file in chunks now; it must not change a batch's
    # numbers: the same seed as hashing the whole content at once, over a chunk boundary.
    data = bytes(range(256)) * 5000  # 1.28 MB, more than one 1 MiB chunk
    (tmp_path / "r.csv").write_bytes(data)
    assert file_seed(7, "r.csv", tmp_path / "r.csv") == record_seed(7, "r.csv", data)
    assert file_seed(7, "gone.csv", tmp_path / "gone.csv") == record_seed(7, "gone.csv", None)
    assert file_seed(7, "r.csv", tmp_path / "r.csv") != file_seed(8, "r.csv", tmp_path / "r.csv")


def test_the_documented_per_record_budget_is_the_one_applied():
    from workbench.cli.population import BATCH_RECORD_LINES

    root = Path(__file__).resolve().parents[1] / "docs"
    figure = f"{BATCH_RECORD_LINES:,}".replace(",", " ")
    for page in ("contracts.md", "guide/population.md"):
        assert (
            f"{figure} lines" in (root / page).read_text()
            or f"({figure})" in (root / page).read_text()
        ), page


@needs_fifo
@pytest.mark.parametrize(
    "argv",
    [
        ["identify", "seed_individual", "--config", "{pipe}"],
        ["batch", "{ok}", "--out", "{out}", "--config", "{pipe}"],
        ["population", "{pipe}", "--out", "{out}"],
        ["sample", "--n", "3", "--laws", "{pipe}", "--out", "{out}.csv"],
    ],
    ids=["identify-config", "batch-config", "population-results", "sample-laws"],
)
def test_a_named_pipe_as_any_other_input_is_refused_before_any_work(argv, tmp_path, capsys):
    pipe = _fifo(tmp_path / "input.toml")
    (tmp_path / "m.csv").write_text("path\nr.csv\n")
    paths = {"pipe": pipe, "ok": tmp_path / "m.csv", "out": tmp_path / "out"}
    assert main([a.format(**paths) for a in argv]) == 2
    line = _error_line(capsys)
    assert line == (
        f"workbench: error: {pipe}, whole file: this is a named pipe (FIFO), not a regular "
        "file; give a file saved on disk."
    )
    assert not (tmp_path / "out").exists() and not (tmp_path / "out.csv").exists()


@needs_fifo
def test_a_named_pipe_where_the_sidecar_belongs_is_refused_not_ignored(tmp_path, capsys):
    (tmp_path / "walk.csv").write_text("time,grf\n0,700\n0.01,700\n")
    pipe = _fifo(tmp_path / "walk.json")
    assert main(["inspect", str(tmp_path / "walk.csv")]) == 2
    line = _error_line(capsys)
    assert line.startswith(f"workbench: error: {pipe}, whole file: the sidecar of walk.csv: ")
    assert "named pipe" in line


def test_file_problem_names_each_kind_of_path(tmp_path):
    from workbench.records.text_table import FILE_MISSING, SPECIAL_FILES, file_problem

    (tmp_path / "r.csv").write_text("time,grf\n")
    assert file_problem(tmp_path / "r.csv") is None
    assert file_problem(tmp_path / "gone.csv") == FILE_MISSING
    assert file_problem(tmp_path) == "this is a folder, not a file"
    assert file_problem(tmp_path / "r.csv" / "x") == (
        "a part of the path before the file name is a file, not a folder"
    )
    # Only what would hang or never end a read counts as special; folders are the
    # commands' own business (a results folder is one).
    assert file_problem(_loop(tmp_path)) in SPECIAL_FILES
    assert file_problem(tmp_path) not in SPECIAL_FILES
    if hasattr(os, "mkfifo"):
        assert file_problem(_fifo(tmp_path / "p")) in SPECIAL_FILES
