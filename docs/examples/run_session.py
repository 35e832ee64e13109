"""Run the notebook session as a notebook would and print what it shows.

Each top-level statement of ``notebook_session.py`` runs in interactive mode, so a bare
expression (``res.params``) prints its value as a notebook cell's last line would. Figures
are drawn off screen, and pandas shows floats to 4 significant digits so that the output
does not depend on the processor's last digits. The output on the docs' notebook page comes
from, and is checked against, this script::

    python docs/examples/run_session.py --write docs/notebook.md
    python docs/examples/run_session.py --check docs/notebook.md

``--write`` replaces the page's block between the two output markers with a fresh run;
``--check`` exits with status 1 when the block differs from a fresh run (CI runs it).
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import io
import os
import re
import sys
from pathlib import Path

SESSION = Path(__file__).with_name("notebook_session.py")
BEGIN = "<!-- begin: output of docs/examples/run_session.py (do not edit by hand) -->"
END = "<!-- end: output of docs/examples/run_session.py -->"
_BLOCK = re.compile(re.escape(BEGIN) + r"\n.*?" + re.escape(END), re.S)


def _four_digits(x: float) -> str:
    # 4 significant digits, written out (10324 shows as 10320, not 1.032e+04).
    return f"{float(f'{x:.4g}'):g}"


def run(source: str, filename: str = str(SESSION)) -> dict[str, object]:
    """Execute ``source`` statement by statement in interactive mode; return its namespace."""
    import pandas as pd

    os.environ.setdefault("MPLBACKEND", "Agg")
    pd.set_option("display.width", 100)
    pd.set_option("display.float_format", _four_digits)
    namespace: dict[str, object] = {"__name__": "__main__"}
    tree = ast.parse(source, filename)
    for node in tree.body:
        code = compile(ast.Interactive(body=[node]), filename, "single")
        exec(code, namespace)
    return namespace


def session_run() -> tuple[str, dict[str, object]]:
    """Run the session; return its output block (markers included) and its namespace."""
    buffer = io.StringIO()
    with contextlib.redirect_stdout(buffer):
        namespace = run(SESSION.read_text(encoding="utf-8"))
    text = "\n".join(line.rstrip() for line in buffer.getvalue().strip().splitlines())
    return f"{BEGIN}\n```text\n{text}\n```\n{END}", namespace


def session_output() -> str:
    """Return what the session prints, as the page's output block (markers included)."""
    return session_run()[0]


def page_block(page: str) -> str:
    """Return the output block of a page (markers included); raise if it has none."""
    match = _BLOCK.search(page)
    if match is None:
        raise SystemExit(f"the page has no block between {BEGIN!r} and {END!r}")
    return match.group(0)


def main(argv: list[str] | None = None) -> int:
    """Print the session's output block, or write it into a page, or check a page's."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--write", type=Path, metavar="PAGE", help="refresh PAGE's output block")
    group.add_argument("--check", type=Path, metavar="PAGE", help="fail if PAGE's block is stale")
    args = parser.parse_args(argv)
    if args.write is None and args.check is None:
        print(session_output())
        return 0
    page_path = args.write or args.check
    page = page_path.read_text(encoding="utf-8")
    old = page_block(page)
    new = session_output()
    if args.write:
        page_path.write_text(page.replace(old, new), encoding="utf-8")
        return 0
    if old != new:
        import difflib

        diff = difflib.unified_diff(
            old.splitlines(), new.splitlines(), "page", "fresh run", lineterm=""
        )
        print("\n".join(diff))
        print(
            f"{page_path}: the session's output differs from a fresh run; refresh it with "
            f"python docs/examples/run_session.py --write {page_path}",
            file=sys.stderr,
        )
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
