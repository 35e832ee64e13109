"""Identification methods as objects with their own options, in the spirit of ``particles``.

A method takes the compiled :class:`~workbench.inference.core.problem.IdentificationProblem` (the
linear-Gaussian form of a pedestrian model on one record, which every method shares) and
returns an :class:`~workbench.inference.core.results.IdentificationResult`::

    wb.identify(record, model, method=wb.RBPF(n_particles=512))
    wb.identify(record, model, method=wb.PF(n_particles=5000, force_proposal="prior"))
    wb.identify(record, model, method=wb.Exact())

- :class:`Exact` (the default, :data:`DEFAULT_METHOD`): the marginal posterior of (C, K) on
  an adaptive grid, each node one Kalman filter run; the reference every particle filter is
  checked against.
- :class:`RBPF`: particles over (C, K) only, a Kalman filter per particle for the response
  and force coefficients; exact for this model, so few particles suffice.
- :class:`PF`: the seed study's bootstrap particle filter over the whole state, kept
  faithful to the seed (Euler discretisation, random walks of C and K).

The registry
------------
Every method class is registered once under its ``name`` (:func:`register_method`, a class
decorator). The registry is the one list of methods: a name stands for the method with its
defaults (:func:`as_method`), the settings accept the registered names and take each
method's defaults from its class, every command's ``--method`` lists them
(:func:`method_names`, in the order of registration), the sensitivity studies vary over them,
``crosscheck`` offers the ones whose class sets ``particle_filter``
(:func:`particle_filter_names`) and the study figures draw each in its ``colour``.
docs/guide/adding-a-method.md shows how to add one.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.core import (
    KALMAN_STATE_FRACTION,
    SCHEMES,
    SEED_STATE_FRACTION,
    FilterResults,
    GridResults,
    IdentificationProblem,
    IdentificationResult,
    ParticleFilterOutput,
    force_correlation,
    identifiability_report,
)
from workbench.inference.core.load_factors import (
    LoadFactorPosterior,
    mix_load_factors,
)
from workbench.inference.core.node_posterior import node_posterior_from_grid
from workbench.inference.kalman import record_loglik
from workbench.inference.methods.exact_force import node_load_factors
from workbench.inference.methods.pf import PF_PARTICLES
from workbench.inference.methods.rbpf import RBPF_PARTICLES, REJUVENATE

FloatArray = NDArray[np.float64]

__all__ = [
    "DEFAULT_METHOD",
    "PF",
    "RBPF",
    "Exact",
    "Method",
    "as_method",
    "load_factors_at_draws",
    "method_class",
    "method_names",
    "particle_filter_names",
    "register_method",
    "unregister_method",
]

#: Particles (a weighted subsample) used to estimate the C/K-force correlation of a filter.
CORRELATION_DRAWS = 128
#: The method of an identification that names none.
DEFAULT_METHOD = "exact"
_SNAKE = re.compile(r"^[a-z][a-z0-9_]*$")
_M = TypeVar("_M", bound="Method")


def _check_resampling(resampling: str, ess_threshold: float, who: str) -> None:
    if resampling not in SCHEMES:
        raise UsageError(
            f"{who}: 'resampling' {resampling!r} is not known; use one of {', '.join(SCHEMES)}",
            parameter="resampling",
        )
    if not (0 < float(ess_threshold) <= 1):
        raise UsageError(
            f"{who}: 'ess_threshold' must be a fraction in (0, 1], got {ess_threshold!r}",
            parameter="ess_threshold",
        )


def _check_particles(n: int, who: str) -> int:
    if isinstance(n, bool) or int(n) != n or int(n) < 2:
        raise UsageError(
            f"{who}: 'n_particles' must be a whole number of at least 2, got {n!r}",
            parameter="n_particles",
        )
    return int(n)


@dataclass(frozen=True)
class Method:
    """Base class of an identification method (subclasses set ``name`` and implement ``run``).

    A method is a frozen dataclass: its fields are its options, and their defaults are the
    method's defaults wherever the method is named without options (the settings, the
    command line). Register the class with :func:`register_method` to make its name known.

    Class attributes
    ----------------
    name : str
        The registered name (snake_case), used by ``method=`` and ``--method``.
    default_state_noise_fraction : float
        The process noise of (u, u') the method uses when the noise settings leave it unset.
    particle_filter : bool
        Whether the method filters the record piece by piece with particles, so that
        ``crosscheck`` can check its per-step posterior (it then has an ``n_particles``
        option).
    colour : str or None
        Matplotlib colour of the method in study figures; None takes one of the colour
        cycle that no registered method has.
    """

    name: ClassVar[str] = ""
    default_state_noise_fraction: ClassVar[float] = KALMAN_STATE_FRACTION
    particle_filter: ClassVar[bool] = False
    colour: ClassVar[str | None] = None

    def run(
        self,
        problem: IdentificationProblem,
        *,
        seed: int = 0,
        progress: bool = False,
        common: dict[str, Any] | None = None,
    ) -> IdentificationResult:
        """Solve a compiled problem whose noise is set.

        Parameters
        ----------
        problem : IdentificationProblem
            The problem (data, basis, pieces, noise and prior).
        seed : int, default 0
            Seed of every random draw of the method.
        progress : bool, default False
            Show a progress bar (filters).
        common : dict, optional
            Fields passed through to the result (``noise``, ``settings``, ``model``).

        Returns
        -------
        IdentificationResult
        """
        raise NotImplementedError

    def replace(self, **changes: Any) -> Method:
        """Return a copy with some options changed."""
        return dataclasses.replace(self, **changes)


# -- registry ----------------------------------------------------------------------------
_REGISTRY: dict[str, type[Method]] = {}


def _validate_method_class(cls: type[Method]) -> None:
    where = f"method class {cls.__name__}"
    if not isinstance(cls.name, str) or not _SNAKE.match(cls.name):
        raise UsageError(
            f"{where}: class attribute 'name' must be a snake_case string, got {cls.name!r}; "
            'set for example name: ClassVar[str] = "my_method"'
        )
    if not dataclasses.is_dataclass(cls) or "__dataclass_fields__" not in vars(cls):
        raise UsageError(
            f"{where}: decorate the class with @dataclass(frozen=True) (under @register_method) "
            "so that its options are fields with defaults"
        )
    missing = [f.name for f in dataclasses.fields(cls) if _has_no_default(f)]
    if missing:
        raise UsageError(
            f"{where}: every option needs a default, so that the method runs when it is "
            f"named without options; give one to {', '.join(missing)}"
        )
    if cls.run is Method.run:
        raise UsageError(
            f"{where}: implement run(problem, *, seed, progress, common) returning an "
            "IdentificationResult"
        )
    if cls.particle_filter and "n_particles" not in {f.name for f in dataclasses.fields(cls)}:
        raise UsageError(
            f"{where}: a particle filter (particle_filter = True) needs an 'n_particles' option"
        )


def _has_no_default(f: dataclasses.Field[Any]) -> bool:
    return f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING


def register_method(cls: type[_M]) -> type[_M]:
    """Class decorator: make an identification method available by its ``name``.

    A registered method is accepted by :func:`as_method` and the settings (``method =
    "NAME"``), listed by every command's ``--method`` (in the order of registration), varied
    by the sensitivity studies and drawn in the study figures; a particle filter
    (``particle_filter = True``) is also offered by ``crosscheck``. Re-registering the same
    class (same module and qualified name, e.g. after a reload) replaces the entry in its
    place; a different class with a taken name is a ``UsageError``.

    Parameters
    ----------
    cls : type
        A frozen dataclass subclass of :class:`Method` that sets ``name`` and implements
        ``run``, every option with a default.

    Returns
    -------
    type
        ``cls`` itself, so it works as a decorator.
    """
    if not (isinstance(cls, type) and issubclass(cls, Method)):
        raise UsageError(
            f"register_method: {cls!r} is not a subclass of Method; derive your method from "
            "workbench.inference.methods.Method"
        )
    _validate_method_class(cls)
    existing = _REGISTRY.get(cls.name)
    if existing is not None and (existing.__module__, existing.__qualname__) != (
        cls.__module__,
        cls.__qualname__,
    ):
        raise UsageError(
            f"register_method: method name '{cls.name}' is already registered by "
            f"{existing.__module__}.{existing.__qualname__}; choose another name"
        )
    _REGISTRY[cls.name] = cls
    return cls


def unregister_method(name: str) -> None:
    """Remove a method from the registry (for tests and interactive sessions).

    Parameters
    ----------
    name : str
        Registered method name; unknown names are a ``UsageError``.
    """
    method_class(name)
    del _REGISTRY[name]


def method_names() -> tuple[str, ...]:
    """Names of the registered methods, in the order of registration.

    Returns
    -------
    tuple of str
        ``("rbpf", "pf", "exact")`` and any added after them.
    """
    return tuple(_REGISTRY)


def particle_filter_names() -> tuple[str, ...]:
    """Names of the registered particle filters (``particle_filter = True``), in order.

    Returns
    -------
    tuple of str
    """
    return tuple(name for name, cls in _REGISTRY.items() if cls.particle_filter)


def method_class(name: str) -> type[Method]:
    """Return the registered class of a method name.

    Parameters
    ----------
    name : str
        Method name, e.g. ``"rbpf"``.

    Returns
    -------
    type
        The :class:`Method` subclass.
    """
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise UsageError(
            f"method {name!r} is not known; choose one of {', '.join(method_names())} or "
            "register your own with @register_method",
            parameter="method",
        ) from None


def _filter_result(
    problem: IdentificationProblem,
    out: ParticleFilterOutput,
    seed: int,
    common: dict[str, Any],
    *,
    collapse_on_few_ancestors: bool,
) -> IdentificationResult:
    w = np.exp(out.log_weights - np.max(out.log_weights))
    identifiability, load_factors = _filter_posterior_checks(problem, out, seed)
    filtered = FilterResults(
        n_particles=out.n_particles,
        settings=out.settings,
        collapse_on_few_ancestors=collapse_on_few_ancestors,
        piece_mean=out.piece_mean,
        piece_sd=out.piece_sd,
        trace_time_s=out.trace_time_s,
        trace_mean=out.mean,
        trace_sd=out.sd,
        ess=out.ess,
        distinct_ancestors=out.distinct_ancestors,
        unique_values=out.unique_values,
    )
    return IdentificationResult(
        method=out.method,
        draws=np.asarray(out.particles),
        weights=w / w.sum(),
        piece_coefficients_mean=out.piece_coefficients_mean,
        piece_coefficients_sd=out.piece_coefficients_sd,
        loglik=float(out.loglik),
        identifiability=identifiability,
        filter_results=filtered,
        load_factors=load_factors,
        problem=problem,
        **common,
    )


def posterior_subsample(weights: FloatArray, seed: int) -> NDArray[np.intp]:
    """Draw :data:`CORRELATION_DRAWS` indices from a weighted cloud, with replacement.

    The draws at which the load factors are mixed and the force correlation is graded;
    seeded, so that a result does not depend on anything but the settings' seed.
    """
    w = np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    rng = np.random.default_rng(seed)
    return rng.choice(w.size, size=min(CORRELATION_DRAWS, w.size), p=w)


def load_factors_at_draws(
    problem: IdentificationProblem, damping: FloatArray, stiffness: FloatArray
) -> tuple[LoadFactorPosterior, FloatArray, FloatArray]:
    """Mix the walk's load factors over equally weighted (C, K) draws.

    Returns the load factors and the conditional mean and variance of every piece's
    coefficients at the draws (shape (B, P, m)), which the identifiability report reuses.
    """
    res = record_loglik(problem, damping, stiffness, return_pieces=True)
    if res.theta_cov is None or res.theta_mean is None:  # pragma: no cover - contract
        raise RuntimeError("record_loglik(return_pieces=True) returned no coefficients")
    mean = np.asarray(res.theta_mean)
    var = np.diagonal(np.asarray(res.theta_cov), axis1=-2, axis2=-1)
    lf = mix_load_factors(
        mean, var, np.ones(mean.shape[0]), problem.mass_kg, problem.harmonics, "draws"
    )
    return lf, mean, var


def _filter_posterior_checks(
    problem: IdentificationProblem, out: ParticleFilterOutput, seed: int
) -> tuple[dict[str, Any], LoadFactorPosterior]:
    """Grade a filter's final cloud and mix its load factors.

    Both rest on the force coefficients given (C, K) at the same weighted subsample of the
    cloud, so one Kalman pass serves the two.
    """
    w = np.exp(out.log_weights - np.max(out.log_weights))
    w /= w.sum()
    draws = out.particles
    # Weighted moments without a degrees-of-freedom correction: np.cov's would divide by
    # zero when all the weight sits on one particle (a collapsed cloud has zero spread).
    dev = draws - w @ draws
    cov = (dev * w[:, None]).T @ dev
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    corr = float(cov[0, 1] / (sd[0] * sd[1])) if np.all(sd > 0) else float("nan")
    idx = posterior_subsample(w, seed)
    load_factors, theta_mean, theta_var = load_factors_at_draws(
        problem, draws[idx, 0], draws[idx, 1]
    )
    force_max = (float("nan"), float("nan"))
    if np.all(sd > 0):
        fc = force_correlation(
            draws[idx, 0],
            draws[idx, 1],
            np.ones(idx.size),
            theta_mean,
            theta_var,
            problem.coefficient_names,
        )
        force_max = (fc.max_damping, fc.max_stiffness)
    report = identifiability_report(sd, problem.prior.sd, corr, force_max)
    return report.to_json(), load_factors


@dataclass(frozen=True)
class _ParticleFilter(Method):
    """What the two particle filters share: particles, resampling and the result.

    Each filter sets its own ``n_particles`` default (that of its filter function).
    ``collapse_on_few_ancestors`` says whether particles that all descend from a handful of
    initial ones mean a collapsed cloud for this filter (its values renewed by nothing but a
    random walk) rather than the normal path degeneracy of a filter whose moves renew them.
    """

    particle_filter: ClassVar[bool] = True
    collapse_on_few_ancestors: ClassVar[bool] = False
    n_particles: int = 0
    resampling: str = "systematic"
    ess_threshold: float = 0.5

    def __post_init__(self) -> None:
        who = type(self).__name__
        object.__setattr__(self, "n_particles", _check_particles(self.n_particles, who))
        _check_resampling(self.resampling, self.ess_threshold, who)

    def _filter(
        self, problem: IdentificationProblem, seed: int, progress: bool
    ) -> ParticleFilterOutput:
        raise NotImplementedError

    def run(
        self,
        problem: IdentificationProblem,
        *,
        seed: int = 0,
        progress: bool = False,
        common: dict[str, Any] | None = None,
    ) -> IdentificationResult:
        """Run the filter on a compiled problem (see :meth:`Method.run`)."""
        out = self._filter(problem, seed, progress)
        return _filter_result(
            problem,
            out,
            seed,
            common or {},
            collapse_on_few_ancestors=self.collapse_on_few_ancestors,
        )


@register_method
@dataclass(frozen=True)
class RBPF(_ParticleFilter):
    """Rao-Blackwellised particle filter over (C, K).

    Parameters
    ----------
    n_particles : int, default 256
        Particles over (C, K) (:data:`~workbench.inference.methods.rbpf.RBPF_PARTICLES`).
    resampling : str, default "systematic"
        Resampling scheme (see :mod:`workbench.inference.core.resampling`).
    ess_threshold : float, default 0.5
        Resample when the effective sample size falls below this fraction of the particles.
    rejuvenate : {"auto", "surprise", "always"}, default "auto"
        When the particles get exact Metropolis moves (:mod:`workbench.inference.methods.rbpf`):
        ``"surprise"`` (when a piece moves the posterior beyond the cloud, cheap),
        ``"always"`` (after every resampling: follows a posterior that drifts along the
        record, several times slower), ``"auto"`` (``"always"`` on a record whose surface
        acts through K and C, where the deck's bursts move the posterior along the record;
        ``"surprise"`` otherwise).
    """

    name: ClassVar[str] = "rbpf"
    colour: ClassVar[str | None] = "C1"
    n_particles: int = RBPF_PARTICLES
    rejuvenate: str = "auto"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.rejuvenate not in REJUVENATE:
            raise UsageError(
                f"RBPF: 'rejuvenate' must be one of {', '.join(REJUVENATE)}, got "
                f"{self.rejuvenate!r}",
                parameter="rejuvenate",
            )

    def _filter(
        self, problem: IdentificationProblem, seed: int, progress: bool
    ) -> ParticleFilterOutput:
        from workbench.inference.methods.rbpf import run_rbpf

        return run_rbpf(
            problem,
            n_particles=self.n_particles,
            seed=seed,
            resampling=self.resampling,
            ess_threshold=self.ess_threshold,
            rejuvenate=self.rejuvenate,
            progress=progress,
        )


@register_method
@dataclass(frozen=True)
class PF(_ParticleFilter):
    """The seed study's bootstrap particle filter over the whole state.

    Parameters
    ----------
    n_particles : int, default 4000
        Particles over (u, u', C, K, force coefficients)
        (:data:`~workbench.inference.methods.pf.PF_PARTICLES`).
    resampling : str, default "systematic"
        Resampling scheme.
    ess_threshold : float, default 0.5
        Resampling threshold as a fraction of the particles.
    force_proposal : {"regression", "prior"}, default "regression"
        How the force coefficients are regenerated at each footfall: from a Gaussian fitted
        to the step's data given each particle's (C, K), with the importance correction that
        keeps the seed's target, or blindly from the force prior as the seed does.
    """

    name: ClassVar[str] = "pf"
    default_state_noise_fraction: ClassVar[float] = SEED_STATE_FRACTION
    colour: ClassVar[str | None] = "C0"
    # Only the random walk renews the values of C and K, so few surviving initial
    # particles is a collapse of the cloud, not path degeneracy.
    collapse_on_few_ancestors: ClassVar[bool] = True
    n_particles: int = PF_PARTICLES
    force_proposal: str = "regression"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.force_proposal not in ("regression", "prior"):
            raise UsageError(
                f"PF: 'force_proposal' must be 'regression' or 'prior', got "
                f"{self.force_proposal!r}",
                parameter="force_proposal",
            )

    def _filter(
        self, problem: IdentificationProblem, seed: int, progress: bool
    ) -> ParticleFilterOutput:
        from workbench.inference.methods.pf import run_pf

        return run_pf(
            problem,
            n_particles=self.n_particles,
            seed=seed,
            resampling=self.resampling,
            ess_threshold=self.ess_threshold,
            force_proposal=self.force_proposal,
            progress=progress,
        )


@register_method
@dataclass(frozen=True)
class Exact(Method):
    """The exact marginal posterior of (C, K) on an adaptive grid (the default method).

    Parameters
    ----------
    n_draws : int, default 4000
        Draws from the grid posterior that the result holds.
    """

    name: ClassVar[str] = "exact"
    colour: ClassVar[str | None] = "C2"
    n_draws: int = 4000

    def __post_init__(self) -> None:
        if isinstance(self.n_draws, bool) or int(self.n_draws) < 2:
            raise UsageError(f"Exact: n_draws must be at least 2, got {self.n_draws!r}")

    def run(
        self,
        problem: IdentificationProblem,
        *,
        seed: int = 0,
        progress: bool = False,
        common: dict[str, Any] | None = None,
    ) -> IdentificationResult:
        """Compute the grid posterior of a compiled problem (see :meth:`Method.run`)."""
        from workbench.inference.methods.exact import exact_posterior

        return exact_result(exact_posterior(problem), problem, int(self.n_draws), seed, common)


def exact_result(
    post: Any,
    problem: IdentificationProblem,
    n_draws: int,
    seed: int,
    common: dict[str, Any] | None = None,
) -> IdentificationResult:
    """Turn an :class:`~workbench.inference.methods.exact_results.ExactPosterior` into a result.

    ``n_draws`` draws from the grid posterior (seeded) stand for it in the result; the force
    coefficients are the grid mixture's.
    """
    draws = post.sample(int(n_draws), np.random.default_rng(seed))
    force = post.force
    if force is None:  # pragma: no cover - only with an injected likelihood and no force
        raise RuntimeError("the exact posterior returned no force coefficients")
    report = post.identifiability
    nodes = node_posterior_from_grid(
        post.nodes,
        post.weights,
        post.cell_edges,
        lambda c, k: node_load_factors(problem, force, c, k),
        post.prior,
        problem.mass_kg,
    )
    return IdentificationResult(
        method="exact",
        draws=draws,
        weights=np.full(draws.shape[0], 1.0 / draws.shape[0]),
        piece_coefficients_mean=force.mean,
        piece_coefficients_sd=force.sd,
        loglik=float(post.log_evidence),
        identifiability=report.to_json() if report is not None else {},
        grid_results=GridResults(post.to_json()),
        load_factors=force.load_factors,
        node_posterior=nodes,
        problem=problem,
        **(common or {}),
    )


def as_method(method: Method | str | None, **options: Any) -> Method:
    """Return a method object from an object, a name or None (the default, Exact).

    Parameters
    ----------
    method : Method, str or None
        A registered name (:func:`method_names`: ``"rbpf"``, ``"pf"``, ``"exact"``, ...) or
        a method object.
    **options
        Options for a method given by name (``n_particles=...``); None values and options the
        method does not have are ignored.

    Returns
    -------
    Method
    """
    opts = {k: v for k, v in options.items() if v is not None}
    if isinstance(method, Method):
        return method.replace(**opts) if opts else method
    name = DEFAULT_METHOD if method is None else method
    try:
        cls = _REGISTRY[name]
    except (KeyError, TypeError):
        raise UsageError(
            f"method {method!r} is not known; choose one of {', '.join(method_names())} or "
            f"pass a method object such as RBPF(n_particles={RBPF_PARTICLES})"
        ) from None
    known = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in opts.items() if k in known})
