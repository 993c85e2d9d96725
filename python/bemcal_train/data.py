"""Training-set loading and feature construction (no torch here: pure numpy).

Dataset directory (written by Rust ``TrainingSet::write``):

* ``params.npy``  f64 [n_points, n_params]  raw parameter values
* ``weather.npy`` f64 [n_hours, 5]          raw weather (dry bulb C, RH %, wind m/s, GHI Wh/m2, day type code)
* ``outputs.npy`` f64 [n_points, n_hours, n_outputs]  kWh per hour
* ``dataset.json`` names, parameter bounds and modes, split by design point

Feature vector of hour t for design point i (``feature_names`` order):
``[(p_i - min)/(max - min) ..., (w_t - mean)/std ..., time features of t ...]``.
A sample is the window of hours (t-2, t-1, t); hours before 0 repeat hour 0.
"""

import json
import os

import numpy as np

from . import DATASET_FORMAT_VERSION, LOOKBACK

TIME_FEATURES = ("none", "hour", "hour+schedule")


def load_dataset(path):
    """Reads and validates a dataset directory; returns a dict of arrays and metadata."""
    with open(os.path.join(path, "dataset.json")) as f:
        meta = json.load(f)
    if meta.get("format_version") != DATASET_FORMAT_VERSION:
        raise ValueError(
            f"{path}/dataset.json: format_version {meta.get('format_version')} is not "
            f"{DATASET_FORMAT_VERSION}"
        )
    params = np.load(os.path.join(path, "params.npy"))
    weather = np.load(os.path.join(path, "weather.npy"))
    outputs = np.load(os.path.join(path, "outputs.npy"))
    n_p, n_h, n_o = len(meta["params"]), meta["n_hours"], len(meta["output_names"])
    if params.shape != (meta["n_points"], n_p):
        raise ValueError(f"params.npy shape {params.shape}, expected {(meta['n_points'], n_p)}")
    if weather.shape != (n_h, 5):
        raise ValueError(f"weather.npy shape {weather.shape}, expected {(n_h, 5)}")
    if outputs.shape != (meta["n_points"], n_h, n_o):
        raise ValueError(f"outputs.npy shape {outputs.shape}, expected {(meta['n_points'], n_h, n_o)}")
    return {"meta": meta, "params": params, "weather": weather, "outputs": outputs}


def normalise_params(raw, specs):
    """(p - min) / (max - min) per column; raw is [..., n_params]."""
    lo = np.array([p["min"] for p in specs], dtype=np.float64)
    hi = np.array([p["max"] for p in specs], dtype=np.float64)
    return (np.asarray(raw, dtype=np.float64) - lo) / (hi - lo)


def weather_stats(weather):
    """Mean and std per weather column; a constant column gets std 1."""
    mean = weather.mean(axis=0)
    std = weather.std(axis=0)
    std = np.where(std > 1e-12, std, 1.0)
    return mean, std


def time_feature_names(mode):
    if mode == "none":
        return []
    if mode == "hour":
        return ["hour_sin", "hour_cos"]
    if mode == "hour+schedule":
        return ["hour_sin", "hour_cos", "offday_hour_sin", "offday_hour_cos"]
    raise ValueError(f"time features '{mode}': expected one of {TIME_FEATURES}")


def time_features(weather, mode):
    """Time-of-day features per hour, [n_hours, k]. Hour of day h = t mod 24 (hour beginning).

    * ``hour``: sin, cos of 2*pi*h/24.
    * ``hour+schedule``: those plus the same two multiplied by the off-day flag (the day type
      code clamped to 0..1: weekend or holiday 1, a partial day 0.5), so working days and off
      days get their own daily profile.
    """
    n = weather.shape[0]
    h = np.arange(n) % 24
    ang = 2.0 * np.pi * h / 24.0
    cols = []
    if mode in ("hour", "hour+schedule"):
        cols += [np.sin(ang), np.cos(ang)]
    if mode == "hour+schedule":
        off = np.clip(weather[:, 4], 0.0, 1.0)  # days off 1, partial days (code 0.5) 0.5
        cols += [off * np.sin(ang), off * np.cos(ang)]
    time_feature_names(mode)
    return np.stack(cols, axis=1) if cols else np.zeros((n, 0))


def hourly_features(weather, mean, std, mode):
    """The per-hour part of the feature vector: normalised weather then time features, [n_hours, k]."""
    w = (weather - mean) / std
    return np.concatenate([w, time_features(weather, mode)], axis=1)


SCHEDULE_COLUMNS = ["off_day", "occupied", "schedule_fixed"]
"""The schedule inputs' first hourly columns (a ``ScheduledSurrogate``'s), before one indicator
per calibrated schedule parameter."""


def schedule_column_names(table, param_names):
    """Names of ``schedule_columns``'s columns."""
    return SCHEDULE_COLUMNS + [f"schedule_is_{param_names[i]}" for i in table["params"]]


def schedule_columns(weather, table):
    """The schedule's hourly inputs, [n_hours, 3 + K], from the building's schedule table
    (``surrogate.json``'s ``schedule_inputs``, written by ``pretrain fold``): per hour, the
    off-day flag (day type code != 0), the occupied flag, the value of the schedule interval
    covering the hour where it is fixed (0 where it is calibrated), and one indicator per
    calibrated schedule parameter (``table["params"]``, K of them) covering the hour. Hour of
    day ``t mod 24``; off days run the off-day table. Identical to the Rust runtime's
    ``SurrogateMeta::hourly_inputs``."""
    n = weather.shape[0]
    k = len(table["params"])
    out = np.zeros((n, 3 + k))
    off = weather[:, 4] != 0
    h = np.arange(n) % 24
    for kind, rows in (("working", ~off), ("off", off)):
        day = table[kind]
        interval = np.asarray(day["interval"])[h[rows]]
        out[rows, 0] = 1.0 if kind == "off" else 0.0
        out[rows, 1] = np.asarray(day["occupied"], dtype=np.float64)[h[rows]]
        out[rows, 2] = np.where(interval < 0, np.asarray(day["fixed"], dtype=np.float64)[h[rows]], 0.0)
        idx = np.nonzero(rows)[0]
        cal = interval >= 0
        out[idx[cal], 3 + interval[cal]] = 1.0
    return out


def window_index(n_hours):
    """[n_hours, LOOKBACK] hour indices of each window (t-2, t-1, t), clamped at 0."""
    t = np.arange(n_hours)[:, None] + np.arange(-(LOOKBACK - 1), 1)[None, :]
    return np.maximum(t, 0)
