"""The record type: one continuous vertical GRF measurement of one walking person."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

#: Standard gravity used throughout the workbench [m/s^2] (docs/science.md 1).
G_M_S2 = 9.81

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Record:
    """A vertical ground reaction force record.

    Records are immutable; processing functions return new records or arrays
    (use :meth:`replace`). Arrays are float64 and share one time base.

    Parameters
    ----------
    time_s : ndarray
        Sample times [s], strictly increasing and (after validation) evenly spaced.
    grf_n : ndarray
        Total vertical ground reaction force [N], positive upwards on the person.
    mass_kg : float or None
        Body mass [kg]. Required for anything beyond loading.
    grf_left_n, grf_right_n : ndarray or None
        Vertical force under each foot (or belt) [N], when the source has them.
    ground_acc_m_s2 : ndarray or None
        Measured vertical acceleration of the walking surface [m/s^2].
    pacing_hz : float or None
        Pacing (step) frequency stated by the source, if any; otherwise estimated.
    subject : str or None
        Subject identifier.
    source : str
        Where the record came from (a file path or a description).
    notes : str
        Free text carried from the source's metadata.
    metadata : mapping
        Anything else the loader found (format, original column names, corrections applied).
    """

    time_s: FloatArray
    grf_n: FloatArray
    mass_kg: float | None = None
    grf_left_n: FloatArray | None = None
    grf_right_n: FloatArray | None = None
    ground_acc_m_s2: FloatArray | None = None
    pacing_hz: float | None = None
    subject: str | None = None
    source: str = "<memory>"
    notes: str = ""
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("time_s", "grf_n", "grf_left_n", "grf_right_n", "ground_acc_m_s2"):
            value = getattr(self, name)
            if value is None:
                continue
            arr = np.asarray(value, dtype=np.float64)
            if arr.ndim != 1:
                raise ValueError(f"Record.{name} must be one-dimensional, got shape {arr.shape}")
            if arr.shape != np.shape(self.time_s):
                raise ValueError(
                    f"Record.{name} has {arr.size} samples but time_s has {np.size(self.time_s)}"
                )
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if self.mass_kg is not None:
            object.__setattr__(self, "mass_kg", float(self.mass_kg))
        if self.pacing_hz is not None:
            object.__setattr__(self, "pacing_hz", float(self.pacing_hz))

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.time_s.size)

    @property
    def dt_s(self) -> float:
        """Median sample interval [s]."""
        return float(np.median(np.diff(self.time_s))) if self.n_samples > 1 else float("nan")

    @property
    def sample_rate_hz(self) -> float:
        """Sample rate [Hz] from the median sample interval."""
        return 1.0 / self.dt_s

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample plus one interval [s]."""
        return float(self.time_s[-1] - self.time_s[0] + self.dt_s) if self.n_samples > 1 else 0.0

    @property
    def weight_n(self) -> float:
        """Body weight M g [N]; raises if the mass is unknown."""
        return self.require_mass() * G_M_S2

    @property
    def name(self) -> str:
        """Short display name: the subject, else the file stem of the source."""
        if self.subject:
            return self.subject
        stem = self.source.replace("\\", "/").rsplit("/", 1)[-1]
        return stem.rsplit(".", 1)[0] if "." in stem else stem

    def require_mass(self) -> float:
        """Return the body mass or raise a clear error telling how to give it."""
        if self.mass_kg is None:
            from workbench.errors import InputError

            raise InputError(
                self.source,
                "metadata",
                "no body mass was given",
                'pass mass_kg=... (--mass KG on the command line) or add "mass_kg" to the '
                "JSON sidecar or the manifest",
            )
        return self.mass_kg

    def replace(self, **changes: Any) -> Record:
        """Return a copy with the given fields changed."""
        return dataclasses.replace(self, **changes)

    def slice(self, t0_s: float, t1_s: float) -> Record:
        """Return the part of the record with ``t0_s <= t < t1_s`` (times kept as they are).

        Parameters
        ----------
        t0_s, t1_s : float
            Start and end of the part [s], on the record's own time axis.

        Returns
        -------
        Record
            The same person, mass and metadata; every column cut to the window.
        """
        from workbench.errors import UsageError

        t0, t1 = float(t0_s), float(t1_s)
        first, last = float(self.time_s[0]), float(self.time_s[-1])
        if not (np.isfinite(t0) and np.isfinite(t1) and t0 < t1):
            raise UsageError(
                f"{self.name}: slice({t0_s!r}, {t1_s!r}) needs a finite start before its end; "
                f"give times in seconds within {first:g}-{last:g} s"
            )
        keep = (self.time_s >= t0) & (self.time_s < t1)
        if np.count_nonzero(keep) < 2:
            raise UsageError(
                f"{self.name}: slice({t0:g}, {t1:g}) holds fewer than two samples; the record "
                f"spans {first:g}-{last:g} s, so give a window inside it"
            )
        changes: dict[str, Any] = {}
        for name in ("time_s", "grf_n", "grf_left_n", "grf_right_n", "ground_acc_m_s2"):
            value = getattr(self, name)
            changes[name] = None if value is None else value[keep]
        return self.replace(**changes)

    def __repr__(self) -> str:
        mass = "unknown" if self.mass_kg is None else f"{self.mass_kg:g} kg"
        return (
            f"Record({self.name!r}, {self.n_samples} samples at {self.sample_rate_hz:.4g} Hz, "
            f"{self.duration_s:.2f} s, mass {mass})"
        )
