"""Fixtures shared by several test modules."""

from __future__ import annotations

import pytest

from workbench.inference.problem import IdentificationProblem, build_problem
from workbench.records.inspection import inspect_record
from workbench.synth.simulate import simulate_walking


@pytest.fixture(scope="session")
def walking_steps_problem() -> tuple[IdentificationProblem, float, float]:
    """A realistic 10 s, 100 Hz walking record in footfall pieces, n = 4, and its (C, K)."""
    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=10.0,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="rest",
        seed=11,
    )
    insp = inspect_record(sim.record, highpass_hz=0.15)
    problem = build_problem(insp.com, insp.steps, harmonics=4)
    return problem, sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]
