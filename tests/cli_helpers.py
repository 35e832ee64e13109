"""Running the command line in-process in tests: its output, and a refusal's one sentence."""

from __future__ import annotations

from typing import Any

from workbench.cli import main


def run_cli(argv: list[Any], capsys: Any) -> tuple[int, str, str]:
    """Run ``workbench ARGV`` in-process; return the exit code, stdout and stderr."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def refused(argv: list[Any], capsys: Any) -> str:
    """Run a command that must be refused: exit 2, one sentence, no traceback."""
    code, _, err = run_cli(argv, capsys)
    assert code == 2, err
    assert "Traceback" not in err and "internal error" not in err
    assert len(err.strip().splitlines()) == 1, err
    return err


def never(*_: Any, **__: Any) -> None:
    """Stand in for a computation that a refusal must stop before."""
    raise AssertionError("the computation started")
