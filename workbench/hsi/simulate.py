"""Pedestrians walking on a modal structure: coupled (HSI) and moving-force responses.

Equations (deck displacements ``q_j`` upwards, pedestrian COM ``y_p`` upwards from its static
position, ``phi_jp(t)`` mode ``j`` at the position of pedestrian ``p``, ``w_p = sum_j
phi_jp q_j`` the deck under the walker)::

    M_p y_p'' + C_p (y_p' - w_p') + K_p (y_p - w_p) = F_p(t)
    m_j q_j'' + c_j q_j' + k_j q_j = - sum_p phi_jp (M_p y_p'' [+ M_p g])

so the SMD base moves with the deck and the deck carries the ground reaction force. On rigid
ground (``phi = 0``, off the deck) the first line is the seed's SMD model. ``w_p'`` is taken
as ``sum_j phi_jp q_j'``: for the first beam mode the convective part ``phi' v q`` is
smaller by ``v / (2 f L)`` (0.6 % for 1.25 m/s on a 50 m, 2 Hz span) and leaving it out
keeps the coupled matrices symmetric, so the system the integrator advances is exactly the
one :mod:`workbench.hsi.modes` analyses.

The moving-force model of the same pedestrians loads the deck with the force each of them
exerts on rigid ground (``M_p y_p''`` of the rigid-ground SMD), or, for comparisons with
published load models, with the biomechanical force ``F_p`` itself.

Time integration: Newmark's average-acceleration rule (trapezoidal, ``gamma = 1/2``, ``beta
= 1/4``) on the coupled second-order system, with the mode shapes evaluated at the end of
each step. For a linear system with constant symmetric positive (semi-)definite mass,
damping and stiffness it is unconditionally stable (its discrete energy never grows) and
adds no numerical damping, so the stiff pedestrian DOFs (several Hz, 30 % damping) and
higher bridge modes cannot blow up whatever the step; here the matrices change only as fast
as the walkers move (a mode shape changes over metres, a step covers millimetres), so each
step is that stable scheme on an almost frozen system. It is second-order accurate, with a
relative period error of ``(w h)^2 / 12`` (4e-4 for a 2.2 Hz mode at h = 0.005 s); the tests
show second-order convergence to scipy's ``solve_ivp`` on a crossing. Each step solves the
coupled system exactly: the pedestrian unknowns are eliminated (each couples only to the
modes), leaving one ``J x J`` solve per scenario, so the cost grows linearly with the number
of pedestrians. Scenarios are integrated side by side (vectorised), which is what makes
Monte Carlo runs fast.

Per-walker histories (``keep_walkers=True``, :class:`WalkerHistory`) store what the step
solved for, not differences of it: the end-of-step ``y_p, y_p', y_p''``, the modal ``q, q',
q''`` and the deck under each walker ``w_p, w_p', w_p''`` with ``phi_jp`` at the walker's
end-of-step position. The Newmark update makes the end-of-step state satisfy the equation
of motion exactly, so ``M_p y_p'' = F_p - C_p (y_p' - w_p') - K_p (y_p - w_p)`` holds at
every stored sample to rounding; these are what :mod:`workbench.hsi.records` turns into the
records a sensor on the walker would give.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

from workbench.errors import UsageError
from workbench.hsi.pedestrians import (
    HARMONICS,
    G,
    Pedestrians,
    pedestrian_arrays,
)
from workbench.hsi.structure import ModalStructure

__all__ = [
    "CrowdBatch",
    "HsiHistory",
    "Model",
    "WalkerHistory",
    "integrate",
    "simulate_pedestrians",
]

Model = Literal["interaction", "moving_force", "biomechanical_force"]
MODELS: tuple[Model, ...] = ("interaction", "moving_force", "biomechanical_force")
#: Largest number of time steps times scenarios times pedestrians one call integrates.
MAX_WORK = 2_000_000_000
#: Largest number of floats the per-walker histories of one call may hold (2 GB).
MAX_KEPT_VALUES = 250_000_000


@dataclass(frozen=True)
class CrowdBatch:
    """Scenarios side by side: ``B`` scenarios of up to ``P`` pedestrians (padded).

    Positions are ``x0_m + speed_m_s t``; a padded slot has ``active`` False and stays off
    the deck. Arrays are ``(B, P)``; force terms ``(B, P, H)``. The pedestrians' force is
    ``a0_n + G M sum_i blf_i cos(2 pi i f_p t + phase_i)``, their models' biomechanical
    force (:class:`~workbench.hsi.pedestrians.PedestrianArrays`).
    """

    mass_kg: NDArray[np.float64]
    stiffness_n_per_m: NDArray[np.float64]
    damping_ns_per_m: NDArray[np.float64]
    pacing_hz: NDArray[np.float64]
    blf: NDArray[np.float64]
    phase_rad: NDArray[np.float64]
    x0_m: NDArray[np.float64]
    speed_m_s: NDArray[np.float64]
    active: NDArray[np.bool_]
    a0_n: NDArray[np.float64]

    @classmethod
    def from_scenarios(
        cls, scenarios: Sequence[tuple[Pedestrians, ArrayLike, ArrayLike]]
    ) -> CrowdBatch:
        """Stack ``(pedestrians, x0_m, speed_m_s)`` scenarios, padding to the largest crowd.

        Parameters
        ----------
        scenarios : sequence of (pedestrians, x0_m, speed_m_s)
            The pedestrians of each scenario (a table, walkers, models or their arrays, see
            :func:`pedestrian_arrays`), where each is at ``t = 0`` and how fast it moves
            (this speed, not the walker's own, moves it: 0 for someone standing).

        Returns
        -------
        CrowdBatch
        """
        arrays = [
            pedestrian_arrays(peds, np.asarray(vs, float))
            if not isinstance(peds, pd.DataFrame) or len(peds)
            else None
            for peds, _, vs in scenarios
        ]
        b = len(scenarios)
        p = max(1, max((a.mass_kg.size for a in arrays if a is not None), default=0))
        h = max((a.blf.shape[1] for a in arrays if a is not None), default=HARMONICS)
        mass = np.ones((b, p))
        k = np.ones((b, p))
        c = np.ones((b, p))
        fp = np.ones((b, p))
        blf = np.zeros((b, p, h))
        ph = np.zeros((b, p, h))
        x0 = np.full((b, p), -1.0)
        v = np.zeros((b, p))
        act = np.zeros((b, p), bool)
        a0 = np.zeros((b, p))
        for i, (a, (_, xs, vs)) in enumerate(zip(arrays, scenarios, strict=True)):
            n = 0 if a is None else a.mass_kg.size
            if a is None or n == 0:
                continue
            hh = a.blf.shape[1]
            mass[i, :n], k[i, :n], c[i, :n] = a.mass_kg, a.stiffness_n_per_m, a.damping_ns_per_m
            fp[i, :n], blf[i, :n, :hh], ph[i, :n, :hh] = a.pacing_hz, a.blf, a.phase_rad
            x0[i, :n], v[i, :n], act[i, :n], a0[i, :n] = xs, vs, True, a.a0_n
        return cls(mass, k, c, fp, blf, ph, x0, v, act, a0)

    def positions(self, t: float | NDArray[np.float64]) -> NDArray[np.float64]:
        """Positions at time ``t`` (``-1`` for padded slots, which is off the deck)."""
        return np.where(self.active, self.x0_m + self.speed_m_s * t, -1.0)

    def force(self, t: float) -> NDArray[np.float64]:
        """Biomechanical forces ``F_p(t)`` [N], ``(B, P)``."""
        i = np.arange(1, self.blf.shape[-1] + 1)
        arg = 2 * np.pi * i * self.pacing_hz[..., None] * t + self.phase_rad
        dynamic = G * self.mass_kg * np.sum(self.blf * np.cos(arg), axis=-1)
        return np.asarray(dynamic + self.a0_n)

    def steady_state(self, t: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """COM displacement and velocity of each SMD walking steadily on rigid ground.

        A constant force ``a0_n`` only moves the static equilibrium, by ``a0_n / K``.
        """
        i = np.arange(1, self.blf.shape[-1] + 1)
        w = 2 * np.pi * i * self.pacing_hz[..., None]
        m, k, c = (
            a[..., None] for a in (self.mass_kg, self.stiffness_n_per_m, self.damping_ns_per_m)
        )
        amp = G * m * self.blf * np.exp(1j * (w * t + self.phase_rad)) / (k - m * w**2 + 1j * c * w)
        offset = self.a0_n / self.stiffness_n_per_m
        return np.sum(amp.real, axis=-1) + offset, np.sum((1j * w * amp).real, axis=-1)


@dataclass(frozen=True, eq=False)
class WalkerHistory:
    """What every walker and the modes did at every step (``integrate(keep_walkers=True)``).

    All values are the end-of-step quantities of the Newmark step (module docstring), so
    ``mass_kg * acc_m_s2 = F - C (vel_m_s - base_vel_m_s) - K (disp_m - base_disp_m)`` at
    every sample to rounding (with the biomechanical force ``batch.force(t)``); the base
    motion is that of the walker's equation: the deck under the walker with interaction,
    zero for the force-only models (their walkers walk on rigid ground).

    Attributes
    ----------
    batch : CrowdBatch
        The scenarios' pedestrians (who they are, where they start, how fast they walk).
    structure : ModalStructure
        The modes they walked on.
    static_weight : bool
        Whether the walkers' weight loaded the deck.
    disp_m, vel_m_s, acc_m_s2 : array (B, P, N)
        Walker COM ``y_p, y_p', y_p''`` (upwards from the static position; absolute).
    base_disp_m, base_vel_m_s, base_acc_m_s2 : array (B, P, N)
        ``w_p = sum_j phi_j(x_p(t)) q_j`` and its rates (zero off the deck).
    modal_disp_m, modal_vel_m_s, modal_acc_m_s2 : array (B, J, N)
        Modal coordinates ``q_j, q_j', q_j''``.
    """

    batch: CrowdBatch
    structure: ModalStructure
    static_weight: bool
    disp_m: NDArray[np.float64]
    vel_m_s: NDArray[np.float64]
    acc_m_s2: NDArray[np.float64]
    base_disp_m: NDArray[np.float64]
    base_vel_m_s: NDArray[np.float64]
    base_acc_m_s2: NDArray[np.float64]
    modal_disp_m: NDArray[np.float64]
    modal_vel_m_s: NDArray[np.float64]
    modal_acc_m_s2: NDArray[np.float64]

    def positions_m(self, time_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """Walker positions ``(B, P, N)`` [m] at ``time_s`` (``-1``, off the deck, for padding).

        The same arithmetic as the integrator's (:meth:`CrowdBatch.positions`), so the mode
        shapes evaluated here are the ones each step used.
        """
        t = np.asarray(time_s, float)
        x = self.batch.x0_m[..., None] + self.batch.speed_m_s[..., None] * t
        return np.where(self.batch.active[..., None], x, -1.0)


@dataclass(frozen=True)
class HsiHistory:
    """Deck acceleration histories of a batch of scenarios.

    Attributes
    ----------
    time_s : array (N,)
    acceleration_m_s2 : array (B, R, N)
        Deck acceleration at each response point.
    response_x_m : array (R,)
    model : str
    dt_s : float
    walkers : WalkerHistory or None
        Per-walker and modal histories, when integrated with ``keep_walkers=True``.
    """

    time_s: NDArray[np.float64]
    acceleration_m_s2: NDArray[np.float64]
    response_x_m: NDArray[np.float64]
    model: str
    dt_s: float
    walkers: WalkerHistory | None = None


def integrate(
    structure: ModalStructure,
    batch: CrowdBatch,
    *,
    duration_s: float,
    dt_s: float = 0.005,
    model: Model = "interaction",
    response_x_m: ArrayLike | None = None,
    static_weight: bool = False,
    keep_walkers: bool = False,
) -> HsiHistory:
    """Integrate a batch of scenarios from a deck at rest, walkers in steady state.

    Parameters
    ----------
    structure : ModalStructure
        The modes.
    batch : CrowdBatch
        The pedestrians of every scenario.
    duration_s : float
        Simulated time [s].
    dt_s : float
        Time step [s].
    model : {"interaction", "moving_force", "biomechanical_force"}
        Coupled SMDs; the rigid-ground force of the same SMDs as moving loads; or their
        biomechanical force as moving loads.
    response_x_m : array, optional
        Where the deck acceleration is recorded (default midspan).
    static_weight : bool
        Add the walkers' weight ``M g`` as a moving load (it only adds a slow, quasi-static
        deflection; off by default, as in the usual load models).
    keep_walkers : bool
        Also keep every walker's and every mode's history (:class:`WalkerHistory`; off by
        default: ``6 P + 3 J`` floats per scenario and step).

    Returns
    -------
    HsiHistory
        Acceleration histories at the response points (and ``walkers`` if kept).
    """
    if model not in MODELS:
        raise UsageError(f"unknown model {model!r}; use one of {', '.join(MODELS)}")
    if not (np.isfinite(dt_s) and dt_s > 0) or not (np.isfinite(duration_s) and duration_s > 0):
        raise UsageError("the time step and the duration must be positive numbers of seconds")
    n = int(np.ceil(duration_s / dt_s - 1e-9))
    b, p = batch.mass_kg.shape
    if n * b * max(p, structure.n_modes) > MAX_WORK:
        raise UsageError(
            f"{n} steps of {b} scenario(s) with {p} pedestrians is too much work; shorten the "
            "duration, lengthen the time step or split the Monte Carlo"
        )
    if keep_walkers and (n + 1) * b * (6 * p + 3 * structure.n_modes) > MAX_KEPT_VALUES:
        raise UsageError(
            f"keeping the histories of {b} scenario(s) with {p} pedestrians over {n} steps "
            "needs more than 2 GB; keep the walkers of fewer scenarios at a time or shorten "
            "the duration"
        )
    xr = np.atleast_1d(
        np.asarray(structure.span_m / 2 if response_x_m is None else response_x_m, float)
    )
    phi_r = structure.shapes(xr)  # (R, J)
    m_j = structure.modal_masses_kg
    c_j = structure.dampings_ns_per_m
    k_j = structure.stiffnesses_n_per_m
    mp, cp, kp = batch.mass_kg, batch.damping_ns_per_m, batch.stiffness_n_per_m
    weight = G * mp * batch.active if static_weight else np.zeros_like(mp)
    coupled = model == "interaction"
    n_j = structure.n_modes

    def accelerations(
        h: float,
        t: float,
        xq: NDArray[np.float64],
        vq: NDArray[np.float64],
        xy: NDArray[np.float64],
        vy: NDArray[np.float64],
    ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        # Solves (M + h/2 C + h^2/4 K) a = f(t) - C v - K x for the end-of-step
        # accelerations, given the Newmark predictors x, v (h = 0: the equation of motion);
        # also returns the mode shapes under the walkers it used.
        phi = structure.shapes(batch.positions(t))  # (B, P, J)
        force = batch.force(t)
        e = 0.5 * h * cp + 0.25 * h * h * kp
        d = mp + e
        s_q = 0.5 * h * c_j + 0.25 * h * h * k_j + m_j
        base_q = -(c_j * vq + k_j * xq)
        if coupled:
            rel_x = xy - np.einsum("bpj,bj->bp", phi, xq)
            rel_v = vy - np.einsum("bpj,bj->bp", phi, vq)
            g_p = force - cp * rel_v - kp * rel_x
            g_q = base_q - np.einsum("bpj,bp->bj", phi, g_p + weight)
            wgt = e * mp / d
            rhs = g_q + np.einsum("bpj,bp->bj", phi, e * g_p / d)
            if n_j == 1:
                red = s_q[0] + np.sum(wgt * phi[..., 0] ** 2, axis=1)
                a_q = rhs / red[:, None]
            else:
                red = np.einsum("bpj,bpk,bp->bjk", phi, phi, wgt)
                red[:, np.arange(n_j), np.arange(n_j)] += s_q
                a_q = np.linalg.solve(red, rhs[..., None])[..., 0]
            a_y = (g_p + e * np.einsum("bpj,bj->bp", phi, a_q)) / d
        else:
            g_p = force - cp * vy - kp * xy
            a_y = g_p / d
            load = mp * a_y if model == "moving_force" else force
            a_q = (base_q - np.einsum("bpj,bp->bj", phi, load + weight)) / s_q
        return a_q, a_y, phi

    xq = np.zeros((b, n_j))
    vq = np.zeros((b, n_j))
    xy, vy = batch.steady_state(0.0)
    aq, ay, phi = accelerations(0.0, 0.0, xq, vq, xy, vy)
    acc = np.empty((b, xr.size, n + 1))
    acc[:, :, 0] = aq @ phi_r.T
    kept = _Kept(b, p, n_j, n + 1, coupled) if keep_walkers else None
    if kept is not None:
        kept.store(0, phi, xq, vq, aq, xy, vy, ay)
    h = float(dt_s)
    for step in range(1, n + 1):
        t = step * h
        pxq = xq + h * vq + 0.25 * h * h * aq
        pvq = vq + 0.5 * h * aq
        pxy = xy + h * vy + 0.25 * h * h * ay
        pvy = vy + 0.5 * h * ay
        aq, ay, phi = accelerations(h, t, pxq, pvq, pxy, pvy)
        xq = pxq + 0.25 * h * h * aq
        vq = pvq + 0.5 * h * aq
        xy = pxy + 0.25 * h * h * ay
        vy = pvy + 0.5 * h * ay
        acc[:, :, step] = aq @ phi_r.T
        if kept is not None:
            kept.store(step, phi, xq, vq, aq, xy, vy, ay)
    walkers = None if kept is None else kept.history(batch, structure, static_weight)
    return HsiHistory(np.arange(n + 1, dtype=np.float64) * h, acc, xr, model, h, walkers)


class _Kept:
    """Preallocated per-walker and modal histories, filled step by step by :func:`integrate`."""

    def __init__(self, b: int, p: int, j: int, n: int, coupled: bool) -> None:
        self.coupled = coupled
        self.walker = np.zeros((6, b, p, n))  # y, y', y'', w, w', w''
        self.modal = np.zeros((3, b, j, n))  # q, q', q''

    def store(
        self,
        step: int,
        phi: NDArray[np.float64],
        xq: NDArray[np.float64],
        vq: NDArray[np.float64],
        aq: NDArray[np.float64],
        xy: NDArray[np.float64],
        vy: NDArray[np.float64],
        ay: NDArray[np.float64],
    ) -> None:
        """Store the end-of-step state of ``step`` (``phi`` the shapes that step used)."""
        for k, q in enumerate((xq, vq, aq)):
            self.modal[k, :, :, step] = q
            if self.coupled:
                # The walker's base as its equation saw it; a force-only walker's stays 0.
                self.walker[3 + k, :, :, step] = np.einsum("bpj,bj->bp", phi, q)
        for k, y in enumerate((xy, vy, ay)):
            self.walker[k, :, :, step] = y

    def history(
        self, batch: CrowdBatch, structure: ModalStructure, static_weight: bool
    ) -> WalkerHistory:
        """Freeze the arrays into a :class:`WalkerHistory`."""
        for arr in (self.walker, self.modal):
            arr.setflags(write=False)
        return WalkerHistory(batch, structure, static_weight, *self.walker, *self.modal)


def simulate_pedestrians(
    structure: ModalStructure,
    pedestrians: Pedestrians,
    *,
    speed_m_s: ArrayLike | None = None,
    entry_times_s: ArrayLike | None = None,
    positions_m: ArrayLike | None = None,
    duration_s: float | None = None,
    dt_s: float = 0.005,
    model: Model = "interaction",
    response_x_m: ArrayLike | None = None,
    static_weight: bool = False,
    keep_walkers: bool = False,
) -> HsiHistory:
    """Simulate one scenario: pedestrians walking over (or standing on) the deck.

    Parameters
    ----------
    structure : ModalStructure
        The modes.
    pedestrians : DataFrame, Walker, SMDModel or sequence of Walker / SMDModel
        A pedestrian table (the shared contract; checked here), or the pedestrians as
        :class:`~workbench.hsi.pedestrians.Walker` s or
        :class:`~workbench.models.smd.SMDModel` s with M, K, C, ``pacing_hz`` and
        ``force_coefficients_n`` known (their force is
        :meth:`~workbench.models.smd.SMDModel.biomechanical_force_n`, in the simulation's
        time).
    speed_m_s : float or sequence of float, optional
        Walking speed of bare SMD models (tables and walkers carry their own).
    entry_times_s : array, optional
        When each walker steps on the deck at ``x = 0`` (default all at ``t = 0``); they
        walk at their speed.
    positions_m : array, optional
        Instead of walking, pedestrians stand (bounce) at these positions.
    duration_s : float, optional
        Default: until the last walker leaves the deck.
    dt_s, model, response_x_m, static_weight, keep_walkers
        As :func:`integrate`.

    Returns
    -------
    HsiHistory
        With ``B = 1``.

    Examples
    --------
    >>> from workbench.hsi.structure import simply_supported_beam
    >>> from workbench.models import FourierForce, SMDModel
    >>> beam = simply_supported_beam(50.0, 500.0, 2.0, 0.005)
    >>> walker = SMDModel.from_modal(
    ...     73.85, 2.21, 0.297, harmonics=1, pacing_hz=2.0,
    ...     force_coefficients_n=FourierForce(1).from_blf([0.4305], None, 73.85))
    >>> hist = simulate_pedestrians(beam, [walker], speed_m_s=1.25, dt_s=0.01)
    >>> round(float(abs(hist.acceleration_m_s2).max()), 2)
    1.68
    """
    standing = positions_m is not None
    if standing and speed_m_s is None:
        speed_m_s = 0.0  # bare models need no speed to stand
    arrays = pedestrian_arrays(pedestrians, speed_m_s)
    speed = arrays.speed_m_s
    if speed.size == 0:
        raise UsageError("there are no pedestrians to simulate; give at least one")
    if standing:
        x0 = np.broadcast_to(np.asarray(positions_m, float), speed.shape).copy()
        speed = np.zeros_like(speed)
        if duration_s is None:
            raise UsageError("give a duration for pedestrians standing on the deck")
    else:
        if np.any(speed <= 0):
            raise UsageError(
                "a walker has speed 0 and would never cross; give it a positive speed_m_s, "
                "or use positions_m for pedestrians standing on the deck"
            )
        te = np.zeros_like(speed) if entry_times_s is None else np.asarray(entry_times_s, float)
        te = np.broadcast_to(te, speed.shape)
        x0 = -speed * te
        if duration_s is None:
            duration_s = float(np.max(te + structure.span_m / speed))
    batch = CrowdBatch.from_scenarios([(arrays, x0, speed)])
    return integrate(
        structure,
        batch,
        duration_s=float(duration_s),
        dt_s=dt_s,
        model=model,
        response_x_m=response_x_m,
        static_weight=static_weight,
        keep_walkers=keep_walkers,
    )
