"""``workbench demo``: the main job on the embedded default data, ending in a report.

At this stage the demo loads the embedded real records (treadmill and insole) and the small
synthetic set, validates, preprocesses and segments them, and writes a report with a summary
table and, per record, the GRF with footfalls, the COM response, the spectrum with pacing
harmonics and the instantaneous pacing. Later stages append their own sections.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tqdm import tqdm

from workbench.datasets import EMBEDDED, embedded_path, synthetic_paths
from workbench.records.inspection import Inspection, inspect_record
from workbench.records.io import load_record
from workbench.reporting.document import Report, Section
from workbench.reporting.inspection_report import inspection_section, inspection_summary_table

__all__ = ["run_demo"]


Job = tuple[str, str, Path, float | None, str, str]


def _jobs() -> list[Job]:
    """(key, label, path, mass or None for the sidecar's, attribution, display name) per record.

    The display name is the path inside the package, so reports never show where the
    package happens to be installed.
    """
    jobs: list[Job] = [
        (
            key,
            key,
            embedded_path(key),
            item.mass_kg,
            item.attribution,
            f"workbench/datasets/{item.filename}",
        )
        for key, item in EMBEDDED.items()
    ]
    for path in synthetic_paths():
        jobs.append(
            (
                f"synthetic_{path.stem}",
                f"synthetic {path.stem}",
                path,
                None,
                "simulated by the workbench (truth in the JSON sidecar)",
                f"workbench/datasets/synthetic/{path.name}",
            )
        )
    return jobs


def run_demo(
    out_dir: str | Path = "reports/demo", *, seed: int = 20261122, progress: bool = True
) -> dict[str, Any]:
    """Run the demo and write its report.

    Parameters
    ----------
    out_dir : path-like
        Report folder (``index.html``, ``report.md``, ``figures/``).
    seed : int
        Seed for every random choice of the later stages (inspection itself is deterministic).
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    dict
        ``report`` (path of the HTML page), ``records`` (the inspect JSON of each record),
        ``seed`` and ``text`` (a human summary).
    """
    out_dir = Path(out_dir)
    report = Report(
        "Pedestrian SMD workbench: demo",
        intro=(
            "The workbench run end to end on its embedded data: two real walking records "
            "(an instrumented treadmill with speed changes and force-sensing insoles with a "
            "known calibration error) and a small seeded synthetic set. Each record is "
            "validated, turned into a COM response (acceleration from GRF, zero-phase high-pass, "
            "trapezoidal integration with drift control) and split into footfall steps."
        ),
    )
    summary = report.add(Section("Summary"))
    inspected: list[tuple[str, Inspection]] = []
    sections: list[Section] = []
    jobs = _jobs()
    for key, label, path, mass, attribution, display in tqdm(
        jobs, desc="demo", unit="record", disable=not progress
    ):
        record = load_record(path, mass_kg=mass, subject=label).replace(source=display)
        insp = inspect_record(record)
        inspected.append((label, insp))
        sections.append(inspection_section(insp, out_dir, key, attribution=attribution))
    summary.table(inspection_summary_table(inspected))
    summary.bullets([f"{label}: {w}" for label, insp in inspected for w in insp.warnings])
    for sec in sections:
        report.add(sec)
    html_path = report.write(out_dir)

    lines = [
        f"{'record':<32}{'pacing Hz':>10}{'steps':>7}{'balance':>9}  warnings",
    ]
    for label, insp in inspected:
        lines.append(
            f"{label:<32}{insp.pacing.pacing_hz:>10.3f}{insp.steps.n_steps:>7d}"
            f"{insp.static_balance_raw:>9.3f}  {len(insp.warnings)}"
        )
    lines.append(f"Report written to {html_path} (and report.md beside it).")
    return {
        "report": str(html_path),
        "seed": seed,
        "records": [dict(insp.to_json(), label=label) for label, insp in inspected],
        "text": "\n".join(lines),
    }
