"""Discretisation of the SMD state ``(u, u')`` over one sample interval, batched over (C, K).

Holds :func:`transition_matrices` and the helpers the Kalman filters of
:mod:`workbench.inference.kalman.filter` use to set up a run: the check of the discretisation's
name, the (C, K) pairs as arrays, and ``sample_dynamics``, the per-sample constants of the
filter (transition, force shares, observation rows) for B pairs.

Discretisation of ``(u, u')`` over one interval given (C, K) (:func:`transition_matrices`)
    ``x_{k+1} = Phi x_k + Gamma0 F_k + Gamma1 F_{k+1} + w_k``, ``F`` the force [N]:

    ``"foh"`` (default)
        Exact with the force a straight line between samples (first-order hold), from the
        matrix exponential of an augmented 4x4 generator (scaling and squaring, batched).
        It is the one that fits sampled data: on a steady, noise-free 100 Hz walking record
        fed with its true u, u', u'' (``tests/test_kalman.py``) the force coefficients come
        back within 0.2 posterior sd of the truth at the true (C, K), where Euler and the
        zero-order hold are off by 4-8 sd; on the seed's numerical example at 1 kHz the
        one-step-ahead u'' innovations at the truth are 8 % of a 1 % observation noise.
    ``"zoh"``
        Exact with the force held at ``F_k`` over the interval; ``Gamma1 = 0``.
    ``"euler"``
        The seed's ``I + A dt`` (eq. 20): ``Phi = I + A dt``, ``Gamma0 = (0, dt / M)``,
        ``Gamma1 = 0``. Use it to compare with the seed-faithful particle filter.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.inference.core import IdentificationProblem

__all__ = ["DISCRETISATIONS", "transition_matrices"]

FloatArray = NDArray[np.float64]
Discretisation = Literal["foh", "zoh", "euler"]

#: Discretisations offered, default first.
DISCRETISATIONS: tuple[str, ...] = ("foh", "zoh", "euler")


def transition_matrices(
    mass_kg: float,
    damping: ArrayLike,
    stiffness: ArrayLike,
    dt_s: float,
    discretisation: str = "foh",
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Discrete transition of ``(u, u')`` over one sample interval, batched over (C, K).

    ``x_{k+1} = Phi x_k + Gamma0 F_k + Gamma1 F_{k+1}`` for the force ``F`` [N] at the two
    ends of the interval (module docstring).

    Parameters
    ----------
    mass_kg : float
        Body mass M [kg].
    damping, stiffness : array_like, shape (B,)
        C [N s/m] and K [N/m] (scalars are taken as B = 1).
    dt_s : float
        Sample interval [s].
    discretisation : {"foh", "zoh", "euler"}
        First-order hold (exact for a force linear between samples), zero-order hold, or
        the seed's Euler ``I + A dt``.

    Returns
    -------
    phi : ndarray, shape (B, 2, 2)
        State transition.
    gamma0, gamma1 : ndarray, shape (B, 2)
        Response to 1 N of force at the start and at the end of the interval [m/N, m/(s N)].
    """
    c, k = _pairs(damping, stiffness)
    m = float(mass_kg)
    dt = float(dt_s)
    if not (np.isfinite(m) and m > 0 and np.isfinite(dt) and dt > 0):
        raise UsageError(
            f"transition_matrices: mass {mass_kg!r} kg and sample interval {dt_s!r} s must be "
            "positive numbers"
        )
    _check_discretisation(discretisation)
    b = c.size
    if discretisation == "euler":
        phi = np.empty((b, 2, 2))
        phi[:, 0, 0] = 1.0
        phi[:, 0, 1] = dt
        phi[:, 1, 0] = -k / m * dt
        phi[:, 1, 1] = 1.0 - c / m * dt
        gamma0 = np.zeros((b, 2))
        gamma0[:, 1] = dt / m
        return phi, gamma0, np.zeros((b, 2))
    # Augmented generator on (u, u', F, dF): u'' = (-K u - C u' + F) / M, F' = dF / dt,
    # dF' = 0. Its exponential over dt maps (x_k, F_k, F_{k+1} - F_k) to x_{k+1}; the F
    # column is the zero-order-hold response and the dF column the ramp response.
    aug = np.zeros((b, 4, 4))
    aug[:, 0, 1] = dt
    aug[:, 1, 0] = -k / m * dt
    aug[:, 1, 1] = -c / m * dt
    aug[:, 1, 2] = dt / m
    aug[:, 2, 3] = 1.0
    e = _expm(aug)
    phi = np.ascontiguousarray(e[:, :2, :2])
    hold = np.ascontiguousarray(e[:, :2, 2])
    if discretisation == "zoh":
        return phi, hold, np.zeros((b, 2))
    ramp = np.ascontiguousarray(e[:, :2, 3])
    return phi, hold - ramp, ramp


def _expm(mats: FloatArray) -> FloatArray:
    """Matrix exponential of a batch of small matrices (B, n, n), vectorised over B.

    Scaling and squaring with a Taylor series: ``exp(M) = exp(M / 2^s)^(2^s)`` with
    ``||M / 2^s||_1 <= 1/4``, where 18 Taylor terms leave a truncation error below
    ``(1/4)^19 / 19! ~ 1e-29``, far below rounding. (scipy's ``expm`` handles a batch one
    matrix at a time, which costs milliseconds per matrix and dominated the filter's run
    time for hundreds of (C, K) pairs.)
    """
    norm = float(np.max(np.sum(np.abs(mats), axis=-2))) if mats.size else 0.0
    squarings = max(0, int(np.ceil(np.log2(norm / 0.25)))) if norm > 0.25 else 0
    scaled = mats / 2.0**squarings
    eye = np.eye(mats.shape[-1])
    result = eye + scaled
    term = scaled
    for order in range(2, 19):
        term = term @ scaled / order
        result = result + term
    for _ in range(squarings):
        result = result @ result
    return result


def _check_discretisation(discretisation: str) -> None:
    if discretisation not in DISCRETISATIONS:
        raise UsageError(
            f"unknown discretisation {discretisation!r}; use one of {', '.join(DISCRETISATIONS)}"
        )


def _pairs(damping: ArrayLike, stiffness: ArrayLike) -> tuple[FloatArray, FloatArray]:
    c = np.atleast_1d(np.asarray(damping, dtype=np.float64))
    k = np.atleast_1d(np.asarray(stiffness, dtype=np.float64))
    if c.ndim != 1 or k.shape != c.shape:
        raise UsageError(
            f"damping and stiffness must be 1-D arrays of equal length B, got shapes {c.shape} "
            f"and {k.shape}"
        )
    if not (np.all(np.isfinite(c)) and np.all(np.isfinite(k))):
        raise UsageError("damping and stiffness must be finite numbers")
    return c, k


class Dynamics(NamedTuple):
    """Per-pair constants of the filter, B on the last axis (fast numpy broadcasting)."""

    k_m: FloatArray  # (B,) K / M
    c_m: FloatArray  # (B,) C / M
    phi: FloatArray  # (2, 2, B) Phi[i, j]
    g0: FloatArray  # (2, B) Gamma0
    g1: FloatArray  # (2, B) Gamma1
    h_in: FloatArray  # (3, B) H Gamma1 + d, see filter_piece
    has_end_share: bool  # Gamma1 != 0 (first-order hold)

    def take(self, idx: NDArray[np.intp] | NDArray[np.bool_]) -> Dynamics:
        """Return the constants of the pairs ``idx`` (an index or mask into the batch)."""
        return Dynamics(
            self.k_m[idx],
            self.c_m[idx],
            self.phi[..., idx],
            self.g0[..., idx],
            self.g1[..., idx],
            self.h_in[..., idx],
            self.has_end_share,
        )


def sample_dynamics(
    problem: IdentificationProblem, c: FloatArray, k: FloatArray, discretisation: str
) -> Dynamics:
    """Compute the per-sample constants of the filter for the (C, K) pairs ``c``, ``k``.

    Used by the Kalman filter and, per particle, by the Rao-Blackwellised particle filter.
    """
    phi, g0, g1 = transition_matrices(problem.mass_kg, c, k, problem.dt_s, discretisation)
    m = problem.mass_kg
    k_m, c_m = k / m, c / m
    phi_b = np.ascontiguousarray(phi.transpose(1, 2, 0))
    g0_b = np.ascontiguousarray(g0.T)
    g1_b = np.ascontiguousarray(g1.T)
    h_in = np.empty((3, c.size))
    h_in[:2] = g1_b
    h_in[2] = 1.0 / m - k_m * g1_b[0] - c_m * g1_b[1]
    return Dynamics(
        k_m,
        c_m,
        phi_b,
        g0_b,
        g1_b,
        h_in,
        discretisation == "foh",
    )
