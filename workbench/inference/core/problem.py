"""The identification problem: observations, force basis, pieces, noise and priors.

Every identification algorithm (seed-faithful particle filter, Rao-Blackwellised particle
filter, exact marginal posterior, emcee) takes an :class:`IdentificationProblem` and nothing
else, the way algorithms in the ``particles`` library take a model. The problem fixes:

- the observations ``y_k = (u_k, u'_k, u''_k)`` of seed eq. 21 on a uniform time grid;
- the Fourier basis row ``b_k`` of every sample, so that the biomechanical force is
  ``F_bio(t_k) = b_k @ theta`` with ``theta = (a0, a1, b1, ..., an, bn)`` (seed eq. 3 with
  ``i f_p``). The basis hides the time convention from the algorithms:

  * ``time_basis="step_phase"`` (the default): each piece has its own clock starting at its
    first sample and its own pacing ``1 / duration``, so harmonic ``i`` completes exactly
    ``i`` cycles per step and the coefficients of different steps are comparable (what
    criticism and population work need);
  * ``time_basis="absolute"``: the seed's ``cos(2 pi i f_p t)`` on the record's time axis with
    one global pacing frequency;

- the pieces: footfall steps, boundary to boundary (seed section 5.2, docs/science.md 2), or
  the whole record as one piece. At the start of each piece the force coefficients are
  drawn afresh from :class:`ForcePrior`; C, K, u and u' carry over;
- the noise model (:class:`NoiseModel`) and the prior box of (C, K)
  (:class:`StiffnessDampingPrior`).

The generative model given (C, K) is linear-Gaussian in ``(u, u', theta)``:

    x_{k+1} = Phi(C, K) x_k + Gamma(C, K) b_k theta / M + w_k,   w_k ~ N(0, diag(state_sd^2))
    y_k     = (u_k, u'_k, (-K u_k - C u'_k + b_k theta) / M) + v_k,  v_k ~ N(0, diag(obs_sd^2))
    theta   ~ N(force_prior.mean_n, diag(force_prior.sd_n^2)) afresh at each piece start
    (u, u') at the first sample ~ N(0, diag(initial_state_sd^2))

with ``x = (u, u')``; how ``Phi`` and ``Gamma`` are discretised is each algorithm's documented
choice (the seed's Euler ``I + A dt`` for ``method="pf"``).

On a moving surface (``surface`` set, docs/science.md 6) the spring and damper act on the
motion relative to the surface, ``M u'' + C (u' - z') + K (u - z) = F_bio``. In the
surface's frame, ``r = u - z``, that is the same model with the known inertial load
``-M z''`` added to the force, ``M r'' + C r' + K r = F_bio - M z''``: ``y`` then holds
``(r, r', r'')`` and every method adds :attr:`IdentificationProblem.surface_force_n` to
``b_k theta``. The load does not depend on (C, K), so the model stays linear-Gaussian given
(C, K); the deck enters the likelihood through the response it drives in ``r``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.models.conversions import damping_ns_per_m, stiffness_n_per_m
from workbench.models.force import DEFAULT_FORCE_HARMONICS, FourierForce
from workbench.records.preprocess import COMResponse
from workbench.records.record import G_M_S2
from workbench.records.steps import Steps
from workbench.records.surface import SurfaceMotion

__all__ = [
    "KALMAN_STATE_FRACTION",
    "OBSERVED_CHANNELS",
    "SEED_OBS_FRACTION",
    "SEED_STATE_FRACTION",
    "ForcePrior",
    "IdentificationProblem",
    "NoiseModel",
    "StiffnessDampingPrior",
    "build_problem",
]

FloatArray = NDArray[np.float64]
TimeBasis = Literal["step_phase", "absolute"]
PieceMode = Literal["steps", "whole"]

#: Seed section 5.2: observation noise 10 % of the RMS of u, u', u''.
SEED_OBS_FRACTION = 0.10
#: Seed section 5.2: process noise 0.5 % of the RMS of each response state, per time step.
SEED_STATE_FRACTION = 0.005
#: Process noise of (u, u') for the Kalman-based methods (rbpf, exact): none (u, u' integrate
#: the measured u''); the seed's 0.5 % only keeps the plain particle filter's particles alive.
KALMAN_STATE_FRACTION = 0.0
#: An unobserved channel keeps an observation sd this many times its RMS: its Kalman gain
#: and its share of the likelihood's (C, K) dependence are then below 1e-8, i.e. rounding.
UNOBSERVED_SD_FACTOR = 1e4
#: Channels of (u, u', u'') the likelihood uses (``observe=``): the seed's three, or the
#: measured u'' alone (u and u' carry integrated noise the i.i.d. model does not describe).
OBSERVED_CHANNELS = {"all": (True, True, True), "acc": (False, False, True)}

#: Seed section 5.2: random-walk std of C [N s/m] and K [N/m] per time step.
SEED_DAMPING_RW_SD = 5.0
SEED_STIFFNESS_RW_SD = 100.0

#: The modal prior box's natural frequency [Hz] and damping ratio ranges (``from_modal``).
MODAL_NATURAL_FREQUENCY_HZ: tuple[float, float] = (1.0, 4.0)
MODAL_DAMPING_RATIO: tuple[float, float] = (0.05, 0.9)


@dataclass(frozen=True)
class StiffnessDampingPrior:
    """Uniform prior box over damping C [N s/m] and stiffness K [N/m].

    Parameters
    ----------
    damping_ns_per_m : (float, float)
        Lower and upper bound of C.
    stiffness_n_per_m : (float, float)
        Lower and upper bound of K.
    label : str
        Where the box came from (shown in reports).
    """

    damping_ns_per_m: tuple[float, float]
    stiffness_n_per_m: tuple[float, float]
    label: str = "custom"

    def __post_init__(self) -> None:
        for name in ("damping_ns_per_m", "stiffness_n_per_m"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (np.isfinite(lo) and np.isfinite(hi) and 0 <= lo < hi):
                raise UsageError(
                    f"prior range of {name} must be two finite numbers 0 <= low < high, got "
                    f"({lo}, {hi})"
                )
            object.__setattr__(self, name, (lo, hi))

    @classmethod
    def seed(cls) -> StiffnessDampingPrior:
        """Return the seed study's initial ranges: C 400-1000 N s/m, K 12000-20000 N/m."""
        return cls((400.0, 1000.0), (12000.0, 20000.0), label="seed (400-1000 N s/m, 12-20 kN/m)")

    @classmethod
    def from_modal(
        cls,
        mass_kg: float,
        natural_frequency_hz: tuple[float, float] = MODAL_NATURAL_FREQUENCY_HZ,
        damping_ratio: tuple[float, float] = MODAL_DAMPING_RATIO,
    ) -> StiffnessDampingPrior:
        """Return the box spanned by natural frequency and damping ratio ranges at a mass.

        The default (1-4 Hz, damping ratio 0.05-0.9) contains every walking value of the seed's
        Table 2 and population laws with a wide margin, and scales with the mass, unlike the
        seed's fixed box (which excludes its own 58 kg individual, K = 8940 N/m).
        """
        k_lo = float(stiffness_n_per_m(natural_frequency_hz[0], mass_kg))
        k_hi = float(stiffness_n_per_m(natural_frequency_hz[1], mass_kg))
        c_lo = float(damping_ns_per_m(damping_ratio[0], k_lo, mass_kg))
        c_hi = float(damping_ns_per_m(damping_ratio[1], k_hi, mass_kg))
        label = (
            f"f_n {natural_frequency_hz[0]:g}-{natural_frequency_hz[1]:g} Hz, damping ratio "
            f"{damping_ratio[0]:g}-{damping_ratio[1]:g} at {mass_kg:g} kg"
        )
        return cls((c_lo, c_hi), (k_lo, k_hi), label=label)

    @property
    def mean(self) -> FloatArray:
        """Prior mean of (C, K)."""
        return np.array([np.mean(self.damping_ns_per_m), np.mean(self.stiffness_n_per_m)])

    @property
    def sd(self) -> FloatArray:
        """Prior standard deviation of (C, K) (uniform: width / sqrt(12))."""
        widths = np.array([np.diff(self.damping_ns_per_m)[0], np.diff(self.stiffness_n_per_m)[0]])
        return widths / np.sqrt(12.0)

    def contains(self, damping: Any, stiffness: Any) -> NDArray[np.bool_]:
        """Whether (C, K) lie inside the box (element-wise)."""
        c, k = np.asarray(damping), np.asarray(stiffness)
        (c_lo, c_hi), (k_lo, k_hi) = self.damping_ns_per_m, self.stiffness_n_per_m
        return (c >= c_lo) & (c <= c_hi) & (k >= k_lo) & (k <= k_hi)

    def sample(self, n: int, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
        """Draw ``n`` (C, K) pairs uniformly from the box."""
        c = rng.uniform(*self.damping_ns_per_m, size=n)
        k = rng.uniform(*self.stiffness_n_per_m, size=n)
        return c, k


@dataclass(frozen=True)
class ForcePrior:
    """Gaussian prior of the force coefficients, drawn afresh at the start of every piece.

    Parameters
    ----------
    mean_n : ndarray, shape (2 n + 1,)
        Prior mean of ``(a0, a1, b1, ..., an, bn)`` [N].
    sd_n : ndarray, shape (2 n + 1,)
        Prior standard deviations [N].
    """

    mean_n: FloatArray
    sd_n: FloatArray

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean_n, dtype=np.float64)
        sd = np.asarray(self.sd_n, dtype=np.float64)
        # Odd length 2 n + 1 for a Fourier force; effect columns may follow (effect_terms).
        if mean.shape != sd.shape or mean.ndim != 1 or mean.size < 1:
            raise UsageError("ForcePrior needs mean_n and sd_n of equal length 2 n + 1 (+ effects)")
        if not (np.all(np.isfinite(sd)) and np.all(sd > 0)):
            raise UsageError("ForcePrior standard deviations must be positive and finite")
        object.__setattr__(self, "mean_n", mean)
        object.__setattr__(self, "sd_n", sd)

    @classmethod
    def default(cls, mass_kg: float, harmonics: int) -> ForcePrior:
        """Zero mean; sd 0.1 M g for a0 and 0.5 M g / i for the cosine and sine of harmonic i.

        Wide enough for any walking force (BLF1 rarely exceeds 0.5, higher BLFs fall off),
        yet proper, so that a step whose data cannot fix a coefficient falls back to a
        finite prior instead of an unbounded one.
        """
        weight = mass_kg * G_M_S2
        sd = [0.1 * weight]
        for i in range(1, harmonics + 1):
            sd += [0.5 * weight / i] * 2
        return cls(np.zeros(2 * harmonics + 1), np.asarray(sd))


@dataclass(frozen=True)
class NoiseModel:
    """Observation and process noise of the state-space model (absolute standard deviations).

    Parameters
    ----------
    obs_sd : ndarray, shape (3,)
        Observation noise std of u [m], u' [m/s], u'' [m/s^2].
    state_sd : ndarray, shape (2,)
        Process noise std of u [m] and u' [m/s] per time step.
    initial_state_sd : ndarray, shape (2,)
        Prior std of u and u' at the first sample.
    damping_rw_sd_ns_per_m, stiffness_rw_sd_n_per_m : float
        Random-walk std of C and K per time step (artificial dynamics that keep static
        parameters from freezing in particle filters; the exact method ignores them).
    obs_fraction : float or None
        When the observation noise is a fraction of the RMS of (u, u', u''), that fraction.
    source : str
        ``"seed"`` (the seed's 10 %), ``"fixed"`` (a user fraction), ``"auto"`` (estimated
        from the record), or ``"custom"``.
    """

    obs_sd: FloatArray
    state_sd: FloatArray
    initial_state_sd: FloatArray
    damping_rw_sd_ns_per_m: float = SEED_DAMPING_RW_SD
    stiffness_rw_sd_n_per_m: float = SEED_STIFFNESS_RW_SD
    obs_fraction: float | None = None
    source: str = "custom"

    def __post_init__(self) -> None:
        for name, size in (("obs_sd", 3), ("state_sd", 2), ("initial_state_sd", 2)):
            arr = np.asarray(getattr(self, name), dtype=np.float64)
            if arr.shape != (size,) or not np.all(np.isfinite(arr)) or np.any(arr < 0):
                raise UsageError(f"NoiseModel.{name} must be {size} finite non-negative numbers")
            object.__setattr__(self, name, arr)
        if np.any(self.obs_sd <= 0):
            raise UsageError(
                "NoiseModel.obs_sd must be positive (a zero observation noise "
                "makes the likelihood singular)"
            )


@dataclass(frozen=True, eq=False)
class IdentificationProblem:
    """Everything an identification algorithm needs; see the module docstring for the model.

    Attributes
    ----------
    mass_kg : float
        Body mass M [kg] (known, not identified).
    dt_s : float
        Sample interval [s].
    time_s : ndarray, shape (N,)
        Sample times [s] on the record's axis.
    y : ndarray, shape (N, 3)
        Observations (u [m], u' [m/s], u'' [m/s^2]).
    basis : ndarray, shape (N, 2 n + 1)
        Fourier basis row of every sample: ``F_bio(t_k) = basis[k] @ theta``.
    piece_starts : ndarray of int, shape (P + 1,)
        Piece ``j`` is samples ``piece_starts[j]:piece_starts[j + 1]`` (indices into ``y``);
        ``piece_starts[0] == 0`` and ``piece_starts[-1] == N``.
    harmonics : int
        Number of harmonics n.
    pacing_hz : float
        Global pacing frequency [Hz].
    piece_pacing_hz : ndarray, shape (P,)
        Pacing of each piece (``1 / duration`` in step-phase mode, else the global value).
    time_basis : {"step_phase", "absolute"}
        Basis time convention.
    noise : NoiseModel
        Noise settings.
    prior : StiffnessDampingPrior
        Prior box of (C, K).
    force_prior : ForcePrior
        Prior of the force coefficients of each piece.
    source : str
        Record the problem was built from.
    rms : ndarray, shape (3,)
        RMS of u, u', u'' over the identified samples (noise fractions refer to these).
    observe : {"all", "acc"}
        Channels the likelihood uses (:data:`OBSERVED_CHANNELS`); an unobserved channel's
        noise sd is :data:`UNOBSERVED_SD_FACTOR` times its RMS.
    effect_names : tuple of str
        Names of effect columns that follow the ``2 n + 1`` Fourier columns of ``basis``
        (:mod:`workbench.inference.pipeline.effect_terms`); empty without effects.
    surface : SurfaceMotion or None
        The walking surface's motion on the problem's samples when it acts through K and C
        (``y`` is then relative to it, module docstring); None on a rigid floor.
    """

    mass_kg: float
    dt_s: float
    time_s: FloatArray
    y: FloatArray
    basis: FloatArray
    piece_starts: NDArray[np.int64]
    harmonics: int
    pacing_hz: float
    piece_pacing_hz: FloatArray
    time_basis: str
    noise: NoiseModel
    prior: StiffnessDampingPrior
    force_prior: ForcePrior
    source: str = "<memory>"
    rms: FloatArray = dataclasses.field(default_factory=lambda: np.ones(3))
    observe: str = "all"
    effect_names: tuple[str, ...] = ()
    surface: SurfaceMotion | None = None

    @property
    def surface_force_n(self) -> FloatArray | None:
        """Known load ``-M z''`` of the surface's motion in its own frame [N]; None if rigid."""
        if self.surface is None:
            return None
        return np.asarray(-self.mass_kg * self.surface.acc_m_s2, dtype=np.float64)

    @property
    def absolute_y(self) -> FloatArray:
        """Observations in the fixed frame: ``(u, u', u'')`` (``y`` plus the surface's motion)."""
        if self.surface is None:
            return self.y
        s = self.surface
        return self.y + np.column_stack([s.disp_m, s.vel_m_s, s.acc_m_s2])

    def obs_sd_for(self, fraction: float) -> FloatArray:
        """Observation sd of (u, u', u'') for a noise fraction of the observed channels' RMS.

        An unobserved channel gets :data:`UNOBSERVED_SD_FACTOR` times its RMS whatever the
        fraction: a sd that scaled with the fraction would add ``-log(fraction)`` per sample
        to the likelihood and bias the ``auto`` estimate (by 1/sqrt(3) with u'' alone).
        """
        observed = np.asarray(OBSERVED_CHANNELS[self.observe])
        rms = np.asarray(self.rms, dtype=np.float64)
        return np.where(observed, float(fraction) * rms, UNOBSERVED_SD_FACTOR * rms)

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.y.shape[0])

    @property
    def n_pieces(self) -> int:
        """Number of pieces P."""
        return int(self.piece_starts.size - 1)

    @property
    def n_coefficients(self) -> int:
        """Number of force coefficients 2 n + 1."""
        return int(self.basis.shape[1])

    @property
    def coefficient_names(self) -> tuple[str, ...]:
        """``("a0", "a1", "b1", ...)``, then the effect columns' names."""
        return FourierForce(self.harmonics).coefficient_names + tuple(self.effect_names)

    @property
    def piece_index(self) -> NDArray[np.int64]:
        """Piece number of every sample."""
        return np.repeat(np.arange(self.n_pieces), np.diff(self.piece_starts))

    @property
    def piece_start_mask(self) -> NDArray[np.bool_]:
        """True at the first sample of every piece (where theta is drawn afresh)."""
        mask = np.zeros(self.n_samples, dtype=bool)
        mask[self.piece_starts[:-1]] = True
        return mask

    def with_noise(self, noise: NoiseModel) -> IdentificationProblem:
        """Return a copy with another noise model."""
        return dataclasses.replace(self, noise=noise)

    def with_prior(self, prior: StiffnessDampingPrior) -> IdentificationProblem:
        """Return a copy with another (C, K) prior box."""
        return dataclasses.replace(self, prior=prior)

    def noise_from_fractions(
        self,
        obs_fraction: float,
        *,
        state_fraction: float = SEED_STATE_FRACTION,
        source: str = "fixed",
    ) -> NoiseModel:
        """Return noise with std as fractions of the RMS of (u, u', u'') (seed section 5.2)."""
        if not (np.isfinite(obs_fraction) and obs_fraction > 0):
            raise UsageError(
                f"the observation noise fraction must be a positive number, got {obs_fraction!r}"
            )
        return NoiseModel(
            obs_sd=self.obs_sd_for(obs_fraction),
            state_sd=state_fraction * self.rms[:2],
            initial_state_sd=2.0 * self.rms[:2],
            damping_rw_sd_ns_per_m=self.noise.damping_rw_sd_ns_per_m,
            stiffness_rw_sd_n_per_m=self.noise.stiffness_rw_sd_n_per_m,
            obs_fraction=float(obs_fraction),
            source=source,
        )


def build_problem(
    com: COMResponse,
    steps: Steps | None = None,
    *,
    harmonics: int = DEFAULT_FORCE_HARMONICS,
    pacing_hz: float | None = None,
    time_basis: TimeBasis = "step_phase",
    pieces: PieceMode = "steps",
    obs_fraction: float = SEED_OBS_FRACTION,
    state_fraction: float = SEED_STATE_FRACTION,
    prior: StiffnessDampingPrior | None = None,
    force_prior: ForcePrior | None = None,
    observe: str = "all",
    surface: SurfaceMotion | None = None,
) -> IdentificationProblem:
    """Build the identification problem of a preprocessed record.

    Parameters
    ----------
    com : COMResponse
        Preprocessed record (u, u', u'').
    steps : Steps or None
        Footfall steps; required for ``pieces="steps"``. Only the samples from the first to
        the last step boundary are used (partial steps at the ends are dropped).
    harmonics : int, default 10
        Number of harmonics n (the seed's numerical example uses 10).
    pacing_hz : float, optional
        Global pacing frequency; default the steps' pacing (:attr:`Steps.pacing_hz
        <workbench.records.steps.Steps.pacing_hz>`, the one every command reports) for
        ``pieces="steps"``. Required for ``pieces="whole"``.
    time_basis : {"step_phase", "absolute"}
        Basis time convention (module docstring). With ``pieces="whole"`` the step phase is
        the global pacing's phase from the first sample.
    pieces : {"steps", "whole"}
        Footfall steps (seed section 5.2) or one piece (the seed's numerical example).
    obs_fraction : float, default 0.10
        Observation noise as a fraction of the RMS of u, u', u'' (the seed's 10 %); the
        ``auto`` estimate replaces it later (:mod:`workbench.inference.pipeline.noise`).
    state_fraction : float, default 0.005
        Process noise of u, u' per time step as a fraction of their RMS (seed: 0.5 %).
    prior : StiffnessDampingPrior, optional
        Default: :meth:`StiffnessDampingPrior.from_modal` for the body mass.
    force_prior : ForcePrior, optional
        Default: :meth:`ForcePrior.default`.
    observe : {"all", "acc"}, default "all"
        Observe u, u', u'' (the seed) or only u'' (:data:`OBSERVED_CHANNELS`).
    surface : SurfaceMotion, optional
        The walking surface's motion on ``com``'s time base: the spring and damper then act
        on the motion relative to it (module docstring). None: a rigid floor.

    Returns
    -------
    IdentificationProblem
    """
    if observe not in OBSERVED_CHANNELS:
        raise UsageError(f"observe must be 'all' or 'acc', got {observe!r}")
    if int(harmonics) < 1:
        raise UsageError(
            f"'harmonics' must be a whole number of at least 1, got {harmonics!r}",
            parameter="harmonics",
        )
    harmonics = int(harmonics)
    if time_basis not in ("step_phase", "absolute"):
        raise UsageError(f"time basis must be 'step_phase' or 'absolute', got {time_basis!r}")
    t = np.asarray(com.time_s)
    if pieces == "steps":
        if steps is None:
            raise UsageError("pieces='steps' needs the record's footfall steps")
        bounds = np.asarray(steps.boundaries, dtype=np.int64)
        first, last = int(bounds[0]), int(bounds[-1])
        starts = bounds - first
        durations = np.diff(t[bounds])
        if pacing_hz is None:
            pacing_hz = steps.pacing_hz
    elif pieces == "whole":
        if pacing_hz is None:
            raise UsageError("pieces='whole' needs a pacing frequency (--pacing HZ)")
        first, last = 0, t.size
        starts = np.array([0, t.size], dtype=np.int64)
        durations = np.array([t[-1] - t[0] + com.dt_s])
    else:
        raise UsageError(f"pieces must be 'steps' or 'whole', got {pieces!r}")
    if not (pacing_hz is not None and np.isfinite(pacing_hz) and pacing_hz > 0):
        raise UsageError(f"the pacing frequency must be a positive number of Hz, got {pacing_hz!r}")
    pacing_hz = float(pacing_hz)
    sl = slice(first, last)
    time_s = t[sl]
    y = np.column_stack([com.disp_m[sl], com.vel_m_s[sl], com.acc_m_s2[sl]])
    n = time_s.size
    # The noise fractions refer to the measured (absolute) response, whatever the frame.
    rms = np.sqrt(np.mean(np.square(y), axis=0))
    if surface is not None:
        if surface.time_s.shape != t.shape:
            raise UsageError(
                f"{com.source}: the surface motion has {surface.time_s.size} samples but the "
                f"record has {t.size}; give the surface acceleration on the record's time base"
            )
        surface = surface.window(first, last)
        y = y - np.column_stack([surface.disp_m, surface.vel_m_s, surface.acc_m_s2])
    piece_of = np.repeat(np.arange(starts.size - 1), np.diff(starts))
    force = FourierForce(harmonics)
    if time_basis == "absolute":
        piece_pacing = np.full(starts.size - 1, pacing_hz)
        basis = force.basis(time_s, pacing_hz)
    else:
        piece_pacing = 1.0 / durations if pieces == "steps" else np.full(starts.size - 1, pacing_hz)
        local_t = time_s - time_s[starts[:-1]][piece_of]
        phase = 2.0 * np.pi * piece_pacing[piece_of] * local_t
        basis = force.basis(time_s, pacing_hz, phase_rad=phase)
    if np.any(rms <= 0) or n < 3:
        raise UsageError(f"{com.source}: the COM response is zero; there is nothing to identify")
    problem = IdentificationProblem(
        mass_kg=float(com.mass_kg),
        dt_s=float(com.dt_s),
        time_s=time_s,
        y=y,
        basis=np.ascontiguousarray(basis, dtype=np.float64),
        piece_starts=starts.astype(np.int64),
        harmonics=harmonics,
        pacing_hz=pacing_hz,
        piece_pacing_hz=np.asarray(piece_pacing, dtype=np.float64),
        time_basis=time_basis,
        noise=NoiseModel(np.ones(3), np.zeros(2), np.ones(2)),
        prior=prior or StiffnessDampingPrior.from_modal(float(com.mass_kg)),
        force_prior=force_prior or ForcePrior.default(float(com.mass_kg), harmonics),
        source=com.source,
        rms=rms,
        observe=observe,
        surface=surface,
    )
    source = "seed" if obs_fraction == SEED_OBS_FRACTION else "fixed"
    return problem.with_noise(
        problem.noise_from_fractions(obs_fraction, state_fraction=state_fraction, source=source)
    )


def seed_example_problem(
    *,
    duration_s: float = 10.0,
    obs_fraction: float = 0.01,
    state_fraction: float = KALMAN_STATE_FRACTION,
    prior: StiffnessDampingPrior | None = None,
) -> tuple[IdentificationProblem, dict[str, Any]]:
    """Return the seed's numerical example (section 4) as a problem, with its truth.

    75 kg, f_n 2.5 Hz, damping ratio 0.4, the force of seed eq. 24 on a 0.5 Hz basis with
    n = 10, 1 kHz from rest, no high-pass (the record starts at rest), one piece.

    Parameters
    ----------
    duration_s : float, default 10
        Record length [s].
    obs_fraction : float, default 0.01
        Observation noise as a fraction of the RMS of u, u', u'' (the data are noise-free).
    state_fraction : float, default 0
        Process noise of (u, u') per sample as a fraction of their RMS (the Kalman-based
        methods' default; pass :data:`SEED_STATE_FRACTION` for the seed-faithful filter).
    prior : StiffnessDampingPrior, optional
        Default: the box from natural frequency and damping ratio at 75 kg.

    Returns
    -------
    (IdentificationProblem, dict)
        The problem and the simulator's truth.
    """
    from workbench.records.preprocess import preprocess
    from workbench.synth.simulate import seed_numerical_example

    sim = seed_numerical_example(duration_s=duration_s)
    com = preprocess(sim.record, highpass_hz=0)
    problem = build_problem(
        com,
        None,
        pieces="whole",
        pacing_hz=0.5,
        time_basis="absolute",
        harmonics=10,
        obs_fraction=obs_fraction,
        state_fraction=state_fraction,
        prior=prior,
    )
    return problem, sim.truth
