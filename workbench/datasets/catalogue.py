"""The catalogue of embedded records: where each file is and what is known about it.

See ``README.md`` in this folder for provenance and licences; keep that attribution in any
copy. Body masses of the real records are not in their files and are given here. This
module imports nothing of the workbench, so the record loaders can consult it.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from pathlib import Path

__all__ = ["EMBEDDED", "EmbeddedRecord", "embedded_path", "names", "synthetic_paths"]


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
    return Path(str(resources.files("workbench.datasets")))


def embedded_path(key: str) -> Path:
    """Path of an embedded real record by key (``"treadmill"`` or ``"insole"``)."""
    try:
        return _root() / EMBEDDED[key].filename
    except KeyError:
        from workbench.errors import UsageError

        raise UsageError(
            f"unknown embedded record {key!r}; choose one of {', '.join(EMBEDDED)}"
        ) from None


def names() -> tuple[str, ...]:
    """Names of every embedded record: the real ones, then the synthetic set's file stems."""
    return (*EMBEDDED, *(p.stem for p in synthetic_paths()))


def synthetic_paths() -> list[Path]:
    """CSV files of the embedded synthetic set, sorted by name."""
    return sorted((_root() / "synthetic").glob("*.csv"))
