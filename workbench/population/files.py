"""Files of the population workflow: a batch's results table in, the fitted laws out."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from workbench.errors import InputError

__all__ = ["read_results", "write_population"]


def read_results(path: str | os.PathLike[str]) -> Any:
    """Read ``results.csv`` from a batch folder (or the file itself) as a DataFrame.

    Parameters
    ----------
    path : path-like
        The ``--out`` folder of a batch (holding ``results.csv``) or the table itself.

    Returns
    -------
    pandas.DataFrame
        One row per identified record.

    Raises
    ------
    InputError
        If there is no table or it cannot be read.
    """
    import pandas as pd

    p = Path(path)
    file = p / "results.csv" if p.is_dir() else p
    if not file.exists():
        raise InputError(
            file,
            "whole file",
            "there is no batch results table here",
            "give the --out folder of 'workbench batch' (it holds results.csv)",
        )
    try:
        return pd.read_csv(file)
    except (ValueError, UnicodeDecodeError) as err:
        raise InputError(
            file, "whole file", f"the table cannot be read ({err})", "rerun 'workbench batch'"
        ) from None


def write_population(fit: Any, out_dir: str | os.PathLike[str]) -> dict[str, str]:
    """Write ``population.json``, ``bands.csv``, ``residuals.csv`` and ``excluded.csv``.

    Parameters
    ----------
    fit : PopulationFit
        A fit from :func:`workbench.population.fit.fit_population`.
    out_dir : path-like
        Output folder (created if needed); every file is written atomically.

    Returns
    -------
    dict
        Path of each file by key (``population``, ``bands``, ``residuals``, ``excluded``).
    """
    from workbench.fileutil import atomic_path, atomic_write_json

    out = Path(out_dir)
    files = {
        "population": out / "population.json",
        "bands": out / "bands.csv",
        "residuals": out / "residuals.csv",
        "excluded": out / "excluded.csv",
    }
    atomic_write_json(files["population"], fit.to_json())
    for key, frame in (("bands", fit.bands), ("residuals", fit.used), ("excluded", fit.excluded)):
        with atomic_path(files[key]) as tmp:
            frame.to_csv(tmp, index=False, float_format="%.10g", lineterminator="\n")
    return {k: str(v) for k, v in files.items()}
