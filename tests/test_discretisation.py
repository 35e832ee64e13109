"""One discretisation: the seed's state-space matrices equal the Kalman filter's.

The seed's reduced state-space form given (C, K) (state ``z = (u, u', a0, a1, b1, ...)``,
continuous matrix of seed eq. 18 without the C and K states, Euler step of eq. 20, or the
matrix exponential held or exact over the interval) is written out here from the
equations, as the library's former ``workbench.models.statespace.reduced_matrices`` built
it; :func:`workbench.inference.kalman.filter.transition_matrices` builds the transition of
``(u, u')`` driven by the force ``F = b(t) theta`` sampled at the interval's ends, and is
the library's one discretisation. For the same (M, C, K, dt) the state blocks agree, and
the force columns are the Kalman responses times the Fourier basis: exactly so for the
Euler and zero-order-hold forms, and for a constant force (``a0``) also for the exact
form, whose harmonic columns the first-order hold approximates to ``O((w dt)^2)``.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from workbench.inference.kalman.filter import transition_matrices
from workbench.models.force import FourierForce

#: (M [kg], C [N s/m], K [N/m], dt [s], pacing [Hz]): the seed, a soft and a stiff walker,
#: the design walker of docs/science.md 7 at a coarse step.
CASES = [
    (75.0, 942.477796, 18505.5, 0.001, 0.5),
    (60.0, 300.0, 9000.0, 0.01, 1.7),
    (90.0, 1500.0, 30000.0, 0.005, 2.1),
    (73.85, 612.5, 14110.0, 0.02, 2.0),
]
HARMONICS = 3
TIMES = np.array([0.0, 0.37, 2.5])


def reduced_matrices(
    m: float,
    k: float,
    c: float,
    harmonics: int,
    t_s: np.ndarray,
    fp: float,
    dt: float,
    method: str = "exact",
) -> tuple[np.ndarray, None]:
    """Transition of ``z = (u, u', a0, a1, b1, ...)`` over ``dt`` from each ``t_s``."""
    force = FourierForce(harmonics)
    p = 2 + force.n_coefficients
    basis = force.basis(t_s, fp)  # (T, 1 + 2 n)
    f = np.broadcast_to(np.eye(p), (t_s.size, p, p)).copy()
    if method == "euler":  # I + A dt, seed eq. 20
        f[:, 0, 1] = dt
        f[:, 1, 0] = -k / m * dt
        f[:, 1, 1] = 1.0 - c / m * dt
        f[:, 1, 2:] = basis / m * dt
        return f, None
    # Generator on (u, u', basis values); the basis rotates, p' = Omega p, unless held.
    aug = np.zeros((p, p))
    aug[0, 1] = 1.0
    aug[1, 0], aug[1, 1] = -k / m, -c / m
    aug[1, 2] = 1.0 / m  # a0
    aug[1, 3::2] = 1.0 / m  # cos(i w s) drives u'; sin(i w s) enters through the rotation
    omega = 2 * np.pi * fp if method == "exact" else 0.0
    for i in range(1, harmonics + 1):
        aug[1 + 2 * i, 2 + 2 * i], aug[2 + 2 * i, 1 + 2 * i] = -i * omega, i * omega
    e = scipy.linalg.expm(aug * dt)
    f[:, :2, :2] = e[:2, :2]
    if method == "zoh":  # the force held at its value at t_k
        f[:, :2, 2:] = e[:2, 2:3][None] * basis[:, None, :]
        return f, None
    # Basis at t_k + s by the angle sums: responses to cos(i w s), -sin(i w s) -> a_i, b_i.
    f[:, :2, 2] = e[:2, 2]
    cos_k, sin_k = basis[:, None, 1::2], basis[:, None, 2::2]
    t_cos, t_sin = e[None, :2, 3::2], e[None, :2, 4::2]
    f[:, :2, 3::2] = t_cos * cos_k + t_sin * sin_k
    f[:, :2, 4::2] = t_cos * sin_k - t_sin * cos_k
    return f, None


@pytest.mark.parametrize(("m", "c", "k", "dt", "fp"), CASES)
@pytest.mark.parametrize("method", ["euler", "zoh"])
def test_statespace_equals_kalman(
    m: float, c: float, k: float, dt: float, fp: float, method: str
) -> None:
    f, _ = reduced_matrices(m, k, c, HARMONICS, TIMES, fp, dt, method=method)
    phi, g0, g1 = (x[0] for x in transition_matrices(m, [c], [k], dt, method))
    basis = FourierForce(HARMONICS).basis(TIMES, fp)
    assert not np.any(g1)
    for i in range(TIMES.size):
        np.testing.assert_allclose(f[i, :2, :2], phi, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(
            f[i, :2, 2:], g0[:, None] * basis[i], rtol=1e-10, atol=1e-16 * dt
        )
        np.testing.assert_array_equal(f[i, 2:], np.eye(3 + 2 * HARMONICS)[2:])


@pytest.mark.parametrize(("m", "c", "k", "dt", "fp"), CASES)
def test_statespace_exact_equals_kalman_foh(
    m: float, c: float, k: float, dt: float, fp: float
) -> None:
    f, _ = reduced_matrices(m, k, c, HARMONICS, TIMES, fp, dt, method="exact")
    phi, g0, g1 = (x[0] for x in transition_matrices(m, [c], [k], dt, "foh"))
    basis = FourierForce(HARMONICS).basis(TIMES, fp)
    basis_next = FourierForce(HARMONICS).basis(TIMES + dt, fp)
    for i in range(TIMES.size):
        np.testing.assert_allclose(f[i, :2, :2], phi, rtol=1e-12, atol=1e-15)
        # A constant force is held and ramped alike: the a0 column is the same response.
        np.testing.assert_allclose(f[i, :2, 2], g0 + g1, rtol=1e-10, atol=1e-16 * dt)
        # Harmonics: the hold interpolates the sinusoid linearly, O((w dt)^2) off.
        foh = g0[:, None] * basis[i] + g1[:, None] * basis_next[i]
        w_dt = 2 * np.pi * HARMONICS * fp * dt
        scale = np.max(np.abs(g0 + g1))
        np.testing.assert_allclose(f[i, :2, 3:], foh[:, 1:], rtol=0, atol=w_dt**2 * scale)
