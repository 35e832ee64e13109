"""The embedded records' names are listed where a user looks first.

In ``workbench/datasets/README.md``, and in the error for a name that is not one of them,
from the Python API and from the command line.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import workbench as wb
from workbench.cli import main
from workbench.errors import InputError, UsageError

README = Path(wb.datasets.__file__).with_name("README.md")


def test_the_datasets_readme_lists_every_name_with_its_file():
    text = README.read_text(encoding="utf-8")
    rows = re.findall(r"^\| `(\w+)` \| `([\w./]+)` \|", text, flags=re.MULTILINE)
    assert sorted(name for name, _ in rows) == sorted(wb.datasets.names())
    for name, file in rows:
        path = wb.datasets.dataset_path(name)
        assert path is not None and path.as_posix().endswith(file), (name, file)


def test_an_unknown_name_in_python_lists_the_names():
    with pytest.raises(UsageError) as err:
        wb.datasets.load("nope")
    msg = str(err.value)
    assert "'nope'" in msg
    for name in wb.datasets.names():
        assert name in msg


@pytest.mark.parametrize("command", ["identify", "inspect", "crosscheck"])
def test_an_unknown_name_on_the_command_line_lists_the_names(
    command, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)  # no file called "nope" here
    code = main([command, "nope"])
    out, err = capsys.readouterr()
    assert code == 2 and out == "" and "Traceback" not in err
    assert err.startswith("workbench: error: nope, record: there is no file and no embedded record")
    assert err.count("\n") == 1  # one sentence
    for name in wb.datasets.names():
        assert name in err


def test_a_missing_path_keeps_the_file_sentence(tmp_path, monkeypatch, capsys):
    """A path (folder or extension) is a file the user meant: no list of names."""
    monkeypatch.chdir(tmp_path)
    assert main(["identify", "walk.csv"]) == 2
    err = capsys.readouterr().err
    assert "walk.csv, whole file: the file does not exist" in err
    assert "treadmill" not in err
    with pytest.raises(InputError, match="no embedded record"):
        wb.datasets.require_record("nope")
    wb.datasets.require_record("treadmill")  # a name passes
    (tmp_path / "nope").write_text("")
    wb.datasets.require_record("nope")  # a file of that name passes (the loader reads it)
