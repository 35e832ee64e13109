"""Effects: extra physical terms in the SMD force balance, and how to write your own.

The base model is ``M u'' + C u' + K u = F_bio``. An *effect* adds one term to the left-hand
side::

    M u'' + C u' + K u + sum_e effect_e(u, u', t; theta_e) = F_bio

so a positive term pushes the body down (like the spring). Each effect is a small class with

``name``
    A snake_case string; it is a contract (command line ``--effects NAME``, JSON reports).
``parameters``
    A tuple of :class:`Parameter` (name with unit suffix, unit, default, description).
``regressors(u, v, t_s, context)``
    For effects *linear in their parameters*: an array of shape ``shape + (n_params,)``
    whose product with the parameter vector is the term (``regressors @ theta``). Linear
    effects let the identification treat their parameters like ``C`` and ``K``.
``force(u, v, t_s, theta, context)``
    The term itself. The default is ``regressors @ theta``; a nonlinear effect sets
    ``linear = False`` and overrides ``force`` instead.

``u``, ``v`` and ``t_s`` broadcast together (one time and many particles, or one particle
and many times); ``theta`` may carry leading axes too (one parameter vector per particle).
``context`` is an :class:`EffectContext` with what an effect may need beyond the state:
body mass, pacing, the model's ``K`` and ``C``, step starts (for step phase and odd/even
steps) and measured ground motion.

Effect instances hold parameter values (the truth when simulating, a start or an estimate
when identifying): ``CubicStiffness(k3_n_per_m3=2e5)``; omitted values take the default.
Effects combine with ``+`` into an ordered, immutable :class:`Effects`, and an
:class:`~workbench.models.smd.SMDModel` takes them the same way::

    model = SMDModel(mass_kg=70) + CubicStiffness() + MyEffect(gain=0.1)

Writing a new effect
--------------------
A user-written effect is a few lines; registering it makes it available by name
everywhere (``effect_from_name``, the command line)::

    import numpy as np
    from workbench.models.effects import Effect, Parameter, register_effect

    @register_effect
    class ExtraDamping(Effect):
        '''Viscous damping added to the model's C: term ``c_extra u'``.'''

        name = "extra_damping"
        parameters = (Parameter("c_extra_ns_per_m", "N s/m", 0.0, "added damping"),)

        def regressors(self, u, v, t_s, context):
            u, v, t_s = self.broadcast(u, v, t_s)
            return v[..., None]

A nonlinear one overrides ``force`` and declares ``linear = False``::

    @register_effect
    class SoftContact(Effect):
        name = "soft_contact"
        linear = False
        parameters = (
            Parameter("k_contact_n_per_m", "N/m", 0.0, "contact stiffness"),
            Parameter("gap_m", "m", 0.01, "free travel before contact"),
        )

        def force(self, u, v, t_s, theta=None, context=None):
            u, v, t_s = self.broadcast(u, v, t_s)
            k, gap = self.split_theta(theta)
            return k * np.maximum(-u - gap, 0.0)

The catalogue of docs/science.md 5 is written this way: ``gait_asymmetry`` (half-harmonic force
terms from ``context.step_phase_rad(t)``), ``cubic_stiffness`` (``u^3``),
``quadratic_damping`` (``|v| v``), ``stiffness_drift`` (``t u``, ``t v``), ``heel_impact``
(a pulse after each ``context.step_start_s``; nonlinear, ``force`` overridden),
``pacing_drift`` (first harmonic drifting in time and with the step rate) and
``base_motion`` (``-(k_g u_g + c_g v_g)`` from ``context.ground_at(t)``). To make a new
effect a candidate of model criticism, see
:func:`workbench.diagnostics.criticism.feature_group_from_effect`.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.models.force import step_index, step_phase_rad

__all__ = [
    "BaseMotion",
    "CubicStiffness",
    "Effect",
    "EffectContext",
    "Effects",
    "GaitAsymmetry",
    "HeelImpact",
    "PacingDrift",
    "Parameter",
    "QuadraticDamping",
    "StiffnessDrift",
    "available_effects",
    "effect_class",
    "effect_from_name",
    "register_effect",
    "unregister_effect",
]

FloatArray = NDArray[np.float64]
_SNAKE = re.compile(r"^[a-z][a-z0-9_]*$")


@dataclass(frozen=True)
class Parameter:
    """One parameter of an effect.

    Parameters
    ----------
    name : str
        Identifier in the field's words with a unit suffix, e.g. ``"k3_n_per_m3"``.
    unit : str
        Unit in plain text, e.g. ``"N/m^3"``.
    default : float
        Value used when the effect is created without one (usually "effect absent").
    description : str
        One line saying what it is.
    typical : float, optional
        A clearly visible but realistic value, for simulations and demonstrations
        (``Effect.typical()``, the command line's ``simulate --effect NAME``); None means
        use ``default``.
    """

    name: str
    unit: str
    default: float = 0.0
    description: str = ""
    typical: float | None = None


@dataclass(frozen=True, eq=False)
class EffectContext:
    """What an effect may need besides the state ``(u, u', t)``.

    All fields are optional; an effect that needs a missing one raises a ``UsageError``
    saying which. :meth:`SMDModel.acceleration <workbench.models.smd.SMDModel.acceleration>`
    fills ``mass_kg``, ``stiffness_n_per_m`` and ``damping_ns_per_m`` from the model.

    Parameters
    ----------
    mass_kg : float, optional
        Body mass [kg].
    pacing_hz : float, optional
        Pacing (step) frequency [Hz].
    stiffness_n_per_m, damping_ns_per_m : float or ndarray, optional
        The model's K [N/m] and C [N s/m] (arrays when evaluated per particle).
    step_start_s : ndarray, optional
        Step start (footfall) times [s], strictly increasing.
    ground_time_s, ground_disp_m, ground_vel_m_s, ground_acc_m_s2 : ndarray, optional
        Measured or prescribed motion of the walking surface on a time grid.
    ground_motion : callable, optional
        ``t_s -> (disp_m, vel_m_s, acc_m_s2)``; when given, :meth:`ground_at` uses it instead
        of interpolating the arrays (the simulator passes its exact ground motion).
    extra : mapping, optional
        Anything else a user-written effect needs.
    """

    mass_kg: float | None = None
    pacing_hz: float | None = None
    stiffness_n_per_m: float | FloatArray | None = None
    damping_ns_per_m: float | FloatArray | None = None
    step_start_s: FloatArray | None = None
    ground_time_s: FloatArray | None = None
    ground_disp_m: FloatArray | None = None
    ground_vel_m_s: FloatArray | None = None
    ground_acc_m_s2: FloatArray | None = None
    ground_motion: Callable[[ArrayLike], tuple[Any, Any, Any]] | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)

    def _require(self, attribute: str, who: str) -> Any:
        value = getattr(self, attribute)
        if value is None:
            raise UsageError(
                f"{who}: the effect context has no '{attribute}'; pass an EffectContext "
                f"with '{attribute}' set"
            )
        return value

    def step_index(self, t_s: ArrayLike) -> NDArray[np.int64]:
        """Return the index of the step containing each time (see ``force.step_index``)."""
        return step_index(t_s, self._require("step_start_s", "EffectContext.step_index"))

    def step_phase_rad(self, t_s: ArrayLike) -> FloatArray:
        """Return the continuous step phase, ``2 pi`` per step (see ``force.step_phase_rad``)."""
        return step_phase_rad(t_s, self._require("step_start_s", "EffectContext.step_phase_rad"))

    def ground_at(self, t_s: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Return ground displacement [m], velocity [m/s] and acceleration [m/s^2] at the times.

        Uses ``ground_motion`` when set, otherwise linear interpolation of the arrays
        (exact at their samples).
        """
        if self.ground_motion is not None:
            d, v, a = self.ground_motion(t_s)
            return (np.asarray(d, float), np.asarray(v, float), np.asarray(a, float))
        tg = self._require("ground_time_s", "EffectContext.ground_at")
        t = np.asarray(t_s, dtype=np.float64)
        out = []
        for attribute in ("ground_disp_m", "ground_vel_m_s", "ground_acc_m_s2"):
            out.append(np.interp(t, tg, self._require(attribute, "EffectContext.ground_at")))
        return out[0], out[1], out[2]


class Effect:
    """Base class of an effect: one extra term in ``M u'' + C u' + K u + term = F_bio``.

    Subclasses set the class attributes ``name`` and ``parameters`` and implement
    :meth:`regressors` (linear effects) or :meth:`force` with ``linear = False``. See the
    module docstring for a worked example.

    Parameters
    ----------
    **values : float
        Parameter values by parameter name; omitted ones take their default.
    """

    name: ClassVar[str] = ""
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    linear: ClassVar[bool] = True

    def __init__(self, **values: float) -> None:
        cls = type(self)
        _validate_effect_class(cls)
        known = [p.name for p in cls.parameters]
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise UsageError(
                f"{cls.__name__}: unknown parameter '{unknown[0]}'; valid parameters are "
                f"{', '.join(known) if known else '(none)'}"
            )
        resolved: dict[str, float] = {}
        for p in cls.parameters:
            raw = values.get(p.name, p.default)
            try:
                value = float(raw)
            except (TypeError, ValueError):
                raise UsageError(
                    f"{cls.__name__}: parameter '{p.name}' must be a number in {p.unit}, "
                    f"got {raw!r}; pass a finite number"
                ) from None
            if not np.isfinite(value):
                raise UsageError(
                    f"{cls.__name__}: parameter '{p.name}' must be finite, got {value!r}; "
                    "pass a finite number"
                )
            resolved[p.name] = value
        self._values = MappingProxyType(resolved)

    # -- values -------------------------------------------------------------------------
    @property
    def values(self) -> Mapping[str, float]:
        """Parameter values by name (read-only)."""
        return self._values

    @property
    def theta(self) -> FloatArray:
        """Parameter values as a vector, in the order of ``parameters``."""
        return np.array([self._values[p.name] for p in self.parameters], dtype=np.float64)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the parameters, in order."""
        return tuple(p.name for p in self.parameters)

    @property
    def qualified_parameter_names(self) -> tuple[str, ...]:
        """Parameter names prefixed with the effect name: ``"cubic_stiffness.k3_n_per_m3"``."""
        return tuple(f"{self.name}.{p.name}" for p in self.parameters)

    @classmethod
    def typical(cls, **values: float) -> Effect:
        """Create the effect with each parameter's ``typical`` value (overridable).

        Parameters
        ----------
        **values : float
            Values that replace the typical ones.

        Returns
        -------
        Effect
        """
        base = {p.name: p.default if p.typical is None else p.typical for p in cls.parameters}
        return cls(**{**base, **values})

    def with_values(self, **values: float) -> Effect:
        """Return a new effect of the same kind with some parameter values changed."""
        merged = {**self._values, **values}
        return type(self)(**merged)

    # -- helpers for subclasses ---------------------------------------------------------
    @staticmethod
    def broadcast(u: ArrayLike, v: ArrayLike, t_s: ArrayLike) -> tuple[FloatArray, ...]:
        """Broadcast ``u, v, t_s`` to one common float shape."""
        arrays = np.broadcast_arrays(
            np.asarray(u, dtype=np.float64),
            np.asarray(v, dtype=np.float64),
            np.asarray(t_s, dtype=np.float64),
        )
        return tuple(arrays)

    def split_theta(self, theta: ArrayLike | None) -> list[FloatArray]:
        """Split a parameter vector (``(..., n_params)``) into one array per parameter."""
        th = self.theta if theta is None else np.asarray(theta, dtype=np.float64)
        if th.ndim == 0 or th.shape[-1] != len(self.parameters):
            raise UsageError(
                f"{type(self).__name__}: 'theta' must have {len(self.parameters)} entries in "
                f"its last axis ({', '.join(self.parameter_names)}), got shape {th.shape}; "
                "pass one value per parameter"
            )
        return [th[..., i] for i in range(th.shape[-1])]

    # -- physics ------------------------------------------------------------------------
    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Columns whose combination with ``theta`` is the term (linear effects only).

        Parameters
        ----------
        u : array_like
            COM displacement [m].
        v : array_like
            COM velocity [m/s].
        t_s : array_like
            Time [s].
        context : EffectContext, optional
            Extra information (pacing, steps, ground motion, ...).

        Returns
        -------
        ndarray
            Shape ``broadcast(u, v, t).shape + (n_params,)``.
        """
        raise UsageError(
            f"{type(self).__name__}: effect '{self.name}' is not linear in its parameters and "
            "has no regressors; call its force() method instead"
        )

    def force(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        theta: ArrayLike | None = None,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Return the term this effect adds to the left-hand side of the force balance [N].

        Parameters
        ----------
        u, v, t_s, context
            As in :meth:`regressors`.
        theta : array_like, optional
            Parameter vector(s), shape ``(..., n_params)``; default: this instance's values.

        Returns
        -------
        ndarray
            Force [N], broadcast shape of the state and of ``theta``'s leading axes.
        """
        regressors = self.regressors(u, v, t_s, context)
        th = self.theta if theta is None else np.asarray(theta, dtype=np.float64)
        self.split_theta(th)  # shape check with a clear message
        return np.sum(regressors * th, axis=-1)

    # -- composition and display ----------------------------------------------------------
    def __add__(self, other: object) -> Effects:
        if isinstance(other, Effect | Effects):
            return Effects([self]) + other
        return NotImplemented

    def __repr__(self) -> str:
        changed = [
            f"{p.name}={self._values[p.name]:.6g}"
            for p in self.parameters
            if self._values[p.name] != p.default
        ]
        return f"{type(self).__name__}({', '.join(changed)})"

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Effect):
            return NotImplemented
        return type(self) is type(other) and dict(self._values) == dict(other._values)

    def __hash__(self) -> int:
        return hash((type(self), tuple(self._values.items())))

    def to_dict(self) -> dict[str, Any]:
        """JSON-able description: ``{"name": ..., "parameters": {...}}``."""
        return {"name": self.name, "parameters": dict(self._values)}


class Effects:
    """An ordered, immutable collection of effects with distinct names.

    Parameters
    ----------
    effects : iterable of Effect, optional
        The effects, in order. Two effects with the same ``name`` are a ``UsageError``.

    Examples
    --------
    >>> effects = Effects([CubicStiffness(k3_n_per_m3=1e5)])
    >>> effects.names
    ('cubic_stiffness',)
    """

    __slots__ = ("_items",)

    def __init__(self, effects: Iterable[Effect] = ()) -> None:
        items: list[Effect] = []
        seen: set[str] = set()
        for effect in effects:
            if not isinstance(effect, Effect):
                raise UsageError(
                    f"Effects: {effect!r} is not an Effect; pass effect instances such as "
                    "CubicStiffness() or use effect_from_name(NAME)"
                )
            if effect.name in seen:
                raise UsageError(
                    f"Effects: effect '{effect.name}' is added twice; add each effect once and "
                    "set its parameters in that one instance"
                )
            seen.add(effect.name)
            items.append(effect)
        self._items: tuple[Effect, ...] = tuple(items)

    def __add__(self, other: object) -> Effects:
        if isinstance(other, Effect):
            return Effects([*self._items, other])
        if isinstance(other, Effects):
            return Effects([*self._items, *other._items])
        return NotImplemented

    def __iter__(self) -> Iterator[Effect]:
        return iter(self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __bool__(self) -> bool:
        return bool(self._items)

    def __contains__(self, name_or_effect: object) -> bool:
        if isinstance(name_or_effect, Effect):
            return name_or_effect in self._items
        return name_or_effect in self.names

    def __getitem__(self, key: int | str) -> Effect:
        if isinstance(key, str):
            for effect in self._items:
                if effect.name == key:
                    return effect
            raise UsageError(
                f"Effects: no effect named '{key}' in {self!r}; use one of "
                f"{', '.join(self.names) or '(none)'}"
            )
        return self._items[key]

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Effects):
            return NotImplemented
        return self._items == other._items

    def __hash__(self) -> int:
        return hash(self._items)

    @property
    def names(self) -> tuple[str, ...]:
        """Effect names, in order."""
        return tuple(e.name for e in self._items)

    def __repr__(self) -> str:
        return " + ".join(repr(e) for e in self._items) if self._items else "Effects()"


def as_effects(effects: Effect | Effects | Iterable[Effect | str] | None) -> Effects:
    """Normalise an effect, a collection, names or ``None`` to :class:`Effects`.

    Parameters
    ----------
    effects : Effect, Effects, iterable of Effect or str, or None
        Strings are looked up in the registry with default parameter values.

    Returns
    -------
    Effects
    """
    if effects is None:
        return Effects()
    if isinstance(effects, Effects):
        return effects
    if isinstance(effects, Effect):
        return Effects([effects])
    if isinstance(effects, str):
        return Effects([effect_from_name(effects)])
    return Effects(effect_from_name(e) if isinstance(e, str) else e for e in effects)


# -- registry ----------------------------------------------------------------------------
_REGISTRY: dict[str, type[Effect]] = {}


def _validate_effect_class(cls: type[Effect]) -> None:
    where = f"effect class {cls.__name__}"
    if not isinstance(cls.name, str) or not _SNAKE.match(cls.name):
        raise UsageError(
            f"{where}: class attribute 'name' must be a snake_case string, got {cls.name!r}; "
            'set for example name = "my_effect"'
        )
    params = cls.parameters
    if not isinstance(params, tuple) or not all(isinstance(p, Parameter) for p in params):
        raise UsageError(
            f"{where}: class attribute 'parameters' must be a tuple of Parameter; declare "
            "parameters = (Parameter(name, unit, default, description), ...)"
        )
    names = [p.name for p in params]
    if len(set(names)) != len(names) or not all(_SNAKE.match(n) for n in names):
        raise UsageError(
            f"{where}: parameter names {names} must be distinct snake_case identifiers; rename them"
        )
    if cls.linear and cls.regressors is Effect.regressors:
        raise UsageError(
            f"{where}: a linear effect must implement regressors(u, v, t_s, context); "
            "implement it, or set linear = False and override force()"
        )
    if not cls.linear and cls.force is Effect.force:
        raise UsageError(
            f"{where}: a nonlinear effect (linear = False) must override force(u, v, t_s, "
            "theta, context); implement it"
        )


def register_effect(cls: type[Effect]) -> type[Effect]:
    """Class decorator: make an effect available by its ``name``.

    Re-registering the same class (same module and qualified name, e.g. after a reload)
    replaces the entry; a different class with a taken name is a ``UsageError``.

    Parameters
    ----------
    cls : type
        A subclass of :class:`Effect`.

    Returns
    -------
    type
        ``cls`` itself, so it works as a decorator.
    """
    if not (isinstance(cls, type) and issubclass(cls, Effect)):
        raise UsageError(
            f"register_effect: {cls!r} is not a subclass of Effect; derive your effect from "
            "workbench.models.effects.Effect"
        )
    _validate_effect_class(cls)
    existing = _REGISTRY.get(cls.name)
    if existing is not None and (existing.__module__, existing.__qualname__) != (
        cls.__module__,
        cls.__qualname__,
    ):
        raise UsageError(
            f"register_effect: effect name '{cls.name}' is already registered by "
            f"{existing.__module__}.{existing.__qualname__}; choose another name"
        )
    _REGISTRY[cls.name] = cls
    return cls


def unregister_effect(name: str) -> None:
    """Remove an effect from the registry (for tests and interactive sessions).

    Parameters
    ----------
    name : str
        Registered effect name; unknown names are a ``UsageError``.
    """
    effect_class(name)
    del _REGISTRY[name]


def available_effects() -> tuple[str, ...]:
    """Names of all registered effects, sorted.

    Returns
    -------
    tuple of str
    """
    return tuple(sorted(_REGISTRY))


def effect_class(name: str) -> type[Effect]:
    """Return the registered class for an effect name.

    Parameters
    ----------
    name : str
        Effect name, e.g. ``"cubic_stiffness"``.

    Returns
    -------
    type
        The :class:`Effect` subclass.
    """
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise UsageError(
            f"effect '{name}' is not known; use one of {', '.join(available_effects())} or "
            "register your own with @register_effect"
        ) from None


def effect_from_name(name: str, **kwargs: float) -> Effect:
    """Create a registered effect by name.

    Parameters
    ----------
    name : str
        Effect name, e.g. ``"cubic_stiffness"``.
    **kwargs : float
        Parameter values.

    Returns
    -------
    Effect
    """
    return effect_class(name)(**kwargs)


# -- catalogue ---------------------------------------------------------------------------
@register_effect
class CubicStiffness(Effect):
    """Hardening (``k3 > 0``) or softening (``k3 < 0``) leg spring: term ``k3 u^3``.

    Parameters
    ----------
    k3_n_per_m3 : float, optional
        Cubic stiffness [N/m^3], default 0 (no effect).

    Notes
    -----
    Typical signature: model error that grows with amplitude and correlates with ``u^3``.
    ``u`` is the COM displacement from the model's reference (the static equilibrium of the
    linear spring), so ``k3`` is relative to that point.
    """

    name = "cubic_stiffness"
    # Typical: k3 u^2 is about 5 % of K = 1e4 N/m at u = 3 cm.
    parameters = (
        Parameter(
            "k3_n_per_m3", "N/m^3", 0.0, "cubic spring coefficient (term k3 u^3)", typical=5e5
        ),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Single column ``u^3`` [m^3]."""
        u_b, _, _ = self.broadcast(u, v, t_s)
        return (u_b**3)[..., None]


def _half_phase_columns(phi: FloatArray, orders: tuple[int, ...]) -> FloatArray:
    cols = []
    for k in orders:
        cols.append(np.cos(0.5 * k * phi))
        cols.append(np.sin(0.5 * k * phi))
    return np.stack(cols, axis=-1)


@register_effect
class GaitAsymmetry(Effect):
    """Left and right steps differ: force terms at half and three halves of the pacing rate.

    The term is ``-(a_h cos(phi/2) + b_h sin(phi/2) + a_3h cos(3 phi/2) + b_3h sin(3 phi/2))``
    with ``phi`` the step phase (``2 pi`` per step), so positive coefficients add to the
    biomechanical force like its Fourier coefficients. Half a step-phase cycle per step is one
    cycle per stride: the force of odd steps differs from that of even steps.

    Parameters
    ----------
    a_half_n, b_half_n, a_3half_n, b_3half_n : float, optional
        Cosine and sine amplitudes [N] at ``f_p / 2`` and ``3 f_p / 2``; default 0.

    Notes
    -----
    Statistic that reveals it: residual power at odd multiples of ``f_p / 2`` and an odd/even
    step contrast of the residual's step-phase profile. Needs ``context.step_start_s``.
    """

    name = "gait_asymmetry"
    parameters = (
        Parameter("a_half_n", "N", 0.0, "cosine amplitude at f_p/2", typical=25.0),
        Parameter("b_half_n", "N", 0.0, "sine amplitude at f_p/2", typical=15.0),
        Parameter("a_3half_n", "N", 0.0, "cosine amplitude at 3 f_p/2"),
        Parameter("b_3half_n", "N", 0.0, "sine amplitude at 3 f_p/2"),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Columns ``-cos(phi/2), -sin(phi/2), -cos(3 phi/2), -sin(3 phi/2)``."""
        _, _, t_b = self.broadcast(u, v, t_s)
        ctx = context if context is not None else EffectContext()
        return -_half_phase_columns(ctx.step_phase_rad(t_b), (1, 3))


@register_effect
class QuadraticDamping(Effect):
    """Velocity-squared damping: term ``c2 |u'| u'``.

    Parameters
    ----------
    c2_ns2_per_m2 : float, optional
        Quadratic damping coefficient [N s^2/m^2]; default 0.

    Notes
    -----
    Statistic that reveals it: residual correlated with ``|u'| u'`` beyond what ``u'`` and the
    step-periodic force shape explain.
    """

    name = "quadratic_damping"
    # Typical: c2 |u'| is about 10 % of C = 500 N s/m at |u'| = 0.2 m/s.
    parameters = (
        Parameter(
            "c2_ns2_per_m2", "N s^2/m^2", 0.0, "quadratic damping (term c2 |u'| u')", typical=250.0
        ),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Single column ``|u'| u'`` [m^2/s^2]."""
        _, v_b, _ = self.broadcast(u, v, t_s)
        return (np.abs(v_b) * v_b)[..., None]


@register_effect
class StiffnessDrift(Effect):
    """K and C change along the record: term ``t (dk u + dc u')``.

    Parameters
    ----------
    dk_n_per_m_s : float, optional
        Rate of change of the stiffness [N/m per s]; default 0.
    dc_ns_per_m_s : float, optional
        Rate of change of the damping [N s/m per s]; default 0.

    Notes
    -----
    ``t`` is the time of the record (its first sample is usually 0), so at that time the
    model's K and C hold. Statistic that reveals it: residual correlated with ``t u`` and
    ``t u'``; per-window estimates of K trend.
    """

    name = "stiffness_drift"
    parameters = (
        Parameter("dk_n_per_m_s", "N/m/s", 0.0, "stiffness change per second", typical=60.0),
        Parameter("dc_ns_per_m_s", "N s/m/s", 0.0, "damping change per second"),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Columns ``t u`` and ``t u'``."""
        u_b, v_b, t_b = self.broadcast(u, v, t_s)
        return np.stack([t_b * u_b, t_b * v_b], axis=-1)


@register_effect
class PacingDrift(Effect):
    """The gait changes along the record: the force shape follows time and the pacing rate.

    The term is ``-((t) (g cos(phi) + h sin(phi)) + (f - f_ref) (p cos(phi) + q sin(phi)))``
    with ``phi`` the step phase, ``f`` the rate of the current step (one over its duration)
    and ``f_ref`` the reference pacing: the first harmonic's amplitude and phase drift in
    time and change with the pacing rate, as they do when a walker speeds up or slows down
    (load factors rise with the pacing rate, and the timing of the force within a step
    shifts). Measured in step phase, the change of step duration itself is absorbed; what a
    shared force shape cannot follow is this change of shape.

    Parameters
    ----------
    drift_cos_n_per_s, drift_sin_n_per_s : float, optional
        Rates of change of the first harmonic's cosine and sine coefficients [N/s].
    rate_cos_n_per_hz, rate_sin_n_per_hz : float, optional
        Change of those coefficients per Hz of pacing rate above ``f_ref`` [N/Hz].

    Notes
    -----
    Statistic that reveals it: the residual's first-harmonic phase and amplitude drift from
    one block of steps to the next; a fixed-f_p basis in absolute time fails. Needs
    ``context.step_start_s``; ``f_ref`` is ``context.pacing_hz`` when given, otherwise the
    median step rate.
    """

    name = "pacing_drift"
    parameters = (
        Parameter("drift_cos_n_per_s", "N/s", 0.0, "drift of a1 per second", typical=4.0),
        Parameter("drift_sin_n_per_s", "N/s", 0.0, "drift of b1 per second", typical=-3.0),
        Parameter("rate_cos_n_per_hz", "N/Hz", 0.0, "change of a1 per Hz of pacing"),
        Parameter("rate_sin_n_per_hz", "N/Hz", 0.0, "change of b1 per Hz of pacing"),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Columns ``-t cos(phi)``, ``-t sin(phi)``, ``-(f - f_ref) cos(phi)``, ``... sin``."""
        _, _, t_b = self.broadcast(u, v, t_s)
        ctx = context if context is not None else EffectContext()
        phi = ctx.step_phase_rad(t_b)
        starts = np.asarray(ctx._require("step_start_s", "PacingDrift"), dtype=np.float64)
        durations = np.diff(starts)
        if durations.size == 0:
            raise UsageError(
                "PacingDrift: the effect context needs at least two step starts; pass "
                "step_start_s with every footfall"
            )
        rates = 1.0 / np.concatenate([durations, durations[-1:]])
        f = rates[np.clip(ctx.step_index(t_b), 0, rates.size - 1)]
        f_ref = float(np.median(rates)) if ctx.pacing_hz is None else float(ctx.pacing_hz)
        df = f - f_ref
        c, s_ = np.cos(phi), np.sin(phi)
        return np.stack([-t_b * c, -t_b * s_, -df * c, -df * s_], axis=-1)


@register_effect
class HeelImpact(Effect):
    """A short impact transient at each heel strike.

    The term is ``-impact_n x exp(1 - x)`` with ``x = (t - t_step) / decay_s`` the time since
    the step's start: a pulse of height ``impact_n`` peaking ``decay_s`` after footfall,
    added to the biomechanical force. Nonlinear in ``decay_s``, so ``force`` is overridden.

    Parameters
    ----------
    impact_n : float, optional
        Peak of the impact force [N]; default 0.
    decay_s : float, optional
        Time from footfall to the peak, also the decay time [s]; default 0.012.

    Notes
    -----
    Statistic that reveals it: residual localised just after footfall, broadband (power at
    step harmonics above those of the force model). Needs ``context.step_start_s``.
    """

    name = "heel_impact"
    linear = False
    parameters = (
        Parameter("impact_n", "N", 0.0, "peak impact force", typical=150.0),
        Parameter("decay_s", "s", 0.012, "time to peak and decay time"),
    )

    def force(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        theta: ArrayLike | None = None,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Return ``-impact_n x exp(1 - x)`` [N], ``x`` the time since the step start."""
        _, _, t_b = self.broadcast(u, v, t_s)
        impact, decay = self.split_theta(theta)
        ctx = context if context is not None else EffectContext()
        starts = np.asarray(ctx._require("step_start_s", "HeelImpact"), dtype=np.float64)
        since = t_b - starts[ctx.step_index(t_b)]
        x = since / np.where(decay > 0, decay, np.inf)
        return np.asarray(-impact * x * np.exp(1.0 - x), dtype=np.float64)


@register_effect
class BaseMotion(Effect):
    """Walking on a vibrating surface: the leg acts on the relative motion.

    The term is ``-(k_g u_g + c_g u_g')`` with ``u_g`` the surface displacement; with
    ``k_g = K`` and ``c_g = C`` the spring and damper act on ``u - u_g``.

    Parameters
    ----------
    k_ground_n_per_m : float, optional
        Stiffness coupling to the surface displacement [N/m]; default 0.
    c_ground_ns_per_m : float, optional
        Damping coupling to the surface velocity [N s/m]; default 0.

    Notes
    -----
    Statistic that reveals it: residual correlated with the measured ground motion, a
    narrow-band peak off the ``f_p`` harmonics. Needs ground motion in the context.
    """

    name = "base_motion"
    parameters = (
        Parameter("k_ground_n_per_m", "N/m", 0.0, "coupling to surface displacement"),
        Parameter("c_ground_ns_per_m", "N s/m", 0.0, "coupling to surface velocity"),
    )

    def regressors(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> FloatArray:
        """Columns ``-u_g`` and ``-u_g'``."""
        _, _, t_b = self.broadcast(u, v, t_s)
        ctx = context if context is not None else EffectContext()
        if ctx.ground_motion is None and ctx.ground_time_s is None:
            raise UsageError(
                "base_motion: there is no ground motion to act through; give the surface's "
                "acceleration (simulate --ground-acc-amplitude, simulate_walking("
                "ground_acc_m_s2=...), or a record with a ground_acc column)"
            )
        disp, vel, _ = ctx.ground_at(t_b)
        return np.stack([-disp, -vel], axis=-1)
