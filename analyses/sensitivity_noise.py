"""Sensitivity of the identified parameters to the filter's noise settings and choices.

Usage::

    python analyses/sensitivity_noise.py [--part synthetic|pf|study|real|all] [--replicates 3]
        [--seed 0] [--workers 1] [--real-seconds 20] [--out analyses/out/sensitivity_noise]

Four studies, each written to its own folder under ``--out`` (tables, statements, report
with tornado charts) by :func:`workbench.sensitivity.study.run_sensitivity`:

``synthetic``
    The record of :func:`workbench.sensitivity.study.demo_record` (70 kg, f_p 1.8 Hz, 8 s at
    100 Hz from rest, no step-to-step variability, GRF noise 2 N; truth f_n 1.9158 Hz,
    damping ratio 0.4928) with the model-class baseline of
    :func:`~workbench.sensitivity.study.demo_settings` (``rbpf``, 32 particles, 4 harmonics,
    one whole-record piece on absolute time, no high-pass, likelihood on u''), one setting
    at a time over the noise settings, the particles, the prior box, the high-pass, the
    harmonics, the segmentation, the time basis and the method.
``pf``
    The same record with the seed's particle filter (``pf``, 1000 particles), over the random
    walks of C and K and the number of particles: the settings that act only in ``pf``.
``study``
    Records of the synthetic population study (:mod:`workbench.population.study`; the first
    ``--study-people`` participants, every pacing case once: 22 records of 4 s by default)
    with the study's settings (one piece on absolute time, u'' observed, 3 harmonics, 64
    particles), over the observation and process noise, the harmonics and the particles;
    effects pooled over the records (``pooled_effects.csv``).
``real``
    The embedded real records (insole: 20 s from 10 s, rescaled to M g; treadmill: 20 s of
    its steady 2.2 Hz stretch from 75 s) with the default settings (``rbpf``, 10 harmonics,
    footfall steps, step phase, ``auto`` observation noise; 128 particles), over the observation and
    process noise, the harmonics and the high-pass cut-off. No truth is known there; the
    question is how far the settings move the numbers, next to the Monte Carlo spread.

Notes. Commands and what they printed (the numbers are in each folder's
``statements.txt``; seed 0):

``python analyses/sensitivity_noise.py --part synthetic`` (3 replicates, 51 runs, about 90 s)

- The default (model-class) settings recover the truth: the 95 % bands of f_n, damping
  ratio, K and C all hold it.
- Settings that only widen: observation noise of u'' x4 (posterior sd of f_n x3.9, f_n
  moves -0.0016 Hz inside the Monte Carlo uncertainty of +-0.012 Hz), of all three channels
  x2 (sd x2.0), prior box twice as wide in log width (sd x8.4, effect -0.005 Hz inside
  +-0.058 Hz). Halving the noise narrows (sd x0.49) without a distinguishable shift.
- Settings that bias: the seed's process noise of (u, u') at 0.5 % of their RMS moves f_n
  by -0.188 Hz (Monte Carlo +-0.015 Hz) and K by -1880 N/m out of their bands; at 0.25 % the
  shift is -0.033 Hz and the wider band still holds the truth. A high-pass at 0.15 Hz on
  this record from rest moves f_n by +0.016 Hz (+-0.0025 Hz) and K by +173 N/m out of their
  (narrow) bands. A prior box 5 % of the default log width (it excludes the truth) pins C
  at its edge (-415 N s/m). Two harmonics for a force with three bias the damping ratio
  (+0.18). Cutting the record into footfall steps gives every step fresh force
  coefficients, which absorb much of the start-up transient that identifies C and K: f_n
  moves by -0.55 Hz with a band 38 times wider, out of the truth's reach (bias).
- Not distinguishable from Monte Carlo noise: 16 or 64 particles instead of 32, 8
  harmonics instead of 4, the exact method instead of rbpf, the step-phase clock.

``python analyses/sensitivity_noise.py --part study --replicates 2`` (22 records, about 4 min)

- Pooled over the 22 records (mean effect, 95 % half-width across records): halving or
  doubling the particles (32, 128) and 6 harmonics instead of 3 move neither f_n nor the
  damping ratio distinguishably (f_n within +-0.0017 Hz). The observation noise moves the
  damping ratio consistently but little (x0.5: -0.0009 +- 0.0006; x2: +0.0036 +- 0.0022)
  and f_n not distinguishably. The seed's process noise of (u, u') (0.5 %) shifts f_n by
  -0.020 +- 0.011 Hz. Two harmonics for a three-harmonic force shift f_n by +0.18 +- 0.17 Hz
  (and scatter the damping ratio by 0.11 from record to record): the one setting that
  matters on these records.

``python analyses/sensitivity_noise.py --part pf`` (seed's particle filter, 1000 particles)

- The seed-faithful filter does not recover the truth on this record at any level: its
  replicates scatter f_n between 0 (K negative) and 3.5 Hz, so its Monte Carlo uncertainty
  (+-3 to 4 Hz) swallows every effect of the random walks of C and K (x0.5, x2) and of the
  particle count (500, 2000): all "not distinguishable". The seed's statement that its
  results are robust "against slight changes of w(k)" cannot be checked with this filter on
  this record; on the same record the rbpf's replicates of f_n have an sd of 0.0012 Hz.

``python analyses/sensitivity_noise.py --part real --replicates 2`` (32 runs, about 6 min)

- No level of any setting makes C and K identified on either real record (0 of 2
  replicates everywhere, ``identified`` in ``sensitivity.csv``): every run reports them
  "not identified", as ``workbench identify`` does at the defaults (README, identification
  section).
- Insole (20 s): f_n sits at 1.000 Hz, the lower edge of the modal prior box, at every level
  (posterior sd 0.0002 Hz): a number that is the prior, not the record. The damping ratio
  moves between 0.19 (high-pass 0.075 Hz) and 0.40 (5 harmonics) from 0.33 at the defaults.
- Treadmill (20 s at 2.2 Hz): f_n moves from 1.56 Hz at the defaults to 1.04 Hz (half the
  observation noise) and 2.13 Hz (twice), both beyond the Monte Carlo uncertainty (+-0.43 and
  +-0.30 Hz), and the damping ratio (2.0 at the defaults, over-critical) from 0.53 (20
  harmonics) to 2.2. On these records the numbers follow the settings: exactly what "not
  identified" means, and why the workbench reports it instead of the values.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path
from typing import Any

from workbench.datasets import embedded_path
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.population.study import (
    STUDY_SETTINGS,
    StudyDesign,
    simulate_study_record,
    study_plan,
)
from workbench.records.inspection import inspect_record
from workbench.records.io import load_record
from workbench.reporting.document import Report
from workbench.reporting.sensitivity import sensitivity_section
from workbench.sensitivity.design import parse_levels
from workbench.sensitivity.study import demo_record, demo_settings, run_sensitivity

SYNTHETIC_LEVELS = [
    "obs_noise=1,0.5,2",
    "obs_noise_ddu=1,4",
    "state_noise=0,0.0025,0.005",
    "particles=32,16,64",
    "prior_box=1,0.5,2,0.05",
    "highpass_hz=0,0.15",
    "harmonics=4,2,8",
    "pieces=whole,steps",
    "time_basis=absolute,step_phase",
    "method=rbpf,exact",
]
PF_LEVELS = ["damping_noise=1,0.5,2", "stiffness_noise=1,0.5,2", "particles=1000,500,2000"]
STUDY_LEVELS = [
    "obs_noise=1,0.5,2",
    "particles=64,32,128",
    "harmonics=3,2,6",
    "state_noise=0,0.005",
]
REAL_LEVELS = [
    "obs_noise=1,0.5,2",
    "state_noise=0,0.005",
    "harmonics=10,5,20",
    "highpass_hz=0.15,0.075,0.3",
]


def _run(
    name: str,
    records: list[tuple[str, Any]],
    base: IdentifySettings,
    levels: list[str],
    args: argparse.Namespace,
) -> dict[str, Any]:
    lv = parse_levels(levels, base)
    study = run_sensitivity(
        records,
        base=base,
        factors=list(lv),
        levels=lv,
        replicates=args.replicates,
        seed=args.seed,
        workers=args.workers,
        progress=True,
    )
    out = args.out / name
    study.write(out)
    report = Report(f"Sensitivity study: {name}")
    report.add(sensitivity_section(study, out))
    report.write(out)
    print(f"\n== {name} ==")
    print(study.text())
    return {
        "folder": str(out),
        "default_recovers_truth": study.default_recovers_truth(),
        "statements": [s["sentence"] for s in study.statements],
    }


def real_records(seconds: float) -> list[tuple[str, Any]]:
    """Return the two embedded real records, cut to ``seconds`` (insole rescaled to M g)."""
    insole = load_record(embedded_path("insole"), mass_kg=83.0).slice(10.0, 10.0 + seconds)
    insole = inspect_record(insole, rescale=True).record
    tread = load_record(embedded_path("treadmill")).slice(75.0, 75.0 + seconds)
    return [("insole", insole), ("treadmill", tread)]


def study_records(n_people: int, seed: int) -> list[tuple[str, Any]]:
    """Return records of the synthetic population study (``workbench.population.study``).

    The first ``n_people`` participants of the study's plan, every pacing case once: records
    from the study's generating laws, in the model class its settings assume.
    """
    design = StudyDesign(n_male=max(1, n_people - n_people // 2), n_female=n_people // 2)
    plan = study_plan(dataclasses.replace(design, n_records=None), seed=seed)
    first = plan.drop_duplicates(subset=["subject", "case"]).head(11 * n_people)
    return [
        (f"{row['subject']}-{row['case']}", simulate_study_record(row, design))
        for _, row in first.iterrows()
    ]


def main(argv: list[str] | None = None) -> dict[str, Any]:
    """Run the studies and return what they found."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--part", choices=["synthetic", "pf", "study", "real", "all"], default="all"
    )
    parser.add_argument(
        "--study-people", type=int, default=2, help="participants of the study part (11 cases each)"
    )
    parser.add_argument("--replicates", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--real-seconds", type=float, default=20.0)
    parser.add_argument("--out", type=Path, default=Path("analyses/out/sensitivity_noise"))
    args = parser.parse_args(argv)
    found: dict[str, Any] = {}
    if args.part in ("synthetic", "all"):
        found["synthetic"] = _run(
            "synthetic", [demo_record()], demo_settings(), SYNTHETIC_LEVELS, args
        )
    if args.part in ("pf", "all"):
        base = demo_settings().replace(method="pf", particles=1000)
        found["pf"] = _run("pf", [demo_record()], base, PF_LEVELS, args)
    if args.part in ("study", "all"):
        base = IdentifySettings.from_flat(**STUDY_SETTINGS, particles=64)
        records = study_records(args.study_people, args.seed)
        found["study"] = _run("study", records, base, STUDY_LEVELS, args)
    if args.part in ("real", "all"):
        base = IdentifySettings.from_flat(particles=128)
        found["real"] = _run("real", real_records(args.real_seconds), base, REAL_LEVELS, args)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(found, indent=2) + "\n", encoding="utf-8")
    return found


if __name__ == "__main__":
    main()
