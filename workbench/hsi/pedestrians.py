"""Pedestrians on a footbridge: SMD models that walk, the shared table, and its checks.

A pedestrian on the bridge is an :class:`~workbench.models.smd.SMDModel` (mass, K, C and a
known biomechanical force: ``pacing_hz`` and ``force_coefficients_n``) walking at a speed:
a :class:`Walker`. A stochastic pedestrian sample is a :class:`pandas.DataFrame`, one row per
pedestrian, with the columns of :data:`PEDESTRIAN_COLUMNS` (the population sampler's
contract); :func:`pedestrian_models` and :func:`walkers` turn its rows into models.

Table conventions: speed is pacing times step length; the SMD has ``K = M (2 pi f_n)^2``
and ``C = 2 zeta sqrt(K M)``; the biomechanical force of harmonic ``i`` is
``blf_i M g cos(2 pi i f_p t + phase_i)``. In the model's Fourier convention
(:class:`~workbench.models.force.FourierForce`, ``A cos(i phi - phi_i) = a cos(i phi) + b
sin(i phi)`` with ``phi = 2 pi f_p t``) that is ``phi_i = -phase_i``, i.e.
``a_i = blf_i M g cos(phase_i)`` and ``b_i = -blf_i M g sin(phase_i)``. The constant term
``a0`` is 0: the force of the table is the dynamic part about the body weight, and the
weight ``M g`` is a separate moving load of the simulator (its ``static_weight`` switch).

The integrator works on :class:`PedestrianArrays`, the vectorised view of a list of
walkers (:meth:`PedestrianArrays.from_models`); a table goes table -> models -> arrays.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TypeAlias

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from workbench.errors import InputError, UsageError
from workbench.models.smd import SMDModel
from workbench.population.sampler import COLUMNS, GRAVITY_M_S2

__all__ = [
    "PEDESTRIAN_COLUMNS",
    "G",
    "PedestrianArrays",
    "PedestrianSampler",
    "Pedestrians",
    "TableSampler",
    "Walker",
    "as_walkers",
    "design_pedestrian",
    "pedestrian_arrays",
    "pedestrian_models",
    "read_pedestrians",
    "validate_pedestrians",
    "walkers",
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
    except IsADirectoryError:
        raise InputError(
            path, "whole file", "this is a folder", "give the table 'workbench sample' writes"
        ) from None
    except OSError as err:  # an input: a sentence about writable --out folders would mislead
        raise InputError(
            path,
            "whole file",
            f"the file cannot be read ({err.strerror or err})",
            "check the path and its permissions",
        ) from None
    return validate_pedestrians(frame, str(path))


def _check_walking_model(model: SMDModel, where: str) -> SMDModel:
    """Return ``model`` if it can walk on a bridge, else raise naming what is missing."""
    if not isinstance(model, SMDModel):
        raise UsageError(
            f"{where}: expected an SMDModel, got {type(model).__name__}; build one with "
            "SMDModel.from_modal(...) or pedestrian_models(table)"
        )
    for name in ("mass_kg", "stiffness_n_per_m", "damping_ns_per_m", "pacing_hz"):
        if getattr(model, name) is None:
            raise UsageError(
                f"{where}: {model!r} has no {name}; a pedestrian on a bridge needs M, K, C, "
                f"pacing_hz and force_coefficients_n (create the model with {name}=...)"
            )
    if model.force_coefficients_n is None:
        raise UsageError(
            f"{where}: {model!r} has no known force; create it with force_coefficients_n=... "
            "(for load factors: FourierForce(n).from_blf(blf, phases, mass))"
        )
    if model.effects:
        raise UsageError(
            f"{where}: {model!r} has effects, but the footbridge simulation integrates the "
            "linear SMD; pass the model without effects"
        )
    if not model.stiffness_n_per_m:
        raise UsageError(
            f"{where}: {model!r} has zero stiffness; a walking SMD needs K > 0 (its steady "
            "state on rigid ground starts the simulation)"
        )
    return model


@dataclass(frozen=True)
class Walker:
    """A pedestrian on a footbridge: an SMD model and the speed it walks at.

    Parameters
    ----------
    model : SMDModel
        Mass, stiffness, damping, ``pacing_hz`` and ``force_coefficients_n`` all known (the
        force is evaluated in absolute time, :meth:`SMDModel.biomechanical_force_n`); no
        effects.
    speed_m_s : float
        Walking speed [m/s] (not an SMD property; a table has it as ``speed_m_s``).

    Examples
    --------
    >>> from workbench.models import FourierForce
    >>> force = FourierForce(3).from_blf([0.4305], None, 73.85)
    >>> model = SMDModel.from_modal(73.85, 2.2, 0.3, harmonics=3, pacing_hz=2.0,
    ...                             force_coefficients_n=force)
    >>> Walker(model, 1.25).speed_m_s
    1.25
    """

    model: SMDModel
    speed_m_s: float

    def __post_init__(self) -> None:
        _check_walking_model(self.model, "Walker")
        try:
            v = float(self.speed_m_s)
        except (TypeError, ValueError):
            v = float("nan")
        if not (np.isfinite(v) and v >= 0):
            raise UsageError(
                f"Walker: speed_m_s must be a finite speed >= 0 in m/s, got {self.speed_m_s!r}"
            )
        object.__setattr__(self, "speed_m_s", v)


def _force_coefficients(frame: pd.DataFrame) -> NDArray[np.float64]:
    """``(n, 1 + 2 HARMONICS)`` coefficients ``a0, a1, b1, ...`` [N] of a checked table."""
    m = frame["mass_kg"].to_numpy(float)
    factors = frame[[f"blf{i}" for i in range(1, HARMONICS + 1)]].to_numpy(float)
    phase = frame[[f"phase{i}_rad" for i in range(1, HARMONICS + 1)]].to_numpy(float)
    # As FourierForce.from_blf with phi_i = -phase_i (module docstring); a0 = 0.
    amplitude = factors * m[:, None] * G
    coef = np.zeros((len(frame), 1 + 2 * HARMONICS))
    coef[:, 1::2] = amplitude * np.cos(-phase)
    coef[:, 2::2] = amplitude * np.sin(-phase)
    return coef


def pedestrian_models(frame: pd.DataFrame) -> list[SMDModel]:
    """Return the SMD model of each row of a pedestrian table.

    Parameters
    ----------
    frame : pandas.DataFrame
        A pedestrian table (checked here).

    Returns
    -------
    list of SMDModel
        One per row: the table's M, K and C, three harmonics, its pacing and the force
        coefficients of its load factors and phases (module docstring), on the absolute
        time basis with one set of coefficients for the whole walk.
    """
    checked = validate_pedestrians(frame)
    coef = _force_coefficients(checked)
    cols = checked[["mass_kg", "stiffness_n_per_m", "damping_ns_per_m", "pacing_hz"]]
    return [
        SMDModel(
            mass_kg=m,
            stiffness_n_per_m=k,
            damping_ns_per_m=c,
            harmonics=HARMONICS,
            time_basis="absolute",
            pieces="whole",
            pacing_hz=fp,
            force_coefficients_n=tuple(row),
        )
        for (m, k, c, fp), row in zip(cols.to_numpy(float), coef, strict=True)
    ]


def walkers(frame: pd.DataFrame) -> list[Walker]:
    """Return the :class:`Walker` of each row of a pedestrian table (model and speed)."""
    checked = validate_pedestrians(frame)
    speeds = checked["speed_m_s"].to_numpy(float)
    return [Walker(m, float(v)) for m, v in zip(pedestrian_models(checked), speeds, strict=True)]


def as_walkers(
    pedestrians: pd.DataFrame | Sequence[Walker | SMDModel] | Walker | SMDModel,
    speed_m_s: ArrayLike | None = None,
) -> list[Walker]:
    """Walkers from a table, walkers, or SMD models with a walking speed.

    Parameters
    ----------
    pedestrians : DataFrame, Walker, SMDModel or sequence of Walker / SMDModel
        A pedestrian table, or the pedestrians themselves.
    speed_m_s : float or sequence of float, optional
        Speed of each bare :class:`SMDModel` (one value for all, or one per pedestrian);
        ignored for walkers and tables, which carry their own.

    Returns
    -------
    list of Walker
    """
    if isinstance(pedestrians, pd.DataFrame):
        return walkers(pedestrians)
    items = [pedestrians] if isinstance(pedestrians, Walker | SMDModel) else list(pedestrians)
    speeds = (
        [None] * len(items)
        if speed_m_s is None
        else list(np.broadcast_to(np.asarray(speed_m_s, float), (len(items),)))
    )
    out = []
    for item, v in zip(items, speeds, strict=True):
        if isinstance(item, Walker):
            out.append(item)
        elif v is None:
            _check_walking_model(item, "the pedestrians")
            raise UsageError(
                f"the pedestrians: {item!r} has no walking speed; pass speed_m_s=... or a "
                "Walker(model, speed_m_s)"
            )
        else:
            out.append(Walker(item, float(v)))
    return out


@dataclass(frozen=True)
class PedestrianArrays:
    """Walkers as arrays, the integrator's vectorised view of their models.

    Shapes ``(n,)``; force terms ``(n, H)`` with ``H`` the largest number of harmonics
    (missing ones are zero). The force of pedestrian ``p`` is
    ``a0_p + M_p g sum_i blf_pi cos(2 pi i f_p t + phase_pi)``, the model's
    ``force_coefficients_n`` written as amplitude and phase (module docstring), which is
    the form the integrator evaluates (one cosine per harmonic and step).
    """

    mass_kg: NDArray[np.float64]
    stiffness_n_per_m: NDArray[np.float64]
    damping_ns_per_m: NDArray[np.float64]
    pacing_hz: NDArray[np.float64]
    speed_m_s: NDArray[np.float64]
    blf: NDArray[np.float64]
    phase_rad: NDArray[np.float64]
    a0_n: NDArray[np.float64]

    @classmethod
    def from_models(
        cls,
        pedestrians: Sequence[Walker | SMDModel],
        speed_m_s: ArrayLike | None = None,
    ) -> PedestrianArrays:
        """From walkers (or SMD models and their speeds, as :func:`as_walkers`).

        Parameters
        ----------
        pedestrians : sequence of Walker or SMDModel
            The pedestrians (may be empty).
        speed_m_s : float or sequence of float, optional
            Speeds of bare models.

        Returns
        -------
        PedestrianArrays
        """
        ws = as_walkers(pedestrians, speed_m_s) if len(pedestrians) else []
        n = len(ws)
        h = max((w.model.harmonics for w in ws), default=HARMONICS)
        coef = np.zeros((n, 1 + 2 * h))
        for row, w in zip(coef, ws, strict=True):
            c = np.asarray(w.model.force_coefficients_n, float)
            row[: c.size] = c
        mass = np.array([w.model.mass_kg for w in ws], dtype=np.float64)
        cos_part, sin_part = coef[:, 1::2], coef[:, 2::2]
        return cls(
            mass_kg=mass,
            stiffness_n_per_m=np.array([w.model.stiffness_n_per_m for w in ws], np.float64),
            damping_ns_per_m=np.array([w.model.damping_ns_per_m for w in ws], np.float64),
            pacing_hz=np.array([w.model.pacing_hz for w in ws], np.float64),
            speed_m_s=np.array([w.speed_m_s for w in ws], np.float64),
            # FourierForce.blf and minus FourierForce.phases_rad, for all walkers at once.
            blf=np.hypot(cos_part, sin_part) / (mass[:, None] * G),
            phase_rad=np.arctan2(-sin_part, cos_part),
            a0_n=coef[:, 0].copy(),
        )

    @classmethod
    def from_frame(cls, frame: pd.DataFrame) -> PedestrianArrays:
        """From a pedestrian table, through its models (:func:`walkers`)."""
        return cls.from_models(walkers(frame))


#: What the simulation functions take as pedestrians: a pedestrian table, walkers, SMD
#: models (with a speed given separately), or their arrays.
Pedestrians: TypeAlias = (
    pd.DataFrame | PedestrianArrays | Walker | SMDModel | Sequence[Walker | SMDModel]
)


def pedestrian_arrays(
    pedestrians: Pedestrians, speed_m_s: ArrayLike | None = None
) -> PedestrianArrays:
    """Return the integrator's arrays of any accepted description of pedestrians.

    Parameters
    ----------
    pedestrians : DataFrame, PedestrianArrays, Walker, SMDModel or sequence of them
        A pedestrian table (checked), arrays (returned as they are), or walkers / models.
    speed_m_s : float or sequence of float, optional
        Speed of bare SMD models (see :func:`workbench.hsi.pedestrians.as_walkers`).

    Returns
    -------
    PedestrianArrays
    """
    if isinstance(pedestrians, PedestrianArrays):
        return pedestrians
    if isinstance(pedestrians, pd.DataFrame):
        return PedestrianArrays.from_frame(pedestrians)
    return PedestrianArrays.from_models(as_walkers(pedestrians, speed_m_s))


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
