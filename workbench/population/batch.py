"""Batch identification: every record of a manifest, fault-tolerant, resumable, scalable.

``run_batch(manifest, out_dir)`` identifies each record with
:func:`workbench.inference.pipeline.identification.identify` and writes

- ``OUT/records/<key>.json``: one file per record, written atomically (temporary file in the
  same folder, then rename; :mod:`workbench.fileutil`) as soon as the record is finished,
  with ``status`` ``"done"`` (and the result row) or ``"failed"`` (and the reason); a done
  record identified on the exact grid (the default, and every deck route) also keeps its
  ``posterior``: the (C, K) posterior on the nodes holding nearly all its mass, the prior
  box, each node's BLF1-3 and whether the force-model check passed
  (:mod:`workbench.inference.core.node_posterior`), read back by
  :func:`workbench.population.posteriors.read_record_posteriors`;
- ``OUT/results.csv``: one row per identified record (:data:`RESULT_COLUMNS`), sorted by
  the record's path, assembled from the record files at the end, so its bytes (and the
  record files') depend only on the records and the settings -- never on worker count,
  scheduling or interruptions;
- ``OUT/failures.csv``: ``path, reason`` for every record that could not be identified
  (missing file, unreadable file, NaN samples, ...), sorted by path;
- ``OUT/timings.csv``: ``path, status, elapsed_s`` (:data:`TIMING_COLUMNS`), the wall time
  of each record's last run, sorted by path; the only output that changes from run to run,
  so it is kept out of the files above (each record's time is written to
  ``OUT/timings/<key>.json`` when it finishes, so a resumed batch keeps the earlier times);
- ``OUT/batch.json``: the settings, so that ``--resume`` refuses to mix settings.

Determinism: the seed of each record is derived from the batch seed, the record's path as
written in the manifest and the bytes of the file (SHA-256), not from its position, so one
worker, two workers or a Dask cluster give the same numbers.

Resume: records with a ``done`` file are skipped; failed records are tried again (a failure
is cheap, and the file may have been fixed in between). Leftover temporary files of a killed
run are ignored and removed.

Lock: a run holds an exclusive lock on ``OUT/.batch.lock`` (:func:`batch_lock`) for its whole
life, so a second run on the same folder is refused in one sentence, and the leftover
temporary files are removed only while holding it (they cannot be a live run's).

Paths: every file names a record as the manifest does, from the manifest's folder, and
``batch.json`` names the manifest from the output folder, so the same batch started from
another folder, or with the manifest's path typed otherwise, writes the same bytes.

Execution: in this process for one worker; a local process pool (``spawn`` start method, so
no state leaks from the parent) for more; a Dask distributed cluster when a scheduler
address is given (``dask[distributed]``, the ``dask`` extra). The parent writes every
record's file, so the workers need no access to the output folder. With the ``spawn`` start
method a script that calls :func:`run_batch` with several workers needs the usual
``if __name__ == "__main__":`` guard (the workers import the main module).

Pacing: when the settings identify the record as one piece (``pieces = "whole"``) and give
no pacing, the pacing stated in the manifest or sidecar is used (a known metronome rate
fixes the Fourier basis better than a spectral estimate); otherwise the record's own
estimate, as ``workbench identify`` does.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import time
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from workbench.errors import UsageError, WorkbenchError
from workbench.executor import run_tasks
from workbench.fileutil import atomic_path, atomic_write_json, strict_json
from workbench.inference.pipeline import IdentifySettings
from workbench.population.batch_folder import (
    as_in_manifest,
    batch_lock,
    check_record_file,
    file_seed,
    manifest_from_folder,
    record_seed,
)
from workbench.result_rows import RESULT_COLUMNS, result_row

__all__ = [
    "FAILURE_COLUMNS",
    "RESULT_COLUMNS",
    "TIMING_COLUMNS",
    "BatchSummary",
    "BatchTask",
    "record_seed",
    "result_row",
    "run_batch",
    "run_task",
]

#: Columns of ``timings.csv``: wall time [s] of each record's last run.
TIMING_COLUMNS = ("path", "status", "elapsed_s")
FAILURE_COLUMNS = ("path", "reason")


@dataclass(frozen=True)
class BatchTask:
    """One record to identify (picklable: it travels to process-pool and Dask workers).

    Parameters
    ----------
    key : str
        File-name-safe unique key of the record (from its manifest path).
    path : str
        The record file as given in the manifest (relative to the manifest's folder).
    file : str
        The record file to open.
    mass_kg, pacing_hz : float or None
        Metadata from the manifest (override the sidecar).
    subject : str or None
        Subject from the manifest.
    seed : int
        The record's seed (:func:`record_seed`).
    settings : dict
        :class:`~workbench.inference.pipeline.settings.IdentifySettings` as JSON.
    allow_negative_force : bool
        Accept force samples below zero with a warning (synthetic benchmarks).
    overrides : Overrides or None
        What a sensitivity design point changes beyond the settings
        (:class:`~workbench.sensitivity.design.Overrides`): applied through the problem
        hooks of :func:`~workbench.inference.pipeline.identification.identify`.
    max_rows : int or None
        Longest record, in file lines, identified; a longer one fails before it is read
        (None: no limit).
    budget : str
        What ``max_rows`` comes from, in words, for the failure's sentence.
    folder : str
        The manifest's folder as given (``file`` starts with it); messages name the record
        from the manifest's folder instead, so they do not depend on the current folder.
    """

    key: str
    path: str
    file: str
    mass_kg: float | None
    pacing_hz: float | None
    subject: str | None
    seed: int
    settings: dict[str, Any] = field(default_factory=dict)
    allow_negative_force: bool = False
    overrides: Any = None
    max_rows: int | None = None
    budget: str = ""
    folder: str = ""


@dataclass
class BatchSummary:
    """What a batch did: counts and the files it wrote.

    ``done`` counts records identified in this run, ``skipped`` records finished by an
    earlier run (``--resume``), ``failed`` records that could not be identified; the three
    add up to the manifest's records.
    """

    done: int
    failed: int
    skipped: int
    results_csv: Path
    failures_csv: Path
    timings_csv: Path
    elapsed_s: float
    failures: list[dict[str, str]]

    def to_json(self) -> dict[str, Any]:
        """Return the ``workbench batch --json`` object."""
        return {
            "done": self.done,
            "failed": self.failed,
            "skipped": self.skipped,
            "results": str(self.results_csv),
            "failures": str(self.failures_csv),
            "timings": str(self.timings_csv),
            "failed_records": self.failures,
            "elapsed_s": round(self.elapsed_s, 3),
        }


def _key(path: str) -> str:
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(path).stem)[:60] or "record"
    return f"{stem}-{hashlib.sha1(path.encode('utf-8')).hexdigest()[:10]}"


def run_task(task: BatchTask) -> dict[str, Any]:
    """Identify one record; never raises for a bad record (the reason is returned).

    Parameters
    ----------
    task : BatchTask
        The record.

    Returns
    -------
    dict
        ``key, path, status`` (``"done"`` or ``"failed"``), ``row`` or ``reason``,
        ``warnings`` (messages raised while identifying) and ``elapsed_s``.
    """
    from workbench.inference.pipeline.identification import identify
    from workbench.records.io import load_record

    start = time.perf_counter()
    out: dict[str, Any] = {"key": task.key, "path": task.path}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            check_record_file(task.path, task.file, task.max_rows, task.budget)
            record = load_record(
                task.file,
                mass_kg=task.mass_kg,
                pacing_hz=task.pacing_hz,
                subject=task.subject,
                allow_negative_force=task.allow_negative_force,
            )
            settings = IdentifySettings.from_flat(**{**task.settings, "seed": task.seed})
            model = settings.model
            if model.pieces == "whole" and model.pacing_hz is None and record.pacing_hz:
                settings = settings.replace(pacing_hz=float(record.pacing_hz))
            ov = task.overrides
            result = identify(
                record,
                settings=settings,
                adjust_problem=None if ov is None else ov.adjust_problem,
                adjust_noise=None if ov is None else ov.adjust_noise,
            )
            out["row"] = result_row(result, task.path, record.subject, task.seed)
            if result.node_posterior is not None:
                # What a fit over many records needs of this one (docs/science.md 8).
                check = result.identifiability.get("force_model_check") or {}
                out["posterior"] = {
                    **result.node_posterior.to_json(),
                    "force_model_check_passed": check.get("passed"),
                }
            out["status"] = "done"
        except WorkbenchError as err:
            out.update(status="failed", reason=as_in_manifest(str(err), task.folder, task.path))
        except Exception as err:  # one bad record must not stop the batch
            reason = f"internal error ({type(err).__name__}: {err})"
            out.update(status="failed", reason=as_in_manifest(reason, task.folder, task.path))
    out["warnings"] = sorted(
        {as_in_manifest(str(w.message), task.folder, task.path) for w in caught}
    )
    out["elapsed_s"] = round(time.perf_counter() - start, 3)
    return out


# ---------------------------------------------------------------------------------------------
def _read_json(p: Path) -> dict[str, Any] | None:
    try:
        obj = json.loads(p.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError, UnicodeDecodeError):
        return None
    return obj if isinstance(obj, dict) else None


def _write_csv(path: Path, frame: pd.DataFrame) -> None:
    with atomic_path(path) as tmp:
        frame.to_csv(tmp, index=False, float_format="%.10g", lineterminator="\n")


def run_batch(
    manifest: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    settings: IdentifySettings | None = None,
    workers: int = 1,
    scheduler: str | None = None,
    resume: bool = False,
    progress: bool = False,
    on_record: Callable[[dict[str, Any]], None] | None = None,
    allow_negative_force: bool = False,
    allow_outside_paths: bool = False,
    overrides: Any = None,
    max_rows: int | None = None,
    budget: str = "",
) -> BatchSummary:
    """Identify every record of a manifest (see the module docstring for the files).

    Parameters
    ----------
    manifest : path-like
        Batch manifest (docs/contracts.md): ``path`` column, optional ``mass_kg``,
        ``pacing_hz``, ``subject``.
    out_dir : path-like
        Output folder.
    settings : IdentifySettings, optional
        Identification settings; ``settings.seed`` is the batch seed from which every
        record's seed is derived.
    workers : int, default 1
        Local worker processes (1: in this process).
    scheduler : str, optional
        Address of a Dask distributed scheduler; overrides ``workers``.
    resume : bool, default False
        Continue a batch in ``out_dir``: skip records already done.
    progress : bool, default False
        Show a tqdm progress bar on stderr.
    on_record : callable, optional
        Called with each record's outcome after its file is written.
    allow_negative_force : bool, default False
        Accept records whose force dips below zero, with a warning (synthetic benchmarks);
        see :func:`~workbench.records.validation.validate_record`.
    allow_outside_paths : bool, default False
        Accept manifest paths outside the manifest's folder
        (:func:`~workbench.records.manifest.load_manifest`).
    overrides : Overrides, optional
        A sensitivity design point's changes beyond the settings
        (:class:`~workbench.sensitivity.design.Overrides`), for every record; stored with the
        settings, so ``resume`` refuses to mix them.
    max_rows : int, optional
        Per-record budget: a record file of more lines fails (its row in ``failures.csv``)
        before it is read; None for no limit.
    budget : str, optional
        Where ``max_rows`` comes from, in words (``"2 GB of memory"``), quoted in the
        failure's sentence.

    Returns
    -------
    BatchSummary
    """
    from tqdm import tqdm

    from workbench.records.io import load_manifest

    t0 = time.perf_counter()
    settings = settings or IdentifySettings()
    if int(workers) < 1:
        raise UsageError(f"'workers' must be at least 1, got {workers}", parameter="workers")
    entries = load_manifest(manifest, allow_outside_paths=allow_outside_paths)
    out = Path(out_dir)
    rec_dir = out / "records"
    time_dir = out / "timings"
    meta_path = out / "batch.json"
    task_settings = settings.to_json()
    # The overrides belong to the run, not to the settings a worker rebuilds, but resume must
    # refuse to mix them as it refuses other settings.
    settings_json = dict(task_settings)
    if overrides is not None:
        settings_json["overrides"] = dataclasses.asdict(overrides)
    meta = {"manifest": manifest_from_folder(out, manifest), "settings": settings_json}
    # Held for the whole run: a second run on the folder (with --resume, or a fresh one
    # while the first has written nothing yet) is refused instead of mixing files, and the
    # temporary files removed below cannot be a live run's.
    with batch_lock(out):
        if meta_path.exists() or (rec_dir.exists() and any(rec_dir.glob("*.json"))):
            if not resume:
                raise UsageError(
                    f"the output folder {out} already holds a batch; pass 'resume' to continue it, "
                    "or choose an empty folder",
                    parameter="resume",
                )
            old = _read_json(meta_path)
            # Compare as JSON reads it back (tuples become lists, for example).
            stored_form = json.loads(json.dumps(strict_json(settings_json)))
            if old is not None and old.get("settings") != stored_form:
                raise UsageError(
                    f"'resume': the batch in {out} was run with other identification settings; "
                    "use the same settings, or a new output folder",
                    parameter="resume",
                )
        rec_dir.mkdir(parents=True, exist_ok=True)
        time_dir.mkdir(exist_ok=True)
        for folder in (rec_dir, time_dir):
            for stale in folder.glob(".*.tmp"):  # a killed run's half-written file
                stale.unlink(missing_ok=True)
        atomic_write_json(meta_path, strict_json(meta))

        manifest_dir = Path(manifest).parent
        tasks: list[BatchTask] = []
        skipped = 0
        keys: dict[str, str] = {}
        for e in entries:
            try:
                rel = e.path.relative_to(manifest_dir).as_posix()
            except ValueError:
                rel = e.path.as_posix()
            key = _key(rel)
            keys[rel] = key
            if resume:
                prev = _read_json(rec_dir / f"{key}.json")
                if prev is not None and prev.get("status") == "done":
                    skipped += 1
                    continue
            tasks.append(
                BatchTask(
                    key=key,
                    path=rel,
                    file=str(e.path),
                    mass_kg=e.mass_kg,
                    pacing_hz=e.pacing_hz,
                    subject=e.subject,
                    seed=file_seed(settings.seed, rel, e.path),
                    settings=task_settings,
                    allow_negative_force=allow_negative_force,
                    overrides=overrides,
                    max_rows=max_rows,
                    budget=budget,
                    folder=str(manifest_dir),
                )
            )

        results: Iterable[dict[str, Any]] = run_tasks(
            run_task,
            tasks,
            workers=min(int(workers), max(len(tasks), 1)),
            scheduler=scheduler,
            keys=[f"workbench-batch-{t.key}" for t in tasks],
        )
        done = 0
        bar = tqdm(total=len(tasks), desc="batch", unit="record", disable=not progress)
        try:
            for res in results:
                timing = {"path": res["path"], "status": res["status"]}
                timing["elapsed_s"] = res.pop("elapsed_s")
                # The timing first: the record's file marks the record done, so a run killed
                # between the two writes redoes the record instead of keeping it without its time.
                atomic_write_json(time_dir / f"{res['key']}.json", strict_json(timing))
                atomic_write_json(rec_dir / f"{res['key']}.json", strict_json(res))
                done += res["status"] == "done"
                bar.update(1)
                if on_record is not None:
                    on_record(res)
        finally:
            bar.close()

        rows: list[dict[str, Any]] = []
        failures: list[dict[str, str]] = []
        timings: list[dict[str, Any]] = []
        for rel in sorted(keys):
            stored = _read_json(rec_dir / f"{keys[rel]}.json")
            if stored is None:
                failures.append({"path": rel, "reason": "no result was written (interrupted?)"})
                continue
            if stored.get("status") == "done":
                rows.append(stored["row"])
            else:
                failures.append({"path": rel, "reason": str(stored.get("reason", "unknown"))})
            timing = _read_json(time_dir / f"{keys[rel]}.json") or {}
            timings.append(
                {
                    "path": rel,
                    "status": stored.get("status"),
                    # A batch of an earlier version kept the time in the record's file.
                    "elapsed_s": timing.get("elapsed_s", stored.get("elapsed_s", math.nan)),
                }
            )
        table = pd.DataFrame(rows, columns=list(RESULT_COLUMNS))
        _write_csv(out / "results.csv", table)
        _write_csv(out / "failures.csv", pd.DataFrame(failures, columns=list(FAILURE_COLUMNS)))
        _write_csv(out / "timings.csv", pd.DataFrame(timings, columns=list(TIMING_COLUMNS)))
        return BatchSummary(
            done=done,
            failed=len(failures),
            skipped=skipped,
            results_csv=out / "results.csv",
            failures_csv=out / "failures.csv",
            timings_csv=out / "timings.csv",
            elapsed_s=time.perf_counter() - t0,
            failures=failures,
        )
