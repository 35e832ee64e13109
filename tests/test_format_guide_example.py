"""The worked example of docs/guide/adding-a-format.md runs, and prints what the page shows.

The page's ``python`` blocks, in order, are one script; it runs in a fresh interpreter in
an empty temporary folder (it writes its record files there), importing the package from
this repository. Every line of the page's ``text`` blocks must be in its output.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "guide" / "adding-a-format.md"


def blocks(language: str) -> list[str]:
    """The page's fenced code blocks of one language, in order."""
    text = PAGE.read_text(encoding="utf-8")
    return re.findall(rf"^```{language}\n(.*?)^```$", text, re.S | re.M)


def test_the_guide_page_example_runs_and_prints_what_the_page_shows(tmp_path: Path) -> None:
    script = "\n".join(blocks("python"))
    assert "@register_format" in script and "load_record(" in script
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    run = subprocess.run(
        [sys.executable, "-c", script],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "walk.belts").is_file()
    shown = [line for block in blocks("text") for line in block.splitlines() if line.strip()]
    assert shown
    for line in shown:
        assert line in run.stdout.splitlines(), line
