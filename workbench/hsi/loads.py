"""Force-only load models engineers use: the moving harmonic force and the Setra/HiVoSS crowd.

These ignore interaction; they are the comparisons the interaction model is judged against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.errors import UsageError
from workbench.hsi.pedestrians import design_pedestrian
from workbench.hsi.simulate import HsiHistory, simulate_pedestrians
from workbench.hsi.structure import ModalStructure

__all__ = ["SetraLoad", "moving_harmonic_force", "setra_crowd_load", "setra_psi"]

#: Setra/HiVoSS amplitude of the vertical load of one pedestrian [N].
SETRA_P_N = 280.0


def moving_harmonic_force(
    structure: ModalStructure,
    *,
    amplitude_n: float,
    frequency_hz: float,
    speed_m_s: float,
    dt_s: float = 0.005,
    response_x_m: float | None = None,
) -> HsiHistory:
    """Simulate a harmonic force ``F0 cos(2 pi f t)`` crossing the span at constant speed.

    Integrated by the same Newmark scheme as the pedestrian models (docs/science.md 7: 311.9 N at
    2 Hz and 1.25 m/s on the 50 m beam peaks at 1.734 m/s^2 at midspan).
    """
    if not (np.isfinite(amplitude_n) and amplitude_n >= 0):
        raise UsageError(f"the force amplitude must be a non-negative number, got {amplitude_n}")
    # A walker of any mass whose biomechanical force is the given harmonic; under the
    # biomechanical-force model its SMD does not act, only the force does.
    mass = 70.0
    walker = design_pedestrian(
        mass_kg=mass,
        pacing_hz=frequency_hz,
        speed_m_s=speed_m_s,
        natural_frequency_hz=2.0,
        damping_ratio=0.3,
        blf=(amplitude_n / (mass * 9.81), 0.0, 0.0),
    )
    return simulate_pedestrians(
        structure, walker, dt_s=dt_s, model="biomechanical_force", response_x_m=response_x_m
    )


def setra_psi(frequency_hz: float) -> float:
    """Setra/HiVoSS reduction factor for vertical walking loads at a modal frequency.

    1 between 1.7 and 2.1 Hz (first harmonic of normal walking), 0.25 between 3.4 and
    4.2 Hz (the second harmonic, equivalent to Setra's 70 N), linear in between, 0 below
    1.25 Hz, between 2.3 and 2.5 Hz and above 4.6 Hz.
    """
    xs = (1.25, 1.7, 2.1, 2.3, 2.5, 3.4, 4.2, 4.6)
    ys = (0.0, 1.0, 1.0, 0.0, 0.0, 0.25, 0.25, 0.0)
    return float(np.interp(frequency_hz, xs, ys, left=0.0, right=0.0))


@dataclass(frozen=True)
class SetraLoad:
    """Setra/HiVoSS equivalent crowd load on one mode and its resonant response.

    Attributes
    ----------
    mode : int
        Index of the mode (0 first).
    pedestrians : float
        ``n = density * span * width``.
    equivalent_pedestrians : float
        ``10.8 sqrt(zeta n)`` below 1 pedestrian/m^2, ``1.85 sqrt(n)`` from there on.
    load_n_per_m2 : float
        Amplitude of the harmonic surface load ``P n_eq psi / S``.
    peak_acceleration_m_s2 : float
        Steady resonant amplitude at the response point (load applied with the sign of the
        mode shape, at the modal frequency).
    """

    mode: int
    pedestrians: float
    equivalent_pedestrians: float
    load_n_per_m2: float
    peak_acceleration_m_s2: float


def setra_crowd_load(
    structure: ModalStructure,
    density_per_m2: float,
    *,
    mode: int = 0,
    response_x_m: float | None = None,
) -> SetraLoad:
    """Setra (2006) / HiVoSS (2008) uniformly distributed crowd load, resonant response.

    Parameters
    ----------
    structure : ModalStructure
        The footbridge (its width sets the deck area).
    density_per_m2 : float
        Crowd density [pedestrians/m^2].
    mode : int
        Mode loaded (0 first); the load oscillates at its frequency.
    response_x_m : float, optional
        Default: where the mode shape is largest.

    Returns
    -------
    SetraLoad
    """
    if not (np.isfinite(density_per_m2) and density_per_m2 > 0):
        raise UsageError(f"the crowd density must be positive, got {density_per_m2}")
    if not 0 <= mode < structure.n_modes:
        raise UsageError(f"mode {mode} does not exist; the structure has {structure.n_modes}")
    area = structure.span_m * structure.width_m
    n = density_per_m2 * area
    zeta = float(structure.damping_ratios[mode])
    n_eq = 10.8 * np.sqrt(zeta * n) if density_per_m2 < 1.0 else 1.85 * np.sqrt(n)
    f = float(structure.frequencies_hz[mode])
    p = SETRA_P_N * n_eq * setra_psi(f) / area
    modal_force = p * structure.width_m * float(structure.abs_shape_integrals_m()[mode])
    if response_x_m is None:
        x = np.linspace(0, structure.span_m, 2001)
        phi_r = float(np.max(np.abs(structure.shapes(x)[:, mode])))
    else:
        phi_r = abs(float(structure.shapes(np.array([response_x_m]))[0, mode]))
    acc = modal_force / (2 * zeta * float(structure.modal_masses_kg[mode])) * phi_r
    return SetraLoad(mode, float(n), float(n_eq), float(p), float(acc))
