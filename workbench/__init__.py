"""Pedestrian spring-mass-damper (SMD) workbench.

Identify a walking pedestrian's SMD model (stiffness, damping and biomechanical force) from
vertical ground reaction force (GRF) records, criticise it against measurements, fit population
laws and simulate pedestrians on structures.
"""

from workbench.errors import InputError, WorkbenchError
from workbench.records.record import G_M_S2, Record

__all__ = ["G_M_S2", "InputError", "Record", "WorkbenchError"]
__version__ = "0.1.0"
