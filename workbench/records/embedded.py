"""The catalogue of embedded records: where each file is and what is known about it.

The files live in ``workbench/datasets/``; see ``README.md`` there for provenance and
licences, and keep that attribution in any copy. Body masses of the real records are not in
their files and are given here, below the loaders, so that
:func:`~workbench.records.io.load_record` gives an embedded file its mass however it is
named. :mod:`workbench.datasets` loads the records by name and re-exports these names.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

from workbench.errors import UsageError

__all__ = [
    "EMBEDDED",
    "EmbeddedRecord",
    "benchmark_paths",
    "dataset_options",
    "dataset_path",
    "embedded_path",
    "names",
    "synthetic_paths",
]


@dataclass(frozen=True)
class EmbeddedRecord:
    """One embedded real record and what the workbench needs to know to read it."""

    key: str
    filename: str
    mass_kg: float
    description: str
    attribution: str


EMBEDDED: dict[str, EmbeddedRecord] = {
    "treadmill": EmbeddedRecord(
        key="treadmill",
        filename="real/treadmill_01_01_grf.mot",
        mass_kg=77.3,
        description="Instrumented split-belt treadmill, 143 s, speed changes (OpenSim .mot)",
        attribution=(
            "Camargo et al. (2021) J Biomech 119:110320, CC BY 4.0; re-processed by "
            "AddBiomechanics, nimblephysics (BSD-2-Clause)"
        ),
    ),
    "insole": EmbeddedRecord(
        key="insole",
        filename="real/GaCo01_01.txt",
        mass_kg=83.0,
        description="Force-sensing insoles, overground, 121 s, calibration 33 % high (PhysioNet)",
        attribution=(
            "PhysioNet gaitpdb v1.0.0, Hausdorff et al.; Yogev et al. (2005); "
            "Goldberger et al. (2000); ODC-By 1.0"
        ),
    ),
}


def _root() -> Path:
    # The data folder of the package, found without importing workbench.datasets (a layer
    # above this one).
    return Path(str(resources.files("workbench"))) / "datasets"


def embedded_path(key: str) -> Path:
    """Path of an embedded real record by key (``"treadmill"`` or ``"insole"``)."""
    try:
        return _root() / EMBEDDED[key].filename
    except KeyError:
        raise UsageError(
            f"unknown embedded record {key!r}; choose one of {', '.join(EMBEDDED)}"
        ) from None


def names() -> tuple[str, ...]:
    """Names of every embedded record: the real ones, the synthetic walks, the benchmarks."""
    return (*EMBEDDED, *(p.stem for p in (*synthetic_paths(), *benchmark_paths())))


def synthetic_paths() -> list[Path]:
    """CSV files of the embedded synthetic walks, sorted by name."""
    return sorted((_root() / "synthetic").glob("*.csv"))


def benchmark_paths() -> list[Path]:
    """CSV files of the embedded benchmark signals (not walks: the seed's numerical example)."""
    return sorted((_root() / "benchmark").glob("*.csv"))


def dataset_path(name: str) -> Path | None:
    """Path of the embedded record called ``name`` (:func:`names`), or None if none is."""
    if name in EMBEDDED:
        return embedded_path(name)
    return next((p for p in (*synthetic_paths(), *benchmark_paths()) if p.stem == name), None)


def dataset_options(name: str) -> tuple[dict[str, object], dict[str, object]]:
    """Loader options and identification settings an embedded record was made for.

    A synthetic sidecar may carry ``"load"`` (keyword arguments of the loader, e.g.
    ``allow_negative_force`` for the seed's benchmark force, which is not a walking GRF and
    dips below zero) and ``"identify"`` (flat identification settings: the force model it
    was simulated with). Only embedded records named by name get them; a file given by its
    path is read as any other.

    Returns
    -------
    (dict, dict)
        Loader options and flat settings; both empty for a record without them.
    """
    import json

    path = dataset_path(name)
    if path is None or name in EMBEDDED:
        return {}, {}
    sidecar = json.loads(path.with_suffix(".json").read_text(encoding="utf-8"))
    return dict(sidecar.get("load") or {}), dict(sidecar.get("identify") or {})
