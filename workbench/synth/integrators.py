"""Time integration of the SMD equation of motion for the simulators.

Integration
    Two schemes give the continuous solution at the samples; ``u''`` at the samples then
    comes from the equation of motion, not from differentiation, so ``GRF = M g + M u''``
    holds exactly for the returned arrays (before noise).

    *Fast scheme* (used when the force bandwidth is known, as in :func:`simulate_walking`
    and :func:`seed_numerical_example`, and the time base is uniform): on a fine grid with
    ``2 pi f_max h <= 0.03`` the force is interpolated by local cubics and the linear SMD
    response to them is integrated exactly (matrix exponential), run as an IIR filter; the
    interpolation error is below about 2e-8 of the response at ``f_max`` and far less for
    the lower harmonics. Effects join the force by fixed-point (Picard) iteration over the
    whole record, evaluated vectorised on the fine grid, until the response changes by less
    than 1e-11; if that does not contract (a strong nonlinearity), the adaptive scheme
    takes over.

    *Adaptive scheme*: ``solve_ivp`` (DOP853, relative tolerance 1e-10, absolute
    tolerances scaled to the response), restarted at step starts where the step phase has
    a kink. Used for arbitrary force functions in :func:`simulate_smd` and as the fallback.
    The two agree to about 1e-8 of the response (tests check 1e-7).

Holds the fast scheme (``_FineLinearSolver`` and ``_integrate_fine``, which returns None
when the fixed-point iteration does not converge) and the adaptive scheme
(``_integrate_ode``); :mod:`workbench.synth.simulate` chooses between them.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.linalg
import scipy.signal
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from workbench.errors import UsageError
from workbench.models.effects import EffectContext
from workbench.models.smd import SMDModel
from workbench.synth.ground import (
    _Ground,
)

FloatArray = NDArray[np.float64]

_RTOL = 1e-10


#: Target of ``2 pi f_max h`` on the fine grid of the fast scheme; the cubic interpolation of
#: the force then errs by about ``0.023 (2 pi f h)^4 < 2e-8`` (relative) at ``f_max``.
_FINE_OMEGA_H = 0.03
#: Fixed-point iterations for effects stop when the response changes by less than this
#: (relative to its largest value).
_PICARD_TOL = 1e-11
_PICARD_MAX_ITER = 200


def _uniform_step(time_s: FloatArray) -> float | None:
    steps = np.diff(time_s)
    dt = float(np.median(steps))
    return dt if np.all(np.abs(steps - dt) <= 1e-9 * dt) else None


class _FineLinearSolver:
    """Linear SMD on a fine uniform grid, exact for a force that is cubic between nodes.

    Over each fine interval ``[t_k, t_k + h]`` the force is the cubic through its values at
    ``t_{k-1} .. t_{k+2}``; the response to that cubic is integrated exactly (matrix
    exponential of the system augmented with a polynomial generator). The linear recurrence
    ``x_{k+1} = Phi x_k + w_k`` then runs as an IIR filter (``scipy.signal.lfilter``).
    """

    def __init__(
        self, mass: float, stiffness: float, damping: float, time_s: FloatArray, bandwidth_hz: float
    ) -> None:
        dt = float(time_s[1] - time_s[0])
        self.refine = max(1, int(np.ceil(dt * 2.0 * np.pi * bandwidth_hz / _FINE_OMEGA_H)))
        h = dt / self.refine
        self.n_nodes = (time_s.size - 1) * self.refine + 1
        self.t_nodes = time_s[0] + h * np.arange(self.n_nodes)
        #: Nodes plus one before and two after, where the force is needed.
        self.t_ext = time_s[0] + h * np.arange(-1, self.n_nodes + 2)
        self.take = self.refine * np.arange(time_s.size)

        # (u, u') driven by the last of four polynomial states q with q' = L q (L the
        # lower shift): starting q at e_(3-m) drives the body with s^m / m!.
        gen = np.zeros((6, 6))
        gen[0, 1] = 1.0
        gen[1, 0] = -stiffness / mass
        gen[1, 1] = -damping / mass
        gen[1, 5] = 1.0 / mass
        gen[3, 2] = gen[4, 3] = gen[5, 4] = 1.0
        e = scipy.linalg.expm(gen * h)
        phi = e[:2, :2]
        factorial = np.array([1.0, 1.0, 2.0, 6.0])
        # Response to (s / h)^m, m = 0..3, then to the cubic through sigma = -1, 0, 1, 2.
        gamma = np.stack([e[:2, 5 - m] * factorial[m] / h**m for m in range(4)], axis=1)
        to_power = np.linalg.inv(np.vander(np.array([-1.0, 0.0, 1.0, 2.0]), 4, increasing=True))
        self._weights = gamma @ to_power
        self._den = [1.0, -(phi[0, 0] + phi[1, 1]), phi[0, 0] * phi[1, 1] - phi[0, 1] * phi[1, 0]]
        self._num = {
            (0, 0): [0.0, 1.0, -phi[1, 1]],
            (0, 1): [0.0, 0.0, phi[0, 1]],
            (1, 0): [0.0, 0.0, phi[1, 0]],
            (1, 1): [0.0, 1.0, -phi[0, 0]],
        }

    def solve(
        self, force_ext: FloatArray, initial: tuple[float, float]
    ) -> tuple[FloatArray, FloatArray]:
        """Displacement and velocity at the nodes for the force at :attr:`t_ext`."""
        windows = np.lib.stride_tricks.sliding_window_view(force_ext, 4)[: self.n_nodes - 1]
        w = windows @ self._weights.T
        # The initial state enters as the first input of the filter; output i is the state
        # at node i - 1.
        inputs = np.vstack([np.asarray(initial, dtype=np.float64), w, np.zeros(2)])
        lf = scipy.signal.lfilter
        disp = lf(self._num[0, 0], self._den, inputs[:, 0]) + lf(
            self._num[0, 1], self._den, inputs[:, 1]
        )
        vel = lf(self._num[1, 0], self._den, inputs[:, 0]) + lf(
            self._num[1, 1], self._den, inputs[:, 1]
        )
        return np.asarray(disp[1:]), np.asarray(vel[1:])

    @staticmethod
    def extend(values: FloatArray) -> FloatArray:
        """Values at the nodes extended to :attr:`t_ext` by cubic extrapolation."""
        head = 4 * values[0] - 6 * values[1] + 4 * values[2] - values[3]
        tail1 = 4 * values[-1] - 6 * values[-2] + 4 * values[-3] - values[-4]
        tail2 = 4 * tail1 - 6 * values[-1] + 4 * values[-2] - values[-3]
        return np.concatenate([[head], values, [tail1, tail2]])


def _integrate_fine(
    model: SMDModel,
    force_fn: Callable[[Any], Any],
    time_s: FloatArray,
    initial: tuple[float, float],
    ground: _Ground | None,
    context: EffectContext | None,
    bandwidth_hz: float,
) -> tuple[FloatArray, FloatArray] | None:
    """Run the fast scheme (effects by fixed-point iteration); None if that fails to converge."""
    m = model.require("mass_kg")
    k = model.require("stiffness_n_per_m")
    c = model.require("damping_ns_per_m")
    solver = _FineLinearSolver(m, k, c, time_s, bandwidth_hz)
    if solver.n_nodes < 4:
        return None
    drive = np.asarray(force_fn(solver.t_ext), dtype=np.float64)
    if ground is not None:
        drive = drive + c * ground.vel(solver.t_ext) + k * ground.disp(solver.t_ext)
    disp, vel = solver.solve(drive, initial)
    if model.effects:
        # Picard iteration on the whole record: the effect terms, evaluated on the previous
        # response, join the force. It contracts when the effects are a modest correction
        # to the linear spring and damper, which is what they are meant to be.
        base = context if context is not None else EffectContext()
        ctx = dataclasses.replace(base, mass_kg=m, stiffness_n_per_m=k, damping_ns_per_m=c)
        previous_change = np.inf
        for _ in range(_PICARD_MAX_ITER):
            # A diverging iteration overflows before the test below sees it; it is then
            # handed to the ODE solver, so the overflow is no news to the caller.
            with np.errstate(over="ignore", invalid="ignore"):
                extra = model.effect_force(disp, vel, solver.t_nodes, None, ctx)
                new_disp, new_vel = solver.solve(drive - solver.extend(extra), initial)
                scale = max(float(np.max(np.abs(new_disp))), 1e-300)
                change = float(np.max(np.abs(new_disp - disp))) / scale
            disp, vel = new_disp, new_vel
            if not np.isfinite(change) or (change > 2.0 * previous_change and change > 1e-8):
                return None  # diverging: leave it to the adaptive ODE solver
            if change < _PICARD_TOL or (change >= previous_change and change < 1e-9):
                break  # converged, or stalled at the rounding floor of the filter
            previous_change = change
        else:
            return None
    return disp[solver.take], vel[solver.take]


def _integrate_ode(
    model: SMDModel,
    force_fn: Callable[[Any], Any],
    time_s: FloatArray,
    initial: tuple[float, float],
    ground: _Ground | None,
    context: EffectContext | None,
    breakpoints_s: FloatArray,
    force_scale_n: float,
) -> tuple[FloatArray, FloatArray]:
    m = model.require("mass_kg")
    k = model.require("stiffness_n_per_m")
    c = model.require("damping_ns_per_m")
    has_effects = bool(model.effects)
    ctx = None
    if has_effects:
        base = context if context is not None else EffectContext()
        ctx = dataclasses.replace(base, mass_kg=m, stiffness_n_per_m=k, damping_ns_per_m=c)

    def rhs(t: float, y: FloatArray) -> list[float]:
        u, v = y
        balance = float(force_fn(t)) - c * v - k * u
        if ground is not None:
            balance += c * float(ground.vel(t)) + k * float(ground.disp(t))
        if has_effects:
            balance -= float(model.effect_force(u, v, t, None, ctx))
        return [v, balance / m]

    # Absolute tolerances scaled to the expected response keep the relative accuracy
    # uniform whether the body moves by metres or micrometres.
    omega = 2.0 * np.pi * max(model.natural_frequency_hz or 0.0, 1.0)
    u_scale = max(abs(initial[0]), force_scale_n / k if k > 0 else 0.0, 1e-9)
    if ground is not None:
        u_scale = max(u_scale, ground.scale_m)
    v_scale = max(abs(initial[1]), omega * u_scale)
    atol = [1e-3 * _RTOL * u_scale, 1e-3 * _RTOL * v_scale]

    t0, t_end = float(time_s[0]), float(time_s[-1])
    inner = np.unique(breakpoints_s[(breakpoints_s > t0) & (breakpoints_s < t_end)])
    edges = np.concatenate([[t0], inner, [t_end]])
    disp = np.empty(time_s.size)
    vel = np.empty(time_s.size)
    y = np.array(initial, dtype=np.float64)
    for j, (a, b) in enumerate(itertools.pairwise(edges)):
        last = j == edges.size - 2
        in_piece = (time_s >= a) & ((time_s <= b) if last else (time_s < b))
        t_eval = time_s[in_piece]
        if not last or t_eval.size == 0 or t_eval[-1] < b:
            t_eval = np.append(t_eval, b)
        sol = solve_ivp(rhs, (a, b), y, method="DOP853", t_eval=t_eval, rtol=_RTOL, atol=atol)
        if not sol.success:  # pragma: no cover - DOP853 on a smooth ODE
            raise UsageError(
                f"simulate: the integrator failed between {a:.4g} s and {b:.4g} s "
                f"({sol.message}); check that the model and force are physical"
            )
        n_in = int(np.count_nonzero(in_piece))
        disp[in_piece] = sol.y[0, :n_in]
        vel[in_piece] = sol.y[1, :n_in]
        y = sol.y[:, -1]
    return disp, vel
