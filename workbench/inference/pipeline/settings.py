"""Settings of an identification run: defaults, a TOML file, and command-line flags.

An identification is set by four parts, each an object of its own:

- the **model** (:class:`~workbench.models.smd.SMDModel`): force harmonics, time basis,
  pieces, pacing and effects;
- the **method** (:mod:`workbench.inference.methods.base`): ``Exact``, ``RBPF``, ``PF`` or any
  other registered method, with its own options (particles, resampling, proposals);
- the **noise and priors** (:class:`NoiseSettings`): observation and process noise, the
  (C, K) prior box and the channels the likelihood observes;
- the **preprocessing** (:class:`Preprocessing`): the high-pass filter and the mass rescale;

plus the seed and whether the force-model check runs. :class:`IdentifySettings` holds them
together; its *flat* form (one key per option, the keys below) is what a ``--config`` TOML
file, the command-line flags and the ``settings`` object of the JSON output use.

Precedence: command-line flags over the TOML file (``--config FILE``) over the defaults
below. The defaults are the seed study's settings (docs/science.md 3) except where the workbench
documents a better choice:

- ``method = "exact"``: the exact posterior of (C, K) from the marginal likelihood, which
  the record's harmonic sufficient statistics make cheaper than any particle filter of it
  (docs/validation/benchmarks.md) and which carries no Monte Carlo error; ``"rbpf"`` (the
  Rao-Blackwellised filter, exact given (C, K), with per-step traces) and ``"pf"`` (the
  seed's plain particle filter, kept seed-faithful) are the filters it cross-checks.
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
  (:mod:`workbench.inference.pipeline.force_check`); costs two mode searches.
- ``observe = "all"``: the likelihood uses u, u', u'' as the seed does; ``"acc"`` uses
  only u'' (what the plate measures), leaving u, u' to the model's dynamics.
- ``force_proposal = "regression"`` (``pf`` only): at each piece start the force
  coefficients are regenerated from a Gaussian fitted to the piece's data given each
  particle's (C, K), with the importance correction that keeps the seed's target; the
  seed's blind draws from the force prior (``"prior"``) leave a single force draw alive on
  its numerical example (:mod:`workbench.inference.methods.pf`, "Regeneration of theta").
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

from workbench.errors import InputError, UsageError, check_seed
from workbench.inference.methods import DEFAULT_METHOD, PF, Method, as_method, method_names
from workbench.inference.pipeline.noise import parse_noise_setting
from workbench.models.effects import Effect, parse_effect_specs
from workbench.models.force import HARMONICS_RANGE
from workbench.models.smd import SURFACE_MODELS, SMDModel
from workbench.records.preprocess import DEFAULT_HIGHPASS_HZ

__all__ = [
    "FLAT_KEYS",
    "IdentifySettings",
    "NoiseSettings",
    "Preprocessing",
]

#: Keys of the flat form (``--config`` file, ``settings`` in the JSON output), in order.
FLAT_KEYS = (
    "method",
    "particles",
    "harmonics",
    "pacing_hz",
    "highpass_hz",
    "obs_noise",
    "state_noise_fraction",
    "time_basis",
    "pieces",
    "prior",
    "resampling",
    "ess_threshold",
    "seed",
    "force_check",
    "observe",
    "force_proposal",
    "effects",
    "rescale_to_mass",
    "surface",
)
#: What a ``--config`` file may hold under each key, as TOML writes it, with an example
#: line: a value of another kind is refused naming the file and the key before the settings
#: are built (``int("ten")`` would otherwise fail deep inside with Python's own words).
_TOML_KINDS: dict[str, tuple[tuple[type, ...], str, str]] = {
    "method": ((str,), "a quoted name", 'method = "exact"'),
    "particles": ((int,), "a whole number", "particles = 256"),
    "harmonics": ((int,), "a whole number", "harmonics = 10"),
    "pacing_hz": ((int, float), "a number", "pacing_hz = 1.8"),
    "highpass_hz": ((int, float), "a number", "highpass_hz = 0.15"),
    "obs_noise": ((str, int, float), "a number or a quoted word", 'obs_noise = "auto"'),
    "state_noise_fraction": ((int, float), "a number", "state_noise_fraction = 0.005"),
    "time_basis": ((str,), "a quoted name", 'time_basis = "step_phase"'),
    "pieces": ((str,), "a quoted name", 'pieces = "steps"'),
    "prior": ((str,), "a quoted name", 'prior = "modal"'),
    "resampling": ((str,), "a quoted name", 'resampling = "systematic"'),
    "ess_threshold": ((int, float), "a number", "ess_threshold = 0.5"),
    "seed": ((int,), "a whole number", "seed = 0"),
    "force_check": ((bool,), "true or false", "force_check = true"),
    "observe": ((str,), "a quoted name", 'observe = "all"'),
    "force_proposal": ((str,), "a quoted name", 'force_proposal = "regression"'),
    "effects": ((str, list), "a quoted list of names", 'effects = "gait_asymmetry"'),
    "rescale_to_mass": ((bool,), "true or false", "rescale_to_mass = false"),
    "surface": ((str,), "a quoted name", 'surface = "coupled"'),
}
#: The flat keys of each part (the rest, ``seed`` and ``force_check``, are the settings').
MODEL_KEYS = ("harmonics", "pacing_hz", "time_basis", "pieces", "effects", "surface")
METHOD_KEYS = ("method", "particles", "resampling", "ess_threshold", "force_proposal")
NOISE_KEYS = ("obs_noise", "state_noise_fraction", "prior", "observe")
PREPROCESSING_KEYS = ("highpass_hz", "rescale_to_mass")
#: Method options by flat key -> the attribute of the method objects that take them.
_METHOD_OPTION = {
    "particles": "n_particles",
    "resampling": "resampling",
    "ess_threshold": "ess_threshold",
    "force_proposal": "force_proposal",
}
#: The method options a particle filter's class sets defaults for (all but the count).
_FILTER_OPTIONS = tuple(key for key in _METHOD_OPTION if key != "particles")


@dataclass(frozen=True)
class NoiseSettings:
    """Noise model and priors of an identification.

    Parameters
    ----------
    obs_noise : float or {"auto", "seed"}, default "auto"
        Observation noise of u, u', u'' as a fraction of their RMS; ``"auto"`` estimates it
        from the record (maximum marginal likelihood), ``"seed"`` is the seed's 0.10.
    state_noise_fraction : float, optional
        Process noise of (u, u') per sample as a fraction of their RMS; None takes the
        method's default (the seed's 0.5 % for ``PF``, none for the Kalman-based methods).
    prior : {"modal", "seed"}, default "modal"
        The (C, K) prior box: natural frequency 1-4 Hz and damping ratio 0.05-0.9 at the
        body mass, or the seed's 400-1000 N s/m by 12000-20000 N/m.
    observe : {"all", "acc"}, default "all"
        Channels the likelihood uses: u, u', u'' as the seed does, or only u''.
    """

    obs_noise: float | str = "auto"
    state_noise_fraction: float | None = None
    prior: str = "modal"
    observe: str = "all"

    def __post_init__(self) -> None:
        object.__setattr__(self, "obs_noise", parse_noise_setting(self.obs_noise))
        if self.prior not in ("modal", "seed"):
            raise UsageError(
                f"'prior' must be 'modal' or 'seed', got {self.prior!r}", parameter="prior"
            )
        if self.observe not in ("all", "acc"):
            raise UsageError(
                f"'observe' must be 'all' or 'acc', got {self.observe!r}", parameter="observe"
            )
        if self.state_noise_fraction is not None and not (
            0 <= float(self.state_noise_fraction) < 1
        ):
            raise UsageError(
                "state_noise_fraction must be a fraction in [0, 1), got "
                f"{self.state_noise_fraction!r}"
            )

    def state_fraction(self, method: Method) -> float:
        """Process noise fraction to use with a method: the given one or the method's."""
        if self.state_noise_fraction is not None:
            return float(self.state_noise_fraction)
        return method.default_state_noise_fraction


@dataclass(frozen=True)
class Preprocessing:
    """How a record is preprocessed before identification.

    Parameters
    ----------
    highpass_hz : float, default 0.15
        Cut-off of the zero-phase high-pass of the COM response [Hz]; 0 switches it off
        (records that start at rest, such as the seed's numerical example).
    rescale_to_mass : bool, default False
        Rescale the force so that its mean over whole steps is the body weight (for a
        mis-calibrated sensor; the inspection reports the static balance either way).
    """

    highpass_hz: float = DEFAULT_HIGHPASS_HZ
    rescale_to_mass: bool = False

    def __post_init__(self) -> None:
        hp = float(self.highpass_hz)
        if not (hp >= 0 and hp < float("inf")):
            raise UsageError(
                f"'highpass_hz' must be 0 (off) or positive, got {self.highpass_hz}",
                parameter="highpass_hz",
            )


def effect_spec(effect: Effect) -> str:
    """Return the spec of an effect: its name, with the values that differ from the defaults.

    Parameters
    ----------
    effect : Effect

    Returns
    -------
    str
        ``"cubic_stiffness"`` or ``"heel_impact:decay_s=0.02"`` (:meth:`Effect.from_spec`
        reads it back).
    """
    changed = [
        f"{p.name}={effect.values[p.name]!r}"
        for p in effect.parameters
        if effect.values[p.name] != p.default
    ]
    return ":".join([effect.name, *changed])


def _model_from_flat(flat: dict[str, Any]) -> SMDModel:
    harmonics = int(flat["harmonics"])
    low, high = HARMONICS_RANGE
    if harmonics < low or harmonics > high:
        raise UsageError(
            f"'harmonics' must be between {low} and {high}, got {flat['harmonics']}",
            parameter="harmonics",
        )
    if flat["time_basis"] not in ("step_phase", "absolute"):
        raise UsageError(
            f"'time_basis' must be 'step_phase' or 'absolute', got {flat['time_basis']!r}",
            parameter="time_basis",
        )
    if flat["pieces"] not in ("steps", "whole"):
        raise UsageError(
            f"'pieces' must be 'steps' or 'whole', got {flat['pieces']!r}", parameter="pieces"
        )
    if flat["surface"] not in SURFACE_MODELS:
        raise UsageError(
            f"'surface' must be one of {', '.join(SURFACE_MODELS)}, got {flat['surface']!r}",
            parameter="surface",
        )
    effects = parse_effect_specs(flat["effects"], where="'effects'")
    return SMDModel(
        harmonics=harmonics,
        effects=effects,
        time_basis=flat["time_basis"],
        pieces=flat["pieces"],
        pacing_hz=flat["pacing_hz"],
        surface=flat["surface"],
    )


def _method_from_flat(
    flat: dict[str, Any], given: set[str] | frozenset[str] = frozenset()
) -> Method:
    """Build the method of the flat keys; options not in ``given`` keep the class's defaults.

    A registered method may have its own defaults (another resampling scheme, say): a flat
    default must not override them, only a key the caller set.
    """
    name = flat["method"]
    if name not in method_names():
        raise UsageError(
            f"'method' {name!r} is not known; choose one of {', '.join(method_names())}",
            parameter="method",
        )
    particles = flat["particles"]
    if particles is not None and int(particles) < 2:
        raise UsageError(f"'particles' must be at least 2, got {particles}", parameter="particles")
    if not (0 < flat["ess_threshold"] <= 1):
        raise UsageError(
            f"'ess_threshold' must be in (0, 1], got {flat['ess_threshold']}",
            parameter="ess_threshold",
        )
    if flat["force_proposal"] not in ("regression", "prior"):
        raise UsageError(
            f"'force_proposal' must be 'regression' or 'prior', got {flat['force_proposal']!r}",
            parameter="force_proposal",
        )
    options = {key: flat[key] for key in _FILTER_OPTIONS}
    return as_method(
        name,
        n_particles=int(particles) if particles else None,
        **{key: value for key, value in options.items() if key in given},
    )


@dataclass(frozen=True)
class IdentifySettings:
    """How to identify one record: model, method, noise and priors, preprocessing, seed.

    Parameters
    ----------
    model : SMDModel, optional
        The pedestrian model (its mass comes from the record when unset).
    method : Method, optional
        ``Exact()`` (default), ``RBPF()``, ``PF()`` or another registered method.
    noise : NoiseSettings, optional
        Noise model and priors.
    preprocessing : Preprocessing, optional
        High-pass filter and mass rescale.
    seed : int, default 0
        Seed of every random draw.
    force_check : bool, default True
        Run the force-model check after the method (costs two mode searches).
    method_options : tuple of (str, value) pairs, default ()
        Flat method options the current method does not take (``force_proposal`` given
        with ``method="rbpf"``), kept so that a switch of method (:meth:`replace`) carries
        them and the flat form reports them, as it always has.

    Notes
    -----
    :meth:`from_flat` builds the settings from the flat keys of :data:`FLAT_KEYS` (a
    ``--config`` file, the command-line flags); :meth:`to_json` gives them back.
    """

    model: SMDModel = dataclasses.field(default_factory=SMDModel)
    method: Method = dataclasses.field(default_factory=lambda: as_method(DEFAULT_METHOD))
    noise: NoiseSettings = dataclasses.field(default_factory=NoiseSettings)
    preprocessing: Preprocessing = dataclasses.field(default_factory=Preprocessing)
    seed: int = 0
    force_check: bool = True
    method_options: tuple[tuple[str, Any], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "seed", check_seed(self.seed))
        object.__setattr__(self, "method", as_method(self.method))

    # -- the flat form ----------------------------------------------------------------------
    @classmethod
    def from_flat(cls, **flat: Any) -> IdentifySettings:
        """Build settings from flat keys (:data:`FLAT_KEYS`); unset keys take the defaults.

        Parameters
        ----------
        **flat
            ``method="pf", particles=5000, harmonics=6, obs_noise="seed", ...``; None values
            take the default.

        Returns
        -------
        IdentifySettings
        """
        unknown = sorted(set(flat) - set(FLAT_KEYS))
        if unknown:
            raise UsageError(
                f"identification setting {unknown[0]!r} is not known; use only "
                f"{', '.join(FLAT_KEYS)}"
            )
        given = {k for k, v in flat.items() if v is not None}
        values = {**_FLAT_DEFAULTS, **{k: flat[k] for k in given}}
        method = _method_from_flat(values, given)
        carried = tuple(
            (key, values[key])
            for key in _FILTER_OPTIONS
            if not hasattr(method, _METHOD_OPTION[key]) and values[key] != _FLAT_DEFAULTS[key]
        )
        return cls(
            model=_model_from_flat(values),
            method=method,
            noise=NoiseSettings(
                obs_noise=values["obs_noise"],
                state_noise_fraction=values["state_noise_fraction"],
                prior=values["prior"],
                observe=values["observe"],
            ),
            preprocessing=Preprocessing(
                highpass_hz=float(values["highpass_hz"]),
                rescale_to_mass=bool(values["rescale_to_mass"]),
            ),
            seed=values["seed"],
            force_check=bool(values["force_check"]),
            method_options=carried,
        )

    def flat(self) -> dict[str, Any]:
        """Return the settings as flat keys (effects as an :class:`Effects` object).

        ``particles`` is None when the method runs its default count (and for the exact
        posterior), the count otherwise.
        """
        method = self.method
        model = self.model
        particles = getattr(method, "n_particles", None)
        if particles == getattr(type(method), "n_particles", None):
            particles = None
        carried = dict(self.method_options)

        def option(key: str) -> Any:
            return getattr(method, _METHOD_OPTION[key], carried.get(key, _FLAT_DEFAULTS[key]))

        return {
            "method": method.name,
            "particles": particles,
            "harmonics": model.harmonics,
            "pacing_hz": model.pacing_hz,
            "highpass_hz": self.preprocessing.highpass_hz,
            "obs_noise": self.noise.obs_noise,
            "state_noise_fraction": self.noise.state_noise_fraction,
            "time_basis": model.time_basis,
            "pieces": model.pieces,
            "prior": self.noise.prior,
            "resampling": option("resampling"),
            "ess_threshold": option("ess_threshold"),
            "seed": self.seed,
            "force_check": self.force_check,
            "observe": self.noise.observe,
            "force_proposal": option("force_proposal"),
            "effects": model.effects,
            "rescale_to_mass": self.preprocessing.rescale_to_mass,
            "surface": model.surface,
        }

    def replace(self, **changes: Any) -> IdentifySettings:
        """Return a copy with flat keys or parts changed (``None`` values are ignored).

        Flat keys (``method="pf"``, ``harmonics=6``) change only the part they belong to;
        everything else, including what the flat form does not hold (a model's mass, an
        ``Exact``'s draws), is kept. A change of method without ``particles`` takes the new
        method's default count; its other options come from the flat form. Parts
        (``model=...``, ``method=RBPF(...)``, ``noise=...``, ``preprocessing=...``) replace
        them whole.
        """
        changes = {k: v for k, v in changes.items() if v is not None}
        parts: dict[str, Any] = {
            k: changes.pop(k) for k in ("model", "noise", "preprocessing") if k in changes
        }
        if isinstance(changes.get("method"), Method):
            parts["method"] = changes.pop("method")
        out = self
        if changes:
            flat = self.flat()
            switching = changes.get("method", flat["method"]) != flat["method"]
            if switching:
                # The new method takes its own defaults, except for options set away from
                # the old method's defaults, which carry over.
                flat["particles"] = None
                for key in _FILTER_OPTIONS:
                    attribute = _METHOD_OPTION[key]
                    if flat[key] == getattr(type(self.method), attribute, _FLAT_DEFAULTS[key]):
                        flat[key] = None
            rebuilt = IdentifySettings.from_flat(**{**flat, **changes})
            touched = set(changes)
            model = self.model
            if touched & set(MODEL_KEYS):
                model = dataclasses.replace(
                    model, **{k: getattr(rebuilt.model, k) for k in MODEL_KEYS}
                )
            method = self.method
            if switching:
                method = rebuilt.method
            elif touched & set(METHOD_KEYS):
                method = method.replace(
                    **{
                        attribute: getattr(rebuilt.method, attribute)
                        for key, attribute in _METHOD_OPTION.items()
                        if key in touched and hasattr(method, attribute)
                    }
                )
            preprocessing = self.preprocessing
            if touched & set(PREPROCESSING_KEYS):
                preprocessing = rebuilt.preprocessing
            out = dataclasses.replace(
                rebuilt,
                model=model,
                method=method,
                noise=rebuilt.noise if touched & set(NOISE_KEYS) else self.noise,
                preprocessing=preprocessing,
            )
        return dataclasses.replace(out, **parts) if parts else out

    # -- derived ------------------------------------------------------------------------------
    @property
    def state_fraction(self) -> float:
        """Process noise fraction to use: the given one or the method's default."""
        return self.noise.state_fraction(self.method)

    @property
    def n_particles(self) -> int:
        """Particles the method runs (0 for the exact posterior)."""
        return int(getattr(self.method, "n_particles", 0))

    def to_json(self) -> dict[str, Any]:
        """Return the settings as the flat JSON-able dict (``settings`` in the output).

        ``effects`` lists effect names, as specs (``"heel_impact:decay_s=0.02"``) for an
        effect with parameter values other than its defaults, so the dict rebuilds the
        same settings (:meth:`from_flat`).
        """
        flat = self.flat()
        flat["effects"] = [effect_spec(e) for e in flat["effects"]]
        return flat

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
                "check the path given (--config on the command line)",
            ) from None
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
            raise InputError(
                path,
                "whole file",
                f"is not valid TOML ({err})",
                "fix the syntax (key = value lines)",
            ) from None
        except IsADirectoryError:
            raise InputError(
                path, "whole file", "this is a folder", "give the settings file (a .toml file)"
            ) from None
        except OSError as err:  # an input: a sentence about writable --out folders would mislead
            raise InputError(
                path,
                "whole file",
                f"the settings file cannot be read ({err.strerror or err})",
                "check the path and its permissions",
            ) from None
        unknown = sorted(set(data) - set(FLAT_KEYS))
        if unknown:
            raise InputError(
                path,
                f"key {unknown[0]!r}",
                "is not an identification setting",
                f"use only {', '.join(sorted(FLAT_KEYS))}",
            )
        for key, value in data.items():
            kinds, kind, example = _TOML_KINDS[key]
            # bool is an int to Python, but "harmonics = true" is no count.
            if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
                raise InputError(
                    path,
                    f"key {key!r}",
                    f"the value {value!r} is not {kind}",
                    f"write for example {example}",
                )
        merged = {**data, **{k: v for k, v in overrides.items() if v is not None}}
        try:
            return cls.from_flat(**merged)
        except UsageError as err:
            if err.parameter not in data or overrides.get(err.parameter) is not None:
                raise
            # The value came from the file: name the file and its key, not a flag.
            raise InputError(path, f"key {err.parameter!r}", str(err), "correct it") from None


def _field_defaults(cls: type) -> dict[str, Any]:
    return {
        f.name: f.default for f in dataclasses.fields(cls) if f.default is not dataclasses.MISSING
    }


_MODEL, _NOISE, _PREPROCESSING, _SETTINGS = (
    _field_defaults(part) for part in (SMDModel, NoiseSettings, Preprocessing, IdentifySettings)
)
#: The method options' defaults are the particle filters' (``PF`` takes all of them).
_FILTER = _field_defaults(PF)
#: The defaults of the flat keys: each is the default of the part that holds it, so that it
#: is stated once, on that part.
_FLAT_DEFAULTS: dict[str, Any] = {
    "method": DEFAULT_METHOD,
    "particles": None,
    "harmonics": _MODEL["harmonics"],
    "pacing_hz": _MODEL["pacing_hz"],
    "highpass_hz": _PREPROCESSING["highpass_hz"],
    "obs_noise": _NOISE["obs_noise"],
    "state_noise_fraction": _NOISE["state_noise_fraction"],
    "time_basis": _MODEL["time_basis"],
    "pieces": _MODEL["pieces"],
    "prior": _NOISE["prior"],
    "resampling": _FILTER["resampling"],
    "ess_threshold": _FILTER["ess_threshold"],
    "seed": _SETTINGS["seed"],
    "force_check": _SETTINGS["force_check"],
    "observe": _NOISE["observe"],
    "force_proposal": _FILTER["force_proposal"],
    "effects": (),
    "rescale_to_mass": _PREPROCESSING["rescale_to_mass"],
    "surface": _MODEL["surface"],
}
