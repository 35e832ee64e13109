"""Reference solution of the coupled crossing by scipy's adaptive ``solve_ivp``.

The same first-order system as :func:`workbench.hsi.simulate.integrate` (matrices from
:func:`workbench.hsi.modes.coupled_matrices` at each instant), integrated by an explicit
Runge-Kutta method to a tight tolerance: the benchmark's speed reference and the tests'
accuracy reference.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from workbench.hsi.modes import coupled_matrices
from workbench.hsi.pedestrians import G, Pedestrians, pedestrian_arrays
from workbench.hsi.structure import ModalStructure

__all__ = ["solve_ivp_crossing"]


def solve_ivp_crossing(
    structure: ModalStructure,
    pedestrians: Pedestrians,
    x0_m: NDArray[np.float64],
    speed_m_s: NDArray[np.float64],
    time_s: NDArray[np.float64],
    *,
    response_x_m: float | None = None,
    rtol: float = 1e-8,
) -> NDArray[np.float64]:
    """Deck acceleration at ``response_x_m`` (midspan) at ``time_s``, coupled model.

    Parameters
    ----------
    structure : ModalStructure
        The modes.
    pedestrians : DataFrame, Walker, SMDModel or sequence of Walker / SMDModel
        A pedestrian table (checked here) or the pedestrians' models.
    x0_m, speed_m_s : array
        Position of each pedestrian at ``t = 0`` [m] and the speed it moves at [m/s].
    time_s : array
        Output times [s]; the integration starts at ``time_s[0]``.
    response_x_m : float, optional
        Where the acceleration is taken (default midspan).
    rtol : float
        Relative tolerance of ``solve_ivp``.

    Returns
    -------
    ndarray
        Deck acceleration [m/s^2] at ``time_s``.
    """
    a = pedestrian_arrays(pedestrians, speed_m_s)
    j, p = structure.n_modes, a.mass_kg.size
    n = j + p
    i = np.arange(1, a.blf.shape[1] + 1)
    w = 2 * np.pi * i * a.pacing_hz[:, None]

    def force(t: float) -> NDArray[np.float64]:
        # The biomechanical force pushes the body up and the deck down.
        vec = np.zeros(n)
        vec[j:] = G * a.mass_kg * np.sum(a.blf * np.cos(w * t + a.phase_rad), axis=1) + a.a0_n
        vec[:j] = -structure.shapes(x0_m + speed_m_s * t).T @ vec[j:]
        return vec

    def matrices(t: float) -> tuple[NDArray[np.float64], ...]:
        return coupled_matrices(
            structure, a.mass_kg, a.stiffness_n_per_m, a.damping_ns_per_m, x0_m + speed_m_s * t
        )

    def rhs(t: float, s: NDArray[np.float64]) -> NDArray[np.float64]:
        mass, damp, stiff = matrices(t)
        acc = (force(t) - damp @ s[n:] - stiff @ s[:n]) / np.diag(mass)
        return np.concatenate([s[n:], acc])

    # Walkers start in steady state on rigid ground, the deck at rest (as the integrator).
    amp = (
        G
        * a.mass_kg[:, None]
        * a.blf
        * np.exp(1j * a.phase_rad)
        / (
            a.stiffness_n_per_m[:, None]
            - a.mass_kg[:, None] * w**2
            + 1j * a.damping_ns_per_m[:, None] * w
        )
    )
    s0 = np.zeros(2 * n)
    s0[j:n] = amp.real.sum(axis=1) + a.a0_n / a.stiffness_n_per_m
    s0[n + j :] = (1j * w * amp).real.sum(axis=1)
    sol = solve_ivp(
        rhs, (time_s[0], time_s[-1]), s0, t_eval=time_s, rtol=rtol, atol=1e-12, method="DOP853"
    )
    xr = structure.span_m / 2 if response_x_m is None else response_x_m
    phi_r = structure.shapes(np.array([xr]))[0]
    out = np.empty(time_s.size)
    for k, t in enumerate(time_s):
        out[k] = phi_r @ rhs(float(t), sol.y[:, k])[n : n + j]
    return out
