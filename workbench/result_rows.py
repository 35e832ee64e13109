"""The flat row of an identification result: the columns of a batch and of a sensitivity study.

A batch's ``results.csv`` (:mod:`workbench.population.batch`) and a sensitivity study's runs
(:mod:`workbench.sensitivity.run`) read the same numbers off an
:class:`~workbench.inference.core.results.IdentificationResult`; :func:`result_row` is that one
reading, kept below both.
"""

from __future__ import annotations

import math
from typing import Any

__all__ = ["RESULT_COLUMNS", "SCALARS", "c_and_k_source", "result_row"]

#: The estimates a row carries, each with its posterior sd.
SCALARS = ("stiffness_n_per_m", "damping_ns_per_m", "natural_frequency_hz", "damping_ratio")
#: Columns of ``results.csv`` (no timing: the table is byte-identical from run to run).
RESULT_COLUMNS: tuple[str, ...] = (
    "path",
    "subject",
    "mass_kg",
    "pacing_hz",
    "method",
    "steps",
    "steps_off_rhythm_share",
    *(c for s in SCALARS for c in (s, f"{s}_sd")),
    *(c for i in (1, 2, 3) for c in (f"blf{i}", f"blf{i}_sd")),
    "identifiability",
    "identified_damping",
    "identified_stiffness",
    "trustworthy",
    "c_and_k_from",
    "seed",
)


def _num(x: Any) -> float:
    x = float(x)
    return x if math.isfinite(x) else math.nan


def c_and_k_source(result: Any) -> str:
    """Return where C and K came from (the ``c_and_k_from`` column).

    The deck's transmissibility, or the time history with the surface coupled jointly,
    ignored, or on a rigid floor.
    """
    surface = result.surface
    if surface is not None and surface.c_and_k_from == "transmissibility":
        return "deck transmissibility"
    model = surface.model if surface is not None else ""
    if model == "coupled":
        return "time history, surface coupled"
    if model.startswith("ignored"):
        return "time history, surface ignored"
    return "time history, rigid floor"


def result_row(result: Any, path: str, subject: str | None, seed: int) -> dict[str, Any]:
    """Turn an :class:`~workbench.inference.core.results.IdentificationResult` into a table row.

    Parameters
    ----------
    result : IdentificationResult
        The identification.
    path : str
        The record's manifest path.
    subject : str or None
        Subject identifier.
    seed : int
        Seed the record was identified with.

    Returns
    -------
    dict
        Keys :data:`RESULT_COLUMNS`.
    """
    est, sd = result.estimates, result.posterior_sd
    ident = result.identifiability
    row: dict[str, Any] = {
        "path": path,
        "subject": subject or "",
        "mass_kg": _num(result.mass_kg),
        "pacing_hz": _num(result.problem.pacing_hz),
        "method": result.method,
        "steps": int(result.problem.n_pieces),
        # The split's consistency check (inspect's "split"); NaN for a record not cut into
        # footfall steps.
        "steps_off_rhythm_share": _num(
            result.split.get("off_rhythm_share", math.nan) if result.split else math.nan
        ),
    }
    for s in SCALARS:
        row[s] = _num(est[s])
        row[f"{s}_sd"] = _num(sd[s])
    blf, blf_sd = list(result.blf), list(result.blf_sd)
    for i in (1, 2, 3):
        row[f"blf{i}"] = _num(blf[i - 1]) if i <= len(blf) else math.nan
        row[f"blf{i}_sd"] = _num(blf_sd[i - 1]) if i <= len(blf_sd) else math.nan
    row["identifiability"] = str(ident.get("level", "not assessed"))
    row["identified_damping"] = bool(ident.get("identified_damping", False))
    row["identified_stiffness"] = bool(ident.get("identified_stiffness", False))
    row["trustworthy"] = bool(result.trustworthy)
    row["c_and_k_from"] = c_and_k_source(result)
    row["seed"] = int(seed)
    return row
