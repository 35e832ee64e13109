"""Files of the population workflow: a batch's results table in, the fitted laws out."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from workbench.errors import InputError

__all__ = ["read_results", "results_path", "write_population"]


def results_path(path: str | os.PathLike[str]) -> Path:
    """Return the results table a path names: ``results.csv`` in a batch folder, or the file.

    Parameters
    ----------
    path : path-like
        The ``--out`` folder of a batch or the table itself.

    Returns
    -------
    Path
    """
    p = Path(path)
    return p / "results.csv" if p.is_dir() else p


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
        If there is no table, it cannot be read, or a cell the fit reads as a number holds
        text.
    """
    import pandas as pd

    file = results_path(path)
    if not file.exists():
        raise InputError(
            file,
            "whole file",
            "there is no batch results table here",
            "give the --out folder of 'workbench batch' (it holds results.csv)",
        )
    try:
        table = pd.read_csv(file)
    except (ValueError, UnicodeDecodeError) as err:
        raise InputError(
            file, "whole file", f"the table cannot be read ({err})", "rerun 'workbench batch'"
        ) from None
    if table.empty:
        raise InputError(
            file,
            "whole file",
            "the table holds no records (only its header)",
            "rerun 'workbench batch' on a manifest whose records identify",
        )
    _check_repeats(table, file)
    _check_numbers(table, file)
    return table


def _check_repeats(table: Any, file: Path) -> None:
    """Refuse a record that appears on more than one row, naming it and its rows.

    Each row counts as one pedestrian in the fit: a repeated row narrows every interval as
    if it were a new walker (doubling the rows of 12 records manufactures a damping slope
    that the 12 do not support). A batch writes each record once, so repeats come from
    editing or concatenating tables, and only the user knows which copy to keep.
    """
    key = ["path"] if "path" in table.columns else list(table.columns)
    repeated = table.duplicated(subset=key, keep=False).to_numpy()
    if not repeated.any():
        return
    first = int(repeated.argmax())
    same = table[key].eq(table[key].iloc[first]).all(axis=1).to_numpy()
    rows = [str(i + 1) for i in range(len(table)) if same[i]]
    name = f"record {table['path'].iloc[first]}" if "path" in table.columns else "one record"
    n_repeated = int(repeated.sum())
    raise InputError(
        file,
        f"rows {', '.join(rows)} of the table",
        f"{name} appears on {len(rows)} rows ({n_repeated} rows of the table are repeats), "
        "and each row would count as another pedestrian in the laws",
        "keep one row per record (rerun 'workbench batch', which writes each record once)",
    )


def _check_numbers(table: Any, file: Path) -> None:
    """Refuse text in a column the fit reads as numbers, naming the record and the column.

    An edited or foreign table can hold ``n/a`` or ``1,8`` where pandas expects a number;
    found here, the message names the cell instead of failing deep inside the fit.
    """
    import pandas as pd

    from workbench.population.fit import LAW_COLUMNS, LOGNORMAL_COLUMNS

    for column in ("pacing_hz", *LAW_COLUMNS, *LOGNORMAL_COLUMNS):
        if column not in table.columns or pd.api.types.is_numeric_dtype(table[column]):
            continue
        cells = table[column]
        numbers = pd.to_numeric(cells, errors="coerce")
        bad = cells.notna() & numbers.isna()
        if not bad.any():
            continue
        i = int(bad.to_numpy().argmax())
        record = f" ({table['path'].iloc[i]})" if "path" in table.columns else ""
        raise InputError(
            file,
            f"column {column!r}, record {i + 1}{record}",
            f"the value {str(cells.iloc[i])!r} is not a number",
            "write a plain number with a decimal point, or leave the cell empty to leave the "
            "record out",
        )


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
