"""The guide pages' worked examples run: every ``python`` code block of a page, in order.

A page's blocks are one script (a later block may use what an earlier one defined), run in
a fresh interpreter in an empty temporary folder (an example may write files there), so that
what the example registers (a method, a format) is gone afterwards and cannot leak into
other tests. A ``text`` block that directly follows a ``python`` block (only blank lines
between) is the output the page shows for it: each of its lines must be printed. Other
``text``, ``bash`` or ``toml`` blocks are not run. To check another page, add its path to
:data:`PAGES`.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: Guide pages whose python blocks are a complete, checked example.
PAGES = ("docs/guide/adding-a-method.md", "docs/guide/adding-a-format.md")

_BLOCK = re.compile(r"^```(\w+)[ \t]*\n(.*?)^```[ \t]*\n?", re.MULTILINE | re.DOTALL)


def code_blocks(text: str) -> list[tuple[str, str, bool]]:
    """Return (language, body, follows a python block directly) of a page's fenced blocks."""
    out: list[tuple[str, str, bool]] = []
    end, last = -1, ""
    for m in _BLOCK.finditer(text):
        direct = last == "python" and not text[end : m.start()].strip()
        out.append((m.group(1), m.group(2), direct))
        end, last = m.end(), m.group(1)
    return out


def python_blocks(text: str) -> list[str]:
    """Return the bodies of a Markdown text's ```python fenced blocks, in order."""
    return [body for lang, body, _ in code_blocks(text) if lang == "python"]


def shown_output(text: str) -> list[str]:
    """Return the non-blank lines of the ``text`` blocks that directly follow python blocks."""
    return [
        line
        for lang, body, direct in code_blocks(text)
        if lang == "text" and direct
        for line in body.splitlines()
        if line.strip()
    ]


def test_blocks_are_told_apart() -> None:
    text = (
        "intro\n```text\nnot output\n```\n```python\na = 1\nprint(a)\n```\n\n```text\n1\n```\n"
        "```bash\nexit 1\n```\n```python\nb = a\n```\nprose\n```text\nnot output\n```\n"
    )
    assert python_blocks(text) == ["a = 1\nprint(a)\n", "b = a\n"]
    assert shown_output(text) == ["1"]


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_the_worked_example_runs_and_prints_what_the_page_shows(page: str, tmp_path: Path) -> None:
    text = (ROOT / page).read_text(encoding="utf-8")
    blocks = python_blocks(text)
    assert blocks, f"{page} has no python code block"
    script = tmp_path / (Path(page).stem.replace("-", "_") + ".py")
    script.write_text("\n\n".join(blocks), encoding="utf-8")
    # The checkout's package first, whatever is installed; the output folder is tmp_path.
    paths = [str(ROOT), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(paths)}
    done = subprocess.run(
        [sys.executable, str(script)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, f"{page}'s example failed:\n{done.stdout}\n{done.stderr}"
    printed = done.stdout.splitlines()
    for line in shown_output(text):
        assert line in printed, f"{page} shows {line!r}, which the example did not print"
