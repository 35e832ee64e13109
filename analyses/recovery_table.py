"""The recovery table: can the population pipeline recover each truth law, floor by floor.

Usage::

    python analyses/recovery_table.py --out recovery_runs [--records 60] [--seed 0]
        [--workers 2] [--truths seed,constant,zhang] [--floors rigid,deck]
        [--settings default,seed] [--markdown FILE]

Every run is one ``workbench recovery`` (``workbench.population.recovery.run_recovery``): a
population of ``--records`` realistic walks (20-30 s at 100 Hz) with the truth law, on the
floor, identified in batch with the settings, and the laws fitted. ``default`` is the
workbench's default identification; ``seed`` the seed-faithful ``--method pf --obs-noise
seed``; ``rbpf`` the Rao-Blackwellised filter, the default of the earlier tables. Every run
writes its folder ``OUT/<truth>-<floor>-<settings>`` and resumes there, so an interrupted
table continues where it stopped. The population seed is the same for every run (fixed
before looking at the results), so a truth's rigid and deck populations share their walkers
and every settings column sees the same records.

Columns: identified (records the pipeline's fit used / simulated), then per law parameter
the recovered value, its 95 % interval and the verdict, for the pipeline's fit and, beside
it, the fit with the identifiability flags ignored: slope and intercept of f_n, zeta and
BLF1 against pacing, ``mu`` and ``sigma`` of the lognormal BLF2 and BLF3.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from workbench.inference.pipeline.settings import IdentifySettings
from workbench.population.recovery import RecoveryDesign, run_recovery, truth_laws

SETTINGS = {
    "default": {},
    "seed": {"method": "pf", "obs_noise": "seed"},
    # The default before the exact posterior became the default method (the earlier tables).
    "rbpf": {"method": "rbpf"},
}
#: The table's law parameters: (law, parameter, column name).
COLUMNS = [
    (law, par, f"{name} {par}")
    for law, name in (("natural_frequency_hz", "f_n"), ("damping_ratio", "zeta"), ("blf1", "BLF1"))
    for par in ("slope", "intercept")
] + [(law, par, f"{law.upper()} {par}") for law in ("blf2", "blf3") for par in ("mu", "sigma")]


def _cell(fit: dict[str, Any], verdicts: dict[str, Any], law: str, par: str) -> str:
    if "laws" not in fit:
        return "not fitted"
    fl = fit["laws"][law] if law in fit["laws"] else fit["lognormal"][law]
    lo, hi = fl[f"{par}_ci"]
    return f"{fl[par]:.3g} [{lo:.3g}, {hi:.3g}] {verdicts[law][par]}"


def main(argv: list[str] | None = None) -> int:
    """Run the table's recoveries and print it."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="folder of the runs")
    ap.add_argument("--records", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--truths", default="seed,constant,zhang")
    ap.add_argument("--floors", default="rigid,deck")
    ap.add_argument("--settings", default="default,seed")
    ap.add_argument("--markdown", help="also write the table to this file")
    args = ap.parse_args(argv)
    names = ["truth", "floor", "settings", "used / simulated", "fit"] + [c[2] for c in COLUMNS]
    header = "| " + " | ".join(names) + " |\n|" + "---|" * len(names)
    lines = [header]
    for truth in args.truths.split(","):
        for floor in args.floors.split(","):
            for name in args.settings.split(","):
                design = RecoveryDesign(truth_laws(truth), floor=floor, n_records=args.records)
                settings = IdentifySettings().replace(**SETTINGS[name])
                out = Path(args.out) / f"{truth}-{floor}-{name}"
                res = run_recovery(
                    out, design, settings, seed=args.seed, workers=args.workers, resume=True
                ).to_json()
                rec = res["records"]
                for which in ("pipeline", "flags_ignored"):
                    fit = res["recovered"][which]
                    used = fit.get("records_used", 0)
                    cells = [_cell(fit, res["verdict"][which], law, par) for law, par, _ in COLUMNS]
                    label = "pipeline" if which == "pipeline" else "flags ignored"
                    lines.append(
                        f"| {truth} | {floor} | {name} | {used} / {rec['simulated']} | {label} | "
                        + " | ".join(cells)
                        + " |"
                    )
                print(lines[-2], lines[-1], sep="\n", flush=True)
    text = "\n".join(lines)
    print("\n" + text)
    if args.markdown:
        Path(args.markdown).write_text(text + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
