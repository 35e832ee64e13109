"""How far the rbpf lands from the exact posterior on realistic 30 s walks, and at what cost.

Usage::

    python analyses/rbpf_rejuvenation.py [--records seed_individual sim3] [--seeds 10]
        [--particles 256] [--json]

For each record (an embedded name, or ``simN``: a 30 s, 200 Hz steady walk of 70 kg at
1.8 Hz, ``simulate_walking(..., seed=N, start="steady")``) the problem is compiled with the
identification defaults (noise estimated from the record), the exact posterior of (C, K) is
computed once, and the rbpf runs with seeds ``0 .. --seeds - 1`` under both rejuvenation
rules: ``surprise`` (exact moves at a second resampling inside a step and while a budget
lasts, Liu-West moves otherwise; the rbpf's default on a rigid floor) and ``always`` (exact
moves after every resampling). Printed per record and rule: the CPU seconds of the filter
(mean and largest; this process is pinned to one core), the rms and largest ``|z|`` of C and
K (distance of the filter's mean from the exact mean in exact posterior sd) and the range of
the filter's sd over the exact sd, and the share of the exact moves' proposals that the
delayed-acceptance screen let through to the exact filter.

``--surprising-step`` measures instead the record of ``tests/test_rbpf.py``'s surprising-step
test (``stumbling_walk_problem``: 70 kg at 1.8 Hz, 8 s at 100 Hz, 3 N force noise, from
rest, seed 4, one quick, heavy step; n = 4; in the simulator's own steps), 128 particles,
seeds 0-9, with the exact moves screened (``delayed_acceptance=True``, the default) and
plain (``False``): the same statistics, the mean ``z`` of the ten runs and the fewest and
most tempering steps of the stumble's piece, against the test's own reference (its zooming
grids, ``tests/test_rbpf.py`` ``grid_posterior``, imported from the test so that the
figures are the test's; ``--exact-reference`` compares with ``exact_posterior`` instead).
It also prints the reference posterior of the pieces before the stumble and with it (how
far the stumble moves it, in the earlier posterior's sd), and how far the footfall split's
boundaries around the stumble lie from the simulator's step starts.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent / "benchmarks"))
from _cores import pin_cores

pin_cores(sys.argv)

import numpy as np  # noqa: E402

import workbench as wb  # noqa: E402
from workbench.inference.methods.exact import exact_posterior  # noqa: E402
from workbench.inference.methods.rbpf import run_rbpf  # noqa: E402
from workbench.inference.pipeline.identification import Prepared, compile_problem, set_noise  # noqa: E402
from workbench.inference.pipeline.settings import IdentifySettings  # noqa: E402
from workbench.synth.simulate import simulate_walking  # noqa: E402


def _record(name: str) -> Any:
    if name.startswith("sim"):
        seed = int(name[3:])
        return simulate_walking(
            mass_kg=70.0,
            pacing_hz=1.8,
            duration_s=30.0,
            sample_rate_hz=200.0,
            seed=seed,
            start="steady",
        ).record
    return wb.datasets.load(name)


def _tests_on_path() -> None:
    """Put the repository root on the path so that the rbpf tests' helpers import."""
    root = str(Path(__file__).resolve().parents[1])
    if root not in sys.path:
        sys.path.insert(0, root)


def _surprising_step_problem() -> Any:
    """Return the rbpf tests' surprising-step record, as those tests build it."""
    _tests_on_path()
    from tests.test_rbpf import stumbling_walk_problem

    return stumbling_walk_problem()


def _stumble_report(problem: Any) -> dict[str, Any]:
    """Return the reference posterior before and with the stumble, and the split's offsets."""
    _tests_on_path()
    from tests.test_rbpf import STUMBLE_PIECE, first_pieces, stumbling_walk

    before = _test_grid_reference(first_pieces(problem, STUMBLE_PIECE))
    after = _test_grid_reference(first_pieces(problem, STUMBLE_PIECE + 1))
    # The split of the same record: its boundaries near the stumble against the steps'.
    sim, insp = stumbling_walk()
    split_s = insp.com.time_s[insp.steps.boundaries]
    steps_s = problem.time_s[problem.piece_starts[:-1]]
    near = steps_s[STUMBLE_PIECE - 1 : STUMBLE_PIECE + 3]
    offsets = [float(np.min(np.abs(split_s - t))) for t in near]
    return {
        "stumble_piece": STUMBLE_PIECE,
        "before_mean": before.mean.tolist(),
        "before_sd": before.sd.tolist(),
        "with_mean": after.mean.tolist(),
        "with_sd": after.sd.tolist(),
        "move_in_earlier_sd": ((after.mean - before.mean) / before.sd).tolist(),
        "split_offsets_s": offsets,
        "truth": [sim.truth["damping_ns_per_m"], sim.truth["stiffness_n_per_m"]],
    }


def _test_grid_reference(problem: Any) -> Any:
    """Return the surprising-step test's reference posterior (mean and sd of C and K)."""
    from types import SimpleNamespace

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from tests.test_rbpf import grid_posterior

    mean, sd = grid_posterior(problem)
    return SimpleNamespace(mean=mean, sd=sd)


def _runs(
    problem: Any,
    exact: Any,
    seeds: int,
    particles: int,
    piece: int | None = None,
    **options: Any,
) -> dict[str, Any]:
    """Run the rbpf over seeds 0..seeds-1 and summarise its distance from the exact posterior.

    With ``piece``, also the fewest and most tempering steps that piece took (and the most
    of any other piece), and per run the Metropolis acceptance and the share of proposals
    filtered exactly (their ranges).
    """
    cpu, z, ratio, evaluated, proposed = [], [], [], 0, 0
    steps, others, acceptance, shares = [], [], [], []
    for seed in range(seeds):
        t0 = time.process_time()
        out = run_rbpf(problem, n_particles=particles, seed=seed, **options)
        cpu.append(time.process_time() - t0)
        z.append((out.mean[-1] - exact.mean) / exact.sd)
        ratio.append(out.sd[-1] / exact.sd)
        evaluated += out.settings["metropolis_exact_evaluations"]
        proposed += out.settings["metropolis_proposals"]
        if piece is not None:
            per_piece = list(out.settings["tempering_steps"])
            steps.append(per_piece.pop(piece))
            others.append(max(per_piece))
            acceptance.append(out.settings["metropolis_acceptance"])
            shares.append(
                out.settings["metropolis_exact_evaluations"] / out.settings["metropolis_proposals"]
            )
    za, ra = np.array(z), np.array(ratio)
    row = {
        "cpu_s_mean": float(np.mean(cpu)),
        "cpu_s_max": float(np.max(cpu)),
        "rms_z": np.sqrt(np.mean(za**2, axis=0)).tolist(),
        "max_abs_z": np.abs(za).max(axis=0).tolist(),
        "mean_z": za.mean(axis=0).tolist(),
        "sd_ratio_min": ra.min(axis=0).tolist(),
        "sd_ratio_max": ra.max(axis=0).tolist(),
        "exact_share": evaluated / proposed if proposed else None,
    }
    if piece is not None:
        row["piece_tempering_steps"] = [min(steps), max(steps)]
        row["other_pieces_most_steps"] = max(others)
        row["acceptance"] = [min(acceptance), max(acceptance)]
        row["exact_share_per_run"] = [min(shares), max(shares)]
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--records", nargs="+", default=["seed_individual", "sim3"])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--particles", type=int, default=256)
    ap.add_argument("--cores", type=int, default=1, help="CPUs to pin to (read before numpy)")
    ap.add_argument("--surprising-step", action="store_true", help="the rbpf tests' record")
    ap.add_argument(
        "--exact-reference", action="store_true", help="with --surprising-step: exact_posterior"
    )
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    settings = IdentifySettings()
    report: dict[str, Any] = {}
    cases: list[tuple[str, dict[str, dict[str, Any]]]]
    if args.surprising_step:
        args.records, args.particles = ["surprising_step"], 128
        cases = [("screened", {}), ("plain", {"delayed_acceptance": False})]
    else:
        cases = [(rule, {"rejuvenate": rule}) for rule in ("surprise", "always")]
    for name in args.records:
        piece = None
        if args.surprising_step:
            problem = _surprising_step_problem()
            stumble = _stumble_report(problem)
            piece = stumble["stumble_piece"]
        else:
            prepared = Prepared.of(_record(name), settings)
            problem, _ = set_noise(compile_problem(prepared, settings), settings)
        test_grid = args.surprising_step and not args.exact_reference
        exact = _test_grid_reference(problem) if test_grid else exact_posterior(problem)
        rows = {
            label: _runs(problem, exact, args.seeds, args.particles, piece, **options)
            for label, options in cases
        }
        report[name] = {
            "n_samples": problem.n_samples,
            "n_pieces": problem.n_pieces,
            "exact_mean": exact.mean.tolist(),
            "exact_sd": exact.sd.tolist(),
            "rules": rows,
        }
        if args.surprising_step:
            report[name]["stumble"] = stumble
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    print(f"rbpf, {args.particles} particles, seeds 0-{args.seeds - 1}; |z| and sd ratios (C, K)")
    for name, rec in report.items():
        for rule, r in rec["rules"].items():
            print(
                f"{name:<16} {rule:<9} CPU {r['cpu_s_mean']:5.2f} s (max {r['cpu_s_max']:5.2f})"
                f"  rms |z| {r['rms_z'][0]:.2f}, {r['rms_z'][1]:.2f}"
                f"  max |z| {r['max_abs_z'][0]:.2f}, {r['max_abs_z'][1]:.2f}"
                f"  mean z {r['mean_z'][0]:.2f}, {r['mean_z'][1]:.2f}"
                f"  sd ratio {r['sd_ratio_min'][0]:.2f}-{r['sd_ratio_max'][0]:.2f},"
                f" {r['sd_ratio_min'][1]:.2f}-{r['sd_ratio_max'][1]:.2f}"
                f"  exact share {r['exact_share'] or 0.0:.2f}"
            )
            if "piece_tempering_steps" in r:
                print(
                    f"{'':<16} {'':<9} stumble's piece: {r['piece_tempering_steps'][0]}-"
                    f"{r['piece_tempering_steps'][1]} tempering steps (any other piece at most "
                    f"{r['other_pieces_most_steps']}); acceptance "
                    f"{r['acceptance'][0]:.2f}-{r['acceptance'][1]:.2f}; exact share per run "
                    f"{r['exact_share_per_run'][0]:.2f}-{r['exact_share_per_run'][1]:.2f}"
                )
        if "stumble" in rec:
            st = rec["stumble"]
            print(
                f"{name}: {rec['n_pieces']} pieces; reference posterior of (C, K) before the "
                f"stumble ({st['stumble_piece']} pieces) {st['before_mean'][0]:.0f} +- "
                f"{st['before_sd'][0]:.0f}, {st['before_mean'][1]:.0f} +- "
                f"{st['before_sd'][1]:.0f}; with it {st['with_mean'][0]:.0f} +- "
                f"{st['with_sd'][0]:.0f}, {st['with_mean'][1]:.0f} +- {st['with_sd'][1]:.0f} "
                f"(moved {st['move_in_earlier_sd'][0]:.2f}, {st['move_in_earlier_sd'][1]:.2f} "
                f"earlier sd); whole record {rec['exact_mean'][0]:.0f} +- "
                f"{rec['exact_sd'][0]:.0f}, {rec['exact_mean'][1]:.0f} +- {rec['exact_sd'][1]:.0f}"
                f" (the simulated walker's {st['truth'][0]:.0f}, {st['truth'][1]:.0f})"
            )
            offsets = ", ".join(f"{v:.3f}" for v in st["split_offsets_s"])
            print(f"{'':<16} footfall split vs the steps around the stumble: {offsets} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
