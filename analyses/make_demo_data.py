"""Regenerate the embedded synthetic records in ``workbench/datasets/synthetic/``.

Run ``python analyses/make_demo_data.py``; the output is bit-for-bit reproducible (fixed
seeds). Each record is a CSV with a JSON sidecar holding its mass and the simulator's truth.

- ``seed_individual``: the seed study's identified individual (58 kg, f_p 1.75 Hz,
  C 434 N s/m, K 8940 N/m, BLF 0.212 / 0.042 / 0.049), 30 s, steady start.
- ``population_typical``: 70 kg at 1.9 Hz with f_n and zeta from the seed's population laws,
  30 s, starting from rest so the start-up transient (the non-periodic content that
  identifies C and K) is in the record.
- ``cubic_stiffness``: as ``population_typical`` with a hardening leg spring
  (``K3 = 2e6 N/m^3``), a hidden effect for the model-criticism loop.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from workbench.models.conversions import damping_ratio, natural_frequency_hz
from workbench.models.effects import CubicStiffness
from workbench.records.io import save_record
from workbench.synth.simulate import simulate_walking

OUT = Path(__file__).resolve().parents[1] / "workbench" / "datasets" / "synthetic"

COMMON = dict(duration_s=30.0, sample_rate_hz=200.0, noise_sd_n=2.0)


def records() -> dict[str, dict]:
    """Return the synthetic set: name -> keyword arguments of ``simulate_walking``."""
    individual_k, individual_c, individual_m = 8940.0, 434.0, 58.0
    return {
        "seed_individual": dict(
            mass_kg=individual_m,
            pacing_hz=1.75,
            natural_frequency_hz=float(natural_frequency_hz(individual_k, individual_m)),
            damping_ratio=float(damping_ratio(individual_c, individual_k, individual_m)),
            blf=(0.212, 0.042, 0.049),
            start="steady",
            seed=1,
            **COMMON,
        ),
        "population_typical": dict(mass_kg=70.0, pacing_hz=1.9, start="rest", seed=2, **COMMON),
        "cubic_stiffness": dict(
            mass_kg=70.0,
            pacing_hz=1.9,
            start="rest",
            seed=2,
            effects=[CubicStiffness(k3_n_per_m3=2e6)],
            **COMMON,
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=OUT, help="output folder")
    args = parser.parse_args()
    for name, kwargs in records().items():
        sim = simulate_walking(**kwargs)
        record = sim.record.replace(subject=name)
        csv_path, _ = save_record(record, args.out / f"{name}.csv")
        truth = sim.truth
        print(
            f"{csv_path.name}: {record.duration_s:.1f} s, truth K "
            f"{truth['stiffness_n_per_m']:.1f} N/m, C {truth['damping_ns_per_m']:.1f} N s/m"
        )


if __name__ == "__main__":
    main()
