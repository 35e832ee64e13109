"""Gait profiles: how each step of a walk differs from steady walking.

A :class:`GaitProfile` scales every simulated step's duration and force amplitude relative
to steady walking at the requested pacing. Steady walking on the spot (the simulator's
default) has every factor 1. The two profiles the model criticism needs are the seed
study's overground protocol and a walk that changes speed: both change the record's
amplitude and pacing inside the record, which is where a nonlinear spring or damper changes
the response in a way one force shape cannot copy.

Overground walk (the seed study's protocol: a 40 m track walked from standing to
standing). Standing steps have amplitude factor 0: the force is the constant body weight
and the step clock only runs on. Gait initiation and termination take three steps each,
with the amplitude rising as 0.35, 0.70, 0.90 and the step duration falling as 1.30, 1.12,
1.04 of steady walking, mirrored at the end. These ramps are assumptions of the workbench,
chosen to match the usual description of gait initiation (a slower, lighter first step
and steady walking by the third); docs/guide/simulate.md states them as such.

Speed change (the real treadmill trial changes belt speed): steady walking at the
requested pacing, a ramp over a few steps to ``pacing_ratio`` times it, and steady walking
at the new pacing. The amplitudes follow Young's BLF1 law ``0.41 (f_p - 0.95)``, the one the
population sampler uses, so a faster walker also pushes harder.

Double-humped steps (:func:`double_hump_force`): the mean step force as two humps of chosen
relative height, the loading hump after heel strike and the push-off hump before the next
one, for testing that footfalls do not jump between humps of similar height.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.records.record import G_M_S2

__all__ = ["DOUBLE_HUMP_PHASES_STEP", "GaitProfile", "double_hump_force"]

FloatArray = NDArray[np.float64]

#: Gait initiation, first step first: force amplitude and step duration relative to steady.
INITIATION_AMPLITUDE = (0.35, 0.70, 0.90)
INITIATION_DURATION = (1.30, 1.12, 1.04)
#: Young's BLF1 law's pacing offset [Hz]: BLF1 = 0.41 (f_p - 0.95).
BLF1_OFFSET_HZ = 0.95
#: Fewest steps of an overground walk: three to start, three to stop, two steady.
MIN_WALKING_STEPS = 2 * len(INITIATION_AMPLITUDE) + 2
#: Range of a speed change's new pacing over the old one.
PACING_RATIO_RANGE = (0.7, 1.4)
#: Step phase of the loading hump and of the push-off hump of :func:`double_hump_force`
#: [share of a step after heel strike]: loading a quarter step after heel strike, push-off
#: just before the other foot's heel strike, so 0.35 step apart across the boundary and
#: 0.65 step apart within the step (the mid-stance valley between them).
DOUBLE_HUMP_PHASES_STEP = (0.25, 0.9)


@dataclass(frozen=True)
class GaitProfile:
    """Per-step duration and amplitude factors relative to steady walking.

    Parameters
    ----------
    duration_factors, amplitude_factors : tuple of float
        One value per step, first step first; steps beyond the end keep the last value.
        An amplitude factor of 0 is standing (the force is the body weight alone).
    label : str
        What the profile is, for the simulation's truth.
    """

    duration_factors: tuple[float, ...]
    amplitude_factors: tuple[float, ...]
    label: str = "custom"

    def __post_init__(self) -> None:
        dur = np.asarray(self.duration_factors, dtype=np.float64)
        amp = np.asarray(self.amplitude_factors, dtype=np.float64)
        if dur.size == 0 or dur.size != amp.size:
            raise UsageError(
                "GaitProfile: give one duration factor and one amplitude factor per step "
                f"(got {dur.size} and {amp.size})"
            )
        if not (np.all(np.isfinite(dur)) and np.all(dur >= 0.5) and np.all(dur <= 2.0)):
            raise UsageError(
                "GaitProfile: step duration factors must lie in 0.5-2 (half to twice a steady step)"
            )
        if not (np.all(np.isfinite(amp)) and np.all(amp >= 0.0) and np.all(amp <= 2.0)):
            raise UsageError("GaitProfile: amplitude factors must lie in 0-2 (0 is standing)")

    @classmethod
    def overground(cls, walking_steps: int = 24, standing_steps: int = 3) -> GaitProfile:
        """Return the overground protocol: stand, start, walk, stop, stand.

        Parameters
        ----------
        walking_steps : int, default 24
            Steps from the first to the last footfall, initiation and termination included
            (the seed's 40 m walks give 20-30 on the measured stretch); at least 8.
        standing_steps : int, default 3
            Step periods of standing before and after the walk.
        """
        if int(walking_steps) != walking_steps or walking_steps < MIN_WALKING_STEPS:
            raise UsageError(
                "GaitProfile.overground: walking_steps must be a whole number of at least "
                f"{MIN_WALKING_STEPS} "
                f"(three to start, three to stop, two steady), got {walking_steps!r}"
            )
        if int(standing_steps) != standing_steps or standing_steps < 1:
            raise UsageError(
                f"GaitProfile.overground: standing_steps must be a whole number of at least 1, "
                f"got {standing_steps!r}"
            )
        steady = int(walking_steps) - 2 * len(INITIATION_AMPLITUDE)
        stand = int(standing_steps)
        amp = (0.0,) * stand + INITIATION_AMPLITUDE + (1.0,) * steady
        amp += INITIATION_AMPLITUDE[::-1] + (0.0,) * stand
        dur = (1.0,) * stand + INITIATION_DURATION + (1.0,) * steady
        dur += INITIATION_DURATION[::-1] + (1.0,) * stand
        return cls(dur, amp, f"overground: {walking_steps} steps between {stand} standing")

    @classmethod
    def speed_change(
        cls,
        pacing_hz: float,
        pacing_ratio: float = 1.15,
        steps_before: int = 15,
        ramp_steps: int = 4,
        steps_after: int = 15,
    ) -> GaitProfile:
        """Return a walk that changes pace: steady, a ramp, steady at the new pacing.

        Parameters
        ----------
        pacing_hz : float
            The walk's starting pacing [Hz] (the amplitude law depends on it).
        pacing_ratio : float, default 1.15
            New pacing over the old one (0.7-1.4).
        steps_before, ramp_steps, steps_after : int
            Steps at the old pacing, of the linear ramp, and at the new pacing.
        """
        lo, hi = PACING_RATIO_RANGE
        if not (np.isfinite(pacing_ratio) and lo <= pacing_ratio <= hi):
            raise UsageError(
                f"GaitProfile.speed_change: pacing_ratio must lie in 0.7-1.4, got {pacing_ratio!r}"
            )
        if pacing_hz <= BLF1_OFFSET_HZ or pacing_hz * pacing_ratio <= BLF1_OFFSET_HZ:
            raise UsageError(
                "GaitProfile.speed_change: the pacing must stay above 0.95 Hz, where the "
                "BLF1 law that scales the amplitudes is positive"
            )
        counts = (steps_before, ramp_steps, steps_after)
        if any(int(c) != c or c < 1 for c in counts):
            raise UsageError("GaitProfile.speed_change: step counts must be whole and positive")
        ratio = np.concatenate(
            [
                np.ones(int(steps_before)),
                np.linspace(1.0, pacing_ratio, int(ramp_steps) + 2)[1:-1],
                np.full(int(steps_after), pacing_ratio),
            ]
        )
        amp = (pacing_hz * ratio - BLF1_OFFSET_HZ) / (pacing_hz - BLF1_OFFSET_HZ)
        return cls(
            tuple(float(x) for x in 1.0 / ratio),
            tuple(float(x) for x in amp),
            f"speed change: pacing x {pacing_ratio:g} over {ramp_steps} steps",
        )

    @property
    def n_steps(self) -> int:
        """Number of steps the profile describes."""
        return len(self.duration_factors)

    def relative_length(self) -> float:
        """Return the profile's length in steady step periods."""
        return float(np.sum(self.duration_factors))

    def step_factors(self, n_steps: int) -> tuple[FloatArray, FloatArray]:
        """Return the duration factors of steps 0..n-1 and the amplitude factors of -1..n.

        The amplitude factors are those of the simulator's force knots (one before the first
        step and one after the last); steps outside the profile keep its end values.
        """
        dur = np.asarray(self.duration_factors, dtype=np.float64)
        amp = np.asarray(self.amplitude_factors, dtype=np.float64)
        index = np.clip(np.arange(n_steps), 0, dur.size - 1)
        knots = np.clip(np.arange(-1, n_steps + 1), 0, amp.size - 1)
        return dur[index], amp[knots]

    def to_json(self) -> dict[str, Any]:
        """Return the profile as JSON-able values (for the simulation's truth)."""
        return {
            "label": self.label,
            "duration_factors": list(self.duration_factors),
            "amplitude_factors": list(self.amplitude_factors),
        }


def double_hump_force(
    mass_kg: float,
    hump_ratio: float = 1.0,
    *,
    peak_fraction: float = 0.25,
    width_step: float = 0.1,
    harmonics: int = 4,
) -> tuple[float, ...]:
    """Return the mean step force of a double-humped step as Fourier coefficients.

    The force over one step (phase ``theta`` from 0 at heel strike to ``2 pi``) is two
    periodic Gaussian humps at :data:`DOUBLE_HUMP_PHASES_STEP`, the push-off hump
    ``hump_ratio`` times the loading one, kept to ``harmonics`` harmonics (without the
    constant) and scaled so that its maximum is ``peak_fraction`` of the body weight above
    the mean. Pass the result as ``coefficients=`` to
    :func:`~workbench.synth.simulate_walking`.

    Parameters
    ----------
    mass_kg : float
        Body mass [kg].
    hump_ratio : float, default 1.0
        Height of the push-off hump over the loading hump (above 0, at most 2); 0.8-1.25
        are humps that differ by up to 20 %.
    peak_fraction : float, default 0.25
        Highest point of the step force above the body weight, as a share of it.
    width_step : float, default 0.1
        Standard deviation of each hump [share of a step].
    harmonics : int, default 4
        Harmonics kept.

    Returns
    -------
    tuple of float
        ``a0, a1, b1, ..., an, bn`` [N] in the simulator's convention
        ``a0 + sum_i a_i cos(i theta) + b_i sin(i theta)``, with ``a0 = 0``.
    """
    checks = (
        (mass_kg, 0.0, np.inf, "mass_kg"),
        (hump_ratio, 0.0, 2.0, "hump_ratio"),
        (peak_fraction, 0.0, 1.0, "peak_fraction"),
        (width_step, 0.02, 0.3, "width_step"),
    )
    for value, lo, hi, name in checks:
        if not (np.isfinite(value) and lo < value <= hi):
            raise UsageError(
                f"double_hump_force: {name} must lie in ({lo:g}, {hi:g}], got {value!r}"
            )
    if int(harmonics) != harmonics or harmonics < 2:
        raise UsageError(
            f"double_hump_force: harmonics must be a whole number >= 2, got {harmonics!r}"
        )
    grid = np.arange(4096) / 4096.0
    shape = np.zeros_like(grid)
    for centre, height in zip(DOUBLE_HUMP_PHASES_STEP, (1.0, float(hump_ratio)), strict=True):
        distance = (grid - centre + 0.5) % 1.0 - 0.5
        shape += height * np.exp(-0.5 * (distance / width_step) ** 2)
    orders = np.arange(1, int(harmonics) + 1)
    cos = np.cos(2.0 * np.pi * np.outer(orders, grid))
    sin = np.sin(2.0 * np.pi * np.outer(orders, grid))
    a = 2.0 * (cos @ shape) / grid.size
    b = 2.0 * (sin @ shape) / grid.size
    kept = a @ cos + b @ sin
    scale = peak_fraction * mass_kg * G_M_S2 / float(kept.max())
    coefficients = np.zeros(1 + 2 * orders.size)
    coefficients[1::2] = scale * a
    coefficients[2::2] = scale * b
    return tuple(float(x) for x in coefficients)
