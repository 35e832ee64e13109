"""Population laws of the SMD pedestrian: mean laws against pacing, residual sds, BLF2/BLF3.

A :class:`PopulationLaws` holds what the population fit (``workbench population``) estimates
and what the pedestrian sampler (:func:`workbench.population.sampler.sample_pedestrians`)
draws from:

- linear mean laws ``y = slope * f_p + intercept`` with normal residuals of sd
  ``residual_sd`` for the natural frequency [Hz], the damping ratio and BLF1;
- lognormal BLF2 and BLF3 (``log BLF ~ N(mu, sigma^2)``), independent of pacing, as the seed
  found;
- the pacing distribution, the body-mass distribution and the step-length relation that the
  sampler needs and the seed's study fixed by design (metronome) rather than measured.

Seed defaults and the assumptions behind them (each one is written down in
:data:`DEFAULT_ASSUMPTIONS` too, so reports can print them):

- f_n = 0.3049 f_p + 1.3670 and zeta = -0.2116 f_p + 0.8737: the seed's population laws
  (docs/science.md 7).
- BLF1 = 0.41 (f_p - 0.95): the seed says BLF1 is linear in f_p but does not print the
  coefficients; this is Young's (2001) design law for the first walking harmonic, used as an
  assumption.
- Residual sds (f_n 0.15 Hz, zeta 0.05, BLF1 0.04): the seed shows the normal fits of its
  model errors only as figures (figs. 13a-c), without numbers; these are assumptions of the
  size the seed's individual results suggest (f_n 1.94-1.98 Hz and zeta 0.29-0.30 for one
  person at one pacing, laws spanning 1.82-2.13 Hz and 0.56-0.34) and, for BLF1, a
  coefficient of variation of about 10 % of the first harmonic as reported for walking
  forces in the literature (Kerr 1998, Zivanovic et al. 2007).
- BLF2 and BLF3 lognormal with medians 0.055 and 0.05 and log-sd 0.4: the seed fits
  lognormals without printing their parameters; the medians lie between the seed's
  individual values (0.042 and 0.049) and the means near 0.07 and 0.06 usually quoted for
  the second and third walking harmonics; the log-sd 0.4 (coefficient of variation about
  40 %) is an assumption.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.errors import InputError, UsageError
from workbench.models.seed_laws import (
    SEED_DAMPING_RATIO,
    SEED_NATURAL_FREQUENCY_HZ,
    SEED_PACING_RANGE_HZ,
)

__all__ = [
    "DEFAULT_ASSUMPTIONS",
    "SEED_DAMPING_RATIO",
    "SEED_NATURAL_FREQUENCY_HZ",
    "SEED_PACING_RANGE_HZ",
    "LinearLaw",
    "LognormalLaw",
    "MassDistribution",
    "PacingDistribution",
    "PopulationLaws",
    "StepLengthLaw",
    "read_laws",
]


@dataclass(frozen=True)
class LinearLaw:
    """A mean law ``y = slope * f_p + intercept`` with normal residuals of sd ``residual_sd``.

    Parameters
    ----------
    slope : float
        Change of the mean per Hz of pacing.
    intercept : float
        Mean at ``f_p = 0`` (a fit parameter, not a physical value).
    residual_sd : float
        Standard deviation of the normal model error about the mean law.
    """

    slope: float
    intercept: float
    residual_sd: float

    def mean(self, pacing_hz: Any) -> Any:
        """Mean of the law at the pacing frequency (scalar or array) [Hz]."""
        return self.slope * pacing_hz + self.intercept


@dataclass(frozen=True)
class LognormalLaw:
    """A lognormal law: ``log(x) ~ N(mu, sigma^2)``.

    Parameters
    ----------
    mu : float
        Mean of ``log(x)``; the median is ``exp(mu)``.
    sigma : float
        Standard deviation of ``log(x)``.
    """

    mu: float
    sigma: float

    @property
    def median(self) -> float:
        """Median ``exp(mu)``."""
        return math.exp(self.mu)

    @property
    def mean(self) -> float:
        """Mean ``exp(mu + sigma^2 / 2)``."""
        return math.exp(self.mu + 0.5 * self.sigma**2)


@dataclass(frozen=True)
class PacingDistribution:
    """Normal pacing frequency truncated to a range.

    The default, N(1.99 Hz, 0.173 Hz) is Matsumoto et al.'s (1978) distribution of normal
    walking, the one footbridge guidelines use; it is truncated to the seed's pacing range
    1.5-2.25 Hz so that sampled pedestrians stay where the laws were fitted.

    Parameters
    ----------
    mean_hz, sd_hz : float
        Mean and standard deviation before truncation [Hz].
    low_hz, high_hz : float
        Truncation range [Hz].
    """

    mean_hz: float = 1.99
    sd_hz: float = 0.173
    low_hz: float = SEED_PACING_RANGE_HZ[0]
    high_hz: float = SEED_PACING_RANGE_HZ[1]


@dataclass(frozen=True)
class MassDistribution:
    """Body mass as a mixture of two truncated normals (the seed's Table 1 participants).

    Parameters
    ----------
    male_fraction : float
        Probability of the first component (39 of 56 participants).
    male_mean_kg, male_sd_kg, male_low_kg, male_high_kg : float
        Male participants: 68.3 +- 15.0 kg, observed range 49.8-95.1 kg (the truncation).
    female_mean_kg, female_sd_kg, female_low_kg, female_high_kg : float
        Female participants: 60.3 +- 4.98 kg; the seed prints no range, so the truncation at
        +- 3 sd (45.4-75.2 kg) is an assumption.
    """

    male_fraction: float = 39 / 56
    male_mean_kg: float = 68.3
    male_sd_kg: float = 15.0
    male_low_kg: float = 49.8
    male_high_kg: float = 95.1
    female_mean_kg: float = 60.3
    female_sd_kg: float = 4.98
    female_low_kg: float = 60.3 - 3 * 4.98
    female_high_kg: float = 60.3 + 3 * 4.98


@dataclass(frozen=True)
class StepLengthLaw:
    """Step length linear in pacing, ``l = slope * f_p + intercept`` plus normal scatter.

    The default passes through Bachmann and Ammann's (1987) slow and normal walking (1.7 Hz,
    0.60 m; 2.0 Hz, 0.75 m): people who step faster also step longer. The scatter sd of
    0.05 m is an assumption. Speed is pacing times step length.

    Parameters
    ----------
    slope_m_per_hz, intercept_m, residual_sd_m : float
        The law and its scatter.
    min_m : float
        Smallest step length kept (draws below are redrawn).
    """

    slope_m_per_hz: float = 0.5
    intercept_m: float = -0.25
    residual_sd_m: float = 0.05
    min_m: float = 0.3


DEFAULT_ASSUMPTIONS: tuple[str, ...] = (
    "f_n = 0.3049 f_p + 1.3670 Hz and zeta = -0.2116 f_p + 0.8737: the seed's population laws.",
    "BLF1 = 0.41 (f_p - 0.95): the seed prints no BLF1 coefficients; Young's (2001) design law "
    "is used instead.",
    "Residual sds f_n 0.15 Hz, zeta 0.05, BLF1 0.04: the seed shows its model-error fits only "
    "as figures; assumed.",
    "BLF2 ~ lognormal(median 0.055, log-sd 0.4), BLF3 ~ lognormal(median 0.05, log-sd 0.4): the "
    "seed prints no lognormal parameters; medians between its individual values (0.042, 0.049) "
    "and the commonly quoted 0.07 and 0.06; log-sd assumed.",
    "Pacing N(1.99, 0.173) Hz (Matsumoto et al. 1978) truncated to the seed's 1.5-2.25 Hz.",
    "Mass: 39/56 male N(68.3, 15.0) kg in 49.8-95.1 kg, 17/56 female N(60.3, 4.98) kg within "
    "+- 3 sd (the seed's Table 1; the female range is assumed).",
    "Step length 0.5 f_p - 0.25 m + N(0, 0.05) m (through Bachmann and Ammann's slow and normal "
    "walking); speed = pacing x step length.",
    "Harmonic phases independent and uniform on [0, 2 pi).",
)


def _seed_fn() -> LinearLaw:
    slope, intercept = SEED_NATURAL_FREQUENCY_HZ
    return LinearLaw(slope=slope, intercept=intercept, residual_sd=0.15)


def _seed_zeta() -> LinearLaw:
    slope, intercept = SEED_DAMPING_RATIO
    return LinearLaw(slope=slope, intercept=intercept, residual_sd=0.05)


def _young_blf1() -> LinearLaw:
    return LinearLaw(slope=0.41, intercept=-0.41 * 0.95, residual_sd=0.04)


@dataclass(frozen=True)
class PopulationLaws:
    """Everything the pedestrian sampler draws from; the defaults are the seed's laws.

    Parameters
    ----------
    natural_frequency_hz, damping_ratio, blf1 : LinearLaw
        Mean laws against pacing with normal residuals.
    blf2, blf3 : LognormalLaw
        Lognormal higher load factors.
    pacing : PacingDistribution
        Pacing frequency distribution.
    mass : MassDistribution
        Body-mass distribution.
    step_length : StepLengthLaw
        Step length against pacing.
    source : str
        Where the laws come from (``"seed defaults"`` or the fitted results).
    parameter_draws : mapping of str to ndarray, optional
        Posterior draws of the laws' parameters (a hierarchical fit's,
        :meth:`from_hierarchical_json`): the sampler then draws every pedestrian from the
        posterior predictive, each with the parameters of one draw. The point laws above
        are then the posterior means, with the residual and walker sds combined.
    """

    natural_frequency_hz: LinearLaw = field(default_factory=_seed_fn)
    damping_ratio: LinearLaw = field(default_factory=_seed_zeta)
    blf1: LinearLaw = field(default_factory=_young_blf1)
    blf2: LognormalLaw = field(default_factory=lambda: LognormalLaw(math.log(0.055), 0.4))
    blf3: LognormalLaw = field(default_factory=lambda: LognormalLaw(math.log(0.05), 0.4))
    pacing: PacingDistribution = field(default_factory=PacingDistribution)
    mass: MassDistribution = field(default_factory=MassDistribution)
    step_length: StepLengthLaw = field(default_factory=StepLengthLaw)
    source: str = "seed defaults"
    parameter_draws: Mapping[str, np.ndarray] | None = field(default=None, compare=False)

    @classmethod
    def seed_defaults(cls) -> PopulationLaws:
        """Return the seed's laws with the documented assumptions (as ``PopulationLaws()``)."""
        return cls()

    @classmethod
    def from_json(cls, obj: Mapping[str, Any], *, source: str = "fitted laws") -> PopulationLaws:
        """Read the object that ``workbench population --json`` prints (docs/contracts.md).

        Parameters
        ----------
        obj : mapping
            With ``laws.{natural_frequency_hz,damping_ratio,blf1}.{slope,intercept,
            residual_sd}`` and ``lognormal.{blf2,blf3}.{mu,sigma}``. The pacing, mass and
            step-length distributions are not fitted and keep their defaults.
        source : str
            Label stored in :attr:`source`.

        Returns
        -------
        PopulationLaws
        """
        kwargs: dict[str, Any] = {"source": source}
        try:
            laws = obj["laws"]
            for key in ("natural_frequency_hz", "damping_ratio", "blf1"):
                law = laws[key]
                residual_sd = _nonneg(law["residual_sd"], f"laws.{key}.residual_sd")
                if residual_sd > MAX_RESIDUAL_SD[key]:
                    raise UsageError(
                        f"the population laws give laws.{key}.residual_sd = {residual_sd:g}, "
                        f"a scatter no walking population has (at most "
                        f"{MAX_RESIDUAL_SD[key]:g}; the draws would spread over the sampler's "
                        "whole physical range); fit the laws again or correct it"
                    )
                kwargs[key] = LinearLaw(
                    slope=_finite(law["slope"], f"laws.{key}.slope"),
                    intercept=_finite(law["intercept"], f"laws.{key}.intercept"),
                    residual_sd=residual_sd,
                )
            logn = obj["lognormal"]
            for key in ("blf2", "blf3"):
                mu = _finite(logn[key]["mu"], f"lognormal.{key}.mu")
                sigma = _nonneg(logn[key]["sigma"], f"lognormal.{key}.sigma")
                # A higher harmonic's load factor is a small fraction of the body weight; a
                # median of 1 or more, or a log-sd past MAX_LOG_SD, draws factors that are not
                # walking (and, far enough out, overflow).
                if mu >= 0 or sigma > MAX_LOG_SD:
                    raise UsageError(
                        f"the population laws give lognormal.{key} mu = {mu:g}, sigma = "
                        f"{sigma:g}: a median load factor exp(mu) of 1 or more, or a log-sd "
                        f"above {MAX_LOG_SD:g}; fit the laws again or correct them"
                    )
                kwargs[key] = LognormalLaw(mu=mu, sigma=sigma)
        except (KeyError, TypeError) as err:
            raise UsageError(
                f"the population laws lack the entry {err}; give the JSON object that "
                "'workbench population --json' prints (keys laws.natural_frequency_hz, "
                "laws.damping_ratio, laws.blf1 with slope, intercept, residual_sd and "
                "lognormal.blf2, lognormal.blf3 with mu, sigma)"
            ) from None
        return cls(**kwargs)

    @classmethod
    def from_hierarchical_json(
        cls, obj: Mapping[str, Any], *, source: str = "hierarchical laws"
    ) -> PopulationLaws:
        """Read the hierarchical laws ``workbench population`` writes (``hierarchical.json``).

        The point laws are the posterior means, each residual sd combined with its walker sd
        (a new pedestrian is a new walker); ``parameter_draws`` keeps the posterior draws.
        """
        fit = obj.get("fit")
        if not isinstance(fit, Mapping):
            raise UsageError(
                "the hierarchical laws hold no fit ("
                f"{obj.get('no_fit') or 'too few usable records'}); sample from the two-stage "
                "laws (population.json) or fit more records"
            )
        try:
            laws, draws = fit["laws"], fit["predictive_draws"]
            values = {k: np.asarray(v, dtype=np.float64) for k, v in draws.items()}
            flat: dict[str, Any] = {"laws": {}, "lognormal": {}}
            for key in ("natural_frequency_hz", "damping_ratio", "blf1", "blf2", "blf3"):
                law = laws[key]
                walker = law.get("walker_sd") or {"mean": 0.0}
                spread = math.hypot(float(law["residual_sd"]["mean"]), float(walker["mean"]))
                if key.startswith("blf") and key != "blf1":
                    flat["lognormal"][key] = {"mu": law["mu"]["mean"], "sigma": spread}
                else:
                    flat["laws"][key] = {
                        "slope": law["slope"]["mean"],
                        "intercept": law["intercept"]["mean"],
                        "residual_sd": spread,
                    }
        except (KeyError, TypeError, ValueError) as err:
            raise UsageError(
                f"the hierarchical laws lack the entry {err}; give the hierarchical.json that "
                "'workbench population BATCH_DIR --out DIR' writes"
            ) from None
        sizes = {v.shape for v in values.values()}
        if len(sizes) != 1 or not all(np.all(np.isfinite(v)) for v in values.values()):
            raise UsageError(
                "the hierarchical laws' predictive_draws are not one finite value per draw for "
                "every parameter; write them again with 'workbench population'"
            )
        point = cls.from_json(flat, source=source)
        return point.replace(parameter_draws=values)

    def to_json(self) -> dict[str, Any]:
        """Return the laws in the shape :meth:`from_json` reads, with the sampler's inputs."""
        return {
            "source": self.source,
            "laws": {
                k: asdict(getattr(self, k))
                for k in ("natural_frequency_hz", "damping_ratio", "blf1")
            },
            "lognormal": {k: asdict(getattr(self, k)) for k in ("blf2", "blf3")},
            "pacing": asdict(self.pacing),
            "mass": asdict(self.mass),
            "step_length": asdict(self.step_length),
        }

    def replace(self, **changes: Any) -> PopulationLaws:
        """Return a copy with some fields changed."""
        return replace(self, **changes)


#: Largest residual sd of each mean law: ten times the seed's (f_n 0.15 Hz, damping
#: ratio 0.05, BLF1 0.04) and wider than the scatter of every published walking population
#: (f_n of walkers 1.1-3.3 Hz in all, docs/science.md 7); a larger one draws mostly the
#: sampler's truncation bounds (f_n anywhere in 0.5-20 Hz), which no data support.
MAX_RESIDUAL_SD = {"natural_frequency_hz": 1.5, "damping_ratio": 0.5, "blf1": 0.4}

#: Largest log-sd of a lognormal load-factor law (a factor e^2 per sd already spans most of
#: the published BLF2 and BLF3 values at once).
MAX_LOG_SD = 2.0


def _finite(value: Any, name: str) -> float:
    try:
        # JSON true/false are no numbers, though Python would read them as 1 and 0.
        x = math.nan if isinstance(value, bool) else float(value)
    except (TypeError, ValueError):
        x = math.nan
    if not math.isfinite(x):
        raise UsageError(f"the population laws give {name} = {value!r}; it must be a number")
    return x


def _nonneg(value: Any, name: str) -> float:
    x = _finite(value, name)
    if x < 0:
        raise UsageError(f"the population laws give {name} = {x:g}; it must not be negative")
    return x


def read_laws(path: str | os.PathLike[str] | None) -> PopulationLaws:
    """Read population laws from the JSON that ``workbench population`` writes.

    Parameters
    ----------
    path : path-like or None
        ``population.json`` of a population fit, or its ``hierarchical.json`` (the sampler
        then draws from the posterior predictive); None gives the seed's laws
        (:class:`PopulationLaws` defaults).

    Returns
    -------
    PopulationLaws
        With ``source`` the path as given.

    Raises
    ------
    InputError
        If the file is missing, not JSON, not an object or not a set of laws, in one
        sentence naming the file and the fix.
    """
    if path is None:
        return PopulationLaws()
    try:
        obj = json.loads(Path(path).read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(
            path, "whole file", "the file does not exist", "give the path of a population JSON"
        ) from None
    except IsADirectoryError:
        raise InputError(
            path,
            "whole file",
            "this is a folder",
            "give the population.json that 'workbench population --out DIR' writes in it",
        ) from None
    except OSError as err:  # an input: the command line's message about writing would mislead
        raise InputError(
            path,
            "whole file",
            f"the file cannot be read ({err.strerror or err})",
            "check its permissions",
        ) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise InputError(
            path,
            "whole file",
            f"the file is not JSON ({err})",
            "give the file that 'workbench population --out DIR' writes (DIR/population.json)",
        ) from None
    if not isinstance(obj, dict):
        raise InputError(
            path, "whole file", "the JSON is not an object", "give a population JSON object"
        )
    try:
        if "fit" in obj and "laws" not in obj:  # hierarchical.json
            return PopulationLaws.from_hierarchical_json(obj, source=str(path))
        return PopulationLaws.from_json(obj, source=str(path))
    except UsageError as err:
        raise InputError(path, "whole file", str(err).rstrip("."), "fix or regenerate it") from None
