"""The simulated walking record several test modules identify (70 kg, 1.8 Hz, 100 Hz, from rest)."""

from __future__ import annotations

from typing import Any

from workbench.inference.core.problem import IdentificationProblem, build_problem
from workbench.records.inspection import inspect_record
from workbench.synth.simulate import Simulation, simulate_walking


def simulated_walk(seed: int, duration_s: float) -> Simulation:
    """A 70 kg walker at 1.8 Hz, 100 Hz, 3 N force noise, starting from rest."""
    return simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=duration_s,
        sample_rate_hz=100,
        noise_sd_n=3.0,
        start="rest",
        seed=seed,
    )


def walking_problem(
    seed: int, duration_s: float, harmonics: int, **build: Any
) -> tuple[IdentificationProblem, Simulation]:
    """The walk in footfall pieces (0.15 Hz high-pass) as an identification problem."""
    sim = simulated_walk(seed, duration_s)
    insp = inspect_record(sim.record, highpass_hz=0.15)
    return build_problem(insp.com, insp.steps, harmonics=harmonics, **build), sim
