"""The demo's population stage: walkers crossing a lively footbridge, both fits, Table 2.

A population law needs records whose C and K are identified, and a rigid floor cannot give
them (the demo's recovery shows it); walkers crossing a lively footbridge can, where the
deck moves away from their gait's harmonics. So the demo's Table 2 comes from a cohort of
walkers who cross the lively span of the design notes several times each, in a stream that
keeps the deck moving (:func:`~workbench.hsi.cohort_study.footbridge_cohort_records`),
together with the steady stretches of the two real rigid-floor records. Every record is
identified in one batch; the two-stage least-squares laws (:mod:`workbench.population.fit`)
and the hierarchical laws fitted to every usable record's posterior
(:mod:`workbench.population.batch_hierarchy`) are reported side by side with the walkers'
own fits (:mod:`workbench.population.walker`) and the records left out with their reasons.

The walkers are simulated from the seed's laws, so the Table-2 rows of this study are a
check that the workbench recovers a known law from footbridge crossings, not a finding about
people; the report says which of the generating law's parameters each fit's intervals hold.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from workbench.fileutil import atomic_write_json, atomic_write_text

__all__ = ["COHORT_CROSSINGS", "COHORT_WALKERS", "footbridge_population_demo"]

#: Walkers of the demo's cohort ...
COHORT_WALKERS = 8
#: ... and the stream windows they cross the footbridge in.
COHORT_CROSSINGS = 8


def _combined_manifest(folder: Path, footbridge: Path, real: Path | None) -> Path:
    """One manifest for the footbridge records and the real stretches (paths relative)."""
    frames = []
    for manifest in (footbridge, real):
        if manifest is None:
            continue
        frame = pd.read_csv(manifest)
        frame["path"] = [
            str((manifest.parent / p).relative_to(folder)).replace("\\", "/") for p in frame["path"]
        ]
        if "subject" not in frame:
            frame["subject"] = [Path(p).stem for p in frame["path"]]
        frames.append(frame[["path", "mass_kg", "subject"]])
    path = folder / "manifest.csv"
    text = pd.concat(frames, ignore_index=True).to_csv(index=False, lineterminator="\n")
    atomic_write_text(path, text)
    return path


def _truth_notes(hierarchical: Any, fit: Any) -> list[str]:
    """Say which of the generating laws' parameters each fit's 95 % intervals hold."""
    from workbench.population.fit import LAW_COLUMNS
    from workbench.population.laws import PopulationLaws

    truth = PopulationLaws()
    words = {"natural_frequency_hz": "natural frequency", "damping_ratio": "damping ratio"}
    held: dict[str, list[str]] = {"hierarchical": [], "two-stage": []}
    missed: dict[str, list[str]] = {"hierarchical": [], "two-stage": []}
    ci = hierarchical.conf_int(0.05) if hierarchical is not None else None
    ols = fit.population_json["laws"]
    for law in LAW_COLUMNS:
        true = getattr(truth, law)
        for part, value in (("slope", true.slope), ("intercept", true.intercept)):
            name = f"{words.get(law, law.upper())} {part}"
            if ci is not None:
                lo, hi = ci.loc[f"{law}.{part}", ["lower", "upper"]]
                (held if lo <= value <= hi else missed)["hierarchical"].append(name)
            if law in ols:
                lo, hi = ols[law][f"{part}_ci"]
                (held if lo <= value <= hi else missed)["two-stage"].append(name)
    notes = []
    for which in ("hierarchical", "two-stage"):
        if which == "hierarchical" and ci is None:
            continue
        total = len(held[which]) + len(missed[which])
        line = (
            f"The {which} fit's 95 % intervals hold {len(held[which])} of the {total} slopes "
            "and intercepts of the laws the walkers were drawn from"
        )
        notes.append(line + (f"; they miss {', '.join(missed[which])}." if missed[which] else "."))
    return notes


def footbridge_population_demo(
    out_dir: str | Path,
    seed: int,
    *,
    real_manifest: str | Path | None = None,
    recovery: list[dict[str, Any]] | None = None,
    workers: int = 2,
    progress: bool = False,
) -> dict[str, Any]:
    """Run the demo's population stage (module docstring) and write its report.

    Parameters
    ----------
    out_dir : path-like
        Output folder: ``footbridge/`` (the records and their truth), ``manifest.csv``,
        ``batch/``, ``hierarchical.json`` and the report (``index.html``, ``report.md``).
    seed : int
        Fixes the cohort, its crossings, every identification and the samplers.
    real_manifest : path-like, optional
        Manifest of real records identified beside the footbridge records.
    recovery : list of dict, optional
        Recovery results for the report's conclusions (``RecoveryResult.to_json()``).
    workers : int
        Local worker processes of the batch.
    progress : bool
        Show the batch's progress bar.

    Returns
    -------
    dict
        Counts, the laws of both fits, the report's files and one line of text.
    """
    from workbench.hsi.cohort_study import footbridge_cohort_records
    from workbench.inference.pipeline import IdentifySettings
    from workbench.population.batch import run_batch
    from workbench.population.batch_hierarchy import hierarchical_laws
    from workbench.population.fit import fit_population
    from workbench.population.walker import fit_walkers
    from workbench.reporting.population import population_report

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = footbridge_cohort_records(
        out / "footbridge", walkers=COHORT_WALKERS, crossings=COHORT_CROSSINGS, seed=seed
    )
    if written.manifest is None:  # pragma: no cover - the stream always puts walkers on it
        raise RuntimeError("the footbridge study wrote no record; nothing to fit")
    manifest = _combined_manifest(
        out, written.manifest, None if real_manifest is None else Path(real_manifest)
    )
    batch = out / "batch"
    summary = run_batch(
        manifest,
        batch,
        settings=IdentifySettings.from_flat(seed=seed),
        workers=workers,
        resume=(batch / "batch.json").exists(),
        progress=progress,
    )
    results = pd.read_csv(batch / "results.csv")
    fit = fit_population(results, source=str(batch))
    atomic_write_json(out / "population.json", fit.population_json)
    laws = hierarchical_laws(batch, seed=seed)
    atomic_write_json(out / "hierarchical.json", laws.to_json())
    walkers = fit_walkers(batch, seed=seed)
    notes = [
        f"Footbridge records: a cohort of {COHORT_WALKERS} walkers drawn from the seed's laws "
        f"crossed the lively span (50 m, 2 Hz, 0.5 % damping) in {COHORT_CROSSINGS} stream "
        f"windows, {len(written.records)} records written ({len(written.skipped)} shorter "
        "than 10 s, walkers at a window's edge, skipped), each walker coupled to the deck "
        "(human-structure interaction). The laws fitted to them are a check of the "
        "workbench against the laws they were drawn from, not a finding about people.",
        *_truth_notes(laws.fit, fit),
    ]
    if real_manifest is not None:
        notes.append(
            "Real records: steady stretches of the embedded treadmill and insole records "
            "(rigid floors), identified with the default settings in the same batch."
        )
    files = population_report(
        results,
        fit,
        out,
        notes=notes,
        recovery=recovery,
        hierarchical=laws,
        walkers=walkers,
    )
    hier = laws.fit
    return {
        "records": len(results),
        "records_used": fit.population_json["records_used"],
        "records_excluded": fit.population_json["records_excluded"],
        "hierarchical_records_used": 0 if hier is None else hier.records_used,
        "records_left_out": len(laws.left_out),
        "walkers": 0 if hier is None else hier.walkers,
        "walker_fits": [w.subject for w in walkers],
        "failed": summary.failed,
        "laws": fit.population_json["laws"],
        "hierarchical": laws.to_json(),
        "report": files["html"],
        "files": files,
        "text": laws.summary() + f"\nreport {files['html']}",
    }
