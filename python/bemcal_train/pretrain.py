"""The pretrained, building-conditioned surrogate (issue 66) and its learning curve.

One LSTM (the reference's family: lookback 3, ReLU after the last step, a linear head) for the
whole building family, trained once on a corpus of generated buildings (``bemcal corpus``) and
fine-tuned per building on a few of its own EnergyPlus runs. What makes it transfer:

* **Inputs that do not assume one parameter layout.** A building's schedule intervals (how many,
  where they end) vary, so schedule fractions enter as the hourly *value* of the schedule at
  that hour (from the intervals, the day type and the parameters), beside an occupied-hours
  flag; the engineering parameters enter by name (a system without one, the fan coils' DOAS
  without unoccupied outdoor air, gets 0 and a flag). The hot-water peak flow enters per m2.
* **The building's descriptors** (storeys, footprint, floor-to-floor height, window-to-wall
  ratio, zoning, heating source, HVAC system, occupied hours and the envelope ratios that follow)
  beside them, constant over the year.
* **Outputs per m2 of floor** (Wh/m2 per hour), a scale that carries between buildings.

Corpus folder (``crates/corpus/src/store.rs``): ``index.jsonl`` (one finished case a line:
spec, values, climate, floor area), ``cases/<key>.npy`` float16 [8760, 5] and
``weather/<climate>.npy`` float32 [8760, 5].

Command line::

    python -m bemcal_train.pretrain curve --corpus DIR --heldout DIR --sizes 100,200 --out DIR
    python -m bemcal_train.pretrain train --corpus DIR --cases N --out DIR [--inputs foldable]
    python -m bemcal_train.pretrain fold --pretrained DIR --dataset DIR --building FILE --hidden H --out DIR

``fold`` turns the network into one building's surrogate, exactly: a ``ScheduledSurrogate``
(model.py) for the conditioned inputs, whose schedule table (``schedule_table``) the runtime
turns into hourly inputs; today's ``Surrogate`` for the foldable ones.
"""

import argparse
import json
import math
import os
import sys
import time

import numpy as np
import torch

from . import LOOKBACK
from .adam import Adam
from .data import window_index
from .model import Surrogate

# The generator's engineering parameters by name (crates/energyplus/src/building/mod.rs).
ENGINEERING = [
    "wall_insulation_conductivity", "roof_insulation_conductivity", "window_glass_conductivity",
    "shgc", "equipment_power_density", "lighting_power_density", "people_area_per_person",
    "cooling_setpoint_occupied", "cooling_setpoint_unoccupied", "heating_setpoint_occupied",
    "heating_setpoint_unoccupied", "chilled_water_supply_temp", "supply_air_temp",
    "outdoor_air_ach_occupied", "outdoor_air_ach_unoccupied", "hot_water_peak_flow",
]
DESCRIPTORS = [
    "storeys", "length_m", "width_m", "floor_to_floor_m", "window_to_wall", "perimeter_core",
    "district_heating", "doas_fan_coil", "occupied_start", "occupied_end", "log_floor_area",
    "perimeter_share", "wall_per_floor", "window_per_floor", "roof_per_floor", "no_unoccupied_oa",
]
HOURLY = ["dry_bulb_c", "rel_humidity_pct", "wind_speed_m_s", "global_horizontal_wh_m2",
          "off_day", "hour_sin", "hour_cos", "schedule", "occupied"]
# The foldable inputs (``--inputs foldable``): the schedule as a static 24-hour profile per day
# type (the value of the interval covering each hour), the hourly inputs those of today's
# surrogate (data.hourly_features, time features hour+schedule), so that the network folds
# into today's per-building surrogate (``fold``).
PROFILE = [f"weekday_h{h:02d}" for h in range(24)] + [f"weekend_h{h:02d}" for h in range(24)]
HOURLY_FOLDABLE = ["dry_bulb_c", "rel_humidity_pct", "wind_speed_m_s", "global_horizontal_wh_m2",
                   "day_type", "hour_sin", "hour_cos", "offday_hour_sin", "offday_hour_cos"]
INPUTS = ("conditioned", "foldable")
CALIBRATED_METERS = ["heating_kwh", "cooling_kwh", "electricity_kwh"]


def read_index(corpus):
    """The finished cases of a corpus folder, in the order of the manifest's sequence."""
    rows = []
    with open(os.path.join(corpus, "index.jsonl")) as f:
        for line in f:
            line = line.strip()
            if line:
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError:
                    pass  # a torn last line (a stop mid-write)
    rows.sort(key=lambda r: r["index"])
    return rows


def describe(spec):
    """The building's descriptors (DESCRIPTORS order) from its spec."""
    L, W = spec["footprint_m"]
    n, h = spec["storeys"], spec["floor_to_floor_m"]
    area = L * W * n
    pc = spec["zoning"] == "perimeter_core"
    d = spec.get("perimeter_depth_m", 4.57)
    perimeter_share = 1.0 - max(L - 2 * d, 0) * max(W - 2 * d, 0) / (L * W) if pc else 0.0
    wall = 2 * (L + W) * h * n / area
    doas = spec.get("hvac", "vav_reheat") == "doas_fan_coil"
    return [n, L, W, h, spec["window_to_wall"], float(pc),
            float(spec["heating_source"] == "district"), float(doas),
            spec["occupied_hours"][0], spec["occupied_hours"][1], math.log(area),
            perimeter_share, wall, wall * spec["window_to_wall"], 1.0 / n, float(doas)]


def engineering(values, area):
    """The engineering parameters (ENGINEERING order); a missing one is 0, hot water per m2."""
    out = []
    for name in ENGINEERING:
        v = values.get(name, 0.0)
        if name == "hot_water_peak_flow":
            v = v / area * 1e6  # ml/s per m2
        out.append(v)
    return out


def schedule_hours(spec, values, off_day):
    """The schedule's value and the occupied flag at every hour, [T, 2], from the spec's interval
    boundaries, the parameters and the day type (weekends and holidays run the weekend intervals)."""
    T = off_day.shape[0]
    hour = np.arange(T) % 24

    def profile(bounds, prefix):
        p = np.zeros(24)
        start = 0
        for i, end in enumerate(bounds):
            p[start:end] = values[f"{prefix}_{i + 1:02d}"]
            start = end
        return p

    wd = profile(spec["weekday_boundaries"], "schedule_weekday")
    we = profile(spec["weekend_boundaries"], "schedule_weekend")
    sched = np.where(off_day, we[hour], wd[hour])
    a, b = spec["occupied_hours"]
    occupied = (~off_day) & (hour >= a) & (hour < b)
    return np.stack([sched, occupied.astype(np.float64)], axis=1)


def profile_names(spec):
    """The schedule parameter covering each hour of a working day and of a day off (PROFILE
    order): ``schedule_weekday_NN`` / ``schedule_weekend_NN`` from the spec's boundaries."""
    names = []
    for bounds, prefix in ((spec["weekday_boundaries"], "schedule_weekday"),
                           (spec["weekend_boundaries"], "schedule_weekend")):
        start = 0
        for i, end in enumerate(bounds):
            names += [f"{prefix}_{i + 1:02d}"] * (end - start)
            start = end
    return names


def static_features(spec, values, area, inputs):
    """A case's static inputs: descriptors, engineering parameters and, for the foldable
    inputs, the 48-hour schedule profile."""
    out = describe(spec) + engineering(values, area)
    if inputs == "foldable":
        out += [values[n] for n in profile_names(spec)]
    return out


def hourly_foldable(w):
    """The foldable hourly inputs of a climate before normalisation, [T, 9]: the five raw weather
    columns (day type as its code) and the hour+schedule time features of data.time_features."""
    T = w.shape[0]
    ang = 2 * np.pi * (np.arange(T) % 24) / 24
    off = (w[:, 4] != 0).astype(np.float64)
    return np.concatenate([w[:, :5], np.stack([np.sin(ang), np.cos(ang), off * np.sin(ang),
                                                off * np.cos(ang)], axis=1)], axis=1)


class Corpus:
    """Cases as arrays: static features [N, S], per-case hourly schedule [N, T, 2], each case's
    climate index, climates' weather [C, T, 7] and targets [N, T, n_out] (Wh/m2)."""

    def __init__(self, folder, rows, climates=None, inputs="conditioned"):
        self.rows = rows
        self.inputs = inputs
        names = sorted({r["climate"] for r in rows})
        self.climates = climates if climates is not None else {}
        for c in names:
            if c not in self.climates:
                self.climates[c] = np.load(os.path.join(folder, "weather", f"{c}.npy")).astype(np.float64)
        with open(os.path.join(folder, "corpus.json")) as f:
            self.outputs = json.load(f)["outputs"]
        self.static = np.array([static_features(r["spec"], r["values"], r["floor_area_m2"], inputs)
                                for r in rows])
        self.climate = [r["climate"] for r in rows]
        self.sched = np.stack([schedule_hours(r["spec"], r["values"], self.climates[r["climate"]][:, 4] != 0)
                               for r in rows])
        self.y = np.stack([np.load(os.path.join(folder, "cases", f"{r['key']}.npy")).astype(np.float32)
                           for r in rows])

    def weather_hourly(self, climate):
        """A climate's hourly inputs before normalisation: its five features (day type as an
        off-day flag) and the hour of day, [T, 7]; for the foldable inputs, [T, 9]
        (``hourly_foldable``)."""
        w = self.climates[climate]
        if self.inputs == "foldable":
            return hourly_foldable(w)
        T = w.shape[0]
        ang = 2 * np.pi * (np.arange(T) % 24) / 24
        return np.concatenate([w[:, :4], (w[:, 4:5] != 0).astype(np.float64),
                               np.sin(ang)[:, None], np.cos(ang)[:, None]], axis=1)


class Normaliser:
    """Mean and standard deviation of the static and hourly inputs, and each output's scale,
    fitted on the pretraining cases and kept with the network (the model card)."""

    def __init__(self, corpus=None, state=None):
        if state is not None:
            self.__dict__.update({k: np.asarray(v) for k, v in state.items()})
            return
        s = corpus.static
        self.static_mean, self.static_std = s.mean(0), np.where(s.std(0) > 1e-9, s.std(0), 1.0)
        self.y_scale = np.maximum(np.quantile(corpus.y.reshape(-1, corpus.y.shape[2]), 0.999, axis=0), 1e-6)
        if corpus.inputs == "foldable":
            # The weather's five columns normalised (over the corpus's climates); the time
            # features as they are.
            h = np.concatenate([corpus.weather_hourly(c) for c in sorted(set(corpus.climate))])
            mean, std = h.mean(0), np.where(h.std(0) > 1e-9, h.std(0), 1.0)
            mean[5:], std[5:] = 0.0, 1.0
            self.hourly_mean, self.hourly_std = mean, std
            return
        h = np.concatenate([np.concatenate([corpus.weather_hourly(c), np.zeros((corpus.y.shape[1], 2))], 1)
                            for c in sorted(set(corpus.climate))])
        sc = corpus.sched.reshape(-1, 2)
        mean = h.mean(0)
        std = np.where(h.std(0) > 1e-9, h.std(0), 1.0)
        mean[-2:], std[-2:] = sc.mean(0), np.where(sc.std(0) > 1e-9, sc.std(0), 1.0)
        # The hour-of-day and off-day columns stay as they are.
        mean[4:7], std[4:7] = 0.0, 1.0
        self.hourly_mean, self.hourly_std = mean, std

    def state(self):
        return {k: np.asarray(v).tolist() for k, v in self.__dict__.items()}


class Windows:
    """Window batches on the device: static features of the case, the climate's weather and the
    case's schedule at hours t-2..t."""

    def __init__(self, corpus, norm, device):
        cl = sorted(corpus.climates)
        self.ci = torch.as_tensor([cl.index(c) for c in corpus.climate], device=device)
        self.foldable = corpus.inputs == "foldable"
        if self.foldable:
            self.w = torch.as_tensor(np.stack([(corpus.weather_hourly(c) - norm.hourly_mean) / norm.hourly_std
                                               for c in cl]), dtype=torch.float32, device=device)  # [C, T, 9]
            self.s = torch.as_tensor((corpus.static - norm.static_mean) / norm.static_std,
                                     dtype=torch.float32, device=device)
            self.y = torch.as_tensor(corpus.y / norm.y_scale, dtype=torch.float32, device=device)
            self.widx = torch.as_tensor(window_index(corpus.y.shape[1]), device=device)
            self.n_features = self.s.shape[1] + 9
            return
        self.w = torch.as_tensor(np.stack([(np.concatenate([corpus.weather_hourly(c), np.zeros((corpus.y.shape[1], 2))], 1)
                                            - norm.hourly_mean) / norm.hourly_std for c in cl])[..., :7],
                                 dtype=torch.float32, device=device)  # [C, T, 7]
        self.sched = torch.as_tensor((corpus.sched - norm.hourly_mean[7:]) / norm.hourly_std[7:],
                                     dtype=torch.float32, device=device)  # [N, T, 2]
        self.s = torch.as_tensor((corpus.static - norm.static_mean) / norm.static_std,
                                 dtype=torch.float32, device=device)  # [N, S]
        self.y = torch.as_tensor(corpus.y / norm.y_scale, dtype=torch.float32, device=device)  # [N, T, O]
        self.widx = torch.as_tensor(window_index(corpus.y.shape[1]), device=device)
        self.n_features = self.s.shape[1] + 9

    def batch(self, case, hour):
        h = self.widx[hour]  # [B, 3]
        w = self.w[self.ci[case][:, None], h]  # [B, 3, 7] ([B, 3, 9] foldable)
        if self.foldable:
            s = self.s[case].unsqueeze(1).expand(-1, LOOKBACK, -1)
            return torch.cat([s, w], dim=2), self.y[case, hour]
        sc = self.sched[case[:, None], h]  # [B, 3, 2]
        s = self.s[case].unsqueeze(1).expand(-1, LOOKBACK, -1)
        return torch.cat([s, w, sc], dim=2), self.y[case, hour]


def predict(model, win, cases, batch=8760):
    """Predictions (scaled) for every hour of ``cases``, [len, T, O]."""
    model.eval()
    T = win.y.shape[1]
    out = []
    with torch.no_grad():
        for c in cases:
            hour = torch.arange(T, device=win.y.device)
            x, _ = win.batch(torch.full_like(hour, c), hour)
            out.append(torch.cat([model(x[s:s + batch]) for s in range(0, T, batch)]))
    return torch.relu(torch.stack(out))


def cv_rmse(pred, true, names):
    """Per output: CV-RMSE and NMBE (%) pooled over the cases' hours (ASHRAE Guideline 14's
    hourly figures, p = 0)."""
    res = {}
    for k, n in enumerate(names):
        e = pred[..., k] - true[..., k]
        m = float(true[..., k].mean())
        res[n] = {"cv_rmse_pct": 100 * float(np.sqrt((e ** 2).mean())) / m if m > 0 else None,
                  "nmbe_pct": 100 * float(e.mean()) / m if m > 0 else None}
    return res


def fit(model, win, cases, epochs, hours_per_case, lr, seed, log=None, held=None, patience=None):
    """Adam on the MSE of scaled targets; each epoch draws ``hours_per_case`` hours of every case
    (all hours where it is None). With ``held`` cases and ``patience``, the best epoch on them
    is kept (early stopping)."""
    gen = torch.Generator().manual_seed(seed)
    opt = Adam(model.parameters(), lr=lr)
    T = win.y.shape[1]
    device = win.y.device
    cases_t = torch.as_tensor(cases)
    best, best_state, bad = float("inf"), None, 0
    for epoch in range(1, epochs + 1):
        t0 = time.time()
        model.train()
        if hours_per_case is None:
            case = cases_t.repeat_interleave(T)
            hour = torch.arange(T).repeat(len(cases))
        else:
            case = cases_t.repeat_interleave(hours_per_case)
            hour = torch.randint(0, T, (len(case),), generator=gen)
        perm = torch.randperm(len(case), generator=gen)
        case, hour = case[perm].to(device), hour[perm].to(device)
        total = 0.0
        for s in range(0, len(case), 1024):
            x, y = win.batch(case[s:s + 1024], hour[s:s + 1024])
            loss = torch.mean((model(x) - y) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += loss.item() * x.shape[0]
        line = f"epoch {epoch:3d} train {total / len(case):.6f}"
        if held:
            h = float(torch.mean((predict(model, win, held) - win.y[held]) ** 2))
            line += f" held-out {h:.6f}"
            if h < best:
                best, bad = h, 0
                best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
            else:
                bad += 1
        if log:
            log(f"{line} {time.time() - t0:.1f} s")
        if patience and bad >= patience:
            break
    if best_state is not None:
        model.load_state_dict(best_state)
    return model


def pretrain(corpus_dir, n_cases, args, log=print):
    """The conditioned network on the first ``n_cases`` finished cases of a corpus."""
    rows = read_index(corpus_dir)[:n_cases]
    corpus = Corpus(corpus_dir, rows, inputs=args.inputs)
    norm = Normaliser(corpus)
    win = Windows(corpus, norm, "cpu")
    torch.manual_seed(args.seed)
    model = Surrogate(win.n_features, len(corpus.outputs), args.hidden, args.layers)
    t0 = time.time()
    fit(model, win, list(range(len(rows))), args.epochs, args.hours_per_case, args.lr, args.seed, log)
    return model, norm, corpus, time.time() - t0


def card(corpus, norm, args, seconds):
    """The model card's training part: the corpus, its ranges, the normalisation."""
    spec = np.array([describe(r["spec"]) for r in corpus.rows])
    foldable = corpus.inputs == "foldable"
    return {"format": "bemcal-pretrained-surrogate", "format_version": 1,
            "model": {"kind": "lstm", "lookback": LOOKBACK, "layers": args.layers, "hidden": args.hidden},
            "inputs": {"kind": corpus.inputs,
                       "static": DESCRIPTORS + ENGINEERING + (PROFILE if foldable else []),
                       "hourly": HOURLY_FOLDABLE if foldable else HOURLY},
            "outputs": corpus.outputs, "output_unit": "Wh/m2 per hour",
            "corpus": {"cases": len(corpus.rows), "climates": sorted(set(corpus.climate)),
                       "descriptor_ranges": {n: [float(spec[:, k].min()), float(spec[:, k].max())]
                                             for k, n in enumerate(DESCRIPTORS)}},
            "normalisation": norm.state(),
            "training": {"epochs": args.epochs, "hours_per_case": args.hours_per_case, "lr": args.lr,
                         "seed": args.seed, "seconds": seconds, "threads": torch.get_num_threads(),
                         "torch_version": torch.__version__}}


def heldout_buildings(heldout_dir, norm, climates, inputs="conditioned"):
    """The held-out corpus grouped by building: (rows, Corpus) of each building's points."""
    rows = read_index(heldout_dir)
    by = {}
    for r in rows:
        by.setdefault(r["building"], []).append(r)
    out = []
    for b, rs in sorted(by.items()):
        rs.sort(key=lambda r: r["point"])
        out.append((b, Corpus(heldout_dir, rs, dict(climates), inputs)))
    return out


def evaluate(model, win, corpus, test):
    pred = predict(model, win, test).numpy()
    y = win.y[test].numpy()
    return cv_rmse(pred, y, corpus.outputs)


def from_scratch(corpus, train, test, args, log):
    """Today's per-building surrogate on the same points: the bemcal_train architecture and
    settings of the demo (2 x 64, Adam 1e-3, early stopping on a fifth of the points, at most
    200 epochs, patience 15), its inputs the building's parameters normalised by their ranges,
    the weather and hour of day; trained from a random start. Each epoch draws ``fit_hours``
    hours of every point (the fine-tuning's budget too; bemcal_train takes all 8,760)."""
    rows = corpus.rows
    names = sorted(rows[0]["values"])
    lo = np.array([rows[0]["ranges"][n][0] for n in names])
    hi = np.array([rows[0]["ranges"][n][1] for n in names])
    p = np.array([[r["values"][n] for n in names] for r in rows])
    p = (p - lo) / (hi - lo)
    w = corpus.weather_hourly(corpus.climate[0])
    w = (w - w.mean(0)) / np.where(w.std(0) > 1e-9, w.std(0), 1.0)
    scale = np.maximum(corpus.y[train].max(axis=(0, 1)), 1e-6)

    class W:
        pass

    win = W()
    win.y = torch.as_tensor(corpus.y / scale, dtype=torch.float32)
    pt = torch.as_tensor(p, dtype=torch.float32)
    wt = torch.as_tensor(w, dtype=torch.float32)
    widx = torch.as_tensor(window_index(w.shape[0]))

    def batch(case, hour):
        x = torch.cat([pt[case].unsqueeze(1).expand(-1, LOOKBACK, -1), wt[widx[hour]]], dim=2)
        return x, win.y[case, hour]

    win.batch = batch
    torch.manual_seed(args.seed)
    model = Surrogate(p.shape[1] + w.shape[1], corpus.y.shape[2], args.scratch_hidden, args.layers)
    k = max(1, len(train) // 5)
    fit(model, win, train[:-k], 200, args.fit_hours, 1e-3, args.seed, None, held=train[-k:], patience=15)
    pred = predict(model, win, test).numpy()
    return cv_rmse(pred, win.y[test].numpy(), corpus.outputs)


def finetune(model, corpus, norm, train, args):
    """The pretrained network fine-tuned on a building's own points: every weight, Adam at a
    tenth of the pretraining rate, early stopping on a fifth of the points where there are 10
    or more (patience 8; else a quarter of the epochs, fixed), ``fit_hours`` hours of every point
    an epoch."""
    import copy

    m = copy.deepcopy(model)
    win = Windows(corpus, norm, "cpu")
    if len(train) >= 10:
        k = len(train) // 5
        fit(m, win, train[:-k], args.finetune_epochs, args.fit_hours, args.lr / 10, args.seed,
            held=train[-k:], patience=8)
    else:
        fit(m, win, train, max(args.finetune_epochs // 4, 3), args.fit_hours, args.lr / 10, args.seed)
    return m, win


def curve(args):
    """Held-out CV-RMSE per meter for each corpus size: zero-shot, fine-tuned on 5 / 10 / 20 of
    a building's own points, and today's from-scratch surrogate on the same 20; tested on the
    building's last ``test`` points."""
    sizes = [int(s) for s in args.sizes.split(",")]
    results = {"sizes": {}, "buildings": {}, "scratch": {}, "settings": vars(args)}
    saved = os.path.join(args.out, "curve.json") if args.out else None
    if saved and os.path.exists(saved):
        with open(saved) as f:
            results = json.load(f)  # sizes already measured stay; the scratch results are reused
        results["settings"] = vars(args)
    available = len(read_index(args.corpus))
    test_n = args.test
    log = (lambda m: print(m, flush=True)) if args.verbose else (lambda m: None)
    scratch = {int(b): r for b, r in results.get("scratch", {}).items()}
    for n in sizes:
        if str(n) in results["sizes"] or n in results["sizes"]:
            print(f"corpus size {n}: measured before ({saved}); kept", flush=True)
            continue
        if n > available:
            print(f"corpus size {n}: only {available} cases finished; skipped", flush=True)
            continue
        model, norm, corpus, secs = pretrain(args.corpus, n, args, log)
        print(f"pretrained on {n} cases in {secs:.0f} s", flush=True)
        rows = {}
        for b, hc in heldout_buildings(args.heldout, norm, corpus.climates, args.inputs):
            pts = len(hc.rows)
            test = list(range(pts - test_n, pts))
            win = Windows(hc, norm, "cpu")
            r = {"zero_shot": evaluate(model, win, hc, test)}
            for k in (5, 10, 20):
                if k <= pts - test_n and k <= args.max_own:
                    t0 = time.time()
                    m, w = finetune(model, hc, norm, list(range(k)), args)
                    r[f"finetuned_{k}"] = evaluate(m, w, hc, test)
                    r[f"finetuned_{k}"]["seconds"] = time.time() - t0
            if b not in scratch and pts - test_n >= 20:
                t0 = time.time()
                scratch[b] = from_scratch(hc, list(range(20)), test, args, log)
                scratch[b]["seconds"] = time.time() - t0
            r["scratch_20"] = scratch.get(b)
            results["scratch"][str(b)] = scratch.get(b)
            spec = hc.rows[0]["spec"]
            results["buildings"][str(b)] = {"climate": hc.climate[0], "storeys": spec["storeys"],
                                       "footprint_m": spec["footprint_m"], "zoning": spec["zoning"],
                                       "hvac": spec.get("hvac", "vav_reheat"),
                                       "heating_source": spec["heating_source"]}
            rows[str(b)] = r
            print(f"  building {b} ({hc.climate[0]}): " + "; ".join(
                f"{how} " + "/".join(f"{v[m]['cv_rmse_pct']:.0f}" for m in CALIBRATED_METERS)
                for how, v in r.items() if v), flush=True)
        results["sizes"][str(n)] = {"pretrain_seconds": secs, "buildings": rows,
                                    "card": card(corpus, norm, args, secs)}
        if args.out:
            os.makedirs(args.out, exist_ok=True)
            torch.save(model.state_dict(), os.path.join(args.out, f"pretrained_{n}.pt"))
            with open(os.path.join(args.out, "curve.json"), "w") as f:
                json.dump(results, f, indent=1)
    print(table(results))
    return results


def table(results):
    """The learning curve as Markdown: median over held-out buildings of each meter's CV-RMSE."""
    hows = ["zero_shot", "finetuned_5", "finetuned_10", "finetuned_20", "scratch_20"]
    lines = ["| corpus cases | " + " | ".join(hows) + " |", "|---|" + "---|" * len(hows)]
    for n, s in results["sizes"].items():
        cells = []
        for how in hows:
            vals = [[b[how][m]["cv_rmse_pct"] for m in CALIBRATED_METERS]
                    for b in s["buildings"].values() if b.get(how)]
            if not vals:
                cells.append("-")
                continue
            med = np.median(np.array(vals, dtype=float), axis=0)
            cells.append(" / ".join(f"{v:.0f}" for v in med))
        lines.append(f"| {n} | " + " | ".join(cells) + " |")
    lines.append("(median over held-out buildings of hourly CV-RMSE %, heating / cooling / electricity)")
    return "\n".join(lines)


FOLD_VERDICT = "pretrained.json"
"""What ``fold`` decided, in its output folder: ``{"admitted": true, ...}`` with the folded
``weights.pt`` beside it, or ``{"admitted": false, "reason": ...}``."""


def admission(card, meta, building, hidden, layers, time_features):
    """Why the pretrained network cannot start this building's surrogate, or None: its inputs
    must be foldable, the building inside the corpus's descriptor ranges, every calibrated
    parameter one it knows, every meter one it predicts, and the surrogate's shape its own."""
    if card.get("format") != "bemcal-pretrained-surrogate":
        return "card.json is not a bemcal pretrained surrogate's"
    if card["inputs"].get("kind") not in INPUTS:
        return f"the pretrained network's inputs '{card['inputs'].get('kind')}' are none of {', '.join(INPUTS)}"
    if time_features != "hour+schedule":
        return f"the surrogate's time features are '{time_features}'; the pretrained network's are hour+schedule"
    m = card["model"]
    if (m["hidden"], m["layers"]) != (hidden, layers):
        return f"the surrogate is {layers} x {hidden}, the pretrained network {m['layers']} x {m['hidden']}"
    missing = [o for o in meta["output_names"] if o not in card["outputs"]]
    if missing:
        return f"the pretrained network does not predict {', '.join(missing)} (it predicts {', '.join(card['outputs'])})"
    spec = building["spec"]
    ranges = card["corpus"]["descriptor_ranges"]
    for name, v in zip(DESCRIPTORS, describe(spec)):
        lo, hi = ranges[name]
        if not lo - 1e-9 * max(1.0, abs(lo)) <= v <= hi + 1e-9 * max(1.0, abs(hi)):
            return f"the building's {name} {v:.4g} is outside the corpus's {lo:.4g} to {hi:.4g}"
    known = set(ENGINEERING) | set(profile_names(spec))
    unknown = [p["name"] for p in meta["params"] if p["name"] not in known]
    if unknown:
        return f"parameter {unknown[0]} is not one the pretrained network knows"
    return None


def fold_static(model, norm, building, params, inputs):
    """Layer 1's static part of the pretrained network on this building, as an affine map of the
    normalised parameters ``params`` (its static inputs are affine in them: each parameter's
    column is the inputs' change from its prior minimum to its maximum): ``(W_p, bias, W_h,
    state_dict)``, with ``W_h`` layer 1's hourly columns left to the caller."""
    spec, area = building["spec"], building["floor_area_m2"]
    lo = {p["name"]: p["min"] for p in params}

    def static(values):
        return np.array(static_features(spec, values, area, inputs))

    base = dict(building["values"], **lo)
    s0 = static(base)
    S = np.stack([static(dict(base, **{p["name"]: p["max"]})) - s0 for p in params], axis=1)
    sd_s = np.asarray(norm.static_std)
    z0 = (s0 - np.asarray(norm.static_mean)) / sd_s
    sd = model.state_dict()
    W = sd["lstm.weight_ih_l0"].double().numpy()
    Ws, Wh = W[:, :len(s0)], W[:, len(s0):]
    return Ws @ (S / sd_s[:, None]), Ws @ z0, Wh, sd


def folded_state(sd, w_ih, bias, card, meta, norm, building):
    """The folded network's state: the pretrained ``sd`` with layer 1's input weights ``w_ih``,
    ``bias`` added to its input bias, and the head's rows of the building's meters;
    ``(state, rows, scale)``, the scale in the building's kWh."""
    out = {k: v.clone() for k, v in sd.items()}
    out["lstm.weight_ih_l0"] = torch.as_tensor(w_ih, dtype=torch.float32)
    out["lstm.bias_ih_l0"] = sd["lstm.bias_ih_l0"] + torch.as_tensor(bias, dtype=torch.float32)
    rows = [card["outputs"].index(o) for o in meta["output_names"]]
    out["head.weight"] = sd["head.weight"][rows]
    out["head.bias"] = sd["head.bias"][rows]
    scale = np.asarray(norm.y_scale)[rows] * building["floor_area_m2"] / 1000.0  # Wh/m2 -> kWh
    return out, rows, scale


def folded(model, card, norm, meta, building, weather):
    """Today's surrogate (``Surrogate(n_params + 9, ...)``, inputs of data.hourly_features with
    hour+schedule) equal to the pretrained network on this building: layer 1's static part
    becomes the parameters' part and a bias (the static inputs are affine in the normalised
    parameters), its weather part is re-normalised to the dataset's weather statistics, and the
    head keeps the building's meters, in kWh at the scale it returns. Exact up to rounding."""
    from .data import weather_stats

    params = meta["params"]
    W_p, bias, Wh, sd = fold_static(model, norm, building, params, "foldable")
    m_d, sd_d = weather_stats(weather)
    mean_c, std_c = np.asarray(norm.hourly_mean), np.asarray(norm.hourly_std)
    W_w = Wh[:, :5] * (sd_d / std_c[:5])[None, :]
    bias = bias + Wh[:, :5] @ ((m_d - mean_c[:5]) / std_c[:5])
    out, rows, scale = folded_state(sd, np.concatenate([W_p, W_w, Wh[:, 5:]], axis=1), bias, card, meta,
                                    norm, building)
    m = card["model"]
    net = Surrogate(len(params) + 9, len(rows), m["hidden"], m["layers"])
    net.load_state_dict(out)
    return net, scale


def schedule_table(spec, values, params):
    """The building's schedule as the runtime's hourly inputs take it (``data.schedule_columns``,
    ``surrogate.json``'s ``schedule_inputs``): for working days and days off, each hour's
    schedule interval, as an index into ``params`` (the surrogate's calibrated schedule
    parameters, by their position among all its parameters) or, where that interval is fixed,
    its value; and the occupied hours (working days between the spec's occupied hours, as the
    corpus's ``schedule_hours``)."""
    names = [p["name"] for p in params]
    hours = profile_names(spec)
    cal = sorted({names.index(n) for n in hours if n in names})
    a, b = spec["occupied_hours"]
    table = {"params": cal}
    for kind, part in (("working", hours[:24]), ("off", hours[24:])):
        table[kind] = {
            "interval": [cal.index(names.index(n)) if n in names else -1 for n in part],
            "fixed": [0.0 if n in names else float(values[n]) for n in part],
            "occupied": [int(kind == "working" and a <= h < b) for h in range(24)],
        }
    return table


def folded_conditioned(model, card, norm, meta, building, weather):
    """A ``ScheduledSurrogate`` equal to the conditioned pretrained network on this building,
    and its schedule table: layer 1's static part (descriptors, engineering parameters) becomes
    the parameters' part and a bias as in ``folded``; its hourly part maps onto the runtime's
    hourly inputs (weather re-normalised, off-day and occupied flags), and the schedule's
    value, ``fixed(t) + sum_k m_k(t) (min_k + width_k p_k)``, onto the fixed-value and indicator
    columns (affine) and the schedule term ``q`` (the bilinear rest). Exact up to rounding."""
    from .data import weather_stats
    from .model import ScheduledSurrogate

    params = meta["params"]
    table = schedule_table(building["spec"], building["values"], params)
    W_p, bias, Wh, sd = fold_static(model, norm, building, params, "conditioned")  # Wh: HOURLY order
    m_d, sd_d = weather_stats(weather)
    mean_c, std_c = np.asarray(norm.hourly_mean), np.asarray(norm.hourly_std)
    k = len(table["params"])
    zero = np.zeros((Wh.shape[0], 1))
    w_sched = Wh[:, 7:8] / std_c[7]
    w_occ = Wh[:, 8:9] / std_c[8]
    lo_k = np.array([params[i]["min"] for i in table["params"]])
    cols = [W_p,                                           # parameters
            Wh[:, :4] * (sd_d[:4] / std_c[:4])[None, :],   # weather, the dataset's normalisation
            zero,                                          # day type code
            Wh[:, 5:7],                                    # hour sin, cos
            zero, zero,                                    # off-day hour sin, cos
            Wh[:, 4:5],                                    # off_day
            w_occ,                                         # occupied
            w_sched,                                       # schedule_fixed
            w_sched * lo_k[None, :],                       # the indicators: the minimum
            w_sched]                                       # q: width * p
    bias = bias + Wh[:, :4] @ ((m_d[:4] - mean_c[:4]) / std_c[:4]) \
        - Wh[:, 7] * mean_c[7] / std_c[7] - Wh[:, 8] * mean_c[8] / std_c[8]
    out, rows, scale = folded_state(sd, np.concatenate(cols, axis=1), bias, card, meta, norm, building)
    m = card["model"]
    width = [params[i]["max"] - params[i]["min"] for i in table["params"]]
    n_features = len(params) + 9 + 3 + k
    net = ScheduledSurrogate(n_features, len(rows), m["hidden"], m["layers"], table["params"], width)
    out["sched_params"] = net.sched_params
    out["sched_width"] = net.sched_width
    net.load_state_dict(out)
    return net, scale, table


def pretrained_inputs(card, norm, building, values, weather):
    """The pretrained network's input rows [T, F] for the building at parameter ``values``."""
    spec, area = building["spec"], building["floor_area_m2"]
    kind = card["inputs"]["kind"]
    st = (np.array(static_features(spec, values, area, kind)) - norm.static_mean) / norm.static_std
    if kind == "foldable":
        hc = (hourly_foldable(weather) - norm.hourly_mean) / norm.hourly_std
    else:
        T = weather.shape[0]
        ang = 2 * np.pi * (np.arange(T) % 24) / 24
        off = weather[:, 4] != 0
        h = np.concatenate([weather[:, :4], off[:, None].astype(np.float64), np.sin(ang)[:, None],
                            np.cos(ang)[:, None], schedule_hours(spec, values, off)], axis=1)
        hc = (h - norm.hourly_mean) / norm.hourly_std
    return np.concatenate([np.broadcast_to(st, (hc.shape[0], len(st))), hc], axis=1)


def fold(args):
    """``fold``: the pretrained network as the warm start of one building's surrogate (the
    calibration's ``[surrogate] pretrained``), or the reason it cannot be."""
    from .data import load_dataset, hourly_features, normalise_params, schedule_columns, weather_stats
    from .train import save_weights

    with open(os.path.join(args.pretrained, "card.json")) as f:
        card = json.load(f)
    with open(args.building) as f:
        building = json.load(f)
    ds = load_dataset(args.dataset)
    meta = ds["meta"]
    os.makedirs(args.out, exist_ok=True)
    verdict = os.path.join(args.out, FOLD_VERDICT)
    reason = admission(card, meta, building, args.hidden, args.layers, args.time_features)
    if reason:
        with open(verdict, "w") as f:
            json.dump({"admitted": False, "reason": reason}, f)
        print(f"pretrained surrogate not used: {reason}", flush=True)
        return
    norm = Normaliser(state=card["normalisation"])
    n_static = len(card["inputs"]["static"])
    n_hourly = len(card["inputs"]["hourly"])
    model = Surrogate(n_static + n_hourly, len(card["outputs"]), card["model"]["hidden"], card["model"]["layers"])
    model.load_state_dict(torch.load(os.path.join(args.pretrained, "weights.pt"), map_location="cpu",
                                     weights_only=True))
    schedule = None
    if card["inputs"]["kind"] == "foldable":
        net, scale = folded(model, card, norm, meta, building, ds["weather"])
    else:
        net, scale, schedule = folded_conditioned(model, card, norm, meta, building, ds["weather"])
    # The check: the folded network and the pretrained one give the same kWh at the design points.
    names = [p["name"] for p in meta["params"]]
    m_d, sd_d = weather_stats(ds["weather"])
    hourly = hourly_features(ds["weather"], m_d, sd_d, "hour+schedule")
    if schedule is not None:
        hourly = np.concatenate([hourly, schedule_columns(ds["weather"], schedule)], axis=1)
    p_norm = normalise_params(ds["params"], meta["params"])
    idx = torch.as_tensor(window_index(hourly.shape[0])[:: max(1, hourly.shape[0] // 500)])
    worst = 0.0
    for i in range(min(len(p_norm), 3)):
        x = np.concatenate([np.broadcast_to(p_norm[i], (hourly.shape[0], len(names))), hourly], axis=1)
        xt = torch.as_tensor(x, dtype=torch.float32)[idx]
        values = dict(building["values"], **dict(zip(names, ds["params"][i])))
        xc = torch.as_tensor(pretrained_inputs(card, norm, building, values, ds["weather"]),
                             dtype=torch.float32)[idx]
        with torch.no_grad():
            a = net(xt).numpy() * scale
            rows = [card["outputs"].index(o) for o in meta["output_names"]]
            b = model(xc).numpy()[:, rows] * np.asarray(norm.y_scale)[rows] * building["floor_area_m2"] / 1000.0
        worst = max(worst, float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-9)))
    if worst > 1e-3:
        raise SystemExit(f"the folded network differs from the pretrained one by {worst:.2e} (relative)")
    save_weights(net, scale, meta["output_names"], hourly.shape[1] + len(names),
                 os.path.join(args.out, "weights.pt"), schedule)
    with open(verdict, "w") as f:
        json.dump({"admitted": True, "pretrained": os.path.abspath(args.pretrained),
                   "corpus_cases": card["corpus"]["cases"], "fold_error": worst,
                   "inputs": card["inputs"]["kind"]}, f)
    print(f"pretrained surrogate folded ({card['corpus']['cases']} corpus cases; "
          f"largest difference {worst:.1e} of the largest output)", flush=True)


def parser():
    ap = argparse.ArgumentParser(prog="python -m bemcal_train.pretrain", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    f = sub.add_parser("fold", help="the pretrained network as the warm start of one building's surrogate")
    f.add_argument("--pretrained", required=True, help="folder with card.json and weights.pt (train's --out)")
    f.add_argument("--dataset", required=True, help="the building's training set (bemcal's dataset/)")
    f.add_argument("--building", required=True, help="JSON: spec, floor_area_m2, values of every parameter")
    f.add_argument("--hidden", type=int, required=True)
    f.add_argument("--layers", type=int, default=2)
    f.add_argument("--time-features", default="hour+schedule")
    f.add_argument("--out", required=True)
    f.add_argument("--threads", type=int, default=0)
    for name in ("curve", "train"):
        p = sub.add_parser(name)
        p.add_argument("--corpus", required=True)
        p.add_argument("--out", default=None)
        p.add_argument("--epochs", type=int, default=15)
        p.add_argument("--hours-per-case", type=int, default=1000)
        p.add_argument("--hidden", type=int, default=64)
        p.add_argument("--scratch-hidden", type=int, default=64)
        p.add_argument("--layers", type=int, default=2)
        p.add_argument("--lr", type=float, default=3e-3)
        p.add_argument("--finetune-epochs", type=int, default=40)
        p.add_argument("--seed", type=int, default=0)
        p.add_argument("--threads", type=int, default=0)
        p.add_argument("--verbose", action="store_true")
        p.add_argument("--inputs", choices=INPUTS, default="conditioned",
                       help="conditioned: the schedule's value at each hour as an input; foldable: "
                            "its 48-hour profile as static inputs, so that the network folds into "
                            "today's per-building surrogate")
        if name == "curve":
            p.add_argument("--heldout", required=True)
            p.add_argument("--sizes", default="100,200,400,800")
            p.add_argument("--test", type=int, default=5)
            p.add_argument("--fit-hours", type=int, default=2000,
                           help="hours of every point an epoch when fine-tuning and training from scratch")
            p.add_argument("--max-own", type=int, default=20,
                           help="the most own simulations fine-tuned on (5, 10, 20 up to it)")
        else:
            p.add_argument("--cases", type=int, required=True)
    return ap


def main(argv=None):
    args = parser().parse_args(sys.argv[1:] if argv is None else argv)
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.command == "curve":
        curve(args)
    elif args.command == "fold":
        fold(args)
    else:
        model, norm, corpus, secs = pretrain(args.corpus, args.cases, args, print)
        os.makedirs(args.out, exist_ok=True)
        torch.save(model.state_dict(), os.path.join(args.out, "weights.pt"))
        with open(os.path.join(args.out, "card.json"), "w") as f:
            json.dump(card(corpus, norm, args, secs), f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
