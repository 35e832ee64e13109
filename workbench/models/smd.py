"""The spring-mass-damper (SMD) pedestrian model as a plain description.

``M u'' + C u' + K u + sum_e effect_e(u, u', t) = F_bio(t)`` with u the COM displacement
(positive up, from static equilibrium) and ``GRF = M g + M u''`` (docs/science.md 1). On a
moving surface with displacement z the spring and damper act on ``u - z`` and ``u' - z'``
(``surface="coupled"``, docs/science.md 6).

An :class:`SMDModel` only describes the system: parameters may be unset (to be identified)
and nothing here fits or filters. Algorithms take a model, as in the ``particles`` library.
Effects compose with ``+`` as in pysindy::

    model = SMDModel(mass_kg=70, harmonics=6) + CubicStiffness()
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.models import conversions
from workbench.models.effects import Effect, EffectContext, Effects, as_effects
from workbench.models.force import DEFAULT_FORCE_HARMONICS, FourierForce

__all__ = ["PIECE_MODES", "SURFACE_MODELS", "TIME_BASES", "SMDModel"]

#: Clocks of the force's Fourier basis (see :mod:`workbench.models.force`).
TIME_BASES = ("step_phase", "absolute")
#: Whether the force coefficients are redrawn at every step or shared by the whole record.
PIECE_MODES = ("steps", "whole")
#: How a measured surface motion enters: through the spring and damper (C and K read from the
#: deck's transmissibility, or from the whole time history jointly with the force), or ignored.
SURFACE_MODELS = ("coupled", "joint", "rigid")

FloatArray = NDArray[np.float64]


def _optional_float(value: Any, name: str, *, positive: bool) -> float | None:
    if value is None:
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise UsageError(
            f"SMDModel: argument '{name}' must be a number or None, got {value!r}; pass a "
            "value in the unit its name states"
        ) from None
    if not np.isfinite(x) or x < 0 or (positive and x == 0):
        bound = "positive" if positive else "zero or positive"
        raise UsageError(
            f"SMDModel: argument '{name}' must be finite and {bound}, got {x!r}; pass a "
            "physical value in the unit its name states"
        )
    return x


@dataclass(frozen=True, eq=True, repr=False)
class SMDModel:
    """Description of a walking pedestrian's SMD model.

    Parameters
    ----------
    mass_kg : float, optional
        Body mass M [kg] (known, never identified).
    stiffness_n_per_m : float, optional
        Stiffness K [N/m]; None while unknown.
    damping_ns_per_m : float, optional
        Viscous damping C [N s/m]; None while unknown.
    harmonics : int, optional
        Number of harmonics n of the Fourier biomechanical force (default 10, the seed's).
    effects : Effect, Effects or iterable of Effect/str, optional
        Extra terms in the force balance (see :mod:`workbench.models.effects`).
    time_basis : {"step_phase", "absolute"}, optional
        Clock of the force's Fourier basis: each step's own (the default; coefficients are
        comparable across steps) or the record's time with one pacing (the seed's).
    pieces : {"steps", "whole"}, optional
        Whether the force coefficients are drawn afresh at every footfall step (the seed's
        formulation, the default) or are one set for the whole record.
    pacing_hz : float, optional
        Pacing (step) frequency f_p [Hz]; None lets identification take it from the record.
    force_coefficients_n : sequence of float, optional
        A known biomechanical force ``a0, a1, b1, ..., an, bn`` [N] (``2 n + 1`` values, the
        order of :class:`~workbench.models.force.FourierForce`), e.g. a sampled walker on a
        footbridge; None while unknown.
    surface : {"coupled", "joint", "rigid"}, optional
        ``"coupled"`` (the default): when the record measures the walking surface's motion
        (a ``ground_acc`` column), the spring and damper act on the motion relative to it,
        ``M u'' + C (u' - z') + K (u - z) = F_bio``, and C and K are read from the deck's
        transmissibility (the response the deck drives, which the step force cannot absorb),
        the force given them from the time history; without deck power away from the gait
        harmonics, or with effects, C and K come from the time history as in ``"joint"``.
        ``"joint"``: the same model with C, K and the force from the time history jointly
        (right when the force model describes the walk; docs/validation/deck.md). On a rigid
        floor both are the plain model. ``"rigid"``: ignore any surface motion (to see what
        it adds).

    Examples
    --------
    >>> from workbench.models.effects import CubicStiffness
    >>> SMDModel.from_modal(75, 2.5, 0.4, harmonics=10) + CubicStiffness()
    SMDModel(mass_kg=75, stiffness_n_per_m=18505.5, damping_ns_per_m=942.478, harmonics=10) + CubicStiffness()
    """  # noqa: E501

    mass_kg: float | None = None
    stiffness_n_per_m: float | None = None
    damping_ns_per_m: float | None = None
    harmonics: int = DEFAULT_FORCE_HARMONICS
    effects: Effects = field(default_factory=Effects)
    time_basis: str = "step_phase"
    pieces: str = "steps"
    pacing_hz: float | None = None
    force_coefficients_n: tuple[float, ...] | None = None
    surface: str = "coupled"

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass_kg", _optional_float(self.mass_kg, "mass_kg", positive=True))
        object.__setattr__(
            self,
            "stiffness_n_per_m",
            _optional_float(self.stiffness_n_per_m, "stiffness_n_per_m", positive=False),
        )
        object.__setattr__(
            self,
            "damping_ns_per_m",
            _optional_float(self.damping_ns_per_m, "damping_ns_per_m", positive=False),
        )
        # FourierForce validates the harmonic count and gives the one-sentence error.
        object.__setattr__(self, "harmonics", FourierForce(self.harmonics).harmonics)
        object.__setattr__(self, "effects", as_effects(self.effects))
        if self.time_basis not in TIME_BASES:
            raise UsageError(
                f"SMDModel: time_basis {self.time_basis!r} is not known; use one of "
                f"{', '.join(TIME_BASES)}"
            )
        if self.pieces not in PIECE_MODES:
            raise UsageError(
                f"SMDModel: pieces {self.pieces!r} is not known; use one of "
                f"{', '.join(PIECE_MODES)}"
            )
        if self.surface not in SURFACE_MODELS:
            raise UsageError(
                f"SMDModel: surface {self.surface!r} is not known; use one of "
                f"{', '.join(SURFACE_MODELS)}",
                parameter="surface",
            )
        object.__setattr__(
            self, "pacing_hz", _optional_float(self.pacing_hz, "pacing_hz", positive=True)
        )
        if self.force_coefficients_n is not None:
            coef = np.asarray(self.force_coefficients_n, dtype=np.float64).reshape(-1)
            expected = self.fourier_force.n_coefficients
            if coef.size != expected or not np.all(np.isfinite(coef)):
                raise UsageError(
                    f"SMDModel: force_coefficients_n must be {expected} finite numbers "
                    f"(a0, a1, b1, ... for {self.harmonics} harmonics), got {coef.size}; "
                    "give one value per coefficient or change harmonics"
                )
            object.__setattr__(self, "force_coefficients_n", tuple(float(x) for x in coef))

    # -- construction ---------------------------------------------------------------------
    @classmethod
    def from_modal(
        cls,
        mass_kg: float,
        natural_frequency_hz: float,
        damping_ratio: float,
        *,
        harmonics: int = DEFAULT_FORCE_HARMONICS,
        effects: Effect | Effects | Iterable[Effect | str] = (),
        **force: Any,
    ) -> SMDModel:
        """Build a model from modal parameters.

        Parameters
        ----------
        mass_kg : float
            Body mass [kg].
        natural_frequency_hz : float
            Undamped natural frequency f_n [Hz].
        damping_ratio : float
            Damping ratio zeta.
        harmonics : int, optional
            Number of force harmonics.
        effects : optional
            Effects, as in the constructor.
        **force
            ``time_basis``, ``pieces``, ``pacing_hz``, ``force_coefficients_n``, ``surface``
            as in the constructor.

        Returns
        -------
        SMDModel
        """
        k = float(conversions.stiffness_n_per_m(natural_frequency_hz, mass_kg))
        c = float(conversions.damping_ns_per_m(damping_ratio, k, mass_kg))
        return cls(mass_kg, k, c, harmonics, as_effects(effects), **force)

    def replace(self, **changes: Any) -> SMDModel:
        """Return a copy with some fields changed (e.g. identified K and C)."""
        return dataclasses.replace(self, **changes)

    def __add__(self, other: object) -> SMDModel:
        if isinstance(other, Effect | Effects):
            return dataclasses.replace(self, effects=self.effects + other)
        return NotImplemented

    # -- derived quantities ---------------------------------------------------------------
    @property
    def fourier_force(self) -> FourierForce:
        """The Fourier biomechanical force with this model's number of harmonics."""
        return FourierForce(self.harmonics)

    @property
    def natural_frequency_hz(self) -> float | None:
        """Undamped natural frequency f_n [Hz], or None while M or K is unknown."""
        if self.mass_kg is None or self.stiffness_n_per_m is None:
            return None
        return float(conversions.natural_frequency_hz(self.stiffness_n_per_m, self.mass_kg))

    @property
    def damping_ratio(self) -> float | None:
        """Damping ratio zeta, or None while M, K or C is unknown (or K is 0)."""
        if (
            self.mass_kg is None
            or self.stiffness_n_per_m is None
            or self.damping_ns_per_m is None
            or self.stiffness_n_per_m == 0
        ):
            return None
        return float(
            conversions.damping_ratio(self.damping_ns_per_m, self.stiffness_n_per_m, self.mass_kg)
        )

    @property
    def blf(self) -> FloatArray | None:
        """Biomechanical load factors BLF1..BLFn of a known force, or None."""
        if self.force_coefficients_n is None:
            return None
        return self.fourier_force.blf(self.force_coefficients_n, self.require("mass_kg"))

    def biomechanical_force_n(self, t_s: ArrayLike) -> FloatArray:
        """Return the known biomechanical force F_bio [N] at times ``t_s`` (absolute time).

        Parameters
        ----------
        t_s : array_like
            Times [s] from the start of the walk.

        Returns
        -------
        ndarray
            Force with the shape of ``t_s``.
        """
        if self.force_coefficients_n is None or self.pacing_hz is None:
            raise UsageError(
                f"{self!r}: the biomechanical force is not known; create the model with "
                "pacing_hz=... and force_coefficients_n=..."
            )
        return self.fourier_force.evaluate(
            self.force_coefficients_n, np.asarray(t_s, dtype=np.float64), pacing_hz=self.pacing_hz
        )

    @property
    def weight_n(self) -> float:
        """Body weight M g [N]."""
        from workbench.records.record import G_M_S2

        return self.require("mass_kg") * G_M_S2

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Static parameters, in state order: C, K, then each effect's (qualified) parameters.

        ``('damping_ns_per_m', 'stiffness_n_per_m', 'cubic_stiffness.k3_n_per_m3', ...)``.
        """
        names = ["damping_ns_per_m", "stiffness_n_per_m"]
        for effect in self.effects:
            names.extend(effect.qualified_parameter_names)
        return tuple(names)

    def parameter_values(self) -> dict[str, float | None]:
        """Values of :attr:`parameter_names` (None for unknown C or K)."""
        values: dict[str, float | None] = {
            "damping_ns_per_m": self.damping_ns_per_m,
            "stiffness_n_per_m": self.stiffness_n_per_m,
        }
        for effect in self.effects:
            for qualified, p in zip(
                effect.qualified_parameter_names, effect.parameters, strict=True
            ):
                values[qualified] = effect.values[p.name]
        return values

    def require(self, *names: str) -> float:
        """Return the (last) named parameter, raising a clear error if any is unset.

        Parameters
        ----------
        *names : str
            Any of ``"mass_kg"``, ``"stiffness_n_per_m"``, ``"damping_ns_per_m"``.

        Returns
        -------
        float
            The value of the last name.
        """
        value: float | None = None
        for name in names:
            value = getattr(self, name)
            if value is None:
                raise UsageError(
                    f"{self!r}: parameter '{name}' is not set; create the model with "
                    f"{name}=... (or identify it first)"
                )
        if value is None:
            raise UsageError("SMDModel.require: no parameter name given; name one")
        return value

    # -- physics --------------------------------------------------------------------------
    def effect_force(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        effect_params: Mapping[str, ArrayLike] | None = None,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Sum of the effect terms on the left-hand side of the force balance [N].

        Parameters
        ----------
        u, v, t_s : array_like
            Displacement [m], velocity [m/s], time [s]; broadcast together.
        effect_params : mapping, optional
            Values by qualified parameter name (``"cubic_stiffness.k3_n_per_m3"``), scalars
            or arrays (e.g. one per particle); missing ones come from the effect instances.
        context : EffectContext, optional
            Passed to the effects.

        Returns
        -------
        ndarray
            Broadcast shape of the state (and of any parameter arrays).
        """
        total: FloatArray = np.zeros(
            np.broadcast_shapes(np.shape(u), np.shape(v), np.shape(t_s)), dtype=np.float64
        )
        params = dict(effect_params or {})
        valid = set(self.parameter_names[2:])
        unknown = sorted(set(params) - valid)
        if unknown:
            raise UsageError(
                f"SMDModel: effect parameter '{unknown[0]}' is not in this model; use one of "
                f"{', '.join(sorted(valid)) or '(none: the model has no effects)'}"
            )
        for effect in self.effects:
            if any(q in params for q in effect.qualified_parameter_names):
                columns = [
                    np.asarray(params.get(q, effect.values[p.name]), dtype=np.float64)
                    for q, p in zip(
                        effect.qualified_parameter_names, effect.parameters, strict=True
                    )
                ]
                theta = np.stack(np.broadcast_arrays(*columns), axis=-1)
            else:
                theta = effect.theta
            total = total + effect.force(u, v, t_s, theta, context)
        return total

    def acceleration(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        force_n: ArrayLike,
        effect_params: Mapping[str, ArrayLike] | None = None,
        context: EffectContext | None = None,
        *,
        stiffness_n_per_m: ArrayLike | None = None,
        damping_ns_per_m: ArrayLike | None = None,
    ) -> FloatArray:
        """COM acceleration ``(F - C v - K u - sum of effect terms) / M`` [m/s^2].

        Parameters
        ----------
        u, v, t_s : array_like
            Displacement [m], velocity [m/s] and time [s]; broadcast together.
        force_n : array_like
            Biomechanical force F_bio [N] at those states.
        effect_params : mapping, optional
            Effect parameter values by qualified name (see :meth:`effect_force`).
        context : EffectContext, optional
            Passed to the effects; its mass, K and C are filled in from the model.
        stiffness_n_per_m, damping_ns_per_m : array_like, optional
            Override the model's K and C (e.g. one value per particle).

        Returns
        -------
        ndarray
            Acceleration with the broadcast shape of all inputs.
        """
        m = self.require("mass_kg")
        k = np.asarray(
            self.require("stiffness_n_per_m") if stiffness_n_per_m is None else stiffness_n_per_m,
            dtype=np.float64,
        )
        c = np.asarray(
            self.require("damping_ns_per_m") if damping_ns_per_m is None else damping_ns_per_m,
            dtype=np.float64,
        )
        u_a = np.asarray(u, dtype=np.float64)
        v_a = np.asarray(v, dtype=np.float64)
        balance = np.asarray(force_n, dtype=np.float64) - c * v_a - k * u_a
        if self.effects:
            ctx = context if context is not None else EffectContext()
            ctx = dataclasses.replace(ctx, mass_kg=m, stiffness_n_per_m=k, damping_ns_per_m=c)
            balance = balance - self.effect_force(u_a, v_a, t_s, effect_params, ctx)
        elif effect_params:
            self.effect_force(u_a, v_a, t_s, effect_params, context)  # reports the bad name
        return balance / m

    # -- display --------------------------------------------------------------------------
    def __repr__(self) -> str:
        parts = []
        for name in ("mass_kg", "stiffness_n_per_m", "damping_ns_per_m"):
            value = getattr(self, name)
            if value is not None:
                parts.append(f"{name}={value:.6g}")
        parts.append(f"harmonics={self.harmonics}")
        for name, default in (
            ("time_basis", "step_phase"),
            ("pieces", "steps"),
            ("surface", "coupled"),
        ):
            if getattr(self, name) != default:
                parts.append(f"{name}={getattr(self, name)!r}")
        if self.pacing_hz is not None:
            parts.append(f"pacing_hz={self.pacing_hz:.6g}")
        if self.force_coefficients_n is not None:
            parts.append("force_coefficients_n=(...)")
        text = f"SMDModel({', '.join(parts)})"
        if self.effects:
            text += " + " + repr(self.effects)
        return text

    def to_dict(self) -> dict[str, Any]:
        """JSON-able description of the model (parameters, modal values, effects)."""
        return {
            "mass_kg": self.mass_kg,
            "stiffness_n_per_m": self.stiffness_n_per_m,
            "damping_ns_per_m": self.damping_ns_per_m,
            "natural_frequency_hz": self.natural_frequency_hz,
            "damping_ratio": self.damping_ratio,
            "harmonics": self.harmonics,
            "time_basis": self.time_basis,
            "pieces": self.pieces,
            "surface": self.surface,
            "pacing_hz": self.pacing_hz,
            "force_coefficients_n": (
                None if self.force_coefficients_n is None else list(self.force_coefficients_n)
            ),
            "effects": [e.to_dict() for e in self.effects],
        }
