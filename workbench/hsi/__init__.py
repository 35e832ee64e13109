"""Pedestrians crossing footbridges: human-structure interaction (HSI).

A pedestrian is an :class:`~workbench.models.smd.SMDModel` with a known force walking at a
speed (:class:`~workbench.hsi.pedestrians.Walker`); a population sample is a table whose
rows become such models (:func:`~workbench.hsi.pedestrians.pedestrian_models`). The main
entry points load lazily from here::

    from workbench import hsi
    beam = hsi.simply_supported_beam(50.0, 500.0, 2.0, 0.005)
    history = hsi.simulate_pedestrians(beam, [model], speed_m_s=1.25)

- ``simulate_pedestrians``: :func:`workbench.hsi.simulate.simulate_pedestrians` (a name
  ``simulate`` would be shadowed by the submodule of that name);
- ``Walker``, ``pedestrian_models``, ``walkers``: :mod:`workbench.hsi.pedestrians`;
- ``coupled_modes``: :func:`workbench.hsi.modes.coupled_modes`;
- ``walker_records``, ``walker_responses``, ``write_walker_records``: the record a sensor
  on each walker would give (GRF and the deck under its feet, with the truth),
  :mod:`workbench.hsi.records` and :mod:`workbench.hsi.record_files`;
- ``ModalStructure``, ``simply_supported_beam``: :mod:`workbench.hsi.structure`.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "ModalStructure",
    "Walker",
    "coupled_modes",
    "pedestrian_models",
    "simply_supported_beam",
    "simulate_pedestrians",
    "walker_records",
    "walker_responses",
    "walkers",
    "write_walker_records",
]

#: ``name -> (module, attribute)`` of the lazily loaded names.
_LAZY: dict[str, tuple[str, str]] = {
    "simulate_pedestrians": ("workbench.hsi.simulate", "simulate_pedestrians"),
    "Walker": ("workbench.hsi.pedestrians", "Walker"),
    "pedestrian_models": ("workbench.hsi.pedestrians", "pedestrian_models"),
    "walkers": ("workbench.hsi.pedestrians", "walkers"),
    "coupled_modes": ("workbench.hsi.modes", "coupled_modes"),
    "ModalStructure": ("workbench.hsi.structure", "ModalStructure"),
    "simply_supported_beam": ("workbench.hsi.structure", "simply_supported_beam"),
    "walker_records": ("workbench.hsi.records", "walker_records"),
    "walker_responses": ("workbench.hsi.records", "walker_responses"),
    "write_walker_records": ("workbench.hsi.record_files", "write_walker_records"),
}


def __getattr__(name: str) -> Any:
    try:
        module, attribute = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'workbench.hsi' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
