"""A cohort crossing a lively footbridge again and again: records a population fit can use.

A rigid floor cannot tell C and K from the force model's misfit (docs/science.md 6); a deck
that moves away from the walker's gait harmonics can, through its transmissibility. A
footbridge's users cross it many times, in crowds that keep the deck moving, so a study of
walkers on a lively footbridge gives every walker several records, some of them informative.
:func:`footbridge_cohort_records` simulates such a study with the human-structure interaction
simulator (:mod:`workbench.hsi`): a cohort drawn from population laws
(:class:`~workbench.population.cohort.CohortSampler`) arrives as a Poisson stream on a simply
supported span, every walker an SMD coupled to the deck, and a sensor on each walker records
the GRF and the deck's acceleration under the feet. The records group by walker (their
subject), which is what the hierarchical population fit needs
(:mod:`workbench.population.hierarchy`). The same study is ``workbench hsi --crowd stream
--cohort N --records DIR --records-crossings K``.
"""

from __future__ import annotations

import os

from workbench.hsi.record_files import RecordsWritten
from workbench.population.laws import PopulationLaws

__all__ = ["LIVELY_SPAN", "footbridge_cohort_records"]

#: The lively footbridge of the design notes (docs/validation/hsi.md): span [m], mass per
#: length [kg/m], first bending frequency [Hz], modal damping ratio, deck width [m].
LIVELY_SPAN = (50.0, 500.0, 2.0, 0.005, 2.0)


def footbridge_cohort_records(
    folder: str | os.PathLike[str],
    *,
    walkers: int,
    crossings: int,
    seed: int,
    flow_per_s: float = 0.1,
    duration_s: float = 60.0,
    dt_s: float = 0.01,
    laws: PopulationLaws | None = None,
    min_record_s: float = 10.0,
) -> RecordsWritten:
    """Simulate a cohort crossing the lively span and write its walkers' records.

    Parameters
    ----------
    folder : path-like
        Where the records, ``truth.csv`` and the batch ``manifest.csv`` go
        (:func:`~workbench.hsi.record_files.write_walker_records`).
    walkers : int
        Cohort size.
    crossings : int
        Stream windows simulated; every walker on the deck in one is recorded.
    seed : int
        Fixes the cohort, the streams and every record.
    flow_per_s : float, default 0.1
        Arrivals per second at the entry.
    duration_s : float, default 60
        Length of each stream window [s] (a walker entering or leaving outside it is
        recorded for the part inside).
    dt_s : float, default 0.01
        Time step of the simulation, and the records' sample interval [s].
    laws : PopulationLaws, optional
        The population the cohort is drawn from (default the seed's laws).
    min_record_s : float, default 10
        Records shorter than this -- walkers caught at a window's edge, a few steps on the
        deck -- are skipped with the reason (identification needs several whole steps, and a
        study would not keep such a fragment).

    Returns
    -------
    RecordsWritten
        The records written (and those the loaders would refuse, skipped with the reason).
    """
    from workbench.hsi.montecarlo import CrossingSpec
    from workbench.hsi.record_files import check_records_folder, write_walker_records
    from workbench.hsi.records import crossing_records, record_name
    from workbench.hsi.structure import simply_supported_beam
    from workbench.population.cohort import CohortSampler

    span, mass_per_m, frequency, damping, width = LIVELY_SPAN
    population = laws or PopulationLaws()
    spec = CrossingSpec(
        simply_supported_beam(span, mass_per_m, frequency, damping, width_m=width),
        CohortSampler.from_laws(walkers, seed=seed, laws=population),
        crowd="stream",
        flow_per_s=flow_per_s,
        duration_s=duration_s,
        dt_s=dt_s,
    )
    check_records_folder(folder)
    records = [r for i in range(int(crossings)) for r in crossing_records(spec, seed, i)]
    keep = [r for r in records if r.duration_s >= min_record_s]
    written = write_walker_records(keep, folder)
    short = [
        {
            "record": record_name(r.metadata["truth"]["crossing"], r.metadata["truth"]["walker"]),
            "reason": f"the record lasts {r.duration_s:.2f} s, shorter than the study's "
            f"{min_record_s:g} s (a walker at the window's edge)",
        }
        for r in records
        if r.duration_s < min_record_s
    ]
    return RecordsWritten(
        written.folder, written.manifest, written.records, [*written.skipped, *short]
    )
