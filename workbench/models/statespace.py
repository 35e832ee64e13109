"""State-space forms of the SMD model: the seed's full state and the reduced linear one.

Full (seed eqs. 15-23)
    State ``X = (u, u', C, K, a0, a1, b1, ..., an, bn)``, ``X' = A(t) X`` with ``A`` of
    eq. 18, Euler discretised ``X_{k+1} = (I + A(t_k) dt) X_k`` (eq. 20) and observed
    through ``C_d(t_k)`` (eq. 23, rows ``u, u', u''``). The ``C`` and ``K`` columns of
    ``A`` are zero: ``C`` and ``K`` enter row 2 as the coefficients of ``u'`` and ``u``
    (taken from the model, or per particle via the ``stiffness_n_per_m`` /
    ``damping_ns_per_m`` overrides), and are constant (random-walk) states otherwise.

Reduced (given C and K)
    State ``z = (u, u', a0, a1, b1, ..., an, bn)``; the model is linear-Gaussian in ``z``,
    which a Kalman filter (and a Rao-Blackwellised particle filter) exploits. Three
    discretisations, all with the Fourier coefficients constant over a sample interval:

    ``"euler"``
        ``I + A dt`` with the basis at ``t_k``: the seed's, first order in ``dt``.
    ``"zoh"``
        Exact for ``(u, u')`` with the force held at its value at ``t_k`` over the
        interval (zero-order hold, ``scipy.linalg.expm``).
    ``"exact"`` (default)
        Exact for ``(u, u')`` with the force basis varying continuously over the interval
        (the cosines and sines are integrated analytically through an augmented matrix
        exponential). For coefficients constant in time this reproduces the continuous
        solution to rounding error, whatever ``dt``.

    All three share the observation matrix ``H(t_k)`` with rows ``u, u', u''``.

Shapes: ``t_s``, and ``stiffness_n_per_m`` / ``damping_ns_per_m`` where accepted, broadcast
together (numpy rules); matrices get that broadcast shape in front of their two matrix axes,
so one time and many particles, or one particle and many times, both work.

Models with effects are refused here: their terms are not linear in the state. Use
:meth:`SMDModel.acceleration <workbench.models.smd.SMDModel.acceleration>` for them.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.models.force import FourierForce, fourier_phase_rad
from workbench.models.smd import SMDModel

__all__ = [
    "ReducedMatrices",
    "continuous_matrix",
    "discrete_matrix",
    "observation_matrix",
    "reduced_matrices",
    "reduced_state_names",
    "state_names",
]

FloatArray = NDArray[np.float64]
Discretisation = Literal["euler", "zoh", "exact"]


def state_names(harmonics: int) -> tuple[str, ...]:
    """Names of the seed's full state (eq. 15): ``u, u_dot, C, K, a0, a1, b1, ...``.

    Parameters
    ----------
    harmonics : int
        Number of force harmonics n.

    Returns
    -------
    tuple of str
        Length ``4 + 1 + 2 n``.
    """
    return ("u", "u_dot", "C", "K", *FourierForce(harmonics).coefficient_names)


def reduced_state_names(harmonics: int) -> tuple[str, ...]:
    """Names of the reduced state: ``u, u_dot, a0, a1, b1, ...``.

    Parameters
    ----------
    harmonics : int
        Number of force harmonics n.

    Returns
    -------
    tuple of str
        Length ``2 + 1 + 2 n``.
    """
    return ("u", "u_dot", *FourierForce(harmonics).coefficient_names)


def _model_parameters(
    model: SMDModel,
    stiffness_n_per_m: ArrayLike | None,
    damping_ns_per_m: ArrayLike | None,
    where: str,
) -> tuple[float, FloatArray, FloatArray]:
    if model.effects:
        raise UsageError(
            f"{where}: the state-space form covers the linear SMD model but {model!r} has "
            "effects; use SMDModel.acceleration for models with effects"
        )
    m = model.require("mass_kg")
    k = np.asarray(
        model.require("stiffness_n_per_m") if stiffness_n_per_m is None else stiffness_n_per_m,
        dtype=np.float64,
    )
    c = np.asarray(
        model.require("damping_ns_per_m") if damping_ns_per_m is None else damping_ns_per_m,
        dtype=np.float64,
    )
    return m, k, c


def continuous_matrix(
    model: SMDModel,
    t_s: ArrayLike,
    pacing_hz: float,
    *,
    time_origin_s: ArrayLike = 0.0,
    phase_rad: ArrayLike | None = None,
    stiffness_n_per_m: ArrayLike | None = None,
    damping_ns_per_m: ArrayLike | None = None,
) -> FloatArray:
    """Matrix ``A(t)`` of seed eq. 18 for the full state ``(u, u', C, K, a0, a_i, b_i)``.

    Parameters
    ----------
    model : SMDModel
        Mass, harmonics and (unless overridden) K and C; no effects.
    t_s : array_like
        Time(s) [s].
    pacing_hz : float
        Pacing frequency [Hz] of the Fourier basis.
    time_origin_s, phase_rad : optional
        Basis time convention (see :mod:`workbench.models.force`).
    stiffness_n_per_m, damping_ns_per_m : array_like, optional
        Per-particle K and C instead of the model's.

    Returns
    -------
    ndarray
        Shape ``broadcast(t, K, C).shape + (d, d)`` with ``d = 5 + 2 n``.
    """
    m, k, c = _model_parameters(model, stiffness_n_per_m, damping_ns_per_m, "continuous_matrix")
    basis = model.fourier_force.basis(
        t_s, pacing_hz, time_origin_s=time_origin_s, phase_rad=phase_rad
    )
    shape = np.broadcast_shapes(basis.shape[:-1], k.shape, c.shape)
    d = 4 + basis.shape[-1]
    a = np.zeros((*shape, d, d))
    a[..., 0, 1] = 1.0
    a[..., 1, 0] = -k / m
    a[..., 1, 1] = -c / m
    a[..., 1, 4:] = basis / m
    return a


def discrete_matrix(
    model: SMDModel,
    t_s: ArrayLike,
    pacing_hz: float,
    dt_s: float,
    *,
    time_origin_s: ArrayLike = 0.0,
    phase_rad: ArrayLike | None = None,
    stiffness_n_per_m: ArrayLike | None = None,
    damping_ns_per_m: ArrayLike | None = None,
) -> FloatArray:
    """Euler-discretised transition ``A_d = I + A(t_k) dt`` of seed eq. 20 (full state).

    Parameters
    ----------
    model, t_s, pacing_hz, time_origin_s, phase_rad, stiffness_n_per_m, damping_ns_per_m
        As in :func:`continuous_matrix`.
    dt_s : float
        Sample interval [s].

    Returns
    -------
    ndarray
        Shape ``broadcast(t, K, C).shape + (d, d)``; ``X_{k+1} = A_d X_k``.
    """
    dt = _check_dt(dt_s, "discrete_matrix")
    a = continuous_matrix(
        model,
        t_s,
        pacing_hz,
        time_origin_s=time_origin_s,
        phase_rad=phase_rad,
        stiffness_n_per_m=stiffness_n_per_m,
        damping_ns_per_m=damping_ns_per_m,
    )
    return np.eye(a.shape[-1]) + a * dt


def observation_matrix(
    model: SMDModel,
    t_s: ArrayLike,
    pacing_hz: float,
    *,
    time_origin_s: ArrayLike = 0.0,
    phase_rad: ArrayLike | None = None,
    stiffness_n_per_m: ArrayLike | None = None,
    damping_ns_per_m: ArrayLike | None = None,
) -> FloatArray:
    """Observation matrix ``C_d(t_k)`` of seed eq. 23: rows ``u, u', u''`` (full state).

    Parameters
    ----------
    model, t_s, pacing_hz, time_origin_s, phase_rad, stiffness_n_per_m, damping_ns_per_m
        As in :func:`continuous_matrix`.

    Returns
    -------
    ndarray
        Shape ``broadcast(t, K, C).shape + (3, d)``. Row 3 is the equation of motion:
        ``u'' = (-K u - C u' + F_bio) / M``.
    """
    a = continuous_matrix(
        model,
        t_s,
        pacing_hz,
        time_origin_s=time_origin_s,
        phase_rad=phase_rad,
        stiffness_n_per_m=stiffness_n_per_m,
        damping_ns_per_m=damping_ns_per_m,
    )
    h = np.zeros((*a.shape[:-2], 3, a.shape[-1]))
    h[..., 0, 0] = 1.0
    h[..., 1, 1] = 1.0
    h[..., 2, :] = a[..., 1, :]
    return h


class ReducedMatrices(NamedTuple):
    """Discrete matrices of the reduced state ``z = (u, u', a0, a1, b1, ...)``.

    Attributes
    ----------
    transition : ndarray
        ``F_k`` with ``z_{k+1} = F_k z_k``; shape ``S + (p, p)``, ``p = 3 + 2 n``.
    observation : ndarray
        ``H_k`` with ``(u_k, u'_k, u''_k) = H_k z_k``; shape ``S + (3, p)``.
    """

    transition: FloatArray
    observation: FloatArray


def _check_dt(dt_s: float, where: str) -> float:
    try:
        dt = float(dt_s)
    except (TypeError, ValueError):
        dt = float("nan")
    if not (np.isfinite(dt) and dt > 0):
        raise UsageError(
            f"{where}: 'dt_s' must be a positive sample interval in seconds, got {dt_s!r}; "
            "pass 1 / sample rate"
        )
    return dt


def reduced_matrices(
    mass_kg: float,
    stiffness: ArrayLike,
    damping: ArrayLike,
    harmonics: int,
    t_s: ArrayLike,
    pacing_hz: float,
    dt_s: float,
    *,
    method: Discretisation = "exact",
    time_origin_s: ArrayLike = 0.0,
    phase_rad: ArrayLike | None = None,
) -> ReducedMatrices:
    """Transition and observation matrices of the reduced state given K and C.

    Parameters
    ----------
    mass_kg : float
        Body mass M [kg].
    stiffness : array_like
        K [N/m]; an array gives one set of matrices per value (e.g. per particle).
    damping : array_like
        C [N s/m], broadcast with ``stiffness``.
    harmonics : int
        Number of force harmonics n.
    t_s : array_like
        Time(s) ``t_k`` [s] at the start of each interval.
    pacing_hz : float
        Pacing frequency [Hz]; with ``phase_rad`` it is the rate at which the phase advances
        over an interval (``2 pi f_p dt`` per interval).
    dt_s : float
        Sample interval [s].
    method : {"exact", "zoh", "euler"}
        Discretisation (module docstring). ``"euler"`` is the seed's (eq. 20); ``"exact"``
        is exact for coefficients constant over the interval.
    time_origin_s, phase_rad : optional
        Basis time convention (see :mod:`workbench.models.force`).

    Returns
    -------
    ReducedMatrices
        ``(transition, observation)`` of shapes ``S + (p, p)`` and ``S + (3, p)`` with
        ``S = broadcast(t, K, C).shape`` and ``p = 3 + 2 n``.
    """
    if method not in ("euler", "zoh", "exact"):
        raise UsageError(
            f"reduced_matrices: unknown method {method!r}; use 'exact', 'zoh' or 'euler'"
        )
    dt = _check_dt(dt_s, "reduced_matrices")
    m = float(mass_kg)
    if not (np.isfinite(m) and m > 0):
        raise UsageError(
            f"reduced_matrices: 'mass_kg' must be a positive mass in kg, got {mass_kg!r}; "
            "pass the body mass"
        )
    k = np.asarray(stiffness, dtype=np.float64)
    c = np.asarray(damping, dtype=np.float64)
    force = FourierForce(harmonics)
    n = force.harmonics
    p = 2 + force.n_coefficients
    phi = fourier_phase_rad(t_s, pacing_hz, time_origin_s=time_origin_s, phase_rad=phase_rad)
    basis = force.basis(t_s, pacing_hz, phase_rad=phi)
    shape = np.broadcast_shapes(phi.shape, k.shape, c.shape)

    h = np.zeros((*shape, 3, p))
    h[..., 0, 0] = 1.0
    h[..., 1, 1] = 1.0
    h[..., 2, 0] = -k / m
    h[..., 2, 1] = -c / m
    h[..., 2, 2:] = basis / m

    f = np.broadcast_to(np.eye(p), (*shape, p, p)).copy()
    if method == "euler":
        f[..., 0, 1] = dt
        f[..., 1, 0] = -k / m * dt
        f[..., 1, 1] = 1.0 - c / m * dt
        f[..., 1, 2:] = basis / m * dt
        return ReducedMatrices(f, h)

    # Augmented generator [[A_s, B w^T], [0, Omega]] on (u, u', basis values): the basis
    # functions obey p' = Omega p (a rotation per harmonic), so expm of the augmented matrix
    # gives the state transition and the exact response to each basis function at once.
    kc_shape = np.broadcast_shapes(k.shape, c.shape)
    # The zero-order hold never rotates the basis, so it does not need the pacing.
    omega = 2.0 * np.pi * _pacing(pacing_hz) if method == "exact" else 0.0
    q = 2 + force.n_coefficients
    aug = np.zeros((*kc_shape, q, q))
    aug[..., 0, 1] = 1.0
    aug[..., 1, 0] = -np.broadcast_to(k, kc_shape) / m
    aug[..., 1, 1] = -np.broadcast_to(c, kc_shape) / m
    aug[..., 1, 2] = 1.0 / m
    aug[..., 1, 3::2] = 1.0 / m
    for i in range(1, n + 1):
        ci, si = 1 + 2 * i, 2 + 2 * i
        aug[..., ci, si] = -i * omega
        aug[..., si, ci] = i * omega
    if method == "zoh":
        # The held force needs only the response to a constant input.
        aug[..., 3:, :] = 0.0
    e = scipy.linalg.expm(aug * dt)
    phi_block = e[..., :2, :2]
    top = e[..., :2, 2:]  # columns: a0, then (cos_i, sin_i) responses
    f[..., :2, :2] = phi_block
    if method == "zoh":
        f[..., :2, 2:] = top[..., :, :1] * basis[..., None, :]
        return ReducedMatrices(f, h)
    f[..., :2, 2] = top[..., :, 0]
    if n:
        # Basis at t_k + s: cos(i phi_k + i w s), sin(...). Expanding with the angle sums
        # maps the responses T_cos, T_sin (to cos(i w s) and -sin(i w s)) onto a_i, b_i.
        cos_k = basis[..., None, 1::2]
        sin_k = basis[..., None, 2::2]
        t_cos = top[..., :, 1::2]
        t_sin = top[..., :, 2::2]
        f[..., :2, 3::2] = t_cos * cos_k + t_sin * sin_k
        f[..., :2, 4::2] = t_cos * sin_k - t_sin * cos_k
    return ReducedMatrices(f, h)


def _pacing(pacing_hz: float) -> float:
    try:
        f = float(pacing_hz)
    except (TypeError, ValueError):
        f = float("nan")
    if not (np.isfinite(f) and f > 0):
        raise UsageError(
            f"reduced_matrices: 'pacing_hz' must be a positive frequency in Hz, got "
            f"{pacing_hz!r}; pass the step frequency"
        )
    return f
