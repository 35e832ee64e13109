"""A synthetic population study like the seed's, generated from known laws (no files shipped).

Design (the seed's section 5.1 and Table 1): 56 participants -- 39 male, 68.3 +- 15.0 kg in
49.8-95.1 kg, 17 female, 60.3 +- 4.98 kg -- walking in 11 pacing cases (1.5, 1.65, 1.75,
1.8, 1.95, 2, 2.1 and 2.25 Hz with a metronome, and self-chosen slow, normal and fast), each
case two or three times: 616 cases, 296 of them (chosen at random) with a third
repetition, 1528 records.

Per record the truth is drawn from :class:`~workbench.population.laws.PopulationLaws`
(default: the seed's f_n and zeta laws and the documented assumptions): f_n, zeta and BLF1
from their mean laws at the record's pacing plus normal residuals, BLF2 and BLF3 lognormal.
Masses belong to the participant. The self-chosen rates are not in the seed; they are drawn
per participant as N(1.65, 0.08), N(1.85, 0.08) and N(2.05, 0.08) Hz within 1.5-2.25 Hz
(an assumption).

Model class. The identification assumes a Fourier biomechanical force locked to the
pacing. Realistic simulated walks whose force drifts smoothly from step to step lie outside
that class and the workbench reports C and K "not identified" on them (README,
"Identification: methods and honest status"). A population study must test the population
fit, not that known limitation, so the records are generated *inside* the class the
identification is told to assume: a periodic Fourier force (three harmonics at the
record's BLFs, random phases) from rest, so the start-up transient carries the information
on (C, K), with white GRF noise; they are identified as one piece on the absolute-time basis
at the metronome pacing, observing u'' only, high-pass off (:data:`STUDY_SETTINGS`) -- the
"consistent" set of ``analyses/coverage_study.py``, where every band held the truth. The
per-step model (coefficients redrawn every footfall) was not used: its pieces are cut at
the acceleration peaks of the record, which a generator cannot place without running the
identification's own segmentation, and a force whose coefficients jump anywhere else is
again outside the model.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from workbench.errors import UsageError, check_seed
from workbench.population.laws import PopulationLaws
from workbench.population.sampler import _truncnorm
from workbench.records.record import Record

__all__ = [
    "FIXED_PACING_HZ",
    "SELF_CHOSEN_PACING",
    "STUDY_SETTINGS",
    "StudyDesign",
    "simulate_study_record",
    "study_plan",
    "write_study",
]

#: The seed's eight metronome rates [Hz].
FIXED_PACING_HZ = (1.5, 1.65, 1.75, 1.8, 1.95, 2.0, 2.1, 2.25)
#: Self-chosen cases: mean and sd of the participant's rate [Hz] (assumption).
SELF_CHOSEN_PACING = {"slow": (1.65, 0.08), "normal": (1.85, 0.08), "fast": (2.05, 0.08)}
#: Identification settings for the study's records (see the module docstring).
STUDY_SETTINGS: dict[str, Any] = {
    "pieces": "whole",
    "time_basis": "absolute",
    "highpass_hz": 0.0,
    "observe": "acc",
    "harmonics": 3,
}


@dataclass(frozen=True)
class StudyDesign:
    """Size and recording settings of a synthetic study.

    Parameters
    ----------
    n_male, n_female : int
        Participants (the seed: 39 and 17).
    n_records : int or None
        Records in all: every case is walked twice and ``n_records - 2 x cases`` cases
        (chosen at random) a third time (the seed: 1528). None: each case once.
    cases : tuple of str
        Pacing cases: rates in Hz as text, or ``slow``, ``normal``, ``fast``.
    duration_s, sample_rate_hz : float
        Record length and rate.
    noise_sd_n : float
        White GRF measurement noise [N].
    laws : PopulationLaws
        The generating laws.
    """

    n_male: int = 39
    n_female: int = 17
    n_records: int | None = 1528
    cases: tuple[str, ...] = (*(f"{f:g}" for f in FIXED_PACING_HZ), *SELF_CHOSEN_PACING)
    duration_s: float = 4.0
    sample_rate_hz: float = 100.0
    noise_sd_n: float = 3.0
    laws: PopulationLaws = field(default_factory=PopulationLaws)


def study_plan(design: StudyDesign | None = None, *, seed: int = 0) -> pd.DataFrame:
    """Draw the study: one row per record with its participant, case and true parameters.

    Parameters
    ----------
    design : StudyDesign, optional
        Defaults to the seed's design (56 participants, 11 cases, 1528 records).
    seed : int
        Fixes every draw.

    Returns
    -------
    pandas.DataFrame
        Columns ``record, subject, sex, mass_kg, case, repetition, pacing_hz,
        natural_frequency_hz, damping_ratio, stiffness_n_per_m, damping_ns_per_m, blf1,
        blf2, blf3, phase1_rad, phase2_rad, phase3_rad, seed``.
    """
    d = design or StudyDesign()
    laws = d.laws
    rng = np.random.default_rng(check_seed(seed, "study_plan"))
    m = laws.mass
    masses = np.concatenate(
        [
            _truncnorm(
                rng, np.full(d.n_male, m.male_mean_kg), m.male_sd_kg, m.male_low_kg, m.male_high_kg
            ),
            _truncnorm(
                rng,
                np.full(d.n_female, m.female_mean_kg),
                m.female_sd_kg,
                m.female_low_kg,
                m.female_high_kg,
            ),
        ]
    )
    sexes = ["male"] * d.n_male + ["female"] * d.n_female
    n_people = d.n_male + d.n_female
    n_cases = n_people * len(d.cases)
    if d.n_records is None:
        reps = np.ones(n_cases, dtype=int)
    else:
        extra = d.n_records - 2 * n_cases
        if not 0 <= extra <= n_cases:
            raise UsageError(
                f"{d.n_records} records do not fit {n_cases} cases walked two or three times; "
                f"give between {2 * n_cases} and {3 * n_cases}"
            )
        reps = np.full(n_cases, 2)
        reps[rng.permutation(n_cases)[:extra]] = 3
    rows: list[dict[str, Any]] = []
    c = 0
    for person in range(n_people):
        for case in d.cases:
            if case in SELF_CHOSEN_PACING:
                mu, sd = SELF_CHOSEN_PACING[case]
                pacing = float(_truncnorm(rng, np.array([mu]), sd, 1.5, 2.25)[0])
            else:
                pacing = float(case)
            for rep in range(1, reps[c] + 1):
                rows.append(
                    {
                        "subject": f"P{person + 1:02d}",
                        "sex": sexes[person],
                        "mass_kg": float(masses[person]),
                        "case": case,
                        "repetition": rep,
                        "pacing_hz": pacing,
                    }
                )
            c += 1
    plan = pd.DataFrame(rows)
    fp = plan["pacing_hz"].to_numpy()
    n = len(plan)
    plan["natural_frequency_hz"] = _truncnorm(
        rng, laws.natural_frequency_hz.mean(fp), laws.natural_frequency_hz.residual_sd, 0.5, 10
    )
    plan["damping_ratio"] = _truncnorm(
        rng, laws.damping_ratio.mean(fp), laws.damping_ratio.residual_sd, 0.01, 0.99
    )
    plan["blf1"] = _truncnorm(rng, laws.blf1.mean(fp), laws.blf1.residual_sd, 0.0, 1.0)
    plan["blf2"] = np.exp(rng.normal(laws.blf2.mu, laws.blf2.sigma, n))
    plan["blf3"] = np.exp(rng.normal(laws.blf3.mu, laws.blf3.sigma, n))
    phases = rng.uniform(0, 2 * np.pi, (n, 3))
    for i in range(3):
        plan[f"phase{i + 1}_rad"] = phases[:, i]
    mass = plan["mass_kg"].to_numpy()
    k = mass * (2 * np.pi * plan["natural_frequency_hz"].to_numpy()) ** 2
    plan["stiffness_n_per_m"] = k
    plan["damping_ns_per_m"] = 2 * plan["damping_ratio"].to_numpy() * np.sqrt(k * mass)
    plan["seed"] = rng.integers(0, 2**31 - 1, n)
    plan.insert(
        0,
        "record",
        [
            f"{s}_{cs}_r{r}"
            for s, cs, r in zip(plan.subject, plan.case, plan.repetition, strict=True)
        ],
    )
    return plan


def simulate_study_record(row: Any, design: StudyDesign | None = None) -> Record:
    """Simulate one planned record (a row of :func:`study_plan`).

    Parameters
    ----------
    row : mapping or pandas.Series
        A row of the plan.
    design : StudyDesign, optional
        Duration, sample rate and noise (defaults as :class:`StudyDesign`).

    Returns
    -------
    Record
        With body mass, the metronome pacing, subject and the truth in its metadata.
    """
    from workbench.synth.simulate import simulate_walking

    d = design or StudyDesign()
    sim = simulate_walking(
        mass_kg=float(row["mass_kg"]),
        pacing_hz=float(row["pacing_hz"]),
        duration_s=d.duration_s,
        natural_frequency_hz=float(row["natural_frequency_hz"]),
        damping_ratio=float(row["damping_ratio"]),
        blf=[float(row[f"blf{i}"]) for i in (1, 2, 3)],
        # The sampler's force is cos(2 pi i f_p t + phase_i); the simulator's cos(i theta - phi_i).
        phases_rad=[-float(row[f"phase{i}_rad"]) for i in (1, 2, 3)],
        step_duration_sd=0.0,
        amplitude_sd=0.0,
        phase_sd_rad=0.0,
        noise_sd_n=d.noise_sd_n,
        sample_rate_hz=d.sample_rate_hz,
        start="rest",
        seed=int(row["seed"]),
    )
    meta = {**sim.record.metadata, "subject": str(row["subject"])}
    return sim.record.replace(
        subject=str(row["subject"]), pacing_hz=float(row["pacing_hz"]), metadata=meta
    )


def write_study(
    plan: pd.DataFrame, out_dir: str | os.PathLike[str], design: StudyDesign | None = None
) -> Path:
    """Write the planned records (CSV + JSON sidecar each) and a batch manifest.

    Parameters
    ----------
    plan : pandas.DataFrame
        Rows of :func:`study_plan` (any subset).
    out_dir : path-like
        Folder; records go to ``out_dir/records/``.
    design : StudyDesign, optional
        Recording settings.

    Returns
    -------
    Path
        ``out_dir/manifest.csv`` (columns ``path, mass_kg, pacing_hz, subject``); the truth
        of every record is in ``out_dir/truth.csv``.
    """
    from workbench.fileutil import atomic_path
    from workbench.records.io import save_record

    out = Path(out_dir)
    rows = []
    for _, row in plan.iterrows():
        record = simulate_study_record(row, design)
        rel = f"records/{row['record']}.csv"
        save_record(record, out / rel)
        rows.append(
            {
                "path": rel,
                "mass_kg": f"{row['mass_kg']:.6f}",
                "pacing_hz": f"{row['pacing_hz']:.6f}",
                "subject": row["subject"],
            }
        )
    manifest = out / "manifest.csv"
    with atomic_path(manifest) as tmp:
        pd.DataFrame(rows).to_csv(tmp, index=False, lineterminator="\n")
    with atomic_path(out / "truth.csv") as tmp:
        plan.to_csv(tmp, index=False, float_format="%.10g", lineterminator="\n")
    return manifest
