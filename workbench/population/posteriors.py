"""The records of a batch with their stored posteriors, and which of them a fit may use.

:func:`read_record_posteriors` reads every done record of a batch folder
(``records/<key>.json``, :mod:`workbench.population.batch`) with its (C, K) posterior on the
nodes (:class:`~workbench.inference.core.node_posterior.NodePosterior`);
:func:`likelihood_use` applies the decision of docs/science.md 8: a record whose C and K come
from the deck's transmissibility is used whatever its grade, one whose C and K come from the
time history only where the force-model check passed, one without a stored posterior never.
Each left-out record carries its reason in words, for the report.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.errors import InputError, UsageError
from workbench.inference.core.node_posterior import NodePosterior
from workbench.population.hierarchy import RecordLikelihood

__all__ = ["StoredRecord", "likelihood_use", "read_record_posteriors", "record_likelihoods"]

#: Grades under which a record counts as identified.
IDENTIFIED = ("well identified", "weakly identified")


@dataclass(frozen=True, eq=False)
class StoredRecord:
    """One done record of a batch, with what a fit over many records needs of it.

    Attributes
    ----------
    path : str
        The record as the manifest names it.
    subject : str or None
        The walker (None when the manifest gives none).
    pacing_hz : float
        The identified pacing [Hz].
    identifiability : str
        The record's grade.
    c_and_k_from : str
        Where C and K came from (``results.csv``'s column).
    force_model_check_passed : bool or None
        Whether the force-model check passed (None: it did not run, as on the deck route).
    posterior : NodePosterior or None
        The stored posterior (None for the particle filters).
    problem : str or None
        Why the stored posterior could not be read, in words (None when it could, or when
        there is none).
    """

    path: str
    subject: str | None
    pacing_hz: float
    identifiability: str
    c_and_k_from: str
    force_model_check_passed: bool | None
    posterior: NodePosterior | None
    problem: str | None = None


def likelihood_use(record: StoredRecord) -> str | None:
    """Return None when a fit may use the record's likelihood, else the reason it may not.

    The decision of docs/science.md 8.

    Parameters
    ----------
    record : StoredRecord
        A record read by :func:`read_record_posteriors`.

    Returns
    -------
    str or None
        The reason in words ("C and K follow the force model's misfit (the force-model
        check failed)", ...), or None.
    """
    if record.problem is not None:
        return record.problem
    if record.posterior is None:
        return (
            "no stored posterior (the particle filters keep none; identify with the exact method)"
        )
    if not math.isfinite(record.pacing_hz):
        return "no pacing"
    if record.c_and_k_from == "deck transmissibility":
        return None
    if record.force_model_check_passed is False:
        return "C and K follow the force model's misfit (the force-model check failed)"
    if record.identifiability not in IDENTIFIED:
        # Also where the check passed: a time history graded not identified for another
        # reason (a deck only near the gait's harmonics, a mode on the prior box's edge)
        # says its numbers are not estimates.
        return f"C and K from the time history, graded {record.identifiability}"
    return None


def _read(file: Path) -> dict[str, Any] | None:
    try:
        obj = json.loads(file.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return obj if isinstance(obj, dict) else None


def _listed_paths(batch_dir: Path) -> set[str] | None:
    """Return the record paths of the batch's ``results.csv`` (None without a readable one)."""
    try:
        return set(pd.read_csv(batch_dir / "results.csv", usecols=["path"])["path"].astype(str))
    except (OSError, ValueError):
        return None


def read_record_posteriors(batch_dir: str | os.PathLike[str]) -> list[StoredRecord]:
    """Read every done record of a batch folder with its stored posterior, sorted by path.

    A record file that cannot be read, or whose posterior is malformed, is kept with its
    ``problem`` set (a fit leaves it out and the report says why), never dropped silently.
    Where the folder has its ``results.csv``, only the records it lists are read: a batch
    resumed in the same folder with a smaller manifest leaves the earlier run's record files
    behind, and they are no longer part of the batch.

    Parameters
    ----------
    batch_dir : path-like
        The ``--out`` folder of ``workbench batch``.

    Returns
    -------
    list of StoredRecord

    Raises
    ------
    InputError
        If the folder holds no record files.
    """
    folder = Path(batch_dir) / "records"
    files = sorted(folder.glob("*.json")) if folder.is_dir() else []
    if not files:
        raise InputError(
            batch_dir,
            "folder 'records'",
            "there are no record files here",
            "give the --out folder of 'workbench batch'",
        )
    listed = _listed_paths(Path(batch_dir))
    out = []
    for file in files:
        obj = _read(file)
        if obj is None or obj.get("status") != "done":
            continue  # failed records are listed in failures.csv
        row = obj.get("row") or {}
        path = str(obj.get("path", file.stem))
        if listed is not None and path not in listed:
            continue  # an earlier manifest's record, not in this batch
        stored = obj.get("posterior")
        posterior, problem, check = None, None, None
        if stored is not None:
            where = f"{file}, key 'posterior'"
            try:
                posterior = NodePosterior.from_json(stored, where)
            except UsageError as err:
                problem = f"its stored posterior cannot be read ({err})"
            check = stored.get("force_model_check_passed") if isinstance(stored, dict) else None
        try:
            pacing = float(row.get("pacing_hz", math.nan))
        except (TypeError, ValueError):
            pacing = math.nan
        subject = row.get("subject") or None
        out.append(
            StoredRecord(
                path=path,
                subject=str(subject) if subject is not None else None,
                pacing_hz=pacing,
                identifiability=str(row.get("identifiability", "not assessed")),
                c_and_k_from=str(row.get("c_and_k_from", "")),
                force_model_check_passed=None if check is None else bool(check),
                posterior=posterior,
                problem=problem,
            )
        )
    return sorted(out, key=lambda r: r.path)


def record_likelihoods(
    stored: list[StoredRecord],
) -> tuple[list[RecordLikelihood], pd.DataFrame]:
    """Turn a batch's stored records into the hierarchical fit's likelihoods.

    Parameters
    ----------
    stored : list of StoredRecord
        From :func:`read_record_posteriors`.

    Returns
    -------
    records : list of RecordLikelihood
        The records :func:`likelihood_use` lets a fit use: each node's f_n and zeta, its
        log mass, the log density of the uniform (C, K) prior in (f_n, zeta) (to divide
        out) and its BLF1-3 given (C, K).
    left_out : pandas.DataFrame
        ``path, reason`` of the others, sorted by path.
    """
    used, left = [], []
    for rec in stored:
        reason = likelihood_use(rec)
        nodes = rec.posterior
        if reason is None and nodes is not None and nodes.blf_mean.shape[1] < 3:
            reason = "fewer than three load factors per node (a model of under three harmonics)"
        if reason is not None or nodes is None:
            left.append({"path": rec.path, "reason": reason or "no stored posterior"})
            continue
        with np.errstate(divide="ignore"):
            log_weight = np.log(nodes.weight)
        var_fn, var_zeta = nodes.modal_cell_variance()
        used.append(
            RecordLikelihood(
                path=rec.path,
                subject=rec.subject,
                pacing_hz=rec.pacing_hz,
                natural_frequency_hz=nodes.natural_frequency_hz,
                damping_ratio=nodes.damping_ratio,
                log_weight=log_weight,
                log_prior=nodes.log_prior_modal(),
                blf_mean=nodes.blf_mean[:, :3],
                blf_sd=nodes.blf_sd[:, :3],
                natural_frequency_var=var_fn,
                damping_ratio_var=var_zeta,
            )
        )
    return used, pd.DataFrame(left, columns=["path", "reason"])
