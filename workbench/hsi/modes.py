"""Eigen-analysis of the occupied structure: apparent frequencies and damping ratios.

The matrices are those :func:`workbench.hsi.simulate.integrate` advances, with the
pedestrians frozen at given positions: unknowns ``(q_1..q_J, y_1..y_P)``,
``M = diag(m_j, M_p)``, ``K = [[diag(k_j) + sum_p K_p phi_p phi_p^T, -K_p phi_p],
[-K_p phi_p^T, diag(K_p)]]`` and ``C`` alike. A complex eigenvalue ``lambda`` gives the
frequency ``|lambda| / 2 pi`` and damping ratio ``-Re(lambda) / |lambda|`` (the undamped
natural frequency and damping ratio of an equivalent single-degree-of-freedom oscillator).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.hsi.pedestrians import Pedestrians, pedestrian_arrays
from workbench.hsi.structure import ModalStructure

__all__ = ["CoupledMode", "apparent_structure_modes", "coupled_matrices", "coupled_modes"]


@dataclass(frozen=True)
class CoupledMode:
    """One mode of the occupied structure.

    Attributes
    ----------
    frequency_hz, damping_ratio : float
    structure_share : float
        Fraction of the mode's kinetic energy in the structure (1: a pure deck mode).
    dominant_structure_mode : int
        Index of the structural mode with the largest share.
    """

    frequency_hz: float
    damping_ratio: float
    structure_share: float
    dominant_structure_mode: int


def coupled_matrices(
    structure: ModalStructure,
    mass_kg: ArrayLike,
    stiffness_n_per_m: ArrayLike,
    damping_ns_per_m: ArrayLike,
    positions_m: ArrayLike,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Mass, damping and stiffness matrices of the structure with SMDs at ``positions_m``."""
    mp = np.atleast_1d(np.asarray(mass_kg, float))
    kp = np.atleast_1d(np.asarray(stiffness_n_per_m, float))
    cp = np.atleast_1d(np.asarray(damping_ns_per_m, float))
    phi = structure.shapes(np.atleast_1d(np.asarray(positions_m, float)))  # (P, J)
    j = structure.n_modes
    n = j + mp.size
    mass = np.diag(np.concatenate([structure.modal_masses_kg, mp]))
    out = []
    for diag_s, vals in (
        (structure.dampings_ns_per_m, cp),
        (structure.stiffnesses_n_per_m, kp),
    ):
        a = np.zeros((n, n))
        a[:j, :j] = np.diag(diag_s) + (phi.T * vals) @ phi
        a[:j, j:] = -(phi.T * vals)
        a[j:, :j] = a[:j, j:].T
        a[j:, j:] = np.diag(vals)
        out.append(a)
    return mass, out[0], out[1]


def coupled_modes(
    structure: ModalStructure, pedestrians: Pedestrians, positions_m: ArrayLike
) -> list[CoupledMode]:
    """All modes of the structure occupied by pedestrians standing at ``positions_m``.

    Parameters
    ----------
    structure : ModalStructure
        The modes of the empty structure.
    pedestrians : DataFrame, Walker, SMDModel or sequence of Walker / SMDModel
        A pedestrian table (checked here) or the pedestrians' models; only M, K and C
        matter here.
    positions_m : array_like
        Where each pedestrian is [m].

    Returns
    -------
    list of CoupledMode
        Sorted by structure share, largest first (deck-dominated modes first).
    """
    a = pedestrian_arrays(pedestrians, 0.0)
    return _modes(structure, a.mass_kg, a.stiffness_n_per_m, a.damping_ns_per_m, positions_m)


def _modes(
    structure: ModalStructure,
    mass_kg: ArrayLike,
    stiffness_n_per_m: ArrayLike,
    damping_ns_per_m: ArrayLike,
    positions_m: ArrayLike,
) -> list[CoupledMode]:
    mass, damp, stiff = coupled_matrices(
        structure, mass_kg, stiffness_n_per_m, damping_ns_per_m, positions_m
    )
    n = mass.shape[0]
    minv = 1.0 / np.diag(mass)
    first = np.block(
        [[np.zeros((n, n)), np.eye(n)], [-(minv[:, None] * stiff), -(minv[:, None] * damp)]]
    )
    lam, vec = np.linalg.eig(first)
    modes = []
    j = structure.n_modes
    for k in np.flatnonzero(lam.imag > 0):
        # Kinetic-energy shares from the velocity part of the eigenvector.
        v = vec[n:, k]
        energy = np.diag(mass) * np.abs(v) ** 2
        share = float(energy[:j].sum() / energy.sum())
        modes.append(
            CoupledMode(
                frequency_hz=float(abs(lam[k]) / (2 * np.pi)),
                damping_ratio=float(-lam[k].real / abs(lam[k])),
                structure_share=share,
                dominant_structure_mode=int(np.argmax(energy[:j])),
            )
        )
    return sorted(modes, key=lambda m: -m.structure_share)


def apparent_structure_modes(
    structure: ModalStructure,
    mass_kg: ArrayLike,
    stiffness_n_per_m: ArrayLike,
    damping_ns_per_m: ArrayLike,
    positions_m: ArrayLike,
) -> list[CoupledMode]:
    """For each structural mode, the occupied-structure mode that carries most of it."""
    modes = _modes(structure, mass_kg, stiffness_n_per_m, damping_ns_per_m, positions_m)
    out = []
    for jj in range(structure.n_modes):
        cands = [m for m in modes if m.dominant_structure_mode == jj]
        out.append(max(cands, key=lambda m: m.structure_share) if cands else modes[0])
    return out
