"""Regenerate the embedded synthetic records in ``workbench/datasets/synthetic/``.

Run ``python analyses/make_demo_data.py``; the output is reproducible (fixed seeds): bit for
bit on one machine, and to rounding (1e-7 of each column's RMS, tested) across processors.
Each record is a CSV with a JSON sidecar holding its mass and the simulator's truth.
``--out`` is the datasets folder: the walks go to its ``synthetic/``, the benchmark signal to
its ``benchmark/``.

- ``seed_individual``: the seed study's identified individual (58 kg, f_p 1.75 Hz,
  C 434 N s/m, K 8940 N/m, BLF 0.212 / 0.042 / 0.049), 30 s, steady start.
- ``population_typical``: 70 kg at 1.9 Hz with f_n and zeta from the seed's population laws,
  30 s, starting from rest so the start-up transient (the non-periodic content that
  identifies C and K) is in the record.
- ``cubic_stiffness``: as ``population_typical`` with a hardening leg spring
  (``K3 = 2e6 N/m^3``), a hidden effect for the model-criticism loop.
- ``seed_individual_deck``: the seed's individual on a vibrating deck (narrow-band, 0.5 m/s^2
  RMS at 2.3 Hz, about 1.3 times the pacing, bandwidth 5 %), the record carrying the deck's
  acceleration: the kind of record on which C and K are identified (the demo's individual
  identification).
- ``benchmark/seed_numerical_example``: the seed's numerical example (section 4; 75 kg, f_n
  2.5 Hz, zeta 0.4, the sum of sines of its eq. 24, 10 s at 1 kHz from rest, noise-free). Its
  sidecar carries the force model it was made with (``identify``: ten harmonics of 0.5 Hz on
  absolute time, one piece, no high-pass, the seed's 10 % observation noise), so ``workbench
  identify seed_numerical_example`` runs it as the seed did, and ``load``:
  ``allow_negative_force`` (its force is not a walking GRF and dips below zero).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from workbench.models.conversions import damping_ratio, natural_frequency_hz
from workbench.models.effects import CubicStiffness
from workbench.records.io import save_record
from workbench.synth.decks import NarrowBandDeck
from workbench.synth.simulate import seed_numerical_example, simulate_walking

OUT = Path(__file__).resolve().parents[1] / "workbench" / "datasets"
#: How the benchmark is identified and loaded: the sidecar's ``identify`` and ``load``.
NUMERICAL_EXAMPLE_SETTINGS = {
    "harmonics": 10,
    "pacing_hz": 0.5,
    "time_basis": "absolute",
    "pieces": "whole",
    "highpass_hz": 0.0,
    "obs_noise": "seed",
}

COMMON = dict(duration_s=30.0, sample_rate_hz=200.0, noise_sd_n=2.0)


def records() -> dict[str, dict]:
    """Return the synthetic set: name -> keyword arguments of ``simulate_walking``."""
    individual_k, individual_c, individual_m = 8940.0, 434.0, 58.0
    individual = dict(
        mass_kg=individual_m,
        pacing_hz=1.75,
        natural_frequency_hz=float(natural_frequency_hz(individual_k, individual_m)),
        damping_ratio=float(damping_ratio(individual_c, individual_k, individual_m)),
        blf=(0.212, 0.042, 0.049),
        start="steady",
        **COMMON,
    )
    return {
        "seed_individual": dict(individual, seed=1),
        "population_typical": dict(mass_kg=70.0, pacing_hz=1.9, start="rest", seed=2, **COMMON),
        "cubic_stiffness": dict(
            mass_kg=70.0,
            pacing_hz=1.9,
            start="rest",
            seed=2,
            effects=[CubicStiffness(k3_n_per_m3=2e6)],
            **COMMON,
        ),
        "seed_individual_deck": dict(
            individual,
            seed=3,
            # Period = the record's length, so the deck's RMS over the record is exact.
            ground_acc_m_s2=NarrowBandDeck(0.5, 2.3, 0.115, seed=7, period_s=30.0),
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help="output folder")
    args = parser.parse_args()
    sims = {name: simulate_walking(**kwargs) for name, kwargs in records().items()}
    sims["seed_numerical_example"] = seed_numerical_example(duration_s=10.0)
    for name, sim in sims.items():
        record = sim.record.replace(subject=name)
        if name == "seed_numerical_example":
            extra = {"load": {"allow_negative_force": True}, "identify": NUMERICAL_EXAMPLE_SETTINGS}
            csv_path, _ = save_record(
                record, args.out / "benchmark" / f"{name}.csv", extra_metadata=extra
            )
        else:
            csv_path, _ = save_record(record, args.out / "synthetic" / f"{name}.csv")
        truth = sim.truth
        print(
            f"{csv_path.name}: {record.duration_s:.1f} s, truth K "
            f"{truth['stiffness_n_per_m']:.1f} N/m, C {truth['damping_ns_per_m']:.1f} N s/m"
        )


if __name__ == "__main__":
    main()
