"""Records for the detection studies of model criticism: catalogued effects hidden in walks.

A detection study asks how often :func:`~workbench.diagnostics.criticism.diagnose` finds an
effect that was put into a record, and how often it calls one that was not. The records
come from :func:`hidden_effect_walk`: a :func:`~workbench.synth.simulate.varied_walk`
(duration, sample rate 100-1000 Hz, GRF noise, pacing, mass and the step-to-step
variability all drawn from the seed) with effects of the catalogue at the sizes of
:data:`HIDDEN_EFFECT_LEVELS`, in one of the kinds of :data:`WALK_KINDS`:

``steady``
    Walking in steady state for 20-120 s on a rigid floor.
``overground``
    The seed study's protocol (:meth:`GaitProfile.overground
    <workbench.synth.gait.GaitProfile.overground>`): standing, gait initiation, steady
    walking, termination, standing; 20-30 walking steps drawn from the seed.
``speed_change``
    Steady walking that changes pace over four steps
    (:meth:`GaitProfile.speed_change <workbench.synth.gait.GaitProfile.speed_change>`): the
    new pacing 0.80-0.90 or 1.10-1.25 times the old, 12-25 steps before and after.
``deck``
    Steady walking for 20-60 s on a vibrating deck: RMS acceleration 0.3-1 m/s^2
    (log-uniform; a narrow-band deck's RMS is that over its 600 s period, so over the record
    it is not exactly that), a sine or a narrow-band response (bandwidth 3-10 % of its centre); the
    centre frequency is 1.15-1.35 or 1.65-1.85 times the pacing. Near a multiple of half
    the pacing the deck drives the body at the frequency of the gait's own lines (the
    harmonics, or the stride lines of a left/right asymmetry), where no record can tell
    the deck's part from the walker's (docs/science.md 6), so detection is studied away
    from them.

The kind's own details are drawn from a generator of their own, so the walk's other
details are those of the steady walk of the same seed.

A walker's walks (:func:`hidden_effect_walker`) are several passes of one walker, as in the
seed study, where every participant walked each pacing case two or three times: the walker
(mass, natural frequency, damping, force shape, step-to-step variability, the hidden
effects and their sizes, the instrument's sample rate and noise) is drawn once from the
seed; each pass has its own length, pacing and noise, and the kinds of
:data:`WALKER_KINDS` say what a pass is:

``overground``
    From standing to standing, 20-30 walking steps, on a rigid floor (the seed's 40 m track).
``speed_change``
    Steady walking that changes pace over four steps (as above), each pass its own change.
``deck``
    Overground passes over a vibrating deck (a footbridge crossing): the deck (its RMS
    acceleration, centre frequency and kind, drawn as above) is the walker's, its phase or
    realisation the pass's own.

A pass's own details come from a generator of its own (seeded by the walker's seed and the
pass's number), so the first ``k`` passes of a walker are the same whatever the number of
passes asked for.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from workbench.errors import UsageError
from workbench.models.effects import Effect, effect_from_name
from workbench.synth.decks import NarrowBandDeck, SineDeck
from workbench.synth.gait import GaitProfile
from workbench.synth.result import Simulation
from workbench.synth.simulate import (
    population_damping_ratio,
    population_natural_frequency_hz,
    simulate_walking,
    varied_walk,
    varied_walk_details,
)

__all__ = [
    "HIDDEN_EFFECT_LEVELS",
    "WALKER_KINDS",
    "WALK_KINDS",
    "hidden_effect_walk",
    "hidden_effect_walker",
]

#: The kinds of record of a detection study (module docstring).
WALK_KINDS = ("steady", "overground", "speed_change", "deck")
#: The kinds of pass of a walker's walks (module docstring).
WALKER_KINDS = ("overground", "speed_change", "deck")
#: Range of a pass's pacing over the walker's [-]: passes of one pacing case differ a little.
PASS_PACING_RANGE = (0.97, 1.03)

#: Three sizes (small, middle, large) of every catalogued effect for detection studies:
#: realistic, clearly present. Drifts are given as their total change over the record
#: (``pacing_drift``: the first harmonic's coefficients [N], split 0.8 / -0.6 between cos and
#: sin; ``stiffness_drift``: K [N/m]) so that a long record does not drift further than a
#: short one; ``base_motion``: amplitude of a 2.7 Hz surface acceleration [m/s^2].
HIDDEN_EFFECT_LEVELS: dict[str, tuple[float, float, float]] = {
    "gait_asymmetry": (30.0, 60.0, 90.0),  # a_half_n (b_half_n is half of it)
    "cubic_stiffness": (1e6, 2e6, 4e6),  # k3_n_per_m3
    "quadratic_damping": (500.0, 1000.0, 2000.0),  # c2_ns2_per_m2
    "heel_impact": (100.0, 150.0, 250.0),  # impact_n, decay 15 ms
    "pacing_drift": (40.0, 80.0, 120.0),  # total change of the first harmonic [N]
    "stiffness_drift": (1500.0, 3000.0, 4500.0),  # total change of K [N/m]
    "base_motion": (0.5, 1.0, 1.5),  # surface acceleration amplitude [m/s^2]
}


def _hidden_effect(name: str, size: float, duration_s: float) -> Effect:
    if name == "gait_asymmetry":
        return effect_from_name(name, a_half_n=size, b_half_n=size / 2)
    if name == "cubic_stiffness":
        return effect_from_name(name, k3_n_per_m3=size)
    if name == "quadratic_damping":
        return effect_from_name(name, c2_ns2_per_m2=size)
    if name == "heel_impact":
        return effect_from_name(name, impact_n=size, decay_s=0.015)
    if name == "pacing_drift":
        rate = size / duration_s
        return effect_from_name(name, drift_cos_n_per_s=0.8 * rate, drift_sin_n_per_s=-0.6 * rate)
    if name == "stiffness_drift":
        return effect_from_name(name, dk_n_per_m_s=size / duration_s)
    raise UsageError(f"no detection level for effect {name!r}")


def _kind_details(seed: int) -> dict[str, Any]:
    """Draw the kinds' own details (module docstring) from their own generator.

    Every kind's details are drawn whatever the kind, so they stay put if one is added.
    """
    rng = np.random.default_rng([seed, 0x6A17])
    out: dict[str, Any] = {
        "walking_steps": int(rng.integers(20, 31)),
        "pacing_ratio": float(rng.choice([rng.uniform(0.80, 0.90), rng.uniform(1.10, 1.25)])),
        "steps_before": int(rng.integers(12, 26)),
        "steps_after": int(rng.integers(12, 26)),
        "deck_rms_m_s2": float(np.exp(rng.uniform(np.log(0.3), np.log(1.0)))),
        "deck_ratio": float(rng.choice([rng.uniform(1.15, 1.35), rng.uniform(1.65, 1.85)])),
        "deck_kind": str(rng.choice(["sine", "narrowband"])),
        "deck_bandwidth_fraction": float(rng.uniform(0.03, 0.10)),
        "deck_phase_rad": float(rng.uniform(0.0, 2.0 * math.pi)),
        "deck_seed": int(rng.integers(2**32)),
    }
    return out


def hidden_effect_walk(
    names: str | Sequence[str],
    seed: int,
    level: int | None = None,
    *,
    kind: str = "steady",
    size_factor: float = 1.0,
    **kwargs: Any,
) -> Simulation:
    """Simulate a walk of one kind with catalogued effects hidden at set sizes.

    The sizes are those of :data:`HIDDEN_EFFECT_LEVELS`; the kinds those of
    :data:`WALK_KINDS` (module docstring).

    Parameters
    ----------
    names : str or sequence of str
        Catalogue names of the hidden effects (``"none"`` or an empty sequence: none).
    seed : int
        Seed of the record.
    level : {0, 1, 2}, optional
        Size from :data:`HIDDEN_EFFECT_LEVELS`; default ``seed % 3`` (sizes in turn).
    kind : {"steady", "overground", "speed_change", "deck"}, default "steady"
        The kind of record.
    size_factor : float, default 1
        Multiplies the sizes of the hidden effects (a detection curve against size).
    **kwargs
        Passed to :func:`~workbench.synth.simulate.varied_walk` (e.g. ``amplitude_sd``,
        ``duration_s``).

    Returns
    -------
    Simulation
        The truth names the kind (``truth["walk_kind"]``) and, on a deck, the deck.
    """
    wanted = _check_names(names, kind, WALK_KINDS, "hidden_effect_walk")
    i = seed % 3 if level is None else int(level)
    if not (math.isfinite(size_factor) and size_factor > 0):
        raise UsageError(
            f"hidden_effect_walk: size_factor must be positive, got {size_factor!r}",
            parameter="size_factor",
        )
    sizes = {n: size_factor * HIDDEN_EFFECT_LEVELS[n][i] for n in wanted}
    ground = sizes.get("base_motion", 0.0)
    extra = _kind_details(seed)
    if kind == "overground":
        kwargs.setdefault("gait", GaitProfile.overground(walking_steps=extra["walking_steps"]))
    elif kind == "speed_change":
        pacing = _steady_pacing_hz(seed)
        kwargs.setdefault(
            "gait",
            GaitProfile.speed_change(
                pacing,
                extra["pacing_ratio"],
                steps_before=extra["steps_before"],
                steps_after=extra["steps_after"],
            ),
        )
    elif kind == "deck":
        kwargs.setdefault("duration_s", (20.0, 60.0))
        centre = extra["deck_ratio"] * _steady_pacing_hz(seed)
        rms = extra["deck_rms_m_s2"]
        if extra["deck_kind"] == "sine":
            deck: Any = SineDeck(rms, centre, extra["deck_phase_rad"])
        else:
            width = extra["deck_bandwidth_fraction"] * centre
            deck = NarrowBandDeck(rms, centre, width, seed=extra["deck_seed"])
        kwargs.setdefault("ground_acc_m_s2", deck)

    def effects(duration_s: float) -> list[Effect]:
        return [_hidden_effect(n, sizes[n], duration_s) for n in wanted if n != "base_motion"]

    sim = varied_walk(seed, effects, ground_amplitude_m_s2=ground, **kwargs)
    sim.record.metadata["truth"]["walk_kind"] = kind
    return sim


def _steady_pacing_hz(seed: int) -> float:
    """Return the pacing :func:`~workbench.synth.simulate.varied_walk` draws for a seed [Hz]."""
    return float(varied_walk_details(seed)["pacing_hz"])


def _check_names(
    names: str | Sequence[str], kind: str, kinds: Sequence[str], where: str
) -> list[str]:
    """Return the hidden effects' names, refusing unknown ones, kinds and base motion on decks."""
    wanted = [names] if isinstance(names, str) else list(names)
    wanted = [n for n in wanted if n != "none"]
    unknown = [n for n in wanted if n not in HIDDEN_EFFECT_LEVELS]
    if unknown:
        raise UsageError(
            f"no detection level for effect {unknown[0]!r}; choose from "
            + ", ".join(HIDDEN_EFFECT_LEVELS)
        )
    if kind not in kinds:
        raise UsageError(
            f"{where}: kind must be one of {', '.join(kinds)}, got {kind!r}", parameter="kind"
        )
    if kind == "deck" and "base_motion" in wanted:
        raise UsageError(
            f"{where}: a deck already moves the surface; hide base_motion in another kind of walk",
            parameter="names",
        )
    return wanted


def _pass_seed(seed: int, index: int) -> int:
    return int(np.random.SeedSequence([seed, 0x9A55, index]).generate_state(1)[0])


def hidden_effect_walker(
    names: str | Sequence[str],
    seed: int,
    walks: int,
    level: int | None = None,
    *,
    kind: str = "overground",
    size_factor: float = 1.0,
) -> list[Simulation]:
    """Simulate several passes of one walker with catalogued effects hidden (module docstring).

    Parameters
    ----------
    names : str or sequence of str
        Catalogue names of the hidden effects (``"none"`` or empty: none), the walker's.
    seed : int
        Seed of the walker.
    walks : int
        Number of passes.
    level : {0, 1, 2}, optional
        Size from :data:`HIDDEN_EFFECT_LEVELS`; default ``seed % 3``.
    kind : {"overground", "speed_change", "deck"}, default "overground"
        What a pass is (:data:`WALKER_KINDS`).
    size_factor : float, default 1
        Multiplies the sizes of the hidden effects.

    Returns
    -------
    list of Simulation
        One per pass; each truth names the walker (``truth["walker_seed"]``), the pass
        (``truth["walk_index"]``) and the kind.
    """
    wanted = _check_names(names, kind, WALKER_KINDS, "hidden_effect_walker")
    if isinstance(walks, bool) or not isinstance(walks, int | np.integer) or walks < 1:
        raise UsageError(
            f"hidden_effect_walker: walks must be a whole number of at least 1, got {walks!r}",
            parameter="walks",
        )
    if not (math.isfinite(size_factor) and size_factor > 0):
        raise UsageError(
            f"hidden_effect_walker: size_factor must be positive, got {size_factor!r}",
            parameter="size_factor",
        )
    if level is not None and level not in (0, 1, 2):
        raise UsageError(
            f"hidden_effect_walker: level must be 0, 1 or 2 (small, middle, large), got {level!r}",
            parameter="level",
        )
    i = seed % 3 if level is None else int(level)
    sizes = {n: size_factor * HIDDEN_EFFECT_LEVELS[n][i] for n in wanted}
    walker = varied_walk_details(seed)
    base_pacing = float(walker.pop("pacing_hz"))
    walker.pop("duration_s")
    # The walker's SMD: the population laws at its usual pacing, the same in every pass.
    fn = population_natural_frequency_hz(base_pacing)
    zeta = population_damping_ratio(base_pacing)
    deck = _kind_details(seed)
    out = []
    for index in range(int(walks)):
        rng = np.random.default_rng([seed, 0x9A55, index])
        pacing = base_pacing * float(rng.uniform(*PASS_PACING_RANGE))
        own = _kind_details(_pass_seed(seed, index))
        if kind == "speed_change":
            gait = GaitProfile.speed_change(
                pacing,
                own["pacing_ratio"],
                steps_before=own["steps_before"],
                steps_after=own["steps_after"],
            )
        else:
            gait = GaitProfile.overground(walking_steps=own["walking_steps"])
        duration = gait.relative_length() / pacing
        ground: Any = None
        if "base_motion" in sizes:
            amp, w = sizes["base_motion"], 2.0 * math.pi * 2.7
            phase = float(rng.uniform(0.0, 2.0 * math.pi))

            def ground(t: Any, amp: float = amp, w: float = w, phase: float = phase) -> Any:
                return amp * np.sin(w * np.asarray(t) + phase)

        elif kind == "deck":
            centre = deck["deck_ratio"] * base_pacing
            if deck["deck_kind"] == "sine":
                ground = SineDeck(deck["deck_rms_m_s2"], centre, own["deck_phase_rad"])
            else:
                width = deck["deck_bandwidth_fraction"] * centre
                ground = NarrowBandDeck(deck["deck_rms_m_s2"], centre, width, seed=own["deck_seed"])
        effects = [_hidden_effect(n, sizes[n], duration) for n in wanted if n != "base_motion"]
        sim = simulate_walking(
            **walker,
            pacing_hz=pacing,
            duration_s=duration,
            natural_frequency_hz=fn,
            damping_ratio=zeta,
            start="rest" if gait.amplitude_factors[0] == 0.0 else "steady",
            effects=effects,
            ground_acc_m_s2=ground,
            seed=_pass_seed(seed, index),
            gait=gait,
        )
        truth = sim.record.metadata["truth"]
        truth.update(walk_kind=kind, walker_seed=seed, walk_index=index)
        out.append(sim)
    return out
