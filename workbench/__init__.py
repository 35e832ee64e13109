"""Pedestrian spring-mass-damper (SMD) workbench.

Identify a walking pedestrian's SMD model (stiffness, damping and biomechanical force) from
vertical ground reaction force (GRF) records, criticise it against measurements, fit population
laws and simulate pedestrians on structures.

The notebook session::

    import workbench as wb
    rec = wb.datasets.load("seed_individual_deck")
    model = wb.SMDModel(harmonics=6)
    res = wb.identify(rec, model, seed=1)
    print(res.summary()); res.params; res.conf_int(); res.plot_diagnostics()
    rigid = wb.identify(wb.datasets.load("treadmill").slice(40, 70), model, seed=1)
    print(rigid.summary())
    d = wb.diagnose(rec, model); print(d.summary())

One pedestrian model (:class:`SMDModel`, effects composed with ``+``) is what the simulator,
every identification method, the criticism and the human-structure interaction consume;
methods are objects with their own options (:class:`RBPF`, :class:`PF`, :class:`Exact`).
The names below are loaded on first use, so that the command line starts quickly.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from workbench.errors import InputError, UsageError, WorkbenchError
from workbench.records.record import G_M_S2, Record

if TYPE_CHECKING:
    from workbench import datasets
    from workbench.diagnostics.criticism import compare, diagnose
    from workbench.diagnostics.walker import compare_walker, diagnose_walker
    from workbench.inference.core import IdentificationResult
    from workbench.inference.crosscheck import crosscheck
    from workbench.inference.methods import PF, RBPF, Exact
    from workbench.inference.pipeline import IdentifySettings, NoiseSettings, Preprocessing
    from workbench.inference.pipeline.identification import identify
    from workbench.models import effects
    from workbench.models.smd import SMDModel
    from workbench.records.io import load_record
    from workbench.synth.simulate import simulate_walking

__all__ = [
    "G_M_S2",
    "PF",
    "RBPF",
    "Exact",
    "IdentificationResult",
    "IdentifySettings",
    "InputError",
    "NoiseSettings",
    "Preprocessing",
    "Record",
    "SMDModel",
    "UsageError",
    "WorkbenchError",
    "compare",
    "compare_walker",
    "crosscheck",
    "datasets",
    "diagnose",
    "diagnose_walker",
    "effects",
    "identify",
    "load_record",
    "simulate_walking",
]
__version__ = "0.1.0"

#: Where each lazily loaded name lives: ``name -> (module, attribute or None for a module)``.
_LAZY: dict[str, tuple[str, str | None]] = {
    "datasets": ("workbench.datasets", None),
    "effects": ("workbench.models.effects", None),
    "SMDModel": ("workbench.models.smd", "SMDModel"),
    "load_record": ("workbench.records.io", "load_record"),
    "identify": ("workbench.inference.pipeline.identification", "identify"),
    "IdentificationResult": ("workbench.inference.core.results", "IdentificationResult"),
    "IdentifySettings": ("workbench.inference.pipeline.settings", "IdentifySettings"),
    "NoiseSettings": ("workbench.inference.pipeline.settings", "NoiseSettings"),
    "Preprocessing": ("workbench.inference.pipeline.settings", "Preprocessing"),
    "RBPF": ("workbench.inference.methods.base", "RBPF"),
    "PF": ("workbench.inference.methods.base", "PF"),
    "Exact": ("workbench.inference.methods.base", "Exact"),
    "crosscheck": ("workbench.inference.crosscheck.check", "crosscheck"),
    "diagnose": ("workbench.diagnostics.criticism", "diagnose"),
    "compare": ("workbench.diagnostics.criticism", "compare"),
    "diagnose_walker": ("workbench.diagnostics.walker", "diagnose_walker"),
    "compare_walker": ("workbench.diagnostics.walker", "compare_walker"),
    "simulate_walking": ("workbench.synth.simulate", "simulate_walking"),
}


def __getattr__(name: str) -> Any:
    try:
        module, attribute = _LAZY[name]
    except KeyError:
        raise AttributeError(f"module 'workbench' has no attribute {name!r}") from None
    value = importlib.import_module(module)
    if attribute is not None:
        value = getattr(value, attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
