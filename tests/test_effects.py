"""The effect mechanism: composition, registry, user-written effects, cubic stiffness physics."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest
from numpy.typing import ArrayLike
from scipy.integrate import solve_ivp

from workbench.errors import UsageError
from workbench.models import (
    CubicStiffness,
    Effect,
    EffectContext,
    Effects,
    Parameter,
    SMDModel,
    available_effects,
    effect_from_name,
    register_effect,
    unregister_effect,
)
from workbench.synth import simulate_smd, simulate_walking


class ExtraDamping(Effect):
    """User-written linear effect: viscous damping added to C, term ``c_extra u'``."""

    name = "extra_damping"
    parameters = (Parameter("c_extra_ns_per_m", "N s/m", 0.0, "added damping"),)

    def regressors(self, u, v, t_s, context=None):  # type: ignore[no-untyped-def]
        _, v, _ = self.broadcast(u, v, t_s)
        return v[..., None]


class SoftContact(Effect):
    """User-written nonlinear effect: a one-sided spring below ``-gap``."""

    name = "soft_contact"
    linear = False
    parameters = (
        Parameter("k_contact_n_per_m", "N/m", 0.0, "contact stiffness"),
        Parameter("gap_m", "m", 0.01, "free travel before contact"),
    )

    def force(self, u, v, t_s, theta=None, context=None):  # type: ignore[no-untyped-def]
        u, v, t_s = self.broadcast(u, v, t_s)
        k, gap = self.split_theta(theta)
        return k * np.maximum(-u - gap, 0.0)


@pytest.fixture
def user_effects() -> Iterator[None]:
    register_effect(ExtraDamping)
    register_effect(SoftContact)
    try:
        yield
    finally:
        unregister_effect("extra_damping")
        unregister_effect("soft_contact")


BASE = SMDModel.from_modal(70.0, 1.9, 0.45, harmonics=3)


def test_composition_returns_new_models() -> None:
    model = SMDModel() + CubicStiffness()
    assert model.effects.names == ("cubic_stiffness",)
    assert SMDModel().effects.names == ()  # the original is untouched
    both = BASE + (CubicStiffness(k3_n_per_m3=1e5) + ExtraDamping(c_extra_ns_per_m=20.0))
    assert both.effects.names == ("cubic_stiffness", "extra_damping")
    assert isinstance(CubicStiffness() + ExtraDamping(), Effects)
    assert (Effects() + CubicStiffness()) + Effects([ExtraDamping()]) == Effects(
        [CubicStiffness(), ExtraDamping()]
    )
    assert both.parameter_names == (
        "damping_ns_per_m",
        "stiffness_n_per_m",
        "cubic_stiffness.k3_n_per_m3",
        "extra_damping.c_extra_ns_per_m",
    )
    assert both.parameter_values()["extra_damping.c_extra_ns_per_m"] == 20.0


def test_repr_reads_like_the_code_that_built_it() -> None:
    model = SMDModel(mass_kg=75, stiffness_n_per_m=18506, damping_ns_per_m=942, harmonics=10)
    assert repr(model + CubicStiffness()) == (
        "SMDModel(mass_kg=75, stiffness_n_per_m=18506, damping_ns_per_m=942, harmonics=10)"
        " + CubicStiffness()"
    )
    assert repr(CubicStiffness(k3_n_per_m3=2e5) + ExtraDamping()) == (
        "CubicStiffness(k3_n_per_m3=200000) + ExtraDamping()"
    )


def test_same_effect_twice_is_a_usage_error() -> None:
    with pytest.raises(UsageError, match="'cubic_stiffness' is added twice"):
        SMDModel() + CubicStiffness() + CubicStiffness(k3_n_per_m3=1.0)
    with pytest.raises(UsageError, match="added twice"):
        CubicStiffness() + CubicStiffness()


def test_registry_builds_effects_by_name() -> None:
    assert "cubic_stiffness" in available_effects()
    effect = effect_from_name("cubic_stiffness", k3_n_per_m3=3e4)
    assert effect == CubicStiffness(k3_n_per_m3=3e4)
    assert effect.values == {"k3_n_per_m3": 3e4}
    np.testing.assert_array_equal(effect.theta, [3e4])
    assert effect.to_dict() == {"name": "cubic_stiffness", "parameters": {"k3_n_per_m3": 3e4}}
    with pytest.raises(UsageError, match="'gait_wobble' is not known; use one of"):
        effect_from_name("gait_wobble")
    with pytest.raises(UsageError, match="unknown parameter 'k3'"):
        effect_from_name("cubic_stiffness", k3=1.0)
    assert CubicStiffness.typical() == CubicStiffness(k3_n_per_m3=5e5)
    assert CubicStiffness.typical(k3_n_per_m3=1.0).values == {"k3_n_per_m3": 1.0}
    # Models accept effect names too.
    assert SMDModel(effects=["cubic_stiffness"]).effects.names == ("cubic_stiffness",)


def test_registry_rejects_malformed_or_clashing_effects() -> None:
    class BadName(Effect):
        name = "Bad Name"

        def regressors(self, u, v, t_s, context=None):  # type: ignore[no-untyped-def]
            return np.zeros((*np.shape(u), 0))

    class NoPhysics(Effect):
        name = "no_physics"

    class Impostor(CubicStiffness):
        pass

    with pytest.raises(UsageError, match="snake_case"):
        register_effect(BadName)
    with pytest.raises(UsageError, match="must implement regressors"):
        register_effect(NoPhysics)
    with pytest.raises(UsageError, match=r"already registered by workbench\.models\.effects"):
        register_effect(Impostor)


def test_user_written_effect_plugs_in_through_the_registry(user_effects: None) -> None:
    assert {"extra_damping", "soft_contact"} <= set(available_effects())
    model = BASE + effect_from_name("extra_damping", c_extra_ns_per_m=55.0)
    stiffer_damper = BASE.replace(damping_ns_per_m=BASE.damping_ns_per_m + 55.0)
    u, v, t = np.array([0.01, -0.02]), np.array([0.3, -0.1]), np.array([0.0, 0.5])
    np.testing.assert_allclose(
        model.acceleration(u, v, t, 100.0), stiffer_damper.acceleration(u, v, t, 100.0)
    )
    # Parameters can be overridden per particle by their qualified name.
    acc = model.acceleration(0.0, 0.2, 0.0, 0.0, {"extra_damping.c_extra_ns_per_m": [0.0, 10.0]})
    np.testing.assert_allclose(
        acc, [-BASE.damping_ns_per_m * 0.2 / 70, -(BASE.damping_ns_per_m + 10) * 0.2 / 70]
    )
    with pytest.raises(UsageError, match="not in this model"):
        model.acceleration(0.0, 0.2, 0.0, 0.0, {"cubic_stiffness.k3_n_per_m3": 1.0})

    # The same physics through the simulator: an added damper is an added damper.
    kw = dict(duration_s=8.0, step_duration_sd=0.02, amplitude_sd=0.05, phase_sd_rad=0.05, seed=5)
    with_effect = simulate_walking(effects=[ExtraDamping(c_extra_ns_per_m=80.0)], **kw)
    base_model = with_effect.model
    zeta = (base_model.damping_ns_per_m + 80.0) / (
        2 * np.sqrt(base_model.stiffness_n_per_m * base_model.mass_kg)
    )
    plain = simulate_walking(damping_ratio=zeta, **kw)
    scale = np.max(np.abs(plain.disp_m))
    np.testing.assert_allclose(with_effect.disp_m, plain.disp_m, rtol=0, atol=1e-7 * scale)
    assert with_effect.truth["effects"] == [
        {"name": "extra_damping", "parameters": {"c_extra_ns_per_m": 80.0}}
    ]


def test_nonlinear_user_effect_overrides_force(user_effects: None) -> None:
    effect = effect_from_name("soft_contact", k_contact_n_per_m=5e4, gap_m=0.02)
    assert not effect.linear
    model = BASE + effect
    u = np.array([0.0, -0.01, -0.03])
    acc = model.acceleration(u, 0.0, 0.0, 0.0)
    expected = (-BASE.stiffness_n_per_m * u - 5e4 * np.maximum(-u - 0.02, 0.0)) / 70.0
    np.testing.assert_allclose(acc, expected)
    with pytest.raises(UsageError, match="not linear"):
        effect.regressors(u, 0.0, 0.0)


def test_cubic_stiffness_term_and_particle_broadcasting() -> None:
    effect = CubicStiffness(k3_n_per_m3=2e5)
    u = np.array([0.01, -0.02, 0.03])
    np.testing.assert_allclose(effect.regressors(u, 0.0, 0.0)[:, 0], u**3)
    np.testing.assert_allclose(effect.force(u, 0.0, 0.0), 2e5 * u**3)
    # One parameter vector per particle.
    theta = np.array([[1e5], [2e5], [3e5]])
    np.testing.assert_allclose(effect.force(u, 0.0, 0.0, theta), theta[:, 0] * u**3)
    model = BASE + effect
    np.testing.assert_allclose(
        model.acceleration(u, 0.0, 0.0, 0.0),
        -(BASE.stiffness_n_per_m * u + 2e5 * u**3) / 70.0,
    )


def test_context_gives_step_phase_and_ground_motion() -> None:
    ctx = EffectContext(
        step_start_s=np.array([0.0, 0.5, 1.1]),
        ground_time_s=np.array([0.0, 1.0]),
        ground_disp_m=np.array([0.0, 0.002]),
        ground_vel_m_s=np.array([0.0, 0.0]),
        ground_acc_m_s2=np.array([0.0, 0.0]),
    )
    np.testing.assert_allclose(ctx.step_phase_rad([0.25, 0.8]), [np.pi, 3 * np.pi])
    np.testing.assert_array_equal(ctx.step_index([0.1, 0.6, 2.0]), [0, 1, 2])
    assert ctx.ground_at(0.5)[0] == pytest.approx(0.001)
    with pytest.raises(UsageError, match="no 'step_start_s'"):
        EffectContext().step_phase_rad(0.0)


# -- physics of a simulated cubic spring ---------------------------------------------------
def _explicit_ode(model: SMDModel, k3: float, force, t: np.ndarray) -> np.ndarray:  # type: ignore[no-untyped-def]
    m, k, c = model.mass_kg, model.stiffness_n_per_m, model.damping_ns_per_m

    def rhs(tt: float, y: ArrayLike) -> list[float]:
        u, v = y  # type: ignore[misc]
        return [v, (force(tt) - c * v - k * u - k3 * u**3) / m]

    sol = solve_ivp(
        rhs, (t[0], t[-1]), [0.0, 0.0], t_eval=t, method="DOP853", rtol=1e-11, atol=1e-14
    )
    return sol.y[0]


@pytest.mark.parametrize("bandwidth_hz", [None, 4.0])  # adaptive ODE path, fast fixed-point path
def test_simulated_cubic_spring_matches_the_explicit_ode(bandwidth_hz: float | None) -> None:
    def force(t):  # type: ignore[no-untyped-def]
        return 300.0 * np.sin(2 * np.pi * 1.8 * t) + 100.0 * np.sin(2 * np.pi * 3.6 * t)

    t = np.arange(0, 6.0, 0.005)
    k3 = 2e6  # about 10 % stiffer at the peak displacement: clearly nonlinear
    sim = simulate_smd(BASE + CubicStiffness(k3_n_per_m3=k3), force, t, bandwidth_hz=bandwidth_hz)
    reference = _explicit_ode(BASE, k3, force, t)
    linear = _explicit_ode(BASE, 0.0, force, t)
    scale = np.max(np.abs(reference))
    assert np.max(np.abs(reference - linear)) > 0.02 * scale  # the effect is visible
    np.testing.assert_allclose(sim.disp_m, reference, rtol=0, atol=1e-7 * scale)


def test_cubic_spring_differs_from_linear_by_the_first_order_perturbation() -> None:
    # u = u0 + u1 + O(k3^2) with M u1'' + C u1' + K u1 = -k3 u0^3 (from rest).
    kw = dict(duration_s=12.0, harmonics=3, seed=11)
    linear = simulate_walking(**kw)
    u0 = linear.disp_m
    k = linear.model.stiffness_n_per_m
    k3 = 0.005 * k / np.max(u0**2)  # k3 u^2 is 0.5 % of K at the peak
    cubic = simulate_walking(effects=[CubicStiffness(k3_n_per_m3=k3)], **kw)
    difference = cubic.disp_m - u0
    first_order = simulate_smd(linear.model, -k3 * u0**3, linear.time_s, bandwidth_hz=20.0).disp_m
    size = np.max(np.abs(difference))
    assert 1e-3 * np.max(np.abs(u0)) < size < 1e-2 * np.max(np.abs(u0))
    # The remainder is second order: a few per cent of the first-order term.
    assert np.max(np.abs(difference - first_order)) < 0.05 * size
