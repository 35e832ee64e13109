"""Run a sensitivity design: one identification per record, design point and replicate.

Execution goes through the study executor (:mod:`workbench.executor`): in
this process for one worker, a local process pool (``spawn`` start method) for more, a Dask
distributed cluster when a scheduler address is given. A design point changes more than an
:class:`IdentifySettings` names (prior box, random walks of C and K, per-channel observation
noise), so the study submits its own picklable tasks; each result becomes a row by
:func:`~workbench.result_rows.result_row`, as in a batch.

Determinism: each run's seed is :func:`~workbench.sensitivity.design.point_seed` of the
study seed, the record, the point and the replicate, and the rows are sorted by those keys
before anything is computed from them, so the numbers do not depend on the worker count.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from workbench.errors import UsageError, WorkbenchError
from workbench.executor import run_tasks as run_engine_tasks
from workbench.inference.pipeline import IdentifySettings
from workbench.records.record import Record
from workbench.result_rows import result_row
from workbench.sensitivity.design import DesignPoint, Overrides, point_seed

__all__ = ["OUTPUTS", "SensitivityTask", "make_tasks", "run_task", "run_tasks"]

#: Outputs the study follows, with units for statements.
OUTPUTS: dict[str, str] = {
    "natural_frequency_hz": "Hz",
    "damping_ratio": "",
    "blf1": "",
    "blf2": "",
    "blf3": "",
    "stiffness_n_per_m": "N/m",
    "damping_ns_per_m": "N s/m",
}


@dataclass(frozen=True)
class SensitivityTask:
    """One identification of a study (picklable: it travels to pool and Dask workers)."""

    record_key: str
    record: Record
    point_key: str
    levels: dict[str, str]
    settings: dict[str, Any]
    overrides: Overrides
    replicate: int
    seed: int


def make_tasks(
    records: Sequence[tuple[str, Record]],
    points: Sequence[DesignPoint],
    base: IdentifySettings,
    replicates: int,
    seed: int,
) -> list[SensitivityTask]:
    """Every (record, point, replicate) of a study, with its seed."""
    if replicates < 1:
        raise UsageError(
            f"'replicates' must be at least 1, got {replicates}", parameter="replicates"
        )
    tasks = []
    for key, record in records:
        for p in points:
            settings, overrides = p.configure(base)
            for r in range(replicates):
                s = point_seed(seed, key, p.key, r)
                tasks.append(
                    SensitivityTask(
                        key,
                        record,
                        p.key,
                        dict(p.levels),
                        settings.replace(seed=s).to_json(),
                        overrides,
                        r,
                        s,
                    )
                )
    return tasks


def run_task(task: SensitivityTask) -> dict[str, Any]:
    """Identify one record at one design point; a failure is returned, not raised."""
    from workbench.inference.pipeline.identification import identify

    start = time.perf_counter()
    out: dict[str, Any] = {
        "record": task.record_key,
        "point": task.point_key,
        "replicate": task.replicate,
        "seed": task.seed,
        "levels": task.levels,
    }
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        try:
            settings = IdentifySettings.from_flat(**task.settings)
            result = identify(
                task.record,
                settings=settings,
                adjust_problem=task.overrides.adjust_problem,
                adjust_noise=task.overrides.adjust_noise,
            )
            row = result_row(result, task.record_key, task.record.subject, task.seed)
            out.update({k: row[k] for k in row if k not in ("path", "subject", "seed")})
            out["obs_fraction"] = result.noise.get("obs_fraction")
            out["status"] = "done"
        except WorkbenchError as err:
            out.update(status="failed", reason=str(err))
        except Exception as err:  # one failing point must not stop the study
            out.update(status="failed", reason=f"internal error ({type(err).__name__}: {err})")
    out["elapsed_s"] = round(time.perf_counter() - start, 3)
    return out


def run_tasks(
    tasks: list[SensitivityTask],
    *,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Run every task and return the rows sorted by record, point and replicate.

    Parameters
    ----------
    tasks : list of SensitivityTask
        From :func:`make_tasks`.
    workers : int, default 1
        Local processes (1: in this process).
    scheduler : str, optional
        Address of a Dask scheduler (overrides ``workers``).
    progress : bool, default False
        Show a progress bar.

    Returns
    -------
    list of dict
    """
    it = run_engine_tasks(
        run_task,
        tasks,
        workers=workers,
        scheduler=scheduler,
        keys=[
            f"workbench-sensitivity-{t.record_key}-{t.point_key}-{t.replicate}-{t.seed}"
            for t in tasks
        ],
    )
    if progress:
        from tqdm import tqdm

        it = tqdm(it, total=len(tasks), desc="sensitivity", unit="run", leave=False)
    rows = list(it)
    rows.sort(key=lambda r: (r["record"], r["point"], r["replicate"]))
    return rows
