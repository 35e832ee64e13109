"""Selection by the records' own f_n: the two-stage fit against the hierarchical one.

Run: ``python analyses/population_selection.py [--seeds 0-19]`` (about ten seconds a seed).

Population seeds 0-19 were fixed before any result was seen. Each is
:func:`workbench.population.selection.selected_population`: 200 records of the seed's laws
whose f_n measurement is weak or strong. A record passes only when it is strong and its
estimate of f_n is below 2.1 Hz, so passing depends on its own f_n. For f_n and zeta, slope
and intercept (and f_n's residual sd), the script prints:

- the two-stage fit (``fit_population``: OLS of the passed records' estimates), the
  hierarchical fit (``fit_hierarchical`` on every record's likelihood), and as a reference
  OLS of *every* record's estimate (no selection, no sampler: what these seeds' data say);
- their mean error over the seeds, with its standard error;
- how many of the seeds' 95 % intervals hold the generating value, and the median width.

The two-stage fit gives no interval for the residual sd. The figures are quoted in
docs/validation/population.md.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
from _crossings import seed_range

from workbench.population.fit import fit_population
from workbench.population.hierarchy import fit_hierarchical
from workbench.population.recovery_design import truth_laws
from workbench.population.selection import selected_population

PARAMETERS = (
    ("natural_frequency_hz", "slope"),
    ("natural_frequency_hz", "intercept"),
    ("natural_frequency_hz", "residual_sd"),
    ("damping_ratio", "slope"),
    ("damping_ratio", "intercept"),
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=seed_range, default=seed_range("0-19"))
    args = ap.parse_args()
    laws = truth_laws("seed")
    truth = {(law, par): float(getattr(getattr(laws, law), par)) for law, par in PARAMETERS}
    rows: dict[tuple[str, str, str], list[tuple[float, float, float]]] = {}
    passed = []
    for seed in args.seeds:
        records, table = selected_population(seed)
        passed.append(int(table["identified_damping"].sum()))
        two = fit_population(table, source=f"population {seed}").to_json()["laws"]
        every = table.assign(identified_damping=True, identified_stiffness=True)
        ref = fit_population(every, source=f"population {seed}").to_json()["laws"]
        hier = fit_hierarchical(records, seed=seed)
        ci = hier.conf_int(0.05)
        for law, par in PARAMETERS:
            key = f"{law}.{par}"
            lo, hi = ci.loc[key, "lower"], ci.loc[key, "upper"]
            rows.setdefault(("hierarchical", law, par), []).append((hier.params[key], lo, hi))
            est = two[law][par]
            if par == "residual_sd":
                lo = hi = math.nan
            else:
                lo, hi = two[law][f"{par}_ci"]
            rows.setdefault(("two-stage", law, par), []).append((est, lo, hi))
            ref_lo, ref_hi = (math.nan, math.nan) if par == "residual_sd" else ref[law][f"{par}_ci"]
            rows.setdefault(("every record, OLS", law, par), []).append(
                (ref[law][par], ref_lo, ref_hi)
            )
        print(f"population {seed}: {passed[-1]} of {len(table)} records passed")
    n = len(args.seeds)
    print(f"\n{n} populations, records passed: median {int(np.median(passed))} of 200")
    print(
        "| parameter | truth | fit | mean error (se) | 95 % intervals holding it | median width |"
    )
    print("|---|---|---|---|---|---|")
    for law, par in PARAMETERS:
        for fit in ("two-stage", "hierarchical", "every record, OLS"):
            values = np.array(rows[(fit, law, par)])
            err = values[:, 0] - truth[(law, par)]
            se = err.std(ddof=1) / math.sqrt(n)
            if np.all(np.isnan(values[:, 1])):
                held, width = "no interval", "-"
            else:
                held = str(
                    int(
                        np.sum(
                            (values[:, 1] <= truth[(law, par)])
                            & (truth[(law, par)] <= values[:, 2])
                        )
                    )
                )
                held += f" of {n}"
                width = f"{np.median(values[:, 2] - values[:, 1]):.3f}"
            print(
                f"| {law} {par} | {truth[(law, par)]:.4f} | {fit} | {err.mean():+.4f} "
                f"({se:.4f}) | {held} | {width} |"
            )


if __name__ == "__main__":
    main()
