"""Fixtures shared by several test modules."""

from __future__ import annotations

import pytest

from tests.walks import walking_problem
from workbench.inference.problem import IdentificationProblem


@pytest.fixture(scope="session")
def walking_steps_problem() -> tuple[IdentificationProblem, float, float]:
    """A realistic 10 s, 100 Hz walking record in footfall pieces, n = 4, and its (C, K)."""
    problem, sim = walking_problem(seed=11, duration_s=10.0, harmonics=4)
    return problem, sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]
