"""A whole sensitivity study: design, runs, tables, statements and files.

``run_sensitivity(records, ...)`` is the one entry point of the command line, the analysis
script and the demo. Outputs written by :meth:`SensitivityStudy.write`:

- ``sensitivity.csv``: the tidy table -- one ``replicate`` row per record, setting, level and
  replicate, and one ``summary`` row per record, setting and level with the mean, the
  Monte Carlo sd over replicates (``*_mc_sd``) and the mean posterior sd (``*_sd``) of
  f_n, damping ratio, BLF1..3, K and C. In a one-at-a-time study the baseline runs appear
  under every setting as its default level (``is_default``); in a factorial study the
  setting is ``factorial`` and the level names every factor's level.
- ``effects.csv``: every non-baseline point and output: effect, 95 % Monte Carlo half-width,
  posterior sd ratio, truth and verdict (:mod:`workbench.sensitivity.analysis`).
- ``pooled_effects.csv`` (two or more records): each point's effect averaged over the
  records with a 95 % t interval over records (the population view);
- ``statements.txt``: the plain-words statements; ``sensitivity.json``: the ``--json`` object.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from workbench.errors import UsageError
from workbench.fileutil import atomic_path, atomic_write_text, strict_json
from workbench.inference.pipeline import IdentifySettings
from workbench.records.record import Record
from workbench.sensitivity.analysis import (
    effects_table,
    pooled_effects,
    recovered,
    replicate_table,
    statements,
    summary_table,
    truth_values,
)
from workbench.sensitivity.design import (
    FACTORS,
    Level,
    build_design,
    default_levels,
    describe_levels,
)
from workbench.sensitivity.run import OUTPUTS, make_tasks, run_tasks

__all__ = [
    "DEMO_LEVELS",
    "SensitivityStudy",
    "demo_record",
    "demo_settings",
    "demo_study",
    "run_sensitivity",
]


@dataclass
class SensitivityStudy:
    """The result of :func:`run_sensitivity` (tables as pandas frames)."""

    design: str
    factors: list[str]
    levels: dict[str, list[Level]]
    base: IdentifySettings
    replicates: int
    seed: int
    records: list[str]
    replicate_rows: pd.DataFrame
    summary: pd.DataFrame
    effects: pd.DataFrame
    statements: list[dict[str, Any]]
    truths: dict[str, dict[str, float]]
    recovered: dict[str, Any]
    files: dict[str, str] = field(default_factory=dict)

    @property
    def pooled(self) -> pd.DataFrame:
        """Effects across the records (:func:`~workbench.sensitivity.analysis.pooled_effects`)."""
        return pooled_effects(self.effects)

    @property
    def defaults(self) -> dict[str, str]:
        """Default level label of each factor."""
        return {n: next(lv.label for lv in lv_ if lv.is_default) for n, lv_ in self.levels.items()}

    def _setting_levels(self) -> list[tuple[str, str, bool, str]]:
        """Return (setting, level, is_default, point key) in table order."""
        out = []
        if self.design == "oat":
            for name, lvls in self.levels.items():
                for lv in lvls:
                    point = "baseline" if lv.is_default else f"{name}={lv.label}"
                    out.append((name, lv.label, lv.is_default, point))
        else:
            for point in self.summary["point"].drop_duplicates():
                out.append(("factorial", str(point), point == "baseline", str(point)))
        return out

    def tidy(self) -> pd.DataFrame:
        """Return the tidy table written as ``sensitivity.csv`` (module docstring)."""
        frames = []
        for setting, level, is_default, point in self._setting_levels():
            for kind, frame in (("replicate", self.replicate_rows), ("summary", self.summary)):
                part = frame[frame["point"] == point].copy()
                if part.empty:
                    continue
                part.insert(1, "setting", setting)
                part.insert(2, "level", level)
                part.insert(3, "is_default", is_default)
                part.insert(4, "row", kind)
                frames.append(part)
        table = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
        lead = ["record", "setting", "level", "is_default", "row", "point", "replicate", "seed"]
        cols = [c for c in lead if c in table.columns]
        cols += [c for c in table.columns if c not in cols]
        return table[cols]

    def rows(self) -> list[dict[str, Any]]:
        """One JSON row per record, setting and level: parameters and their spreads."""
        out = []
        eff = self.effects
        for record in self.records:
            s = self.summary[self.summary["record"] == record]
            for setting, level, is_default, point in self._setting_levels():
                hit = s[s["point"] == point]
                if hit.empty:
                    continue
                r = hit.iloc[0]
                row: dict[str, Any] = {
                    "record": record,
                    "setting": setting,
                    "level": level,
                    "is_default": bool(is_default),
                    "point": point,
                    "replicates": int(r["replicates"]),
                    "failed": int(r["failed"]),
                    "identified_replicates": int(r["identified"]),
                }
                for o in OUTPUTS:
                    row[o] = _clean(r[o])
                    row[f"{o}_mc_sd"] = _clean(r[f"{o}_mc_sd"])
                    row[f"{o}_posterior_sd"] = _clean(r[f"{o}_sd"])
                if not is_default and not eff.empty:
                    e = eff[(eff["record"] == record) & (eff["point"] == point)]
                    row["effects"] = {
                        str(x["output"]): {
                            "effect": _clean(x["effect"]),
                            "mc_halfwidth_95": _clean(x["mc_halfwidth_95"]),
                            "posterior_sd_ratio": _clean(x["posterior_sd_ratio"]),
                            "verdict": str(x["verdict"]),
                        }
                        for _, x in e.iterrows()
                    }
                out.append(row)
        return out

    def default_recovers_truth(self) -> dict[str, bool]:
        """Per record with a truth: whether the baseline's 95 % bands hold every true output."""
        return {rec: bool(p.get("baseline", {}).get("all")) for rec, p in self.recovered.items()}

    def to_json(self) -> dict[str, Any]:
        """Return the ``workbench sensitivity --json`` object."""
        return {
            "design": self.design,
            "factors": self.factors,
            "levels": describe_levels(self.levels),
            "replicates": self.replicates,
            "seed": self.seed,
            "settings": self.base.to_json(),
            "records": self.records,
            "runs": len(self.replicate_rows),
            "failed_runs": int((self.replicate_rows["status"] != "done").sum()),
            "rows": self.rows(),
            "statements": self.statements,
            "pooled": [
                {k: (_clean(v) if isinstance(v, float) else v) for k, v in r.items()}
                for r in self.pooled.to_dict("records")
            ],
            "truth": self.truths,
            "default_recovers_truth": self.default_recovers_truth(),
            "files": self.files,
        }

    def text(self) -> str:
        """Human-readable summary: the statements."""
        lines = [
            f"sensitivity ({self.design}, {len(self.factors)} settings, {self.replicates} "
            f"replicates) on {len(self.records)} record(s)"
        ]
        for rec, ok in self.default_recovers_truth().items():
            lines.append(
                f"{rec}: default settings {'recover' if ok else 'do NOT recover'} the truth "
                "(95 % bands)"
            )
        lines += [f"- {s['record']}: {s['sentence']}" for s in self.statements]
        return "\n".join(lines)

    def write(self, out_dir: str | Path) -> dict[str, str]:
        """Write the tables, statements and JSON into ``out_dir`` (module docstring)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        files = {
            "table": out / "sensitivity.csv",
            "effects": out / "effects.csv",
            "statements": out / "statements.txt",
            "json": out / "sensitivity.json",
        }
        frames = [("table", self.tidy()), ("effects", self.effects)]
        if len(self.records) > 1:
            files["pooled"] = out / "pooled_effects.csv"
            frames.append(("pooled", self.pooled))
        for key, frame in frames:
            with atomic_path(files[key]) as tmp:
                frame.to_csv(tmp, index=False, float_format="%.10g", lineterminator="\n")
        atomic_write_text(
            files["statements"],
            "\n".join(f"{s['record']}: {s['sentence']}" for s in self.statements) + "\n",
        )
        self.files = {k: str(v) for k, v in files.items()}
        atomic_write_text(
            files["json"],
            json.dumps(strict_json(self.to_json()), indent=2, default=_json_default) + "\n",
        )
        return self.files


def _clean(x: Any) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def _json_default(obj: Any) -> Any:
    if hasattr(obj, "item"):
        return obj.item()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


def run_sensitivity(
    records: Sequence[tuple[str, Record]],
    *,
    base: IdentifySettings | None = None,
    factors: Sequence[str] | None = None,
    levels: dict[str, list[Level]] | None = None,
    design: str = "oat",
    replicates: int = 3,
    seed: int = 0,
    workers: int = 1,
    scheduler: str | None = None,
    progress: bool = False,
) -> SensitivityStudy:
    """Run a sensitivity study of the identification settings on one or more records.

    Parameters
    ----------
    records : sequence of (str, Record)
        Records with a stable key each (a manifest path or a name); a simulated record's
        ``metadata["truth"]`` is used as the truth.
    base : IdentifySettings, optional
        The baseline settings (default: :class:`IdentifySettings` defaults).
    factors : sequence of str, optional
        Factor names (:data:`~workbench.sensitivity.design.FACTORS`); all when not given.
    levels : dict, optional
        Levels replacing the defaults for some factors
        (:func:`~workbench.sensitivity.design.parse_levels`).
    design : {"oat", "factorial"}
        One at a time or full factorial.
    replicates : int
        Runs per design point with different seeds.
    seed : int
        Study seed; each run's seed derives from it
        (:func:`~workbench.sensitivity.design.point_seed`).
    workers : int
        Local processes.
    scheduler : str, optional
        Dask scheduler address.
    progress : bool
        Show a progress bar.

    Returns
    -------
    SensitivityStudy
    """
    base = base or IdentifySettings()
    names = list(factors) if factors else list(FACTORS)
    for n in names:
        if n not in FACTORS:
            raise UsageError(f"{n!r} is not a sensitivity factor; choose from {', '.join(FACTORS)}")
    if not records:
        raise UsageError("the sensitivity study needs at least one record")
    keys = [k for k, _ in records]
    if len(set(keys)) != len(keys):
        raise UsageError("two records of the study have the same key; give each a unique name")
    chosen = {n: (levels or {}).get(n) or default_levels(n, base) for n in names}
    _, points = build_design(design, chosen)
    if design == "factorial" and len(points) * replicates * len(records) > 2000:
        raise UsageError(
            f"the factorial design has {len(points)} points x {replicates} replicates per "
            "record; name fewer factors or give fewer levels"
        )
    tasks = make_tasks(records, points, base, replicates, seed)
    rows = run_tasks(tasks, workers=workers, scheduler=scheduler, progress=progress)
    reps = replicate_table(rows, names)
    summary = summary_table(reps, names)
    truths = {k: t for k, r in records if (t := truth_values(r.metadata.get("truth")))}
    effects = effects_table(summary, names, truths)
    desc = {n: FACTORS[n].description for n in names}
    defaults = {n: next(lv.label for lv in chosen[n] if lv.is_default) for n in names}
    return SensitivityStudy(
        design=design,
        factors=names,
        levels=chosen,
        base=base,
        replicates=replicates,
        seed=seed,
        records=keys,
        replicate_rows=reps,
        summary=summary,
        effects=effects,
        statements=statements(effects, desc, defaults),
        truths=truths,
        recovered=recovered(summary, truths),
    )


#: Levels of the demonstration study: one setting that only widens (u'' noise x4), one that
#: biases (a prior box whose log-width is 5 % of the default's, excluding the truth), and
#: the seed's process noise of (u, u'), which the data do not have.
DEMO_LEVELS = ("obs_noise_ddu=1,4", "prior_box=1,0.05", "state_noise=0,0.005")


def demo_record(seed: int = 1) -> tuple[str, Record]:
    """Return a record in the model class with a known truth: 8 s at 100 Hz from rest, 70 kg.

    No step-to-step variability, so a whole-record Fourier force on absolute time with the
    stated pacing is the generating model, and the start-up transient identifies C and K.
    """
    from workbench.synth.simulate import simulate_walking

    sim = simulate_walking(
        mass_kg=70.0,
        pacing_hz=1.8,
        duration_s=8.0,
        sample_rate_hz=100.0,
        start="rest",
        seed=seed,
        noise_sd_n=2.0,
        amplitude_sd=0.0,
        phase_sd_rad=0.0,
        step_duration_sd=0.0,
    )
    return f"simulated-rest-seed{seed}", sim.record


def demo_settings(particles: int = 32) -> IdentifySettings:
    """Baseline settings for :func:`demo_record`: the model class's (whole, absolute, acc)."""
    return IdentifySettings.from_flat(
        method="rbpf",
        particles=particles,
        harmonics=4,
        pieces="whole",
        time_basis="absolute",
        pacing_hz=1.8,
        highpass_hz=0.0,
        observe="acc",
        force_check=False,
    )


def demo_study(seed: int = 0, replicates: int = 2, workers: int = 1) -> SensitivityStudy:
    """Run the small study of :data:`DEMO_LEVELS` on :func:`demo_record` (about half a minute)."""
    from workbench.sensitivity.design import parse_levels

    base = demo_settings()
    levels = parse_levels(list(DEMO_LEVELS), base)
    return run_sensitivity(
        [demo_record()],
        base=base,
        factors=list(levels),
        levels=levels,
        replicates=replicates,
        seed=seed,
        workers=workers,
    )
