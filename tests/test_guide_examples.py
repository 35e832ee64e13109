"""The guide pages' worked examples run: every ``python`` code block of a page, in order.

A page's blocks are one script (a later block may use what an earlier one defined), run in
a fresh interpreter so that what the example registers (a method, a format) is gone
afterwards and cannot leak into other tests. Blocks fenced as ``text``, ``bash`` or ``toml``
are not run. To check another page, add its path to :data:`PAGES`.
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
PAGES = ("docs/guide/adding-a-method.md",)

_BLOCK = re.compile(r"^```python[ \t]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)


def python_blocks(text: str) -> list[str]:
    """Return the bodies of a Markdown text's ```python fenced blocks, in order."""
    return [m.group(1) for m in _BLOCK.finditer(text)]


def test_python_blocks_are_found_and_nothing_else() -> None:
    text = "intro\n```python\na = 1\n```\n```bash\nexit 1\n```\n```python\nb = a\n```\n"
    assert python_blocks(text) == ["a = 1\n", "b = a\n"]


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_the_worked_example_runs(page: str, tmp_path: Path) -> None:
    blocks = python_blocks((ROOT / page).read_text(encoding="utf-8"))
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
