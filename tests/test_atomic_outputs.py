"""A full disk ends in one sentence naming the file, and leaves nothing half-written.

The disk is filled in-process by making the writers' ``open`` fail with ENOSPC; where this
machine lets the test mount a small tmpfs, a real full disk is tried too (skipped elsewhere).
"""

import builtins
import errno
import json
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from workbench import fileutil
from workbench.cli import main
from workbench.errors import OutputError
from workbench.inference.crosscheck.results import CrosscheckResult, _netcdf_bytes


def _fill_disk_after(monkeypatch, files_written: int) -> None:
    """Let ``files_written`` files be written through the atomic writers, then ENOSPC."""
    real_open = builtins.open
    count = {"n": 0}

    class Full:
        def __init__(self, handle):
            self.handle = handle

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.handle.close()

        def write(self, data):
            raise OSError(errno.ENOSPC, "No space left on device")

    def fake_open(file, mode="r", *args, **kwargs):
        handle = real_open(file, mode, *args, **kwargs)
        if "w" not in mode:
            return handle
        count["n"] += 1
        return handle if count["n"] <= files_written else Full(handle)

    monkeypatch.setattr(fileutil, "open", fake_open, raising=False)


def _leftovers(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


@pytest.mark.parametrize("suffix", [".csv", ".mot"])
def test_simulate_on_a_full_disk_leaves_no_sidecar_without_its_record(
    suffix, tmp_path, monkeypatch, capsys
):
    _fill_disk_after(monkeypatch, files_written=1)  # the sidecar fits, the record does not
    out = tmp_path / f"sim{suffix}"
    assert main(["simulate", "--out", str(out), "--duration", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"workbench: error: could not write {out} (the disk is full) and left no "
        "half-written file; free space on that disk or write to another folder"
    ]
    assert _leftovers(tmp_path) == []  # no sim.json, no truth, no temporary file


def test_simulate_writes_the_record_its_sidecar_and_its_truth(tmp_path, capsys):
    out = tmp_path / "sim.csv"
    assert main(["simulate", "--out", str(out), "--duration", "5", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert _leftovers(tmp_path) == ["sim.csv", "sim.json", "sim.truth.json"]
    truth = json.loads((tmp_path / "sim.truth.json").read_text())
    assert truth["stiffness_n_per_m"] == result["stiffness_n_per_m"]
    assert json.loads((tmp_path / "sim.json").read_text())["truth"] == truth


def test_a_group_of_files_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
    (tmp_path / "a.json").write_text("old sidecar\n")
    _fill_disk_after(monkeypatch, files_written=1)
    files = {tmp_path / "a.json": "new sidecar\n", tmp_path / "a.csv": "new data\n"}
    with pytest.raises(OutputError, match=r"a\.csv \(the disk is full\)") as caught:
        fileutil.atomic_write_texts(files)
    assert caught.value.target == str(tmp_path / "a.csv")
    assert _leftovers(tmp_path) == ["a.json"]
    assert (tmp_path / "a.json").read_text() == "old sidecar\n"  # not replaced


def _inference_data():
    import arviz as az

    rng = np.random.default_rng(3)
    return az.from_dict(
        posterior={"damping_ns_per_m": rng.normal(size=(2, 40, 3))},
        sample_stats={"lp": rng.normal(size=(2, 40))},
        observed_data={"y": rng.normal(size=25)},
        attrs={"record": "walk"},
    )


def test_the_netcdf_built_in_memory_reads_back_as_arviz_writes_it(tmp_path):
    import arviz as az
    import h5py

    idata = _inference_data()
    data = _netcdf_bytes(idata)
    if data is None:
        pytest.skip("this xarray has no DataTree; ArviZ writes the file itself")
    (tmp_path / "memory.nc").write_bytes(data)
    idata.to_netcdf(str(tmp_path / "arviz.nc"))
    ours, theirs = az.from_netcdf(tmp_path / "memory.nc"), az.from_netcdf(tmp_path / "arviz.nc")
    assert ours.groups() == theirs.groups() == idata.groups()
    for group in idata.groups():
        assert getattr(ours, group).identical(getattr(theirs, group)), group
    assert ours.attrs == theirs.attrs == {"record": "walk"}
    with h5py.File(tmp_path / "memory.nc") as h5:  # compressed as ArviZ compresses
        assert h5["posterior/damping_ns_per_m"].compression == "gzip"


def test_a_crosscheck_netcdf_on_a_full_disk_is_one_sentence(tmp_path, monkeypatch):
    _fill_disk_after(monkeypatch, files_written=0)
    target = tmp_path / "walk_crosscheck_rbpf.nc"
    holder = SimpleNamespace(inference_data=_inference_data())
    with pytest.raises(OutputError, match="the disk is full") as caught:
        CrosscheckResult.to_netcdf(holder, target)  # type: ignore[arg-type]
    assert caught.value.target == str(target)
    assert _leftovers(tmp_path) == []


def _mount_tmpfs(folder: Path, size: str) -> bool:
    folder.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(folder)],
        capture_output=True,
        check=False,
    )
    return mounted.returncode == 0


@pytest.fixture
def small_disks(tmp_path):
    """A 64 kB and a 1.2 MB tmpfs, where this machine lets the test mount them (root)."""
    tiny, small = tmp_path / "tiny", tmp_path / "small"
    if not _mount_tmpfs(tiny, "64k"):
        pytest.skip("mounting a tmpfs is not permitted here")
    try:
        if not _mount_tmpfs(small, "1200k"):
            pytest.skip("mounting a second tmpfs is not permitted here")
        try:
            yield tiny, small
        finally:
            subprocess.run(["umount", str(small)], check=False)
    finally:
        subprocess.run(["umount", str(tiny)], check=False)


def _simulate(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "workbench", "simulate", "--out", str(out), *extra],
        capture_output=True,
        text=True,
        check=False,
    )


def test_a_real_full_disk_ends_in_one_sentence(small_disks):
    tiny, small = small_disks
    # A nearly full disk is refused before the computation, whose result would be lost.
    run = _simulate(tiny / "sim.csv")
    assert run.returncode == 2, run.stderr
    (line,) = run.stderr.strip().splitlines()
    assert line.startswith(f"workbench: error: --out {tiny / 'sim.csv'}: its disk has only ")
    assert line.endswith("free space there or choose a folder on another disk")
    # A record larger than the free space (300 s at the default rate: about 1.4 MB on a
    # 1.2 MB disk) meets the full disk while being written.
    run = _simulate(small / "sim.csv", "--duration", "300")
    assert run.returncode == 2, run.stderr
    assert run.stderr.strip().splitlines() == [
        f"workbench: error: could not write {small / 'sim.csv'} (the disk is full) and "
        "left no half-written file; free space on that disk or write to another folder"
    ]
    assert _leftovers(tiny) == [] and _leftovers(small) == []


def test_an_unreadable_input_is_not_blamed_on_out(tmp_path, capsys):
    (tmp_path / "a.toml").symlink_to(tmp_path / "b.toml")
    (tmp_path / "b.toml").symlink_to(tmp_path / "a.toml")
    code = main(["batch", "m.csv", "--config", str(tmp_path / "a.toml"), "--out", str(tmp_path)])
    assert code == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line == (
        f"workbench: error: {tmp_path / 'a.toml'}, whole file: the path is a loop of symbolic "
        "links that point at each other; point the link at the file itself."
    )


def test_a_system_error_says_whether_a_file_was_read_or_written(tmp_path):
    # What reaches the command line's last resort: an OSError from a reader or from making
    # an output folder. Only a write may be blamed on --out.
    from argparse import Namespace

    from workbench.cli.main import _file_error_sentence

    out = tmp_path / "out"
    (tmp_path / "settings.toml").write_text("")
    args = Namespace(out=str(out))
    loop = OSError(errno.ELOOP, "Too many levels of symbolic links", str(tmp_path / "x.toml"))
    assert _file_error_sentence(args, loop) == (
        f"could not read {tmp_path / 'x.toml'} (it is a loop of symbolic links that point at "
        "each other); check the path"
    )
    inside = OSError(errno.EACCES, "Permission denied", str(out / "figures"))
    assert _file_error_sentence(args, inside) == (
        f"could not write {out / 'figures'} (permission denied); free space there or choose a "
        "folder you can write to with --out"
    )
    full = OSError(errno.ENOSPC, "No space left on device", str(out / ".r.csv.abc.tmp"))
    assert _file_error_sentence(args, full).startswith(
        f"could not write {out / 'r.csv'} (the disk is full)"
    )
    existing_input = OSError(errno.EACCES, "Permission denied", str(tmp_path / "settings.toml"))
    assert _file_error_sentence(Namespace(out=str(tmp_path)), existing_input).startswith(
        f"could not read {tmp_path / 'settings.toml'} (permission denied)"
    )


def test_every_output_goes_through_the_atomic_writer():
    # A guard on the source: library writers may only write to the temporary path that
    # workbench.fileutil hands them (or build text/bytes in memory); anything else would
    # be a file a full disk or a kill could leave half-written.
    import re

    root = Path(fileutil.__file__).parent
    writes = re.compile(r"\.(to_csv|savefig|to_netcdf|to_parquet|to_excel|tofile)\(\s*([^,)]*)")
    direct = re.compile(
        r"\.write_text\(|\.write_bytes\(|np\.save|json\.dump\(|open\([^)]*[\"'][wax]b?[\"']"
    )
    # The workbench's own result writers, atomic themselves (tested above and in identify).
    own = re.compile(r"result\.to_netcdf\(")
    offending = []
    for path in sorted(root.rglob("*.py")):
        if path.name == "fileutil.py":
            continue
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            where = f"{path.relative_to(root)}:{number}"
            if direct.search(line):
                offending.append(where)
            for match in writes.finditer(line):
                first = match.group(2).strip()
                if own.search(line) or first in ("tmp", "str(tmp", "None", "") or "=" in first:
                    continue
                offending.append(where)
    assert offending == []


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes here")
def test_a_device_or_pipe_as_out_is_refused_not_replaced(tmp_path, capsys):
    import stat

    pipe = tmp_path / "sim.csv"
    os.mkfifo(pipe)
    # The library: renaming over it would put a regular file in its place.
    with pytest.raises(OutputError, match=r"sim\.csv \(it is a device, a pipe or a socket"):
        fileutil.atomic_write_text(pipe, "x\n")
    # The command line: refused before any work, in one sentence naming --out.
    assert main(["simulate", "--out", str(pipe)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"workbench: error: --out {pipe}: this is a device, a pipe or a socket, not a file or "
        "a folder; give the name of a file or folder to write"
    ]
    assert stat.S_ISFIFO(os.lstat(pipe).st_mode)
    assert _leftovers(tmp_path) == ["sim.csv"]


@pytest.mark.parametrize("as_json", [True, False])
def test_a_result_whose_files_cannot_be_written_is_still_printed(
    as_json, tmp_path, monkeypatch, capsys
):
    # The identification ran; only its --out files fail. The result must reach the user
    # (one JSON object carrying the error too, or the text summary), then exit 2.
    from workbench.inference.core.results import IdentificationResult

    def full(self, path):
        raise OutputError(path, OSError(errno.ENOSPC, "No space left on device"))

    monkeypatch.setattr(IdentificationResult, "to_netcdf", full)
    out = tmp_path / "out"
    argv = ["identify", "seed_numerical_example", "--allow-negative-force", "--out", str(out)]
    code = main([*argv, "--json"] if as_json else argv)
    captured = capsys.readouterr()
    assert code == 2
    assert "the disk is full" in captured.err
    if as_json:
        payload = json.loads(captured.out)  # exactly one JSON object on stdout
        assert "the disk is full" in payload["error"]
        assert "stiffness_n_per_m" in payload and "identifiability" in payload
        assert "netcdf" not in payload and "report" not in payload
    else:
        assert "SMD identification" in captured.out
        assert "report:" not in captured.out
