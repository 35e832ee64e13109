"""Steps and pacing that inspect, identify and diagnose report on every embedded record.

Usage::

    python analyses/pacing_agreement.py [--csv pacing_agreement.csv] [--one-step]
                                        [--records NAME,...] [--markdown FILE]

Every record of ``workbench.datasets.names()`` goes through the three commands as a user
runs them, ``python -m workbench inspect|identify|diagnose NAME --json``, each a process of
its own with default settings (the workbench this script imports runs them). From each
JSON: ``steps`` and ``pacing_hz`` (``inspect``: top level; ``identify``: the problem's
pieces and pacing; ``diagnose``: ``baseline``). A command that refuses the record (exit
code 2) is written as refused, with its message.

``diagnose`` runs with ``--no-one-step`` unless ``--one-step`` is given: the one-step-ahead
check identifies the record again with a particle filter and adds nothing to the
baseline's steps and pacing. ``identify`` may take minutes on the long real records, so every
command's result is appended to the CSV as soon as it is known and a run resumes from it
(delete the file to measure again).

Agreement: the three step counts are equal, and the three pacings are equal to the
rounding of ``inspect``'s JSON (4 decimals; ``identify`` rounds to 5). A record that
``inspect`` refuses has no footfall steps (the seed's numerical example is no walk): it
agrees when ``diagnose`` refuses it too and ``identify`` either refuses it or identifies it
as one piece at its stated pacing (``pieces = "whole"`` in the record's own settings), which
counts no steps.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import workbench
from workbench import datasets

COMMANDS = ("inspect", "identify", "diagnose")
FIELDS = ("record", "command", "status", "steps", "pacing_hz", "pieces", "seconds", "message")
#: Pacings agree within the rounding of inspect's JSON (4 decimals) and identify's (5).
PACING_TOLERANCE_HZ = 0.5e-4 + 0.5e-5


def _environment() -> dict[str, str]:
    """Return the command processes' environment: the workbench this script imports."""
    env = dict(os.environ)
    root = str(Path(workbench.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (root, env.get("PYTHONPATH")) if p)
    return env


def run_command(name: str, command: str, one_step: bool) -> dict[str, Any]:
    """Run one command on one embedded record and return its row."""
    args = [sys.executable, "-m", "workbench", command, name, "--json"]
    if command == "diagnose" and not one_step:
        args.append("--no-one-step")
    start = time.perf_counter()
    # An empty working folder: a file named like the record there would win over it.
    with tempfile.TemporaryDirectory() as cwd:
        out = subprocess.run(
            args, capture_output=True, text=True, check=False, cwd=cwd, env=_environment()
        )
    row: dict[str, Any] = {
        "record": name,
        "command": command,
        "seconds": round(time.perf_counter() - start, 1),
    }
    if out.returncode != 0:
        lines = out.stderr.strip().splitlines() or ["(no message)"]
        status = "refused" if out.returncode == 2 else f"failed ({out.returncode})"
        return {
            **row,
            "status": status,
            "steps": "",
            "pacing_hz": "",
            "pieces": "",
            "message": lines[-1],
        }
    obj = json.loads(out.stdout)
    where = obj["baseline"] if command == "diagnose" else obj
    return {
        **row,
        "status": "ok",
        "steps": where["steps"],
        "pacing_hz": where["pacing_hz"],
        # What identify cut the record into; the others always count footfall steps.
        "pieces": obj["settings"]["pieces"] if command == "identify" else "steps",
        "message": "",
    }


def _read(path: Path) -> dict[tuple[str, str], dict[str, str]]:
    if not path.exists():
        return {}
    with path.open(newline="", encoding="utf-8") as fh:
        return {(r["record"], r["command"]): r for r in csv.DictReader(fh)}


def measure(names: list[str], path: Path, one_step: bool) -> dict[tuple[str, str], dict[str, str]]:
    """Run every command missing from the CSV on every record, appending as it goes."""
    done = _read(path)
    for name in names:
        for command in COMMANDS:
            if (name, command) in done:
                continue
            row = run_command(name, command, one_step)
            new = not path.exists()
            with path.open("a", newline="", encoding="utf-8") as fh:
                writer = csv.DictWriter(fh, fieldnames=FIELDS)
                if new:
                    writer.writeheader()
                writer.writerow(row)
            print(
                f"{name} {command}: {row['status']} {row['steps']} {row['pacing_hz']} "
                f"({row['seconds']} s)",
                file=sys.stderr,
                flush=True,
            )
    return _read(path)


def agree(rows: list[dict[str, str]]) -> bool:
    """Whether the three commands report one step count and one pacing (module docstring)."""
    seen, identified, diagnosed = rows
    if seen["status"] == "refused":
        no_steps = identified["status"] == "refused" or identified["pieces"] == "whole"
        return diagnosed["status"] == "refused" and no_steps
    if any(r["status"] != "ok" for r in rows):
        return False
    steps = {int(r["steps"]) for r in rows}
    pacings = [float(r["pacing_hz"]) for r in rows]
    return len(steps) == 1 and max(pacings) - min(pacings) <= PACING_TOLERANCE_HZ


def table(names: list[str], done: dict[tuple[str, str], dict[str, str]]) -> list[str]:
    """Return the markdown table of the module docstring."""
    head = " | ".join(f"{c} steps | {c} pacing [Hz]" for c in COMMANDS)
    lines = [f"| record | {head} | agree |", "|---|" + "---|---|" * len(COMMANDS) + "---|"]
    for name in names:
        rows = [done[(name, c)] for c in COMMANDS]
        cells = []
        for r in rows:
            if r["status"] != "ok":
                cells += [r["status"], "-"]
            elif r["pieces"] == "whole":
                cells += ["one piece", f"{float(r['pacing_hz']):g} (stated)"]
            else:
                # As the JSON gives it: inspect rounds to 4 decimals, identify to 5.
                digits = 4 if r["command"] == "inspect" else 5
                cells += [r["steps"], f"{float(r['pacing_hz']):.{digits}f}"]
        lines.append(f"| {name} | " + " | ".join(cells) + f" | {'yes' if agree(rows) else 'no'} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--csv",
        type=Path,
        default=Path("pacing_agreement.csv"),
        help="results, appended as they come and resumed from",
    )
    ap.add_argument("--records", help="NAME,... (default: every embedded record)")
    ap.add_argument(
        "--one-step",
        action="store_true",
        help="run diagnose with its one-step-ahead check (slower)",
    )
    ap.add_argument("--markdown", type=Path, help="also write the table to this file")
    args = ap.parse_args(argv)
    names = args.records.split(",") if args.records else list(datasets.names())
    done = measure(names, args.csv, args.one_step)
    lines = table(names, done)
    refusals = sorted({r["message"] for r in done.values() if r["status"] != "ok"})
    text = "\n".join([*lines, *("", "Refusals:", *refusals)] if refusals else lines)
    print(text)
    if args.markdown:
        args.markdown.write_text(text + "\n", encoding="utf-8")
    bad = [n for n in names if not agree([done[(n, c)] for c in COMMANDS])]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
