"""The pretrained surrogate through the calibration's own trainer (issue 66): on each held-out
building of the learning curve, today's surrogate (python -m bemcal_train, the settings a
calibration passes) trained on the building's first OWN EnergyPlus years from a random start,
against the same trainer warm-started from the pretrained network folded onto the building
(pretrain.fold, the path of `[surrogate] pretrained`); both tested on the building's last 5
points, hourly CV-RMSE per meter. Calibrated parameters: the engineering ones the building has
and its schedule intervals (what `calibrate` leaves empty: every parameter).

    PRETRAINED=~/.cache/bemcal/pretrained-foldable-200 OWN=20 EPOCHS=200 WARM=60 \
      .venv/bin/python scripts/pretrained_fold.py
"""
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np
import torch

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "python"))
from bemcal_train import pretrain as P  # noqa: E402
from bemcal_train.data import (hourly_features, normalise_params, schedule_columns, weather_stats,  # noqa: E402
                               window_index)
from bemcal_train.model import ScheduledSurrogate, Surrogate  # noqa: E402

HO = os.path.join(os.environ.get("CORPUS", os.path.expanduser("~/.cache/bemcal/corpus")), "heldout")
PRE = os.path.expanduser(os.environ.get("PRETRAINED", "~/.cache/bemcal/pretrained-foldable-200"))
OWN, EPOCHS, WARM = int(os.environ.get("OWN", 20)), int(os.environ.get("EPOCHS", 200)), int(os.environ.get("WARM", 60))
HIDDEN, THREADS = 64, os.environ.get("THREADS", "1")
PY = sys.executable


def dataset(folder, rows, names, weather):
    """A bemcal training set (TrainingSet::write's files) of `rows`, outputs in kWh."""
    area = rows[0]["floor_area_m2"]
    meta = {"format_version": 1, "n_points": len(rows), "n_hours": weather.shape[0],
            "params": [{"name": n, "min": rows[0]["ranges"][n][0], "max": rows[0]["ranges"][n][1],
                        "mode": 0.5 * sum(rows[0]["ranges"][n])} for n in names],
            "weather_features": ["dry_bulb_c", "rel_humidity_pct", "wind_speed_m_s", "global_horizontal_wh_m2", "day_type"],
            "weather_units": ["C", "%", "m/s", "Wh/m2", "code"], "output_names": P.CALIBRATED_METERS,
            "output_unit": "kWh", "layout": "experiment"}
    k = max(1, len(rows) // 5)
    meta["split"] = {"seed": 0, "train": list(range(len(rows) - k)), "held_out": list(range(len(rows) - k, len(rows)))}
    y = np.stack([np.load(os.path.join(HO, "cases", f"{r['key']}.npy")).astype(np.float64) for r in rows])
    with open(os.path.join(HO, "corpus.json")) as f:
        outs = json.load(f)["outputs"]
    y = y[:, :, [outs.index(o) for o in P.CALIBRATED_METERS]] * area / 1000.0
    os.makedirs(folder, exist_ok=True)
    np.save(os.path.join(folder, "params.npy"), np.array([[r["values"][n] for n in names] for r in rows]))
    np.save(os.path.join(folder, "weather.npy"), weather.astype(np.float64))
    np.save(os.path.join(folder, "outputs.npy"), y)
    with open(os.path.join(folder, "dataset.json"), "w") as f:
        json.dump(meta, f)
    return y


def evaluate(sdir, train_ds, rows, names, weather, y):
    """Hourly CV-RMSE per meter of the trained surrogate in `sdir` at `rows`."""
    saved = torch.load(os.path.join(sdir, "weights.pt"), weights_only=True)
    with open(os.path.join(train_ds, "dataset.json")) as f:
        meta = json.load(f)
    m, s = weather_stats(np.load(os.path.join(train_ds, "weather.npy")))
    hourly = hourly_features(weather, m, s, "hour+schedule")
    table = saved.get("schedule")
    if table is None:
        net = Surrogate(saved["n_features"], len(saved["output_names"]), HIDDEN, 2)
    else:  # the conditioned network folded: the schedule's hourly inputs beside
        hourly = np.concatenate([hourly, schedule_columns(weather, table)], axis=1)
        net = ScheduledSurrogate(saved["n_features"], len(saved["output_names"]), HIDDEN, 2, table["params"],
                                 saved["state_dict"]["sched_width"].tolist())
    net.load_state_dict(saved["state_dict"])
    idx = torch.as_tensor(window_index(hourly.shape[0]))
    preds = []
    for r in rows:
        p = normalise_params(np.array([r["values"][n] for n in names]), meta["params"])
        x = torch.as_tensor(np.concatenate([np.broadcast_to(p, (hourly.shape[0], len(p))), hourly], 1), dtype=torch.float32)
        with torch.no_grad():
            preds.append(torch.relu(net(x[idx])).numpy() * np.asarray(saved["scale"]))
    return P.cv_rmse(np.stack(preds), y, P.CALIBRATED_METERS)


def trainer(ds, out, epochs, init=None):
    cmd = [PY, "-m", "bemcal_train", "--dataset", ds, "--out", out, "--epochs", str(epochs), "--patience", "15",
           "--hidden", str(HIDDEN), "--time-features", "hour+schedule", "--threads", THREADS]
    if init:
        cmd += ["--init", init]
    t0 = time.time()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=dict(os.environ, PYTHONPATH=os.path.join(HERE, "..", "python")))
    return time.time() - t0


def main():
    rows = P.read_index(HO)
    by = {}
    for r in rows:
        by.setdefault(r["building"], []).append(r)
    results = {}
    with open(os.path.join(PRE, "card.json")) as f:
        cases = json.load(f)["corpus"]["cases"]
    for b, rs in sorted(by.items()):
        rs.sort(key=lambda r: r["point"])
        if len(rs) < OWN + 5:
            print(f"building {b}: {len(rs)} of its points simulated, {OWN + 5} needed; left out", flush=True)
            continue
        spec = rs[0]["spec"]
        known = set(P.ENGINEERING) | set(P.profile_names(spec))
        names = [n for n in sorted(rs[0]["values"]) if n in known and rs[0]["ranges"][n][1] > rs[0]["ranges"][n][0]]
        weather = np.load(os.path.join(HO, "weather", f"{rs[0]['climate']}.npy")).astype(np.float64)
        own, test = rs[:OWN], rs[-5:]
        with tempfile.TemporaryDirectory() as tmp:
            ds, tds = os.path.join(tmp, "dataset"), os.path.join(tmp, "test")
            dataset(ds, own, names, weather)
            y_test = dataset(tds, test, names, weather)
            building = {"spec": spec, "floor_area_m2": rs[0]["floor_area_m2"], "values": rs[0]["values"]}
            with open(os.path.join(tmp, "building.json"), "w") as f:
                json.dump(building, f)
            t_scratch = trainer(ds, os.path.join(tmp, "scratch"), EPOCHS)
            scratch = evaluate(os.path.join(tmp, "scratch"), ds, test, names, weather, y_test)
            t0 = time.time()
            subprocess.run([PY, "-m", "bemcal_train.pretrain", "fold", "--pretrained", PRE, "--dataset", ds,
                            "--building", os.path.join(tmp, "building.json"), "--hidden", str(HIDDEN),
                            "--out", os.path.join(tmp, "fold")], check=True,
                           env=dict(os.environ, PYTHONPATH=os.path.join(HERE, "..", "python")))
            with open(os.path.join(tmp, "fold", "pretrained.json")) as f:
                verdict = json.load(f)
            r = {"scratch": scratch, "scratch_seconds": t_scratch, "verdict": verdict}
            if verdict["admitted"]:
                r["zero_shot"] = evaluate(os.path.join(tmp, "fold"), ds, test, names, weather, y_test)
                r["fine_tuned_seconds"] = trainer(ds, os.path.join(tmp, "tuned"), WARM, os.path.join(tmp, "fold")) + time.time() - t0
                r["fine_tuned"] = evaluate(os.path.join(tmp, "tuned"), ds, test, names, weather, y_test)
        results[b] = r
        fmt = lambda v: "/".join(f"{v[m]['cv_rmse_pct']:.0f}" for m in P.CALIBRATED_METERS) if v else "-"
        print(f"building {b} {rs[0]['climate']} ({len(names)} parameters): scratch {fmt(scratch)} ({t_scratch:.0f} s); "
              f"folded zero-shot {fmt(r.get('zero_shot'))}; fine-tuned {fmt(r.get('fine_tuned'))} "
              f"({r.get('fine_tuned_seconds', 0):.0f} s) {'' if verdict['admitted'] else verdict['reason']}", flush=True)
    out = os.path.join(PRE, f"fold_own{OWN}.json")
    with open(out, "w") as f:
        json.dump({"corpus_cases": cases, "own": OWN, "epochs": EPOCHS, "warm_epochs": WARM, "buildings": results}, f, indent=1)
    for how in ("scratch", "zero_shot", "fine_tuned"):
        vals = [[r[how][m]["cv_rmse_pct"] for m in P.CALIBRATED_METERS] for r in results.values() if r.get(how)]
        if vals:
            print(f"median {how}: " + " / ".join(f"{v:.0f}" for v in np.median(vals, axis=0)))


if __name__ == "__main__":
    main()
