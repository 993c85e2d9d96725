"""``bemcal.load``: a calibration's output folder as Python objects.

The posterior is an :class:`arviz.InferenceData` with the groups ArviZ's plots and statistics
expect (``posterior``, ``sample_stats``, ``prior``, ``observed_data``, ``posterior_predictive``,
``constant_data``); Guideline 14 metrics and hourly predictions are pandas DataFrames; the
estimate is a dict. Everything is read from the files ``bemcal calibrate`` writes (the folder's
layout is in the repository's ARCHITECTURE.md): ``draws.csv``, ``summary.json``,
``dataset/``, ``validation/`` and ``posterior_predictive.csv``.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Union

import numpy as np
import pandas as pd

#: Sampler statistics in ``draws.csv`` (CmdStan's column names) and ArviZ's names for them.
SAMPLER_STATS = {
    "log_posterior": "lp",
    "accept_stat__": "acceptance_rate",
    "stepsize__": "step_size",
    "n_leapfrog__": "n_steps",
    "divergent__": "diverging",
}

#: Draws of each parameter's prior in the ``prior`` group (one chain, fixed seed).
PRIOR_DRAWS = 1000


@dataclass
class Calibration:
    """One calibration's results (see :func:`load`)."""

    #: The output folder.
    out_dir: Path
    #: ``summary.json`` as it is.
    summary: dict
    #: ``draws.csv`` as it is: one row per chain and draw, parameters and sampler statistics.
    draws: pd.DataFrame
    #: The posterior and its companions, for ArviZ (``az.summary``, ``az.plot_trace``, ...).
    posterior: "object"
    #: Guideline 14 (ASHRAE 2014) per model, meter, period and resolution: a tidy DataFrame
    #: with columns model (calibrated / initial / surrogate), output, period (in_sample /
    #: held_out), resolution (hourly / monthly), n, mean_measured, nmbe_pct, cv_rmse_pct, passes.
    metrics: pd.DataFrame
    #: Hourly predictions indexed by timestamp: measured meters, EnergyPlus at the estimate
    #: (``<output>_calibrated``), the surrogate's posterior quantiles (``<output>_q5/q50/q95``)
    #: and, where simulated, the predictive intervals from EnergyPlus at posterior draws with
    #: the error model's noise, recalibrated on the calibration period (``<output>_pi5 ..
    #: _pi95``: the bounds of the 90 % and 50 % intervals; ``held_out`` marks held-out hours).
    predictions: pd.DataFrame
    #: The calibrated parameters' values at the estimate (``summary.json`` ``estimate``: by
    #: default the posterior draw EnergyPlus fits best by Guideline 14's hourly criteria).
    estimate: Dict[str, float]
    #: The calibrated EnergyPlus model (every parameter at its calibrated or fixed value).
    model_path: Optional[Path]
    #: Whether the chains met their R-hat and ESS targets.
    converged: bool
    #: The calibrated parameters, in the draws' order.
    parameters: List[str] = field(default_factory=list)
    #: The sampled noise scales (``sigma_delta_<output>``), where the calibration sampled them;
    #: in the ``posterior`` group beside the parameters.
    noise: List[str] = field(default_factory=list)
    #: Retrofit measures' savings (``bemcal savings``; empty before it ran): a tidy DataFrame
    #: with columns measure, output, weather (calibration / typical), month (NaN: the year;
    #: 1-12), n (draws), median_kwh, q5_kwh, q25_kwh, q75_kwh, q95_kwh (the 90 % and 50 %
    #: credible intervals), median_pct, at_estimate_kwh (the year's) and warning.
    savings: pd.DataFrame = field(default_factory=lambda: savings_frame({}))

    def __repr__(self) -> str:
        return (
            f"Calibration({self.summary.get('project')!r}, {len(self.parameters)} parameters, "
            f"{self.draws['chain'].nunique()} chains x {self.draws.groupby('chain').size().iloc[0]} "
            f"draws, converged={self.converged}, out_dir={str(self.out_dir)!r})"
        )


def load(out_dir: Union[str, Path]) -> Calibration:
    """Reads a finished calibration's output folder ``out_dir``."""
    out = Path(out_dir)
    summary_file = out / "summary.json"
    if not summary_file.is_file():
        raise FileNotFoundError(
            f"{summary_file}: no summary.json (is {out} the --out folder of a finished calibration?)"
        )
    summary = json.loads(summary_file.read_text())
    draws = pd.read_csv(out / "draws.csv")
    # Columns as bemcal writes them (bemcal_report::io::Draws): chain, draw, the calibrated
    # parameters, the noise, the log posterior and the sampler's statistics.
    sampled = [c for c in draws.columns if c not in ("chain", "draw") and c not in SAMPLER_STATS]
    noise = [c for c in sampled if c.startswith("sigma_delta_")]
    parameters = [c for c in sampled if c not in noise]
    model = out / "calibrated.idf"
    return Calibration(
        out_dir=out,
        summary=summary,
        draws=draws,
        posterior=inference_data(out, summary, draws, parameters, noise),
        metrics=metrics_frame(summary),
        predictions=predictions_frame(out),
        estimate=named(summary.get("calibrated_values", {})),
        model_path=model if model.is_file() else None,
        converged=bool(summary.get("converged", False)),
        parameters=parameters,
        noise=noise,
        savings=savings_frame(summary),
    )


def named(pairs) -> Dict[str, float]:
    """``{name: value}`` from either a JSON object or a list of ``[name, value]`` pairs (the
    form older output folders wrote)."""
    if isinstance(pairs, dict):
        return {str(k): float(v) for k, v in pairs.items()}
    return {str(k): float(v) for k, v in pairs}


def by_chain(draws: pd.DataFrame, column: str) -> np.ndarray:
    """One column of the draws as an array (chain, draw), chains and draws in order."""
    table = draws.pivot(index="chain", columns="draw", values=column)
    return table.sort_index().sort_index(axis=1).to_numpy()


def inference_data(
    out: Path, summary: dict, draws: pd.DataFrame, parameters: List[str], noise: List[str] = ()
):
    """The ArviZ InferenceData of a calibration: the parameters and the sampled noise in its
    ``posterior`` group, the parameters' priors in ``prior``."""
    az = arviz()

    posterior = {p: by_chain(draws, p) for p in [*parameters, *noise]}
    sample_stats = {
        name: by_chain(draws, column)
        for column, name in SAMPLER_STATS.items()
        if column in draws.columns
    }
    if "diverging" in sample_stats:
        sample_stats["diverging"] = sample_stats["diverging"].astype(bool)
    if "n_steps" in sample_stats:
        sample_stats["n_steps"] = sample_stats["n_steps"].astype(np.int64)
    groups = dict(
        posterior=posterior,
        sample_stats=sample_stats,
        prior=prior_draws(summary, parameters),
    )
    coords = {}
    dims = {}

    hourly = hourly_frames(out)
    if hourly is not None:
        measured, timestamps = hourly["measured"], hourly["timestamps"]
        coords["hour"] = timestamps
        groups["observed_data"] = {k: v for k, v in measured.items()}
        dims.update({k: ["hour"] for k in measured})
        simulated = predictive_draws(out, list(measured))
        if simulated:
            groups["posterior_predictive"] = simulated
    weather = weather_features(out)
    if weather is not None and "hour" in coords and len(coords["hour"]) == len(
        next(iter(weather.values()))
    ):
        groups["constant_data"] = weather
        dims.update({k: ["hour"] for k in weather})
    data = az.from_dict(**groups, coords=coords, dims=dims)
    holdout = summary.get("holdout") or {}
    data.posterior.attrs.update(
        project=summary.get("project", ""),
        converged=int(bool(summary.get("converged", False))),
        estimate=summary.get("estimate", ""),
    )
    if "posterior_predictive" in groups:
        data.posterior_predictive.attrs["note"] = (
            "EnergyPlus at posterior draws (validation/predictive_NN.csv), without the "
            "likelihood's noise; validation/predictive_intervals.csv adds it and recalibrates "
            "the intervals on the calibration period"
        )
    if "observed_data" in groups:
        data.observed_data.attrs["held_out"] = str(holdout.get("period") or "")
    data.prior.attrs["note"] = (
        "triangular priors of summary.json, independent draws (the model's constraints, such "
        "as heating set-point <= cooling set-point, are not applied)"
    )
    return data


def arviz():
    """ArviZ, imported without its banner about the coming 1.0 refactor (bemcal pins < 0.24)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz as az
    return az


def prior_draws(summary: dict, parameters: List[str]) -> Dict[str, np.ndarray]:
    """Independent draws of each calibrated parameter's triangular prior, shape (1, draws)."""
    priors = {p["name"]: p for p in summary.get("parameters", [])}
    rng = np.random.default_rng(0)
    out = {}
    for name in parameters:
        p = priors.get(name)
        if p is None:
            continue
        lo, mode, hi = p["prior_min"], p["prior_mode"], p["prior_max"]
        out[name] = rng.triangular(lo, mode, hi, size=(1, PRIOR_DRAWS)) if hi > lo else np.full(
            (1, PRIOR_DRAWS), lo
        )
    return out


def hourly_frames(out: Path):
    """Measured meters by output (NaN = missing) and the hours' timestamps."""
    path = out / "posterior_predictive.csv"
    if not path.is_file():
        return None
    table = pd.read_csv(path)
    timestamps = pd.to_datetime(table["timestamp"]).to_numpy()
    measured = {
        c[: -len("_measured")]: table[c].to_numpy(dtype=float)
        for c in table.columns
        if c.endswith("_measured")
    }
    return {"measured": measured, "timestamps": timestamps}


def predictive_draws(out: Path, outputs: List[str]) -> Dict[str, np.ndarray]:
    """EnergyPlus's hourly outputs at the posterior draws simulated for the predictive intervals
    (``validation/predictive_NN.csv``), shape (1, draws, hours) per output."""
    files = sorted((out / "validation").glob("predictive_[0-9][0-9].csv"))
    if not files:
        return {}
    runs = [pd.read_csv(f) for f in files]
    return {
        o: np.stack([r[o].to_numpy(dtype=float) for r in runs])[np.newaxis]
        for o in outputs
        if all(o in r.columns for r in runs)
    }


def weather_features(out: Path) -> Optional[Dict[str, np.ndarray]]:
    """The hourly weather the surrogate saw (``dataset/weather.npy`` and its names)."""
    meta_file, data_file = out / "dataset" / "dataset.json", out / "dataset" / "weather.npy"
    if not (meta_file.is_file() and data_file.is_file()):
        return None
    names = json.loads(meta_file.read_text()).get("weather_features", [])
    weather = np.load(data_file)
    return {name: weather[:, k] for k, name in enumerate(names) if k < weather.shape[1]}


def metrics_frame(summary: dict) -> pd.DataFrame:
    """Guideline 14 of every model the summary judges, as one tidy table."""
    rows = []
    models = {
        "calibrated": summary.get("validation") or [],
        "initial": summary.get("initial") or [],
        "surrogate": summary.get("surrogate_at_estimate") or [],
    }
    for model, outputs in models.items():
        for m in outputs:
            held = m.get("held_out") or {}
            periods = [
                ("in_sample", "hourly", m),
                ("in_sample", "monthly", m.get("monthly")),
                ("held_out", "hourly", held.get("hourly")),
                ("held_out", "monthly", held.get("monthly")),
            ]
            for period, resolution, g in periods:
                if not g:
                    continue
                rows.append(
                    dict(
                        model=model,
                        output=m["output"],
                        period=period,
                        resolution=resolution,
                        n=g.get("n"),
                        mean_measured=g.get("mean_measured"),
                        nmbe_pct=g.get("nmbe"),
                        cv_rmse_pct=g.get("cv_rmse"),
                        passes=g.get("pass"),
                    )
                )
    columns = [
        "model", "output", "period", "resolution", "n", "mean_measured", "nmbe_pct",
        "cv_rmse_pct", "passes",
    ]
    return pd.DataFrame(rows, columns=columns)


def savings_frame(summary: dict) -> pd.DataFrame:
    """``summary.json``'s ``savings`` as one tidy table: a row per measure, output, weather
    and period (the year, then each month), with the measure's edits (``; ``-joined) and how
    its savings were estimated (``energyplus`` or ``surrogate_corrected``)."""
    rows = []
    for m in (summary.get("savings") or {}).get("measures") or []:
        for o in m.get("outputs") or []:
            periods = [(float("nan"), o["savings_kwh"], o.get("savings_percent"))]
            periods += [(float(k + 1), s, None) for k, s in enumerate(o.get("monthly_kwh") or [])]
            for month, s, pct in periods:
                (q5, q95), (q25, q75) = s["interval_90"], s["interval_50"]
                rows.append(
                    dict(
                        measure=m["measure"],
                        edits="; ".join(m.get("edits") or []),
                        method=m.get("method"),
                        output=o["output"],
                        weather=o["weather"],
                        month=month,
                        n=o["n"],
                        median_kwh=s["median"],
                        q5_kwh=q5,
                        q25_kwh=q25,
                        q75_kwh=q75,
                        q95_kwh=q95,
                        median_pct=pct["median"] if pct else float("nan"),
                        at_estimate_kwh=o["at_estimate_kwh"] if pct else float("nan"),
                        warning=o.get("warning"),
                    )
                )
    columns = [
        "measure", "edits", "method", "output", "weather", "month", "n", "median_kwh", "q5_kwh", "q25_kwh",
        "q75_kwh", "q95_kwh", "median_pct", "at_estimate_kwh", "warning",
    ]
    return pd.DataFrame(rows, columns=columns)


def predictions_frame(out: Path) -> pd.DataFrame:
    """Hourly measured meters, EnergyPlus at the estimate, posterior quantiles and intervals."""
    frames = []
    pp = out / "posterior_predictive.csv"
    if pp.is_file():
        frames.append(pd.read_csv(pp, index_col="timestamp"))
    calibrated = out / "validation" / "calibrated.csv"
    if calibrated.is_file():
        frames.append(pd.read_csv(calibrated, index_col="timestamp").add_suffix("_calibrated"))
    intervals = out / "validation" / "predictive_intervals.csv"
    if intervals.is_file():
        t = pd.read_csv(intervals, index_col="timestamp")
        t = t.drop(columns=[c for c in t.columns if c.endswith("_measured")])
        t.columns = [re.sub(r"_q(\d+)$", r"_pi\1", c) for c in t.columns]
        if "held_out" in t.columns:
            t["held_out"] = t["held_out"].astype(bool)
        frames.append(t)
    if not frames:
        return pd.DataFrame()
    table = pd.concat(frames, axis=1)
    table.index = pd.to_datetime(table.index)
    return table
