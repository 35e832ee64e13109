"""Run the notebook session as a notebook would and print what it shows.

Each top-level statement of ``notebook_session.py`` runs in interactive mode, so a bare
expression (``res.params``) prints its value as a notebook cell's last line would. Figures
are drawn off screen. The output on the docs' notebook page comes from::

    python docs/examples/run_session.py
"""

from __future__ import annotations

import ast
import os
import sys
from pathlib import Path

SESSION = Path(__file__).with_name("notebook_session.py")


def run(source: str, filename: str = str(SESSION)) -> dict[str, object]:
    """Execute ``source`` statement by statement in interactive mode; return its namespace."""
    os.environ.setdefault("MPLBACKEND", "Agg")
    namespace: dict[str, object] = {"__name__": "__main__"}
    tree = ast.parse(source, filename)
    for node in tree.body:
        code = compile(ast.Interactive(body=[node]), filename, "single")
        exec(code, namespace)
    return namespace


if __name__ == "__main__":
    import pandas as pd

    pd.set_option("display.width", 100)
    run(SESSION.read_text(encoding="utf-8"))
    sys.exit(0)
