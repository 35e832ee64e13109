"""The analytic HSI checks of docs/science.md 7, computed by the workbench's own simulator.

Usage::

    python analyses/hsi_benchmarks.py [--json] [--dt 0.005]

1. Two-DOF check: the 50 m simply supported beam (500 kg/m, modal mass 12 500 kg, 2 Hz,
   0.5 % damping) with a 73.85 kg, 14.11 kN/m, 612.5 N s/m pedestrian standing at midspan.
   The coupled modes come from :func:`workbench.hsi.modes.coupled_modes`, the eigen-analysis
   of the matrices the integrator advances (``tests/test_hsi.py`` checks the integrator
   step by step against a dense Newmark on those same matrices). Expected 1.991 Hz / 0.90 %
   (structure mode) and 2.210 Hz / 29.7 % (human mode).
2. Moving harmonic force: ``F0 = 0.41 (2 - 0.95) 73.85 g = 311.9 N`` at 2 Hz crossing at
   1.25 m/s, integrated by :func:`workbench.hsi.loads.moving_harmonic_force` (the Newmark
   integrator with the force as moving load). Expected peak midspan acceleration
   1.734 m/s^2; the stationary resonant bound ``F0 / (2 zeta m)`` is 2.495 m/s^2.
3. The same walker as an SMD at resonance, with interaction and as the moving force it
   exerts on rigid ground, at halving time steps: the interaction response is lower and the
   ratio converges at second order.

``--json`` prints ``two_dof`` (list of ``frequency_hz, damping_ratio``, structure mode
first), ``moving_force_peak_acceleration_m_s2`` and the resonance table.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from workbench.hsi.loads import moving_harmonic_force
from workbench.hsi.modes import coupled_modes
from workbench.hsi.pedestrians import G, design_pedestrian
from workbench.hsi.simulate import simulate_pedestrians
from workbench.hsi.structure import simply_supported_beam


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.add_argument("--dt", type=float, default=0.005, help="time step of the checks [s]")
    parser.add_argument(
        "--steps",
        type=lambda s: [float(x) for x in s.split(",")],
        default=[0.02, 0.01, 0.005, 0.0025],
        help="time steps of the resonance convergence table",
    )
    args = parser.parse_args()
    beam = simply_supported_beam(50.0, 500.0, 2.0, 0.005)
    walker = design_pedestrian()  # 73.85 kg, 14.11 kN/m, 612.5 N s/m, 2 Hz, BLF1 0.41 (2-0.95)
    modes = coupled_modes(beam, walker, [25.0])
    f0 = 0.41 * (2.0 - 0.95) * 73.85 * G
    hist = moving_harmonic_force(
        beam, amplitude_n=f0, frequency_hz=2.0, speed_m_s=1.25, dt_s=args.dt
    )
    peak = float(np.max(np.abs(hist.acceleration_m_s2)))
    bound = f0 / (2 * 0.005 * 12500.0)
    table = []
    for dt in args.steps:
        row = {"dt_s": dt}
        for m in ("interaction", "moving_force", "biomechanical_force"):
            h = simulate_pedestrians(beam, walker, dt_s=dt, model=m)
            row[f"peak_{m}_m_s2"] = float(np.max(np.abs(h.acceleration_m_s2)))
        row["ratio"] = row["peak_interaction_m_s2"] / row["peak_moving_force_m_s2"]
        table.append(row)
    out = {
        "two_dof": [
            {"frequency_hz": m.frequency_hz, "damping_ratio": m.damping_ratio} for m in modes
        ],
        "moving_force_peak_acceleration_m_s2": peak,
        "moving_force_amplitude_n": f0,
        "stationary_resonant_bound_m_s2": bound,
        "dt_s": args.dt,
        "resonant_walker": table,
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return
    (fs, zs), (fh, zh) = ((m.frequency_hz, m.damping_ratio) for m in modes)
    print("two-DOF (pedestrian at midspan), coupled eigen-analysis:")
    print(f"  structure mode {fs:.4f} Hz, {100 * zs:.3f} %   (expected 1.991 Hz, 0.90 %)")
    print(f"  human mode     {fh:.4f} Hz, {100 * zh:.2f} %   (expected 2.210 Hz, 29.7 %)")
    print(f"moving harmonic force {f0:.1f} N at 2 Hz, 1.25 m/s, dt {args.dt:g} s:")
    print(f"  peak midspan acceleration {peak:.4f} m/s^2 (expected 1.734; bound {bound:.3f})")
    print("resonant walker (SMD), peak midspan acceleration [m/s^2]:")
    print("  dt [s]   interaction  moving force (rigid GRF)  biomech. force  ratio")
    for r in table:
        print(
            f"  {r['dt_s']:<8g} {r['peak_interaction_m_s2']:11.4f}  "
            f"{r['peak_moving_force_m_s2']:24.4f}  {r['peak_biomechanical_force_m_s2']:14.4f}"
            f"  {r['ratio']:.4f}"
        )


if __name__ == "__main__":
    main()
