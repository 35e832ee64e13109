"""One discretisation: the seed's state-space matrices equal the Kalman filter's.

:func:`workbench.models.statespace.reduced_matrices` builds the transition of the reduced
state ``z = (u, u', a0, a1, b1, ...)`` given (C, K); :func:`workbench.inference.kalman.
transition_matrices` builds that of ``(u, u')`` driven by the force ``F = b(t) theta``
sampled at the interval's ends. For the same (M, C, K, dt) the state blocks agree, and the
force columns are the Kalman responses times the Fourier basis: exactly so for the Euler
and zero-order-hold forms, and for a constant force (``a0``) also for the exact form, whose
harmonic columns the first-order hold approximates to ``O((w dt)^2)``.
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.inference.kalman import transition_matrices
from workbench.models.force import FourierForce
from workbench.models.statespace import reduced_matrices

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


@pytest.mark.parametrize(("m", "c", "k", "dt", "fp"), CASES)
@pytest.mark.parametrize("method", ["euler", "zoh"])
def test_statespace_equals_kalman(
    m: float, c: float, k: float, dt: float, fp: float, method: str
) -> None:
    f, _ = reduced_matrices(m, k, c, HARMONICS, TIMES, fp, dt, method=method)  # type: ignore[arg-type]
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
