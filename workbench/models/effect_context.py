"""What an effect works on: its parameters, its context and a record prepared for criticism.

The data types shared by the effect mechanism (:mod:`workbench.models.effect_base`), the
catalogue (:mod:`workbench.models.effects`) and their users:

- :class:`Parameter`: one parameter of an effect (name with unit suffix, unit, default);
- :class:`EffectContext`: what an effect's term may need besides the state ``(u, u', t)``;
- :class:`CriticismRecord`: what an effect's criticism columns and statistic may read from a
  record prepared for model criticism. The concrete type is
  :class:`workbench.diagnostics.criticism.CriticismData`; models must not import diagnostics,
  so effects see it through this protocol.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.models.force import step_index, step_phase_rad

__all__ = [
    "CRITICISM_HARMONICS",
    "CriticismRecord",
    "EffectContext",
    "Parameter",
    "phase_harmonics",
]

FloatArray = NDArray[np.float64]

#: Harmonics of the criticism baseline's shared force shape by default
#: (``workbench.diagnostics.criticism.DEFAULT_HARMONICS``); the heel-impact columns start
#: above them.
CRITICISM_HARMONICS = 6


@dataclass(frozen=True)
class Parameter:
    """One parameter of an effect.

    Parameters
    ----------
    name : str
        Identifier in the field's words with a unit suffix, e.g. ``"k3_n_per_m3"``.
    unit : str
        Unit in plain text, e.g. ``"N/m^3"``.
    default : float
        Value used when the effect is created without one (usually "effect absent").
    description : str
        One line saying what it is.
    typical : float, optional
        A clearly visible but realistic value, for simulations and demonstrations
        (``Effect.typical()``, the command line's ``simulate --effect NAME``); None means
        use ``default``.
    """

    name: str
    unit: str
    default: float = 0.0
    description: str = ""
    typical: float | None = None


@dataclass(frozen=True, eq=False)
class EffectContext:
    """What an effect may need besides the state ``(u, u', t)``.

    All fields are optional; an effect that needs a missing one raises a ``UsageError``
    saying which. :meth:`SMDModel.acceleration <workbench.models.smd.SMDModel.acceleration>`
    fills ``mass_kg``, ``stiffness_n_per_m`` and ``damping_ns_per_m`` from the model.

    Parameters
    ----------
    mass_kg : float, optional
        Body mass [kg].
    pacing_hz : float, optional
        Pacing (step) frequency [Hz].
    stiffness_n_per_m, damping_ns_per_m : float or ndarray, optional
        The model's K [N/m] and C [N s/m] (arrays when evaluated per particle).
    step_start_s : ndarray, optional
        Step start (footfall) times [s], strictly increasing.
    ground_time_s, ground_disp_m, ground_vel_m_s, ground_acc_m_s2 : ndarray, optional
        Measured or prescribed motion of the walking surface on a time grid.
    ground_motion : callable, optional
        ``t_s -> (disp_m, vel_m_s, acc_m_s2)``; when given, :meth:`ground_at` uses it instead
        of interpolating the arrays (the simulator passes its exact ground motion).
    step_amplitude : ndarray, optional
        The walker's force amplitude factor of each step, one per entry of
        ``step_start_s`` (a gait profile, :mod:`workbench.synth.gait`: 0 while standing,
        rising through gait initiation). Effects that are part of the walker's force (a
        left/right asymmetry, heel impacts, a drift of the force) scale with it, so that
        nothing strikes the floor while the walker stands. None is 1 for every step.
    extra : mapping, optional
        Anything else a user-written effect needs.
    """

    mass_kg: float | None = None
    pacing_hz: float | None = None
    stiffness_n_per_m: float | FloatArray | None = None
    damping_ns_per_m: float | FloatArray | None = None
    step_start_s: FloatArray | None = None
    ground_time_s: FloatArray | None = None
    ground_disp_m: FloatArray | None = None
    ground_vel_m_s: FloatArray | None = None
    ground_acc_m_s2: FloatArray | None = None
    ground_motion: Callable[[ArrayLike], tuple[Any, Any, Any]] | None = None
    step_amplitude: FloatArray | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def _require(self, attribute: str, who: str) -> Any:
        value = getattr(self, attribute)
        if value is None:
            raise UsageError(
                f"{who}: the effect context has no '{attribute}'; pass an EffectContext "
                f"with '{attribute}' set"
            )
        return value

    def step_index(self, t_s: ArrayLike) -> NDArray[np.int64]:
        """Return the index of the step containing each time (see ``force.step_index``)."""
        return step_index(t_s, self._require("step_start_s", "EffectContext.step_index"))

    def step_phase_rad(self, t_s: ArrayLike) -> FloatArray:
        """Return the continuous step phase, ``2 pi`` per step (see ``force.step_phase_rad``)."""
        return step_phase_rad(t_s, self._require("step_start_s", "EffectContext.step_phase_rad"))

    def amplitude_at(self, t_s: ArrayLike) -> FloatArray:
        """Return the walker's force amplitude factor at each time (1 without a gait profile)."""
        t = np.asarray(t_s, dtype=np.float64)
        if self.step_amplitude is None:
            return np.ones_like(t)
        amp = np.asarray(self.step_amplitude, dtype=np.float64)
        return np.asarray(amp[np.clip(self.step_index(t), 0, amp.size - 1)], dtype=np.float64)

    def ground_at(self, t_s: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return ground displacement [m], velocity [m/s] and acceleration [m/s^2] at the times.

        Uses ``ground_motion`` when set, otherwise linear interpolation of the arrays
        (exact at their samples).
        """
        if self.ground_motion is not None:
            d, v, a = self.ground_motion(t_s)
            return (np.asarray(d, float), np.asarray(v, float), np.asarray(a, float))
        tg = self._require("ground_time_s", "EffectContext.ground_at")
        t = np.asarray(t_s, dtype=np.float64)
        out = []
        for attribute in ("ground_disp_m", "ground_vel_m_s", "ground_acc_m_s2"):
            out.append(np.interp(t, tg, self._require(attribute, "EffectContext.ground_at")))
        return out[0], out[1], out[2]


class CriticismRecord(Protocol):
    """A record prepared for model criticism, as an effect's criticism methods see it.

    :class:`workbench.diagnostics.criticism.CriticismData` implements it (see there for the
    meaning of each field); only samples inside whole steps are kept. Arrays are on the
    kept samples.
    """

    @property
    def time_s(self) -> FloatArray:
        """Sample times [s]."""

    @property
    def target_n(self) -> FloatArray:
        """``GRF - M g`` [N], the quantity predicted."""

    @property
    def disp_m(self) -> FloatArray:
        """COM displacement [m] (preprocessed)."""

    @property
    def vel_m_s(self) -> FloatArray:
        """COM velocity [m/s] (preprocessed)."""

    @property
    def phase_rad(self) -> FloatArray:
        """Step phase, ``2 pi`` per step, 0 at the first kept footfall."""

    @property
    def step(self) -> NDArray[np.int64]:
        """Index of the step each sample belongs to."""

    @property
    def mass_kg(self) -> float:
        """Body mass [kg]."""

    @property
    def pacing_hz(self) -> float:
        """Mean pacing [Hz]."""

    @property
    def sample_rate_hz(self) -> float:
        """Sample rate [Hz]."""

    @property
    def footfall_times_s(self) -> FloatArray:
        """Step boundaries of the kept steps [s]."""

    @property
    def ground(self) -> tuple[FloatArray, FloatArray, FloatArray] | None:
        """Ground displacement [m], velocity [m/s], acceleration [m/s^2], when measured."""

    @property
    def n_steps(self) -> int:
        """Number of whole steps kept."""

    @property
    def step_fraction(self) -> FloatArray:
        """Position within the step, 0 at footfall and 1 at the next."""

    def centred_time(self) -> FloatArray:
        """Time scaled to ``[-1/2, 1/2]`` over the kept samples (dimensionless)."""

    def state_without_stride_lines(self) -> tuple[FloatArray, FloatArray]:
        """``u`` and ``u'`` with their steady lines at odd multiples of ``f_p / 2`` removed."""

    def shape_slope(self) -> FloatArray:
        """Step-phase derivative of the record's shared force shape [N/rad]."""

    def slow_pacing_change(self) -> FloatArray | None:
        """Slow change of the pacing along the record [Hz], or None without a local pacing."""

    def force_timed_phase(self) -> FloatArray:
        """Step phase with each step re-timed to its own force [rad]."""


def phase_harmonics(phi: FloatArray, orders: Iterable[float]) -> FloatArray:
    """Columns ``cos(k phi), sin(k phi)`` for each order ``k``, interleaved.

    Parameters
    ----------
    phi : ndarray, shape (n,)
        Step phase [rad].
    orders : iterable of float
        Orders (multiples of the pacing; half orders are stride lines).

    Returns
    -------
    ndarray, shape (n, 2 len(orders))
    """
    cols = []
    for k in orders:
        cols.append(np.cos(k * phi))
        cols.append(np.sin(k * phi))
    return np.stack(cols, axis=1)
