"""Factors, levels and design points of a sensitivity study.

A *factor* is one identification setting the study varies; a *level* one value of it; a
*design point* one combination of levels. The *baseline* is the point where every factor sits
at its default level (the settings the user would otherwise run). Two designs:

- ``"oat"`` (one at a time): the baseline, then each factor's other levels with every other
  factor at its default;
- ``"factorial"``: every combination of the factors' levels (keep the factors few: the
  number of points is the product of the numbers of levels).

Default levels (``LEVELS`` in the table below; ``--levels NAME=V1,V2`` replaces them, and the
default level is always added because the effects are measured against it):

================ ================================================ ===========================
factor           what it changes                                  default levels
================ ================================================ ===========================
obs_noise        observation noise sd of u, u', u'' (all three)   x0.5, x1, x2
obs_noise_u      observation noise sd of u only                   x0.5, x1, x2
obs_noise_du     observation noise sd of u' only                  x0.5, x1, x2
obs_noise_ddu    observation noise sd of u'' only                 x0.5, x1, x2
state_noise      process noise of (u, u'), fraction of their RMS  x0.5, x1, x2 (0, 0.0025,
                                                                  0.005 when the default is 0)
damping_noise    random-walk sd of C per sample [N s/m] (pf)      x0.5, x1, x2 of 5 N s/m
stiffness_noise  random-walk sd of K per sample [N/m] (pf)        x0.5, x1, x2 of 100 N/m
particles        number of particles (particle filters)           x0.5, x1, x2
prior_box        initial ranges of C and K: log-width scale       x0.5, x1, x2
highpass_hz      high-pass cut-off [Hz]                           x0.5, x1, x2 (0, 0.075,
                                                                  0.15 when the default is 0)
harmonics        number of Fourier harmonics                      n/2, n, 2n
pieces           segmentation: footfall steps or whole record     steps, whole
time_basis       force basis clock: step phase or absolute time   step_phase, absolute
method           identification method                            the registered methods,
                                                                  the baseline's first
================ ================================================ ===========================

The observation-noise scales multiply whatever the ``--obs-noise`` setting gives (with
``auto``, the estimate from the record), so ``obs_noise_ddu = 2`` reads "twice the noise of
u'' the default would use". The prior box is scaled about its geometric centre in log space,
so its bounds stay positive: a scale s maps ``(lo, hi)`` to ``(g / r^s, g r^s)`` with
``g = sqrt(lo hi)`` and ``r = sqrt(hi / lo)``. Random walks of C and K act only in ``pf``
(the ``rbpf`` and ``exact`` methods have static C and K), and u, u' are unobserved with
``observe = "acc"``, so those factors show no effect there -- the study then says so.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from workbench.errors import UsageError
from workbench.inference.core import (
    SEED_DAMPING_RW_SD,
    SEED_STATE_FRACTION,
    SEED_STIFFNESS_RW_SD,
    IdentificationProblem,
    StiffnessDampingPrior,
)
from workbench.inference.methods import method_names
from workbench.inference.pipeline.settings import IdentifySettings
from workbench.models.force import HARMONICS_RANGE

__all__ = [
    "DESIGNS",
    "FACTORS",
    "DesignPoint",
    "Factor",
    "Level",
    "Overrides",
    "build_design",
    "default_levels",
    "parse_factors",
    "parse_levels",
    "point_seed",
]

DESIGNS = ("oat", "factorial")
SCALES = (0.5, 1.0, 2.0)


@dataclass(frozen=True)
class Factor:
    """One setting a study can vary.

    Parameters
    ----------
    name : str
        Name on the command line (``--factors``).
    description : str
        Plain words, used in statements ("the observation noise of u''").
    kind : str
        ``"scale"`` (levels multiply the default; labels ``x0.5``), ``"number"``,
        ``"integer"`` or ``"choice"``.
    """

    name: str
    description: str
    kind: str


FACTORS: dict[str, Factor] = {
    f.name: f
    for f in (
        Factor("obs_noise", "the observation noise of u, u' and u''", "scale"),
        Factor("obs_noise_u", "the observation noise of u", "scale"),
        Factor("obs_noise_du", "the observation noise of u'", "scale"),
        Factor("obs_noise_ddu", "the observation noise of u''", "scale"),
        Factor("state_noise", "the process noise of u and u' (fraction of their RMS)", "number"),
        Factor("damping_noise", "the random walk of C", "scale"),
        Factor("stiffness_noise", "the random walk of K", "scale"),
        Factor("particles", "the number of particles", "integer"),
        Factor("prior_box", "the width of the initial ranges of C and K", "scale"),
        Factor("highpass_hz", "the high-pass cut-off [Hz]", "number"),
        Factor("harmonics", "the number of harmonics", "integer"),
        Factor("pieces", "the segmentation (footfall steps or whole record)", "choice"),
        Factor("time_basis", "the clock of the force basis", "choice"),
        Factor("method", "the identification method", "choice"),
    )
}
#: The levels of the choice factors; the method's are the registered methods
#: (:func:`~workbench.inference.methods.method_names`), read when a design is built.
_CHOICES: dict[str, Callable[[], Sequence[str]]] = {
    "pieces": lambda: ("steps", "whole"),
    "time_basis": lambda: ("step_phase", "absolute"),
    "method": method_names,
}


@dataclass(frozen=True)
class Level:
    """One level of a factor: a value, its label and whether it is the default."""

    value: float | int | str
    label: str
    is_default: bool


@dataclass(frozen=True)
class Overrides:
    """What a design point changes that :class:`IdentifySettings` does not name.

    ``obs_scale`` multiplies the observation sd of (u, u', u''); ``prior_scale`` the log-width
    of the (C, K) box; the random-walk sds of C and K are absolute (N s/m, N/m per sample).
    """

    obs_scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    prior_scale: float = 1.0
    damping_rw_sd_ns_per_m: float = SEED_DAMPING_RW_SD
    stiffness_rw_sd_n_per_m: float = SEED_STIFFNESS_RW_SD

    def adjust_problem(self, problem: IdentificationProblem) -> IdentificationProblem:
        """Apply the prior scale and the random walks (before the noise is set)."""
        if self.prior_scale != 1.0:
            problem = problem.with_prior(scale_prior(problem.prior, self.prior_scale))
        noise = dataclasses.replace(
            problem.noise,
            damping_rw_sd_ns_per_m=float(self.damping_rw_sd_ns_per_m),
            stiffness_rw_sd_n_per_m=float(self.stiffness_rw_sd_n_per_m),
        )
        return problem.with_noise(noise)

    def adjust_noise(self, problem: IdentificationProblem) -> IdentificationProblem:
        """Apply the per-channel observation scales (after the noise is set)."""
        scale = np.asarray(self.obs_scale, dtype=np.float64)
        if np.all(scale == 1.0):
            return problem
        noise = dataclasses.replace(problem.noise, obs_sd=problem.noise.obs_sd * scale)
        return problem.with_noise(noise)


def scale_prior(prior: StiffnessDampingPrior, scale: float) -> StiffnessDampingPrior:
    """Scale a (C, K) box about its geometric centre in log space (bounds stay positive)."""

    def one(bounds: tuple[float, float]) -> tuple[float, float]:
        lo, hi = bounds
        lo = max(lo, 1e-6 * hi)  # a zero lower bound has no log; a tiny one behaves alike
        centre, ratio = np.sqrt(lo * hi), np.sqrt(hi / lo)
        return float(centre / ratio**scale), float(centre * ratio**scale)

    return StiffnessDampingPrior(
        one(prior.damping_ns_per_m),
        one(prior.stiffness_n_per_m),
        label=f"{prior.label}, log-width x{scale:g}",
    )


def _fmt(x: float) -> str:
    return f"{x:g}"


def default_levels(name: str, base: IdentifySettings) -> list[Level]:
    """Return the default levels of a factor around the base settings (module docstring table).

    Parameters
    ----------
    name : str
        Factor name.
    base : IdentifySettings
        The settings at the baseline.

    Returns
    -------
    list of Level
        The default level first.
    """
    factor = _factor(name)
    if factor.kind == "scale":
        return _levels(name, base, list(SCALES))
    if name == "state_noise":
        d = base.state_fraction
        values = (
            [d * s for s in SCALES]
            if d > 0
            else [0.0, SEED_STATE_FRACTION / 2, SEED_STATE_FRACTION]
        )
        return _levels(name, base, values)
    if name == "highpass_hz":
        d = base.preprocessing.highpass_hz
        values = [d * s for s in SCALES] if d > 0 else [0.0, 0.075, 0.15]
        return _levels(name, base, values)
    if name == "particles":
        if base.n_particles == 0:  # a method without particles (exact)
            return _levels(name, base, [0])
        n = base.n_particles
        return _levels(name, base, sorted({max(2, n // 2), n, 2 * n}))
    if name == "harmonics":
        n = base.model.harmonics
        low, high = HARMONICS_RANGE
        return _levels(name, base, sorted({max(low, round(n / 2)), n, min(high, 2 * n)}))
    if name == "method":
        method = base.method.name
        return _levels(name, base, [method, *(m for m in method_names() if m != method)])
    return _levels(name, base, list(_CHOICES[name]()))


def _default_value(name: str, base: IdentifySettings) -> float | int | str:
    factor = _factor(name)
    if factor.kind == "scale":
        return 1.0
    values: dict[str, float | int | str] = {
        "state_noise": base.state_fraction,
        "highpass_hz": base.preprocessing.highpass_hz,
        "particles": base.n_particles,
        "harmonics": base.model.harmonics,
        "pieces": base.model.pieces,
        "time_basis": base.model.time_basis,
        "method": base.method.name,
    }
    return values[name]


def _label(name: str, value: float | int | str) -> str:
    if _factor(name).kind == "scale":
        return f"x{_fmt(float(value))}"
    if isinstance(value, float):
        return _fmt(value)
    return str(value)


def _levels(name: str, base: IdentifySettings, values: Sequence[float | int | str]) -> list[Level]:
    default = _default_value(name, base)
    kind = _factor(name).kind
    out: list[Level] = []
    seen: set[str] = set()
    for v in [default, *values]:
        if kind in ("scale", "number"):
            v = float(v)
        elif kind == "integer":
            v = int(v)
        label = _label(name, v)
        if label in seen:
            continue
        seen.add(label)
        is_default = (
            bool(np.isclose(float(v), float(default)))
            if kind in ("scale", "number")
            else v == default
        )
        out.append(Level(v, label, is_default))
    return out


def _factor(name: str, parameter: str = "factors") -> Factor:
    try:
        return FACTORS[name]
    except KeyError:
        raise UsageError(
            f"'{parameter}': {name!r} is not a sensitivity factor; choose from "
            f"{', '.join(FACTORS)}",
            parameter=parameter,
        ) from None


def parse_factors(text: str | None) -> list[str]:
    """Parse ``--factors NAME,...`` (all factors when not given), checking the names."""
    if not text:
        return list(FACTORS)
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise UsageError(
            "'factors' is empty; give names such as obs_noise,harmonics", parameter="factors"
        )
    for n in names:
        _factor(n, "factors")
    if len(set(names)) != len(names):
        raise UsageError(
            f"'factors' {text!r} names a factor twice; name each once", parameter="factors"
        )
    return names


def parse_levels(
    items: Sequence[str], base: IdentifySettings, factors: Sequence[str] | None = None
) -> dict[str, list[Level]]:
    """Parse ``--levels NAME=V1,V2,...`` options into levels (the default level is added).

    Scale factors take multipliers (``obs_noise_ddu=1,4``); the others take values
    (``harmonics=2,4``, ``pieces=steps,whole``). With ``factors`` given, a level for a
    factor the design does not vary is refused rather than silently ignored.
    """
    out: dict[str, list[Level]] = {}
    for item in items:
        name, eq, values = item.partition("=")
        name = name.strip()
        factor = _factor(name, "levels")
        if factors is not None and name not in factors:
            raise UsageError(
                f"--levels names {name!r}, which is not among --factors; add it there",
                parameter="levels",
            )
        raw = [v.strip() for v in values.split(",") if v.strip()]
        if not eq or not raw:
            raise UsageError(
                f"'levels' {item!r} is not of the form NAME=V1,V2; write for example "
                "obs_noise_ddu=0.5,1,2",
                parameter="levels",
            )
        parsed: list[float | int | str] = []
        for v in raw:
            if factor.kind == "choice":
                choices = _CHOICES[name]()
                if v not in choices:
                    raise UsageError(
                        f"'levels' {name}: {v!r} is not a choice; use {', '.join(choices)}",
                        parameter="levels",
                    )
                parsed.append(v)
                continue
            try:
                num = float(v)
            except ValueError:
                raise UsageError(
                    f"'levels' {name}: {v!r} is not a number", parameter="levels"
                ) from None
            ok = num > 0 if factor.kind in ("scale", "integer") else num >= 0
            if not (np.isfinite(num) and ok) or (factor.kind == "integer" and num != int(num)):
                raise UsageError(
                    f"'levels' {name}: {v!r} must be a "
                    + ("positive whole number" if factor.kind == "integer" else "positive number"),
                    parameter="levels",
                )
            parsed.append(int(num) if factor.kind == "integer" else num)
        out[name] = _levels(name, base, parsed)
    return out


@dataclass(frozen=True)
class DesignPoint:
    """One combination of levels; ``levels`` maps each factor of the study to a level label."""

    levels: dict[str, str]
    values: dict[str, float | int | str] = field(default_factory=dict)
    defaults: dict[str, str] = field(default_factory=dict)

    @property
    def changed(self) -> dict[str, str]:
        """The factors not at their default level, with their labels."""
        return {k: v for k, v in self.levels.items() if self.defaults.get(k) != v}

    @property
    def key(self) -> str:
        """Stable key: the changed factors as ``name=label`` sorted, ``baseline`` for none."""
        changed = self.changed
        return "; ".join(f"{k}={changed[k]}" for k in sorted(changed)) or "baseline"

    def configure(self, base: IdentifySettings) -> tuple[IdentifySettings, Overrides]:
        """Return the settings and problem overrides of this point."""
        v = self.values
        settings = base
        overrides = Overrides()
        scale = [1.0, 1.0, 1.0]
        for name, value in v.items():
            if name == "obs_noise":
                scale = [s * float(value) for s in scale]
            elif name in ("obs_noise_u", "obs_noise_du", "obs_noise_ddu"):
                i = ("obs_noise_u", "obs_noise_du", "obs_noise_ddu").index(name)
                scale[i] *= float(value)
            elif name == "state_noise":
                settings = settings.replace(state_noise_fraction=float(value))
            elif name == "damping_noise":
                overrides = dataclasses.replace(
                    overrides, damping_rw_sd_ns_per_m=SEED_DAMPING_RW_SD * float(value)
                )
            elif name == "stiffness_noise":
                overrides = dataclasses.replace(
                    overrides, stiffness_rw_sd_n_per_m=SEED_STIFFNESS_RW_SD * float(value)
                )
            elif name == "prior_box":
                overrides = dataclasses.replace(overrides, prior_scale=float(value))
            elif name == "particles":
                if int(value) > 0:
                    settings = settings.replace(particles=int(value))
            elif name in ("highpass_hz", "harmonics", "pieces", "time_basis"):
                settings = settings.replace(**{name: value})
        # The method last: a method change keeps the other factors' explicit values and takes
        # the new method's default particle count unless the design sets one.
        if "method" in v and v["method"] != settings.method.name:
            given = int(v["particles"]) if "particles" in v and int(v["particles"]) > 0 else None
            settings = settings.replace(method=str(v["method"]), particles=given)
        overrides = dataclasses.replace(overrides, obs_scale=(scale[0], scale[1], scale[2]))
        return settings, overrides


def build_design(
    design: str, levels: dict[str, list[Level]]
) -> tuple[DesignPoint, list[DesignPoint]]:
    """Return the baseline and every design point (the baseline first, no duplicates).

    Parameters
    ----------
    design : {"oat", "factorial"}
        One at a time or full factorial.
    levels : dict
        Levels of each factor of the study, in study order.

    Returns
    -------
    (DesignPoint, list of DesignPoint)
    """
    if design not in DESIGNS:
        raise UsageError(
            f"'design' {design!r} is not known; choose oat or factorial", parameter="design"
        )
    defaults = {n: next(lv.label for lv in lvls if lv.is_default) for n, lvls in levels.items()}
    default_values = {
        n: next(lv.value for lv in lvls if lv.is_default) for n, lvls in levels.items()
    }

    def point(chosen: dict[str, Level]) -> DesignPoint:
        labels = dict(defaults)
        values = dict(default_values)
        for n, lv in chosen.items():
            labels[n], values[n] = lv.label, lv.value
        return DesignPoint(labels, values, defaults)

    baseline = point({})
    points = [baseline]
    if design == "oat":
        for name, lvls in levels.items():
            points += [point({name: lv}) for lv in lvls if not lv.is_default]
    else:
        names = list(levels)
        for combo in itertools.product(*(levels[n] for n in names)):
            p = point(dict(zip(names, combo, strict=True)))
            if p.key != "baseline":
                points.append(p)
    return baseline, points


def _hash_int(text: str) -> int:
    return int.from_bytes(hashlib.sha256(text.encode("utf-8")).digest()[:4], "little")


def point_seed(seed: int, record_key: str, point_key: str, replicate: int) -> int:
    """Seed of one run: ``SeedSequence(seed, spawn_key=(record, point, replicate))``.

    The spawn key hashes the record's key and the point's key, so a run's seed depends on
    neither the worker count nor the order of the design (nor on which other factors the
    study names): the baseline of a one-at-a-time and of a factorial study is the same run.
    """
    ss = np.random.SeedSequence(
        int(seed), spawn_key=(_hash_int(record_key), _hash_int(point_key), int(replicate))
    )
    return int(ss.generate_state(1, dtype=np.uint32)[0])


#: A function of a problem, as the ``identify`` hooks take.
ProblemHook = Callable[[IdentificationProblem], IdentificationProblem]


def describe_levels(levels: dict[str, list[Level]]) -> dict[str, Any]:
    """JSON-able description of the levels of a study."""
    return {
        n: [{"label": lv.label, "value": lv.value, "default": lv.is_default} for lv in lvls]
        for n, lvls in levels.items()
    }
