"""Settings of an identification run: defaults, a TOML file, and command-line flags.

Precedence: command-line flags over the TOML file (``--config FILE``) over the defaults
below. The defaults are the seed study's settings (docs/science.md 3) except where the workbench
documents a better choice:

- ``method = "rbpf"``: the Rao-Blackwellised filter is exact for this model and needs far
  fewer particles than the seed's plain particle filter (``"pf"``, kept seed-faithful).
- ``obs_noise = "auto"``: the observation noise is estimated from the record (maximum
  marginal likelihood); ``"seed"`` is the seed's 10 % of the RMS of u, u', u''.
- ``prior = "modal"``: a (C, K) box from natural frequency 1-4 Hz and damping ratio
  0.05-0.9 at the body mass; ``"seed"`` is the seed's 400-1000 N s/m, 12000-20000 N/m.
- ``state_noise_fraction``: process noise of (u, u') per sample as a fraction of their RMS.
  Unset, it is the seed's 0.5 % for ``"pf"`` (whose particles need it to stay alive) and
  zero for ``"rbpf"`` and ``"exact"``: u and u' are integrals of the measured u'', so the
  SMD equation holds exactly between samples, and a process noise the data do not have is
  part of the model that pulls the estimate (seed example, obs noise 1 %: the exact
  posterior mean moves from 1.0 % / 1.4 % below the truth in C / K with the seed's 0.5 %
  to 0.2 % / 0.02 % with none; ``tests/test_exact.py``).
- ``force_check = true``: after the method, refit (C, K) with a richer force (harmonics
  drifting across each step) and call C or K "not identified" when the two disagree
  (:mod:`workbench.inference.force_check`); costs two mode searches.
- ``observe = "all"``: the likelihood uses u, u', u'' as the seed does; ``"acc"`` uses
  only u'' (what the plate measures), leaving u, u' to the model's dynamics.
- ``force_proposal = "regression"`` (``pf`` only): at each piece start the force
  coefficients are regenerated from a Gaussian fitted to the piece's data given each
  particle's (C, K), with the importance correction that keeps the seed's target; the
  seed's blind draws from the force prior (``"prior"``) leave a single force draw alive on
  its numerical example (:mod:`workbench.inference.pf`, "Regeneration of theta").
- ``time_basis = "step_phase"``: each step's force basis runs on its own clock, so force
  coefficients are comparable across steps; ``"absolute"`` is the seed's.

Example TOML file::

    method = "pf"
    particles = 5000
    harmonics = 10
    obs_noise = "seed"
    prior = "seed"
    resampling = "systematic"
    ess_threshold = 0.5
    seed = 7
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from workbench.errors import InputError, UsageError
from workbench.inference.problem import KALMAN_STATE_FRACTION, SEED_STATE_FRACTION

__all__ = ["METHODS", "IdentifySettings", "parse_obs_noise"]

METHODS = ("rbpf", "pf", "exact")
#: Particles per method when not given: the RBPF needs few, the seed's filter many.
DEFAULT_PARTICLES = {"rbpf": 256, "pf": 4000, "exact": 0}


def parse_obs_noise(value: Any, where: str = "--obs-noise") -> float | str:
    """Parse an observation-noise setting: a positive fraction, ``"seed"`` or ``"auto"``."""
    if isinstance(value, str):
        text = value.strip().lower()
        if text in ("seed", "auto"):
            return text
        try:
            value = float(text)
        except ValueError:
            raise UsageError(
                f"{where} {value!r} is not understood; give a fraction of the RMS of u, u', u'' "
                "such as 0.05, or 'seed' (0.10) or 'auto' (estimated from the record)"
            ) from None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise UsageError(f"{where} must be a number, 'seed' or 'auto', not {value!r}")
    if not (0 < float(value) < 1):
        raise UsageError(
            f"{where} {value!r} must be a fraction between 0 and 1 of the RMS of u, u', u''"
        )
    return float(value)


def parse_effects(value: Any, where: str = "--effects") -> tuple[str, ...]:
    """Parse effect names: ``"a,b"`` or a sequence of names, each a registered effect."""
    from workbench.models.effects import available_effects

    if value is None:
        return ()
    items = value.split(",") if isinstance(value, str) else list(value)
    names = tuple(str(v).strip() for v in items if str(v).strip())
    known = available_effects()
    for name in names:
        if name not in known:
            raise UsageError(
                f"{where}: effect {name!r} is not known; choose from {', '.join(known)}"
            )
    if len(set(names)) != len(names):
        raise UsageError(f"{where}: an effect is named twice in {', '.join(names)}")
    return names


@dataclass(frozen=True)
class IdentifySettings:
    """How to identify one record (see the module docstring for the defaults)."""

    method: str = "rbpf"
    particles: int | None = None
    harmonics: int = 10
    pacing_hz: float | None = None
    highpass_hz: float = 0.15
    obs_noise: float | str = "auto"
    state_noise_fraction: float | None = None
    time_basis: str = "step_phase"
    pieces: str = "steps"
    prior: str = "modal"
    resampling: str = "systematic"
    ess_threshold: float = 0.5
    seed: int = 0
    force_check: bool = True
    observe: str = "all"
    force_proposal: str = "regression"
    effects: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "effects", parse_effects(self.effects))
        if self.method not in METHODS:
            raise UsageError(
                f"--method {self.method!r} is not known; choose one of {', '.join(METHODS)}"
            )
        if self.particles is not None and int(self.particles) < 2:
            raise UsageError(f"--particles must be at least 2, got {self.particles}")
        if int(self.harmonics) < 1 or int(self.harmonics) > 40:
            raise UsageError(f"--harmonics must be between 1 and 40, got {self.harmonics}")
        object.__setattr__(self, "obs_noise", parse_obs_noise(self.obs_noise))
        if self.prior not in ("modal", "seed"):
            raise UsageError(f"prior must be 'modal' or 'seed', got {self.prior!r}")
        if self.time_basis not in ("step_phase", "absolute"):
            raise UsageError(
                f"time_basis must be 'step_phase' or 'absolute', got {self.time_basis!r}"
            )
        if self.observe not in ("all", "acc"):
            raise UsageError(f"--observe must be 'all' or 'acc', got {self.observe!r}")
        if self.force_proposal not in ("regression", "prior"):
            raise UsageError(
                f"--force-proposal must be 'regression' or 'prior', got {self.force_proposal!r}"
            )
        if self.pieces not in ("steps", "whole"):
            raise UsageError(f"pieces must be 'steps' or 'whole', got {self.pieces!r}")
        if not (0 < self.ess_threshold <= 1):
            raise UsageError(f"ess_threshold must be in (0, 1], got {self.ess_threshold}")
        if self.state_noise_fraction is not None and not (
            0 <= float(self.state_noise_fraction) < 1
        ):
            raise UsageError(
                "state_noise_fraction must be a fraction in [0, 1), got "
                f"{self.state_noise_fraction!r}"
            )
        if self.highpass_hz < 0:
            raise UsageError(f"--highpass-hz must be 0 (off) or positive, got {self.highpass_hz}")

    @property
    def state_fraction(self) -> float:
        """Process noise fraction to use: the given one or the method's default."""
        if self.state_noise_fraction is not None:
            return float(self.state_noise_fraction)
        return SEED_STATE_FRACTION if self.method == "pf" else KALMAN_STATE_FRACTION

    @property
    def n_particles(self) -> int:
        """Particles to use: the given number or the method's default."""
        return int(self.particles) if self.particles else DEFAULT_PARTICLES[self.method]

    def replace(self, **changes: Any) -> IdentifySettings:
        """Return a copy with the given fields changed (``None`` values are ignored)."""
        return dataclasses.replace(self, **{k: v for k, v in changes.items() if v is not None})

    def to_json(self) -> dict[str, Any]:
        """Return the settings as a JSON-able dict."""
        return dataclasses.asdict(self)

    @classmethod
    def from_toml(cls, path: str | Path, **overrides: Any) -> IdentifySettings:
        """Read settings from a TOML file, then apply non-``None`` overrides (the flags)."""
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise InputError(
                path,
                "whole file",
                "the settings file does not exist",
                "check the path given to --config",
            ) from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
            raise InputError(
                path,
                "whole file",
                f"is not valid TOML ({err})",
                "fix the syntax (key = value lines)",
            ) from None
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise InputError(
                path,
                f"key {unknown[0]!r}",
                "is not an identification setting",
                f"use only {', '.join(sorted(known))}",
            )
        return cls(**data).replace(**overrides)
