"""The surface route: C and K from the walking surface's transmissibility.

On a vibrating deck the response the deck drives sets C and K
(:mod:`~workbench.inference.surface.frf`); the route then finds the force given them
(:mod:`~workbench.inference.surface.route`);
:mod:`~workbench.inference.surface.bound` is the Cramer-Rao bound of what the deck drives, and
:mod:`~workbench.inference.surface.information` measures how much of what a record says
about C and K came from the surface's motion.
"""

from workbench.inference.surface.bound import InformationBound, information_bound
from workbench.inference.surface.frf import deck_spectra, surface_transmissibility
from workbench.inference.surface.information import surface_report
from workbench.inference.surface.route import identify_through_surface

__all__ = [
    "InformationBound",
    "deck_spectra",
    "identify_through_surface",
    "information_bound",
    "surface_report",
    "surface_transmissibility",
]
