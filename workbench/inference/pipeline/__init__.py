"""Identify a record: settings, preprocessing, the problem, the noise, the method, the grade.

:func:`~workbench.inference.pipeline.identification.identify` runs the stages; around it
live the run's settings, the observation noise from the data, the effect terms of the
force model, the force-model check and the identification along a record's prefixes.
"""

from workbench.inference.pipeline.identification import Prepared, identify, set_noise
from workbench.inference.pipeline.prefixes import PrefixConvergence, identify_on_prefixes
from workbench.inference.pipeline.settings import IdentifySettings, NoiseSettings, Preprocessing

__all__ = [
    "IdentifySettings",
    "NoiseSettings",
    "PrefixConvergence",
    "Prepared",
    "Preprocessing",
    "identify",
    "identify_on_prefixes",
    "set_noise",
]
