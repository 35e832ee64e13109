"""The result of a simulation and its truth bookkeeping.

Holds :class:`Simulation` (the synthetic record with its true response, force and
parameters) and the helpers that assemble it: ``_finish`` turns an integrated response
into the GRF record with its truth, ``_model_truth`` describes a model in the truth, and
``_jsonable`` makes the truth plain JSON.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.models.effects import EffectContext
from workbench.models.smd import SMDModel
from workbench.records.record import G_M_S2, Record
from workbench.synth.ground import (
    _Ground,
)

__all__ = ["Simulation"]

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Simulation:
    """A simulated record with its true response and parameters.

    Attributes
    ----------
    record : Record
        The synthetic measurement (``metadata["truth"]`` holds :attr:`truth`).
    model : SMDModel
        The model simulated (mass, K, C, harmonics, effects with their true values).
    disp_m, vel_m_s, acc_m_s2 : ndarray
        True COM displacement [m], velocity [m/s] and acceleration [m/s^2] at the samples.
    force_n : ndarray
        True biomechanical force F_bio [N] at the samples.
    step_start_s : ndarray
        Start times of the steps that begin inside the record [s] (empty if not walking).
    truth : dict
        JSON-able description of everything needed to reproduce and check the record.
    """

    record: Record
    model: SMDModel
    disp_m: FloatArray
    vel_m_s: FloatArray
    acc_m_s2: FloatArray
    force_n: FloatArray
    step_start_s: FloatArray
    truth: dict[str, Any] = field(default_factory=dict)

    @property
    def time_s(self) -> FloatArray:
        """Sample times [s] (those of the record)."""
        return self.record.time_s

    def truth_json(self, indent: int | None = 2) -> str:
        """Return the truth as a JSON string.

        Parameters
        ----------
        indent : int or None, optional
            Passed to :func:`json.dumps`.

        Returns
        -------
        str
        """
        return json.dumps(self.truth, indent=indent, allow_nan=False)


def _jsonable(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return [_jsonable(v) for v in value.tolist()]
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, np.floating | float):
        return float(value)
    return value


def _finish(
    *,
    model: SMDModel,
    time_s: FloatArray,
    disp: FloatArray,
    vel: FloatArray,
    force: FloatArray,
    ground: _Ground | None,
    context: EffectContext | None,
    noise_sd_n: float,
    rng: np.random.Generator,
    step_start_s: FloatArray,
    truth: dict[str, Any],
    record_fields: Mapping[str, Any],
) -> Simulation:
    m = model.require("mass_kg")
    acc_model = model.acceleration(disp, vel, time_s, force, context=context)
    if ground is not None:
        u_g, v_g, _ = ground(time_s)
        acc_model = (
            acc_model
            + (model.require("damping_ns_per_m") * v_g + model.require("stiffness_n_per_m") * u_g)
            / m
        )
    acc = np.asarray(acc_model, dtype=np.float64)
    grf = m * G_M_S2 + m * acc
    if noise_sd_n > 0:
        grf = grf + noise_sd_n * rng.standard_normal(time_s.size)
    truth = _jsonable(truth)
    record = Record(
        time_s=time_s,
        grf_n=grf,
        mass_kg=m,
        ground_acc_m_s2=None if ground is None else ground.acc_at_samples,
        metadata={"format": "synthetic", "truth": truth},
        **record_fields,
    )
    for arr in (disp, vel, acc, force):
        arr.setflags(write=False)
    starts = np.asarray(step_start_s, dtype=np.float64)
    starts.setflags(write=False)
    return Simulation(
        record=record,
        model=model,
        disp_m=disp,
        vel_m_s=vel,
        acc_m_s2=acc,
        force_n=force,
        step_start_s=starts,
        truth=truth,
    )


def _model_truth(model: SMDModel) -> dict[str, Any]:
    return {
        "mass_kg": model.mass_kg,
        "stiffness_n_per_m": model.stiffness_n_per_m,
        "damping_ns_per_m": model.damping_ns_per_m,
        "natural_frequency_hz": model.natural_frequency_hz,
        "damping_ratio": model.damping_ratio,
        "harmonics": model.harmonics,
        "effects": [e.to_dict() for e in model.effects],
    }


def _model_context(model: SMDModel, context: EffectContext | None) -> EffectContext | None:
    return context if model.effects else None
