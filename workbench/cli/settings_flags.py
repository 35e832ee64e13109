"""Command-line flags of the identification settings whose choices and defaults the library owns.

``--method`` and its options, ``--harmonics``, ``--obs-noise``, ``--prior`` and
``--state-noise``: every choice and default here is read from the method registry
(:mod:`workbench.inference.methods.base`) and the library's constants when a parser is built,
so a registered method appears in every command's ``--method`` and no help text states a
default of its own. :mod:`workbench.cli.common` re-exports these names, so that a command
module still needs only that one.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = [
    "CROSSCHECK_FILTER",
    "add_method_flag",
    "harmonics_help",
    "modal_box_words",
    "obs_noise_help",
    "particles_help",
    "prior_help",
    "seed_box_words",
    "state_noise_help",
    "warn_ignored_method_flags",
]

#: The particle filter a cross-check tests when no ``--method`` names one (``crosscheck``,
#: ``identify --crosscheck``).
CROSSCHECK_FILTER = "rbpf"


def add_method_flag(parser: Any, *, filters_only: bool = False, help: str | None = None) -> None:
    """Add ``--method`` with the registered methods as its choices, read now.

    The choices come from the method registry (:func:`workbench.inference.methods.method_names`)
    when the parser is built, so a method registered before that is offered by every command.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
    filters_only : bool, default False
        Offer only the particle filters, with :data:`CROSSCHECK_FILTER` as the default
        (``crosscheck``).
    help : str, optional
        The help text; by default it names the default method.
    """
    from workbench.inference.methods import DEFAULT_METHOD, method_names, particle_filter_names

    if filters_only:
        parser.add_argument(
            "--method",
            choices=particle_filter_names(),
            default=CROSSCHECK_FILTER,
            help=help or f"filter ({CROSSCHECK_FILTER})",
        )
        return
    parser.add_argument(
        "--method", choices=method_names(), help=help or f"method (default {DEFAULT_METHOD})"
    )


def particles_help() -> str:
    """Help of ``--particles``: each registered particle filter's default count.

    Returns
    -------
    str
        ``"particles (rbpf 256, pf 4000)"``.
    """
    from workbench.inference.methods import method_class, particle_filter_names

    # A method named without options is its class with every default (registry rule).
    counts = [f"{n} {vars(method_class(n)())['n_particles']}" for n in particle_filter_names()]
    return f"particles ({', '.join(counts)})"


def harmonics_help(prefix: str = "force harmonics n") -> str:
    """Help of ``--harmonics``: the accepted range and the default.

    Parameters
    ----------
    prefix : str
        What the flag sets.

    Returns
    -------
    str
        ``"force harmonics n, 1-40 (default 10)"``.
    """
    from workbench.models.force import DEFAULT_FORCE_HARMONICS, HARMONICS_RANGE

    low, high = HARMONICS_RANGE
    return f"{prefix}, {low}-{high} (default {DEFAULT_FORCE_HARMONICS})"


def obs_noise_help() -> str:
    """Help of ``--obs-noise``, with the seed's fraction."""
    from workbench.inference.core import SEED_OBS_FRACTION

    return (
        "observation noise of u, u', u'' as a fraction of their RMS, "
        f"'seed' ({SEED_OBS_FRACTION:.2f}) or 'auto' (estimated from the record; default)"
    )


def modal_box_words() -> str:
    """Return the modal prior box in words: ``"f_n 1-4 Hz and damping ratio 0.05-0.9"``."""
    from workbench.inference.core import MODAL_DAMPING_RATIO, MODAL_NATURAL_FREQUENCY_HZ

    (f_lo, f_hi), (z_lo, z_hi) = MODAL_NATURAL_FREQUENCY_HZ, MODAL_DAMPING_RATIO
    return f"f_n {f_lo:g}-{f_hi:g} Hz and damping ratio {z_lo:g}-{z_hi:g}"


def seed_box_words() -> str:
    """Return the seed's prior box in words: ``"400-1000 N s/m, 12-20 kN/m"``."""
    from workbench.inference.core import StiffnessDampingPrior

    seed = StiffnessDampingPrior.seed()
    (c_lo, c_hi), (k_lo, k_hi) = seed.damping_ns_per_m, seed.stiffness_n_per_m
    return f"{c_lo:g}-{c_hi:g} N s/m, {k_lo / 1e3:g}-{k_hi / 1e3:g} kN/m"


def prior_help() -> str:
    """Help of ``--prior``, with the ranges of both boxes."""
    return (
        f"(C, K) prior box: from {modal_box_words()} at the body mass (default), or the "
        f"seed's {seed_box_words()}"
    )


def state_noise_help() -> str:
    """Help of ``--state-noise``: each registered method's default, from its class."""
    from workbench.inference.core import SEED_STATE_FRACTION
    from workbench.inference.methods import method_class, method_names

    by_fraction: dict[float, list[str]] = {}
    for name in method_names():
        fraction = method_class(name).default_state_noise_fraction
        by_fraction.setdefault(fraction, []).append(name)
    parts = [
        ("the seed's " if fraction == SEED_STATE_FRACTION else "")
        + f"{fraction:g} for {_and(names)}"
        for fraction, names in sorted(by_fraction.items(), reverse=True)
    ]
    return (
        "process noise of u, u' per sample as a fraction of their RMS (default: "
        f"{', '.join(parts)})"
    )


def _and(names: list[str]) -> str:
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def warn_ignored_method_flags(args: argparse.Namespace, method: str) -> None:
    """Say on stderr that a filter's flag is ignored by the method that runs.

    A warning, not a refusal: scripts that pass --particles to every run keep working, and
    the result is what the method gives without the flag, but nobody believes the flag acted.

    Parameters
    ----------
    args : argparse.Namespace
    method : str
        The registered name of the method that runs.
    """
    if "method" in (getattr(args, "factors", None) or ""):
        return  # a study that varies the method runs the filters too
    from workbench.inference.methods import method_names, particle_filter_names

    def takers(option: str) -> list[str]:
        return [name for name in method_names() if option in _method_options(name)]

    options = _method_options(method)
    ignored = []
    if getattr(args, "particles", None) is not None and "n_particles" not in options:
        filters = " or ".join(particle_filter_names())
        ignored.append(f"--particles ({method} is not a particle filter; add --method {filters})")
    if getattr(args, "force_proposal", None) is not None and "force_proposal" not in options:
        owners = " and ".join(f"the {name}'s" for name in takers("force_proposal"))
        ignored.append(f"--force-proposal (it is {owners}; {method} draws no force proposals)")
    for flag in ignored:
        print(f"workbench: warning: the {method} method ignores {flag}", file=sys.stderr)


def _method_options(name: str) -> set[str]:
    """Return the options (dataclass fields) of a registered method."""
    import dataclasses

    from workbench.inference.methods import method_class

    return {f.name for f in dataclasses.fields(method_class(name))}
