"""What the cross-check returns: one :class:`StepCheck` per step and the whole run's result.

:class:`CrosscheckResult` holds the per-step comparisons of a filter with the MCMC (made by
:mod:`workbench.inference.crosscheck.compare`), the run's settings and its InferenceData,
and turns them into the verdict, the convergence summary, the text table and the JSON of
``workbench crosscheck`` (docs/contracts.md). The agreement tolerances live here because
the verdict is stated in them.

Its own idea: the result types carry no sampling and no comparison code, so the reporting
side (:mod:`workbench.reporting.crosscheck`) can use them without the run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from workbench.errors import UsageError
from workbench.inference.crosscheck.mcmc_result import McmcResult
from workbench.inference.crosscheck.step_target import PARAMS

__all__ = ["SD_RATIO_RANGE", "Z_TOLERANCE", "CrosscheckResult", "StepCheck"]

FloatArray = NDArray[np.float64]

#: A step agrees when |z| is below this for C and for K.
Z_TOLERANCE = 2.0
#: The filter's sd may differ from the MCMC's by this factor before it is flagged.
SD_RATIO_RANGE = (0.5, 2.0)


@dataclass(frozen=True, eq=False)
class StepCheck:
    """The cross-check of one step.

    Attributes
    ----------
    index : int
        Step (piece) index.
    start_s, end_s : float
        Times of the step's first and last sample [s].
    pf_mean, pf_sd, mcmc_mean, mcmc_sd : ndarray, shape (2,)
        (C, K) mean and sd of the filter and of the MCMC.
    z, sd_ratio, wasserstein : ndarray, shape (2,)
        Agreement measures (crosscheck module docstring).
    converged : bool
        The MCMC passed every convergence check.
    agree : bool or None
        Converged and ``|z| <`` :data:`Z_TOLERANCE` for C and K; None when not converged.
    flags : list of str
        One sentence per reason for doubt (empty when all is well).
    mcmc : McmcResult
        The step's run.
    prior_mean, prior_sd : ndarray, shape (2,)
        The (C, K) prior the step was sampled with (NaN-free; the box's moments at step 0).
    modal_mean, modal_sd : dict
        MCMC mean and sd of natural frequency [Hz] and damping ratio.
    pf_modal_mean, pf_modal_sd : dict
        The same for the filter (first-order propagation of its mean and sd).
    noise_scale_mean : float or None
        MCMC mean of the noise scale (None when fixed).
    """

    index: int
    start_s: float
    end_s: float
    pf_mean: FloatArray
    pf_sd: FloatArray
    mcmc_mean: FloatArray
    mcmc_sd: FloatArray
    z: FloatArray
    sd_ratio: FloatArray
    wasserstein: FloatArray
    converged: bool
    agree: bool | None
    flags: list[str]
    mcmc: McmcResult
    prior_mean: FloatArray
    prior_sd: FloatArray
    modal_mean: dict[str, float]
    modal_sd: dict[str, float]
    pf_modal_mean: dict[str, float]
    pf_modal_sd: dict[str, float]
    noise_scale_mean: float | None
    surrogate_error: dict[str, Any] | None = None

    def to_json(self) -> dict[str, Any]:
        """Return the step's JSON object (docs/contracts.md keys first)."""

        def per(values: FloatArray) -> dict[str, float | None]:
            return {p: _num(v) for p, v in zip(PARAMS, values, strict=True)}

        return {
            "index": self.index,
            "pf_mean": per(self.pf_mean),
            "pf_sd": per(self.pf_sd),
            "mcmc_mean": per(self.mcmc_mean),
            "mcmc_sd": per(self.mcmc_sd),
            "z": per(self.z),
            "sd_ratio": per(self.sd_ratio),
            "wasserstein_sd": per(self.wasserstein),
            "converged": self.converged,
            "agree": self.agree,
            "flags": list(self.flags),
            "start_s": round(self.start_s, 6),
            "end_s": round(self.end_s, 6),
            "prior_mean": per(self.prior_mean),
            "prior_sd": per(self.prior_sd),
            "mcmc_modal_mean": {k: _num(v) for k, v in self.modal_mean.items()},
            "mcmc_modal_sd": {k: _num(v) for k, v in self.modal_sd.items()},
            "pf_modal_mean": {k: _num(v) for k, v in self.pf_modal_mean.items()},
            "pf_modal_sd": {k: _num(v) for k, v in self.pf_modal_sd.items()},
            "noise_scale_mean": _num(self.noise_scale_mean),
            "surrogate_error": self.surrogate_error,
            "mcmc": {
                "n_steps": self.mcmc.n_steps,
                "tau_max": _num(float(np.nanmax(self.mcmc.tau))),
                "rhat_max": _num(float(np.nanmax(self.mcmc.rhat))),
                "ess_bulk_min": _num(float(np.nanmin(self.mcmc.ess_bulk))),
                "ess_tail_min": _num(float(np.nanmin(self.mcmc.ess_tail))),
                "acceptance": [_num(a) for a in self.mcmc.acceptance_fraction],
                "seconds": round(self.mcmc.seconds, 4),
                "reasons": list(self.mcmc.reasons),
            },
        }


def _num(x: Any) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


@dataclass(frozen=True, eq=False)
class CrosscheckResult:
    """What :func:`~workbench.inference.crosscheck.check.crosscheck` returns.

    Attributes
    ----------
    method : str
        The filter compared (``"rbpf"`` or ``"pf"``).
    mode, prior, noise_scale : str
        Settings of the MCMC (crosscheck module docstring).
    steps : list of StepCheck
        One per step checked, in record order.
    inference_data : arviz.InferenceData or None
        Per-record posterior, sample_stats, log_likelihood, observed_data and prior
        (:func:`~workbench.inference.crosscheck.posterior.build_inference_data`).
    seconds : float
        Wall time of the MCMC over all steps.
    settings : dict
        Everything else that defines the run.
    """

    method: str
    mode: str
    prior: str
    noise_scale: str
    steps: list[StepCheck]
    inference_data: Any = None
    seconds: float = 0.0
    settings: dict[str, Any] = field(default_factory=dict)

    @property
    def compared(self) -> list[StepCheck]:
        """Steps whose MCMC converged (the only ones compared)."""
        return [s for s in self.steps if s.converged]

    @property
    def agreement(self) -> float | None:
        """Fraction of compared steps that agree (None when none converged)."""
        comp = self.compared
        if not comp:
            return None
        return sum(bool(s.agree) for s in comp) / len(comp)

    @property
    def flagged_fraction(self) -> float:
        """Fraction of all steps with at least one flag."""
        return sum(bool(s.flags) for s in self.steps) / max(1, len(self.steps))

    def disagreements(self) -> list[dict[str, Any]]:
        """Return the flagged steps: index, time and reasons."""
        return [
            {"index": s.index, "start_s": round(s.start_s, 3), "reasons": list(s.flags)}
            for s in self.steps
            if s.flags
        ]

    def verdict(self) -> str:
        """One sentence: where the filter and the MCMC disagree, if anywhere."""
        n = len(self.steps)
        bad = self.disagreements()
        not_conv = [s.index for s in self.steps if not s.converged]
        agree = self.agreement
        part = (
            f"{self.method} and MCMC agree (|z| < {Z_TOLERANCE:g}) on "
            f"{sum(bool(s.agree) for s in self.compared)} of {len(self.compared)} compared steps"
            if agree is not None
            else "no step's MCMC converged, so nothing was compared"
        )
        if not bad:
            return f"{part}; no step is flagged."
        where = ", ".join(str(d["index"]) for d in bad[:12]) + (", ..." if len(bad) > 12 else "")
        conv = f"; MCMC not converged on steps {not_conv}" if not_conv else ""
        return f"{part}; {len(bad)} of {n} steps flagged (steps {where}){conv}."

    def diagnostics(self) -> dict[str, Any]:
        """Summary of the MCMC convergence over all steps."""
        runs = [s.mcmc for s in self.steps]

        def agg(fn: Any, values: list[float]) -> float | None:
            vals = [v for v in values if math.isfinite(v)]
            return _num(fn(vals)) if vals else None

        return {
            "converged_steps": sum(s.converged for s in self.steps),
            "not_converged_steps": [s.index for s in self.steps if not s.converged],
            "rhat_max": agg(max, [float(np.nanmax(r.rhat)) for r in runs]),
            "ess_bulk_min": agg(min, [float(np.nanmin(r.ess_bulk)) for r in runs]),
            "ess_tail_min": agg(min, [float(np.nanmin(r.ess_tail)) for r in runs]),
            "tau_max": agg(max, [float(np.nanmax(r.tau)) for r in runs]),
            "acceptance_min": agg(min, [float(np.min(r.acceptance_fraction)) for r in runs]),
            "acceptance_max": agg(max, [float(np.max(r.acceptance_fraction)) for r in runs]),
            "n_ensembles": runs[0].n_ensembles if runs else None,
            "n_walkers": runs[0].n_walkers if runs else None,
            "chain_steps_max": max((r.n_steps for r in runs), default=None),
            "evaluations": sum(r.n_evaluations for r in runs),
            "seconds": round(self.seconds, 3),
            "seconds_per_step": round(self.seconds / max(1, len(runs)), 4),
            "thresholds": {
                "rhat_max": 1.01,
                "ess_min": 400,
                "tau_factor": self.settings.get("tau_factor", 50.0),
                "acceptance": [0.1, 0.9],
            },
        }

    def summary(self) -> str:
        """Return a text table: per compared step the filter's and the MCMC's (C, K), z."""
        lines = [
            f"Cross-check of {self.method} against per-step MCMC ({self.mode}, {self.prior} "
            f"prior), {len(self.steps)} steps",
            "",
            f"{'step':>5}{'filter C':>11}{'MCMC C':>11}{'z C':>7}{'filter K':>11}{'MCMC K':>11}"
            f"{'z K':>7}  flags",
        ]
        for s in self.steps:
            z = s.z if s.converged else np.array([np.nan, np.nan])
            lines.append(
                f"{s.index:>5}{s.pf_mean[0]:>11.1f}{s.mcmc_mean[0]:>11.1f}{z[0]:>7.2f}"
                f"{s.pf_mean[1]:>11.0f}{s.mcmc_mean[1]:>11.0f}{z[1]:>7.2f}  "
                + ("; ".join(s.flags) if s.flags else "")
            )
        diag = self.diagnostics()
        rhat = "n/a" if diag["rhat_max"] is None else f"{diag['rhat_max']:.3f}"
        ess = "n/a" if diag["ess_bulk_min"] is None else f"{diag['ess_bulk_min']:.0f}"
        lines += [
            "",
            self.verdict(),
            f"MCMC: R-hat max {rhat}, bulk ESS min {ess}, "
            f"{diag['converged_steps']} of {len(self.steps)} steps converged",
        ]
        return "\n".join(lines)

    def to_json(self) -> dict[str, Any]:
        """Return the ``workbench crosscheck`` JSON object (docs/contracts.md)."""
        return {
            "method": self.method,
            "mode": self.mode,
            "prior": self.prior,
            "noise_scale": self.noise_scale,
            "steps": [s.to_json() for s in self.steps],
            "agreement": _num(self.agreement),
            "flagged_fraction": round(self.flagged_fraction, 4),
            "disagreements": self.disagreements(),
            "verdict": self.verdict(),
            "mcmc_diagnostics": self.diagnostics(),
            "tolerances": {"z": Z_TOLERANCE, "sd_ratio": list(SD_RATIO_RANGE)},
            "settings": self.settings,
        }

    def posterior_moments(self, step: int | None = None) -> tuple[FloatArray, FloatArray]:
        """(C, K) mean and covariance of the MCMC at a step (default the last converged)."""
        pool = self.compared or self.steps
        if not pool:
            raise UsageError("the cross-check has no steps")
        chosen = pool[-1] if step is None else next(s for s in self.steps if s.index == step)
        r = chosen.mcmc
        return r.mean[:2].copy(), r.cov[:2, :2].copy()

    def to_netcdf(self, path: str | Path) -> Path:
        """Write the InferenceData to netCDF (atomically; see :func:`_netcdf_bytes`)."""
        from workbench.fileutil import atomic_path, atomic_write_bytes

        if self.inference_data is None:
            raise UsageError("this cross-check kept no InferenceData (keep_inference_data=False)")
        path = Path(path)
        data = _netcdf_bytes(self.inference_data)
        if data is not None:
            atomic_write_bytes(path, data)
            return path
        with atomic_path(path) as tmp:  # an xarray without DataTree: HDF5 writes the disk
            self.inference_data.to_netcdf(str(tmp))
        return path


def _netcdf_bytes(idata: Any) -> bytes | None:
    """Return the bytes of ``idata.to_netcdf`` built in memory (None without xarray.DataTree).

    HDF5 that meets a full disk mid-write prints its error stack, and the process may then
    crash when the half-written file is closed; built in memory, the file reaches the disk
    as bytes through the atomic writer, which turns a full disk into one sentence naming the
    file. Same layout as ArviZ's own writer: the root attributes, then one group per
    InferenceData group, numbers compressed with zlib.
    """
    import xarray as xr

    if not hasattr(xr, "DataTree"):
        return None
    groups = list(idata._groups_all)  # ArviZ's order, warm-up groups included
    tree = xr.DataTree.from_dict(
        {"/": xr.Dataset(attrs=dict(idata._attrs or {}))}
        | {f"/{group}": getattr(idata, group) for group in groups}
    )
    encoding = {
        f"/{group}": {
            name: {"zlib": True}
            for name, values in getattr(idata, group).variables.items()
            if values.dtype.kind in "biufc"
        }
        for group in groups
    }
    return bytes(tree.to_netcdf(None, engine="h5netcdf", encoding=encoding))
