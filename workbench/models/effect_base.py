"""The effect mechanism: the :class:`Effect` base class, collections, registry and specs.

They are one mechanism in one module: apart, the base class and the registry would import
each other.

How to write an effect is in the module docstring of :mod:`workbench.models.effects`, which
also holds the catalogue and re-exports everything here; import from there.

An effect carries everything about itself: its parameters, its term in the force balance
(:meth:`Effect.regressors` or :meth:`Effect.force`), the columns it adds to model
criticism's regression (:meth:`Effect.criticism_columns`), the statistic that reveals it
(:meth:`Effect.statistic`), the plain-words reason reported when it is significant
(:attr:`Effect.reason`) and its columns in the identification problem
(:meth:`Effect.identification_columns`). Registering it with :func:`register_effect` is the
only registration: simulation, identification, ``diagnose`` and ``compare`` read the same
registry.

Effect specs
------------
:meth:`Effect.from_spec` is the one parser of an effect written as text::

    NAME                      default parameter values
    NAME:P=V                  one parameter set
    NAME:P=V:Q=W  or  NAME:P=V,Q=W

and :func:`parse_effect_specs` reads a comma-separated list of them. A comma-separated item
of the form ``P=V`` continues the spec before it (effect names never hold ``=``), so
``gait_asymmetry:a_half_n=20,b_half_n=10,cubic_stiffness`` is two effects.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Iterator, Mapping, Sequence
from types import MappingProxyType
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.models.effect_context import CriticismRecord, EffectContext, Parameter

__all__ = [
    "Effect",
    "Effects",
    "as_effects",
    "available_effects",
    "effect_class",
    "effect_from_name",
    "parse_effect_specs",
    "register_effect",
    "split_effect_specs",
    "unregister_effect",
]

FloatArray = NDArray[np.float64]
_SNAKE = re.compile(r"^[a-z][a-z0-9_]*$")


class Effect:
    """Base class of an effect: one extra term in ``M u'' + C u' + K u + term = F_bio``.

    Subclasses set the class attributes ``name``, ``parameters`` and (for criticism)
    ``reason``, and implement :meth:`regressors` (linear effects) or :meth:`force` with
    ``linear = False``. A linear effect is then also a candidate of model criticism (its
    regressors on the record's measured state are its columns) and a term of the
    identification; a nonlinear one overrides :meth:`criticism_columns` and
    :meth:`identification_columns` to be either. See the module docstring of
    :mod:`workbench.models.effects` for worked examples.

    Parameters
    ----------
    **values : float
        Parameter values by parameter name; omitted ones take their default.
    """

    name: ClassVar[str] = ""
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    linear: ClassVar[bool] = True
    #: Plain-words sentence model criticism gives when the effect is significant.
    reason: ClassVar[str] = "the error follows the columns of its term"
    #: Whether the effect's criticism columns change sign when the left and right feet swap
    #: labels (terms at odd multiples of half the pacing rate). Criticism over a walker's
    #: walks (:mod:`workbench.diagnostics.walker`) then shares their coefficients only when
    #: the walks' feet are known, and otherwise fits them walk by walk.
    swaps_with_feet: ClassVar[bool] = False

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

    def __reduce__(self) -> tuple[Any, ...]:
        # The read-only view of the values does not pickle; rebuild from the values, so a
        # model with effects (and a result holding it) travels between processes.
        return (_rebuild_effect, (type(self), dict(self._values)))

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

    # -- model criticism ----------------------------------------------------------------
    @classmethod
    def is_criticism_candidate(cls) -> bool:
        """Whether model criticism can test the effect (linear, or criticism columns given).

        Returns
        -------
        bool
        """
        return cls.linear or cls.criticism_columns is not Effect.criticism_columns

    def criticism_columns(self, data: CriticismRecord) -> FloatArray | None:
        """Columns the effect adds to the criticism baseline's regression.

        The default, for linear effects, is :meth:`regressors` on the record's measured
        state with an :class:`EffectContext` holding the body mass, the pacing, the step
        boundaries and the ground motion (when measured); the values of the parameters do
        not matter. The catalogue's effects override it with columns that survive the
        criticism baseline (see :mod:`workbench.diagnostics.criticism`).

        Parameters
        ----------
        data : CriticismRecord
            A record prepared for criticism
            (:func:`workbench.diagnostics.criticism.prepare`).

        Returns
        -------
        ndarray, shape (n_samples, n_columns), or None
            None when the record cannot test the effect (e.g. no ground motion).
        """
        if not self.linear:
            raise UsageError(
                f"{type(self).__name__}: effect '{self.name}' is not linear in its parameters "
                "and has no criticism columns; override criticism_columns(data) to make it a "
                "candidate"
            )
        ground = data.ground
        ctx = EffectContext(
            mass_kg=data.mass_kg,
            pacing_hz=data.pacing_hz,
            step_start_s=data.footfall_times_s,
            ground_time_s=None if ground is None else data.time_s,
            ground_disp_m=None if ground is None else ground[0],
            ground_vel_m_s=None if ground is None else ground[1],
            ground_acc_m_s2=None if ground is None else ground[2],
        )
        try:
            cols = self.regressors(data.disp_m, data.vel_m_s, data.time_s, ctx)
        except UsageError:
            return None  # the record lacks what the effect needs (e.g. ground motion)
        return np.asarray(cols, dtype=np.float64).reshape(data.time_s.size, -1)

    def statistic(
        self, data: CriticismRecord, baseline_residual_n: FloatArray
    ) -> tuple[float, str] | None:
        """Return the statistic that reveals the effect in the baseline's held-out error.

        Parameters
        ----------
        data : CriticismRecord
            A record prepared for criticism.
        baseline_residual_n : ndarray
            The criticism baseline's held-out error on the record's samples [N].

        Returns
        -------
        (float, str) or None
            The value and a sentence reporting it (evidence of the candidate); the default
            is None (no statistic).
        """
        return None

    # -- identification -------------------------------------------------------------------
    def identification_columns(
        self,
        u: ArrayLike,
        v: ArrayLike,
        t_s: ArrayLike,
        context: EffectContext | None = None,
    ) -> tuple[FloatArray, tuple[str, ...]]:
        """Return the term's columns in the identification problem and the coefficients' names.

        The identification fits coefficients ``beta`` shared by the whole record with the
        term equal to ``columns @ beta`` (see :mod:`workbench.inference.pipeline.effect_terms`). The
        default, for linear effects, is :meth:`regressors` with every parameter fitted; a
        nonlinear effect may override it to fit the parameters its term is linear in, the
        others held at the instance's values (``heel_impact`` fits its height, its decay
        held).

        Parameters
        ----------
        u, v, t_s : array_like, shape (n,)
            Observed COM displacement [m], velocity [m/s] and time [s].
        context : EffectContext, optional
            As in :meth:`regressors`.

        Returns
        -------
        columns : ndarray, shape (n, d)
            The term's columns (left-hand side of the force balance).
        names : tuple of str
            ``effect.parameter`` of each column.
        """
        if not self.linear:
            raise UsageError(
                f"effect {self.name!r} is nonlinear in its parameters; identification accepts "
                "linear effects and those that override identification_columns() (such as "
                "heel_impact); give it regressors() or leave it out of 'effects'",
                parameter="effects",
            )
        t = np.asarray(t_s, dtype=np.float64)
        r = np.asarray(self.regressors(u, v, t, context), dtype=np.float64)
        return r.reshape(t.size, -1), self.qualified_parameter_names

    # -- specs ----------------------------------------------------------------------------
    @classmethod
    def from_spec(cls, spec: str) -> Effect:
        """Create a registered effect from its spec, ``NAME[:P=V[:Q=W...]]``.

        The one parser of an effect written as text (module docstring): ``"cubic_stiffness"``
        gives default values, ``"cubic_stiffness:k3_n_per_m3=2e6"`` sets one; parameters are
        separated by ``:`` or ``,``. Called on a subclass, the spec must name that effect.

        Parameters
        ----------
        spec : str
            The effect spec.

        Returns
        -------
        Effect
            An instance of the registered class.

        Examples
        --------
        >>> Effect.from_spec("cubic_stiffness:k3_n_per_m3=2e6")
        CubicStiffness(k3_n_per_m3=2e+06)
        """
        effect = _from_spec(spec)
        if cls is not Effect and not isinstance(effect, cls):
            raise UsageError(
                f"effect spec {spec!r} names '{effect.name}', not '{cls.name}'; call "
                "Effect.from_spec for any effect or give a spec of this one"
            )
        return effect

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


# -- specs -------------------------------------------------------------------------------
def _spec_example(cls: type[Effect]) -> str:
    if not cls.parameters:
        return cls.name
    p = cls.parameters[0]
    value = p.default if p.typical is None else p.typical
    return f"{cls.name}:{p.name}={value:g}"


def _from_spec(spec: object) -> Effect:
    if not isinstance(spec, str):
        raise UsageError(
            f"effect spec {spec!r} is not text; write NAME or NAME:PARAMETER=NUMBER, for "
            "example cubic_stiffness:k3_n_per_m3=2e6"
        )
    name, _, rest = spec.strip().partition(":")
    name = name.strip()
    if not name or "=" in name:
        raise UsageError(
            f"effect spec {spec!r} does not start with an effect name; write NAME or "
            "NAME:PARAMETER=NUMBER, for example cubic_stiffness:k3_n_per_m3=2e6"
        )
    try:
        cls = effect_class(name)
    except UsageError as err:
        if not rest:
            raise
        raise UsageError(f"effect spec {spec!r}: {err}") from None
    units = {p.name: p.unit for p in cls.parameters}
    values: dict[str, float] = {}
    for item in filter(None, (i.strip() for i in re.split(r"[:,]", rest))):
        key, eq, text = (x.strip() for x in item.partition("="))
        if not eq or not key:
            raise UsageError(
                f"effect spec {spec!r}: {item!r} is not of the form PARAMETER=NUMBER; write "
                f"for example {_spec_example(cls)}"
            )
        if key not in units:
            known = ", ".join(units) or "(none)"
            raise UsageError(
                f"effect spec {spec!r}: {name} has no parameter {key!r}; use one of {known}"
            )
        if key in values:
            raise UsageError(
                f"effect spec {spec!r}: parameter {key!r} is given twice; give it once"
            )
        try:
            values[key] = float(text)
        except ValueError:
            raise UsageError(
                f"effect spec {spec!r}: the value of {key!r} ({text!r}) is not a number; "
                f"give a number in {units[key]}"
            ) from None
    return cls(**values)


def split_effect_specs(text: str) -> list[str]:
    """Split a comma-separated list of effect specs (module docstring).

    A comma-separated item of the form ``P=V`` continues the spec before it, so
    ``"gait_asymmetry:a_half_n=20,b_half_n=10,cubic_stiffness"`` is two specs.

    Parameters
    ----------
    text : str

    Returns
    -------
    list of str
        The specs, stripped; empty items are dropped.
    """
    specs: list[str] = []
    for item in filter(None, (i.strip() for i in text.split(","))):
        if "=" in item.partition(":")[0]:
            if not specs:
                raise UsageError(
                    f"effect specs {text!r} start with a parameter ({item!r}); put the effect "
                    "name first, e.g. cubic_stiffness:k3_n_per_m3=2e6"
                )
            specs[-1] += "," + item
        else:
            specs.append(item)
    return specs


def parse_effect_specs(
    specs: str | Effect | Effects | Iterable[str | Effect] | None, *, where: str | None = None
) -> Effects:
    """Parse effect specs into :class:`Effects` (the one parser of effect lists).

    Parameters
    ----------
    specs : str, Effect, Effects, iterable of str or Effect, or None
        ``"NAME[:P=V...],NAME..."`` (module docstring), or a sequence whose strings are each
        such a list; effects pass through. None is no effect.
    where : str, optional
        What the text came from (e.g. ``"--effects"``), put before an error message.

    Returns
    -------
    Effects
        In order; an effect named twice is a ``UsageError``.

    Examples
    --------
    >>> parse_effect_specs("gait_asymmetry:a_half_n=20,b_half_n=10,cubic_stiffness").names
    ('gait_asymmetry', 'cubic_stiffness')
    """
    if specs is None:
        return Effects()
    if isinstance(specs, Effects):
        return specs
    if isinstance(specs, Effect):
        return Effects([specs])
    items: Sequence[Any] = [specs] if isinstance(specs, str) else list(specs)
    try:
        effects: list[Effect] = []
        for item in items:
            if isinstance(item, Effect):
                effects.append(item)
            elif isinstance(item, str):
                effects += [Effect.from_spec(s) for s in split_effect_specs(item)]
            else:
                raise UsageError(
                    f"{item!r} is not an effect spec; give NAME[:PARAMETER=NUMBER] or an Effect"
                )
        return Effects(effects)
    except UsageError as err:
        if where is None:
            raise
        shown = specs if isinstance(specs, str) else ",".join(map(str, items))
        raise UsageError(f"{where} {shown}: {err}") from None


def _rebuild_effect(cls: type[Effect], values: dict[str, float]) -> Effect:
    """Rebuild an effect from its class and values (unpickling, :meth:`Effect.__reduce__`)."""
    return cls(**values)
