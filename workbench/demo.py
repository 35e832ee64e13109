"""``workbench demo``: the main job on the embedded default data, ending in a report.

The chain, on the embedded real records (treadmill and insole) and the small synthetic set:

1. inspection: every record validated, preprocessed and split into footfall steps (GRF with
   footfalls, COM response, spectrum with pacing harmonics, instantaneous pacing);
2. model criticism: the compare-locate-explain-extend-re-score loop on the whole treadmill
   record (``workbench diagnose`` / ``compare``): the error its smooth force shape leaves
   gathers at the heel strikes, a heel impact is called and added, then a small left/right
   difference beyond it, and the held-out error falls (criticism fits regressions, not a
   filter, so the whole trial is cheap);
3. individual identification, as the seed's section 5.3: the embedded deck walk of the
   seed's individual identified (C and K converging as more of the record is used, the
   biomechanical force, its load factors, the identifiability sentence) and the real
   treadmill stretch under the default and the seed-faithful settings side by side;
4. sensitivity: a small study of how the filter's settings move the identified parameters on
   a simulated record with known truth;
5. population: a cohort of walkers crossing a lively footbridge several times each (with
   human-structure interaction) and steady stretches of the two real records, identified
   in one batch; the hierarchical laws fitted to every usable record's posterior beside the
   two-stage least squares, the walkers' own fits, and the Table-2-style report
   (:mod:`workbench.demo_population`); a small rigid-floor recovery says what rigid floors
   cannot give.

The real stretches (the first steady-pacing plateau of the treadmill record, the first
30 s of the insole record) keep the demo to minutes: whole records take several minutes
each (``workbench identify`` does them; ``analyses/individual.py`` does every plateau).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd
from tqdm import tqdm

from workbench.datasets import EMBEDDED, embedded_path, synthetic_paths
from workbench.fileutil import atomic_write_json, atomic_write_text
from workbench.records.inspection import Inspection, inspect_record
from workbench.records.io import load_record
from workbench.records.plateaus import find_pacing_plateaus
from workbench.records.record import Record
from workbench.reporting.document import Report, Section, Table
from workbench.reporting.inspection_report import inspection_section, inspection_summary_table

__all__ = ["run_demo", "warning_bullets"]


Job = tuple[str, str, Path, float | None, str, str]

#: Longest stretch of a real record the demo identifies [s].
REAL_STRETCH_S = 30.0
#: Records of the demo's recovery (the smallest design: one per metronome rate and a half).
RECOVERY_RECORDS = 12


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


def warning_bullets(inspected: list[tuple[str, Inspection]]) -> list[str]:
    """List every record's warnings, each under its record's label once.

    Inspection warnings often start with the record's name already ("treadmill: ..."); that
    name is dropped so the label is not repeated ("treadmill: treadmill: ...").

    Parameters
    ----------
    inspected : list of (str, Inspection)
        Label and inspection of each record.

    Returns
    -------
    list of str
        ``"label: warning"`` per warning, in record order.
    """
    bullets = []
    for label, insp in inspected:
        names = {label, insp.record.name, insp.record.source}
        for warning in insp.warnings:
            for name in names:
                if name and warning.startswith(f"{name}: "):
                    warning = warning[len(name) + 2 :]
                    break
            bullets.append(f"{label}: {warning}")
    return bullets


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
            "trapezoidal integration with drift control) and split into footfall steps; then "
            "the model is criticised on a real record, one walker is identified end to end "
            "(on a vibrating deck, and the real treadmill under two settings), the "
            "sensitivity of the identification to its settings is measured, and a population "
            "of records is identified in batch and summarised in the Table-2-style report "
            "(population/index.html)."
        ),
    )
    summary = report.add(Section("Summary"))
    inspected: list[tuple[str, Inspection]] = []
    sections: list[Section] = []
    jobs = _jobs()
    stages = tqdm(total=len(jobs) + 4, desc="demo", unit="stage", disable=not progress)
    records: dict[str, tuple[Record, Inspection]] = {}
    for key, label, path, mass, attribution, display in jobs:
        record = load_record(path, mass_kg=mass, subject=label).replace(source=display)
        insp = inspect_record(record)
        inspected.append((label, insp))
        records[key] = (record, insp)
        sections.append(inspection_section(insp, out_dir, key, attribution=attribution))
        stages.update()
    summary.table(inspection_summary_table(inspected))
    summary.bullets(warning_bullets(inspected))
    for sec in sections:
        report.add(sec)

    # Real stretches: the treadmill's first steady plateau, the insole's first seconds.
    stretches = _real_stretches(records)
    from workbench.reporting.criticism import criticism_demo_section

    # The whole trial, not the steady stretch: every step is evidence, and the baseline
    # follows the trial's speed changes (its pace block), so they are not called as effects.
    report.add(criticism_demo_section(records["treadmill"][0], out_dir, seed))
    stages.update()
    from workbench.reporting.individual import individual_demo_section

    individual, individual_json = individual_demo_section(out_dir, seed, stretches["treadmill"])
    report.add(individual)
    stages.update()
    from workbench.reporting.sensitivity import sensitivity_demo_section

    report.add(sensitivity_demo_section(out_dir, seed))
    stages.update()
    from workbench.demo_population import footbridge_population_demo

    manifest = _write_stretches(stretches, out_dir / "population" / "real_stretches")
    recovery = _recovery(out_dir / "population" / "recovery", seed)
    population = footbridge_population_demo(
        out_dir / "population", seed, real_manifest=manifest, recovery=[recovery]
    )
    stages.update()
    stages.close()
    pop = report.add(Section("Population laws and Table 2"))
    pop.paragraph(
        f"{population['records']} records identified in one batch: walkers of a cohort "
        "crossing a lively footbridge several times each, and steady stretches of the two "
        "real rigid-floor records. "
        + (
            f"The hierarchical laws use {population['hierarchical_records_used']} records' "
            f"posteriors ({population['walkers']} walkers; "
            f"{population['records_left_out']} left out, with their reasons in the population "
            "report)"
            if population["hierarchical_records_used"]
            else "No hierarchical laws could be fitted (the population report says why)"
        )
        + "; the two-stage least squares uses the point "
        f"estimates of {population['records_used']} records graded identified. The walkers "
        "were drawn from the seed's laws, so these rows check the workbench, they are not a "
        "finding; the full report with the walkers' own panels, figures like the seed's "
        "figs. 11-14 and the tables as CSV: population/index.html."
    )
    table2 = pd.read_csv(out_dir / "population" / "table2.csv", dtype=str).fillna("")
    pop.table(
        Table(
            list(table2.columns),
            table2.to_numpy().tolist(),
            caption="Seed Table 2 beside the laws fitted here",
        )
    )
    html_path = report.write(out_dir)

    lines = [
        f"{'record':<32}{'pacing Hz':>10}{'steps':>7}{'balance':>9}  warnings",
    ]
    for label, insp in inspected:
        lines.append(
            f"{label:<32}{insp.pacing.pacing_hz:>10.3f}{insp.steps.n_steps:>7d}"
            f"{insp.static_balance_raw:>9.3f}  {len(insp.warnings)}"
        )
    lines.append(population["text"])
    lines.append(f"Report written to {html_path} (and report.md beside it).")
    lines.append(f"Table-2-style population report: {population['report']}")
    return {
        "report": str(html_path),
        "population_report": str(population["report"]),
        "seed": seed,
        "records": [dict(insp.to_json(), label=label) for label, insp in inspected],
        "population": {
            k: population[k]
            for k in (
                "records",
                "records_used",
                "records_excluded",
                "hierarchical_records_used",
                "records_left_out",
                "walkers",
                "failed",
            )
        },
        "individual": individual_json,
        "recovery": {k: recovery[k] for k in ("truth", "verdict", "records")},
        "text": "\n".join(lines),
    }


def _recovery(folder: Path, seed: int) -> dict[str, Any]:
    """Run a small recovery with the real records' settings: rigid floors, no pacing law.

    Can the default pipeline tell a pacing-dependent law from a constant one on rigid-floor
    walks? :data:`RECOVERY_RECORDS` realistic walks of a population whose f_n and zeta do not
    depend on pacing, identified as the demo's real records are; ``workbench recovery`` and
    ``analyses/recovery_table.py`` do it at full size (docs/validation/recovery.md).
    """
    from workbench.inference.pipeline import IdentifySettings
    from workbench.population.recovery import RecoveryDesign, run_recovery, truth_laws

    design = RecoveryDesign(
        truth_laws("constant"), "rigid", RECOVERY_RECORDS, ranges={"duration_s": (12.0, 14.0)}
    )
    settings = IdentifySettings().replace(seed=seed)
    # Like the population batches, a demo run again in its folder continues what is there.
    resume = (folder / "recovery_design.json").is_file()
    return run_recovery(folder, design, settings, seed=seed, workers=2, resume=resume).to_json()


def _real_stretches(records: dict[str, tuple[Record, Inspection]]) -> dict[str, Record]:
    """Steady stretches of the real records, at most :data:`REAL_STRETCH_S` long."""
    out: dict[str, Record] = {}
    record, insp = records["treadmill"]
    plateaus = find_pacing_plateaus(insp.steps)
    if plateaus:
        plateau = plateaus[0]
        half_step = 0.5 / plateau.pacing_hz
        start = plateau.start_s - half_step
        stop = min(plateau.stop_s + half_step, start + REAL_STRETCH_S)
    else:  # no steady stretch: the record's start
        start, stop = float(record.time_s[0]), float(record.time_s[0]) + REAL_STRETCH_S
    out["treadmill"] = record.slice(start, stop)
    record, _ = records["insole"]
    t0 = float(record.time_s[0])
    out["insole"] = record.slice(t0, t0 + REAL_STRETCH_S)
    return out


def _write_stretches(stretches: dict[str, Record], folder: Path) -> Path:
    """Write the stretches as CSV records with JSON sidecars and return their manifest."""
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for key, rec in stretches.items():
        path = folder / f"{key}.csv"
        frame = pd.DataFrame({"time": rec.time_s, "grf": rec.grf_n})
        atomic_write_text(path, frame.to_csv(index=False))
        atomic_write_json(
            path.with_suffix(".json"),
            {"mass_kg": rec.require_mass(), "subject": key, "notes": EMBEDDED[key].attribution},
        )
        rows.append(f"{path.name},{rec.require_mass()}")
    manifest = folder / "manifest.csv"
    atomic_write_text(manifest, "path,mass_kg\n" + "\n".join(rows) + "\n")
    return manifest
