"""The pedestrian table shared with the population sampler, and its checks.

A stochastic pedestrian sample is a :class:`pandas.DataFrame`, one row per pedestrian, with
the columns of :data:`PEDESTRIAN_COLUMNS`. Speed is pacing times step length; the SMD has
``K = M (2 pi f_n)^2`` and ``C = 2 zeta sqrt(K M)``; the biomechanical force of harmonic
``i`` is ``blf_i M g cos(2 pi i f_p t + phase_i)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from numpy.typing import NDArray

from workbench.errors import InputError
from workbench.population.sampler import COLUMNS, GRAVITY_M_S2

__all__ = [
    "PEDESTRIAN_COLUMNS",
    "G",
    "PedestrianSampler",
    "TableSampler",
    "read_pedestrians",
    "validate_pedestrians",
]

# The table is the population sampler's (one definition of the contract).
G = GRAVITY_M_S2
HARMONICS = 3
PEDESTRIAN_COLUMNS = COLUMNS
#: Relative mismatch allowed between a derived column and the value the others imply
#: (values read back from CSV carry rounding).
_RTOL = 1e-2

#: ``sampler(n, seed=...)`` returns ``n`` pedestrians as a table.
PedestrianSampler = Callable[..., pd.DataFrame]


def validate_pedestrians(frame: pd.DataFrame, source: str = "the pedestrian table") -> pd.DataFrame:
    """Check a pedestrian table and return it with float columns in contract order.

    Parameters
    ----------
    frame : pandas.DataFrame
        One row per pedestrian, the columns of :data:`PEDESTRIAN_COLUMNS` (others are kept
        out of the result).
    source : str
        Name of the table in error messages (a file name).

    Raises
    ------
    InputError
        Naming the column or row and the fix, for a missing column, a non-number, a value
        out of its physical range, or derived columns that disagree with the others.
    """
    if not isinstance(frame, pd.DataFrame):
        raise InputError(source, "whole table", "is not a table", "pass a pandas DataFrame")
    missing = [c for c in PEDESTRIAN_COLUMNS if c not in frame.columns]
    if missing:
        raise InputError(
            source,
            f"column {missing[0]!r}",
            f"is missing (needs {', '.join(PEDESTRIAN_COLUMNS)})",
            "write the table with `workbench sample` or add the column",
        )
    if len(frame) == 0:
        raise InputError(source, "whole table", "has no pedestrians", "give at least one row")
    out = pd.DataFrame(index=range(len(frame)))
    for col in PEDESTRIAN_COLUMNS:
        values = pd.to_numeric(frame[col].reset_index(drop=True), errors="coerce")
        bad = np.flatnonzero(~np.isfinite(values.to_numpy(dtype=float)))
        if bad.size:
            raise InputError(
                source,
                f"column {col!r}, row {bad[0] + 1}",
                f"is not a finite number ({frame[col].iloc[bad[0]]!r})",
                "give a number there",
            )
        out[col] = values.astype(float)
    positive = ("mass_kg", "pacing_hz", "step_length_m", "speed_m_s", "natural_frequency_hz")
    for col in (*positive, "stiffness_n_per_m", "damping_ns_per_m", "damping_ratio"):
        bad = np.flatnonzero(out[col].to_numpy() <= 0)
        if bad.size:
            raise InputError(
                source,
                f"column {col!r}, row {bad[0] + 1}",
                f"must be positive, got {out[col].iloc[bad[0]]:g}",
                "fix the value or redraw the sample",
            )
    for col in ("blf1", "blf2", "blf3"):
        v = out[col].to_numpy()
        bad = np.flatnonzero((v < 0) | (v >= 1))
        if bad.size:
            raise InputError(
                source,
                f"column {col!r}, row {bad[0] + 1}",
                f"is a load factor and must lie in [0, 1), got {v[bad[0]]:g}",
                "fix the value or redraw the sample",
            )
    m = out["mass_kg"].to_numpy()
    k = m * (2 * np.pi * out["natural_frequency_hz"].to_numpy()) ** 2
    c = 2 * out["damping_ratio"].to_numpy() * np.sqrt(k * m)
    checks = (
        ("speed_m_s", out["pacing_hz"].to_numpy() * out["step_length_m"].to_numpy(), "f_p x L"),
        ("stiffness_n_per_m", k, "M (2 pi f_n)^2"),
        ("damping_ns_per_m", c, "2 zeta sqrt(K M)"),
    )
    for col, implied, formula in checks:
        v = out[col].to_numpy()
        bad = np.flatnonzero(np.abs(v - implied) > _RTOL * np.abs(implied))
        if bad.size:
            i = bad[0]
            raise InputError(
                source,
                f"column {col!r}, row {i + 1}",
                f"is {v[i]:g} but the other columns give {formula} = {implied[i]:g}",
                "make the columns consistent (write the table with `workbench sample`)",
            )
    return out


def read_pedestrians(path: str | Path) -> pd.DataFrame:
    """Read and check a pedestrian table written as CSV (for example by `workbench sample`)."""
    path = Path(path)
    try:
        frame = pd.read_csv(path)
    except FileNotFoundError:
        raise InputError(path, "whole file", "does not exist", "check the path") from None
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as err:
        raise InputError(
            path, "whole file", f"is not a readable CSV table ({err})", "give a CSV file"
        ) from None
    return validate_pedestrians(frame, str(path))


@dataclass(frozen=True)
class PedestrianArrays:
    """A pedestrian table as arrays (shape ``(n,)``; force terms ``(n, HARMONICS)``)."""

    mass_kg: NDArray[np.float64]
    stiffness_n_per_m: NDArray[np.float64]
    damping_ns_per_m: NDArray[np.float64]
    pacing_hz: NDArray[np.float64]
    speed_m_s: NDArray[np.float64]
    blf: NDArray[np.float64]
    phase_rad: NDArray[np.float64]

    @classmethod
    def from_frame(cls, frame: pd.DataFrame) -> PedestrianArrays:
        """From a checked table."""
        return cls(
            mass_kg=frame["mass_kg"].to_numpy(float),
            stiffness_n_per_m=frame["stiffness_n_per_m"].to_numpy(float),
            damping_ns_per_m=frame["damping_ns_per_m"].to_numpy(float),
            pacing_hz=frame["pacing_hz"].to_numpy(float),
            speed_m_s=frame["speed_m_s"].to_numpy(float),
            blf=frame[["blf1", "blf2", "blf3"]].to_numpy(float),
            phase_rad=frame[["phase1_rad", "phase2_rad", "phase3_rad"]].to_numpy(float),
        )


class TableSampler:
    """Draw pedestrians by resampling the rows of a given table (with replacement).

    Parameters
    ----------
    frame : pandas.DataFrame
        A pedestrian table (checked here).
    source : str
        Its name, for error messages.
    """

    def __init__(self, frame: pd.DataFrame, source: str = "the pedestrian table") -> None:
        self.frame = validate_pedestrians(frame, source)

    def __call__(self, n: int, *, seed: int) -> pd.DataFrame:
        """Return ``n`` rows drawn with replacement; phases redrawn uniformly."""
        rng = np.random.default_rng(seed)
        rows = self.frame.iloc[rng.integers(0, len(self.frame), size=n)].reset_index(drop=True)
        # The same person walking again does not keep the phase of their force.
        for i in range(1, HARMONICS + 1):
            rows[f"phase{i}_rad"] = rng.uniform(0.0, 2 * np.pi, size=n)
        return rows


def design_pedestrian(
    *,
    mass_kg: float = 73.85,
    natural_frequency_hz: float | None = None,
    damping_ratio: float | None = None,
    stiffness_n_per_m: float = 14110.0,
    damping_ns_per_m: float = 612.5,
    pacing_hz: float = 2.0,
    speed_m_s: float = 1.25,
    blf: tuple[float, float, float] | None = None,
    phase_rad: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> pd.DataFrame:
    """One pedestrian as a table; by default the docs/science.md 7 walker at 2 Hz.

    The load factor defaults to the moving-force check's ``0.41 (f_p - 0.95)`` on the first
    harmonic only. ``natural_frequency_hz`` and ``damping_ratio`` given override the
    stiffness and damping.
    """
    k, c = stiffness_n_per_m, damping_ns_per_m
    if natural_frequency_hz is not None:
        k = mass_kg * (2 * np.pi * natural_frequency_hz) ** 2
    if damping_ratio is not None:
        c = 2 * damping_ratio * np.sqrt(k * mass_kg)
    b = blf if blf is not None else (0.41 * (pacing_hz - 0.95), 0.0, 0.0)
    row = {
        "mass_kg": mass_kg,
        "pacing_hz": pacing_hz,
        "step_length_m": speed_m_s / pacing_hz,
        "speed_m_s": speed_m_s,
        "natural_frequency_hz": np.sqrt(k / mass_kg) / (2 * np.pi),
        "damping_ratio": c / (2 * np.sqrt(k * mass_kg)),
        "stiffness_n_per_m": k,
        "damping_ns_per_m": c,
        "blf1": b[0],
        "blf2": b[1],
        "blf3": b[2],
        "phase1_rad": phase_rad[0],
        "phase2_rad": phase_rad[1],
        "phase3_rad": phase_rad[2],
    }
    return pd.DataFrame([row])
