"""Helpers the crossing analyses share: seed ranges, simulating a plan, identifying it in batch.

Imported by ``walker_crossings.py``, ``population_selection.py`` and
``population_calibration.py`` (run as scripts, this folder is on the import path).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pandas as pd

from workbench.population.recovery_design import simulate_recovery_record
from workbench.records.io import save_record


def seed_range(text: str) -> list[int]:
    """Parse ``"0-19"`` (or ``"3"``) into the list of seeds it names, both ends included."""
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def simulate_and_identify(
    plan: pd.DataFrame, folder: Path, sample_rate_hz: float, workers: int
) -> Path:
    """Simulate a plan's records into ``folder`` and identify them with ``workbench batch``.

    The records and ``manifest.csv`` are written once (a rerun finds the manifest and keeps
    them); the batch (default settings: the exact method) resumes where it stopped.

    Returns
    -------
    Path
        The batch's output folder, ``folder/batch``.
    """
    manifest = folder / "manifest.csv"
    if not manifest.exists():
        for row in plan.to_dict(orient="records"):
            save_record(simulate_recovery_record(row, sample_rate_hz), folder / row["path"])
        manifest.write_text("path\n" + "".join(f"{p}\n" for p in plan["path"]))
    batch = folder / "batch"
    args = [sys.executable, "-m", "workbench", "batch", str(manifest), "--out", str(batch)]
    args += ["--workers", str(workers), "--json"]
    if (batch / "batch.json").exists():
        args.append("--resume")
    run = subprocess.run(args, capture_output=True, text=True, check=False)
    if run.returncode not in (0, 4):
        sys.exit(f"workbench batch failed in {folder}: {run.stderr.strip()}")
    return batch
