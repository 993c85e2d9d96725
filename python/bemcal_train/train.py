"""Training loop, held-out metrics, export and metadata."""

import json
import math
import os
import time

import numpy as np
import torch

from . import FORMAT, FORMAT_VERSION, LOOKBACK
from .adam import Adam
from .data import (hourly_features, load_dataset, normalise_params, schedule_column_names,
                   schedule_columns, time_feature_names, weather_stats, window_index)
from .export import export_all, run_onnx, vjp_check
from .fused import CHUNK
from .model import Denormalised, ScheduledSurrogate, Surrogate


def pick_device(name):
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise SystemExit("--device cuda: CUDA is not available to this torch")
    return torch.device(name)


class Windows:
    """Builds window batches on the device from the compact arrays (no per-hour repeated matrix)."""

    def __init__(self, p_norm, hourly, targets, device):
        self.p = torch.as_tensor(p_norm, dtype=torch.float32, device=device)  # [N, n_params]
        self.w = torch.as_tensor(hourly, dtype=torch.float32, device=device)  # [T, n_hourly]
        self.y = torch.as_tensor(targets, dtype=torch.float32, device=device)  # [N, T, n_out]
        self.widx = torch.as_tensor(window_index(hourly.shape[0]), device=device)  # [T, 3]

    def batch(self, point, hour):
        """point, hour: int64 tensors [B] -> x [B, 3, F], y [B, n_out]."""
        w = self.w[self.widx[hour]]  # [B, 3, n_hourly]
        p = self.p[point].unsqueeze(1).expand(-1, LOOKBACK, -1)
        return torch.cat([p, w], dim=2), self.y[point, hour]


def predict(model, win, points, batch_size):
    """Normalised predictions for all hours of ``points`` -> [len(points), T, n_out]."""
    model.eval()
    T = win.w.shape[0]
    out = []
    with torch.no_grad():
        for i in points:
            pred = []
            for s in range(0, T, batch_size):
                hour = torch.arange(s, min(s + batch_size, T), device=win.w.device)
                x, _ = win.batch(torch.full_like(hour, i), hour)
                pred.append(model(x))
            out.append(torch.cat(pred))
    return torch.stack(out)


def metrics(pred_kwh, true_kwh, names):
    """Per output: RMSE (kWh, = sigma_eta), CV-RMSE (%) = RMSE / mean(true), NMBE (%), mean."""
    res = {}
    for k, name in enumerate(names):
        e = pred_kwh[..., k] - true_kwh[..., k]
        rmse = float(np.sqrt(np.mean(e**2)))
        mean = float(np.mean(true_kwh[..., k]))
        res[name] = {
            "rmse_kwh": rmse,
            "cv_rmse_pct": 100.0 * rmse / mean if mean > 0 else None,
            "nmbe_pct": 100.0 * float(np.mean(e)) / mean if mean > 0 else None,
            "mean_kwh": mean,
        }
    return res


WEIGHTS = "weights.pt"


def save_weights(model, scale, names, n_features, path, schedule=None):
    """The trained weights and the output scale they predict in (for a later warm start); a
    ``ScheduledSurrogate``'s schedule table (``schedule``) with them."""
    saved = {"state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()},
             "scale": [float(s) for s in scale], "output_names": list(names),
             "n_features": int(n_features)}
    if schedule is not None:
        saved["schedule"] = schedule
    torch.save(saved, path)


def read_init(init_dir):
    """``init_dir/weights.pt`` as ``save_weights`` wrote it."""
    path = os.path.join(init_dir, WEIGHTS)
    try:
        return torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise SystemExit(f"--init {init_dir}: no {WEIGHTS} there (a surrogate trained before warm "
                         f"starts existed); train from scratch instead")


def build_model(n_features, names, args, schedule, specs):
    """Today's surrogate, or a ``ScheduledSurrogate`` where the warm start carries a schedule
    table (the pretrained network folded onto the building)."""
    if schedule is None:
        return Surrogate(n_features, len(names), args.hidden, args.layers)
    width = [specs[i]["max"] - specs[i]["min"] for i in schedule["params"]]
    return ScheduledSurrogate(n_features, len(names), args.hidden, args.layers, schedule["params"], width)


def warm_start(model, saved, init_dir, scale, n_features, names):
    """Loads the weights ``read_init`` read from ``init_dir`` into ``model``. The head is
    rescaled by old / new output scale so that the warm-started model predicts the same kWh as
    the one it came from (the scale, each output's maximum over the training points, can grow
    as points are added)."""
    path = os.path.join(init_dir, WEIGHTS)
    if saved["output_names"] != list(names) or saved["n_features"] != n_features:
        raise SystemExit(f"--init {path}: trained for outputs {saved['output_names']} and "
                         f"{saved['n_features']} features, this dataset has {list(names)} and {n_features}")
    try:
        model.load_state_dict(saved["state_dict"])
    except RuntimeError as e:
        raise SystemExit(f"--init {path}: architecture differs ({e})")
    ratio = torch.as_tensor(np.asarray(saved["scale"]) / scale, dtype=torch.float32)
    with torch.no_grad():
        model.head.weight.mul_(ratio.to(model.head.weight.device)[:, None])
        model.head.bias.mul_(ratio.to(model.head.bias.device))
    print(f"warm start from {path} (head rescaled by {ratio.tolist()})", flush=True)


LR_FLOOR = 0.01
"""The cosine schedule's last learning rate, as a fraction of the first."""


def learning_rate(lr, schedule, progress):
    """The learning rate at `progress` (0 at the first step, 1 after the last epoch): `lr`
    throughout (`constant`), or annealed from `lr` to `LR_FLOOR * lr` along a half cosine
    (`cosine`: Loshchilov & Hutter, "SGDR: stochastic gradient descent with warm restarts",
    ICLR 2017, eq. 5, one period, no restart)."""
    if schedule == "constant":
        return lr
    low = LR_FLOOR * lr
    return low + 0.5 * (lr - low) * (1 + math.cos(math.pi * min(progress, 1.0)))


def train(args):
    t_start = time.time()
    torch.manual_seed(args.seed)
    np.random.seed(args.seed)
    if args.threads:
        torch.set_num_threads(args.threads)
    device = pick_device(args.device)
    ds = load_dataset(args.dataset)
    meta = ds["meta"]
    specs = meta["params"]
    names = meta["output_names"]
    n_params = len(specs)
    split = meta["split"]
    train_pts, held_pts = list(split["train"]), list(split["held_out"])

    init = getattr(args, "init", None)
    saved = read_init(init) if init else None
    sched_table = saved.get("schedule") if saved else None
    mean, std = weather_stats(ds["weather"])
    hourly = hourly_features(ds["weather"], mean, std, args.time_features)
    if sched_table is not None:
        hourly = np.concatenate([hourly, schedule_columns(ds["weather"], sched_table)], axis=1)
    p_norm = normalise_params(ds["params"], specs)
    outputs = ds["outputs"]
    nonnegative = bool(np.all(outputs >= 0))
    # Targets are divided by each output's maximum over the training points (so in [0, 1] for
    # meters); an all-zero output keeps scale 1.
    scale = np.abs(outputs[train_pts]).max(axis=(0, 1))
    scale = np.where(scale > 0, scale, 1.0)
    win = Windows(p_norm, hourly, outputs / scale, device)

    n_features = n_params + hourly.shape[1]
    model = build_model(n_features, names, args, sched_table, specs).to(device)
    if init:
        warm_start(model, saved, init, scale, n_features, names)
    opt = Adam(model.parameters(), lr=args.lr)
    T = hourly.shape[0]
    tr_point = torch.as_tensor(np.repeat(train_pts, T), device=device)
    tr_hour = torch.as_tensor(np.tile(np.arange(T), len(train_pts)), device=device)
    n = tr_point.shape[0]
    gen = torch.Generator(device="cpu").manual_seed(args.seed)
    y_held = win.y[held_pts]

    schedule = getattr(args, "lr_schedule", "constant")
    steps_per_epoch = -(-n // args.batch_size)
    best, best_state, best_epoch, bad, history = float("inf"), None, 0, 0, []
    for epoch in range(1, args.epochs + 1):
        t0 = time.time()
        model.train()
        perm = torch.randperm(n, generator=gen).to(device)
        total = 0.0
        for k, s in enumerate(range(0, n, args.batch_size)):
            opt.lr = learning_rate(args.lr, schedule, (epoch - 1 + k / steps_per_epoch) / args.epochs)
            idx = perm[s : s + args.batch_size]
            x, y = win.batch(tr_point[idx], tr_hour[idx])
            loss = torch.mean((model(x) - y) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            total += loss.item() * idx.shape[0]
        train_loss = total / n
        held_loss = float(torch.mean((predict(model, win, held_pts, args.eval_batch_size) - y_held) ** 2))
        secs = time.time() - t0
        history.append({"epoch": epoch, "train_loss": train_loss, "held_out_loss": held_loss, "seconds": secs})
        print(f"epoch {epoch:4d}  train {train_loss:.6f}  held-out {held_loss:.6f}  {secs:.1f} s", flush=True)
        if held_loss < best:
            best, best_epoch, bad = held_loss, epoch, 0
            best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        else:
            bad += 1
            if bad >= args.patience:
                print(f"early stop: no held-out improvement in {args.patience} epochs (best epoch {best_epoch})")
                break
    if best_state is not None:  # (--epochs 0 keeps the initial, e.g. warm-started, weights)
        model.load_state_dict(best_state)
    train_seconds = time.time() - t_start

    # Held-out accuracy in kWh, with the same non-negativity clamp the exported graph applies.
    pred = predict(model, win, held_pts, args.eval_batch_size).cpu().numpy()
    if nonnegative:
        pred = np.maximum(pred, 0)
    pred_kwh = pred * scale
    held = metrics(pred_kwh, outputs[held_pts], names)
    for name, m in held.items():
        cv = "n/a" if m["cv_rmse_pct"] is None else f"{m['cv_rmse_pct']:.2f} %"
        print(f"held-out {name}: RMSE {m['rmse_kwh']:.4f} kWh  CV-RMSE {cv}")

    os.makedirs(args.out, exist_ok=True)
    model = model.cpu().eval()
    save_weights(model, scale, names, n_features, os.path.join(args.out, WEIGHTS), sched_table)
    files = export_all(model, n_params, hourly.shape[1], scale, nonnegative, args.out)

    # Parity fixture: a few windows of the first held-out point, and its whole year.
    rng = np.random.default_rng(args.seed)
    i = held_pts[0]
    hours = np.sort(rng.choice(T, size=min(16, T), replace=False))
    hours[0] = 0  # include the padded first window
    winc = Windows(p_norm, hourly, outputs / scale, "cpu")
    x, _ = winc.batch(torch.full((len(hours),), i), torch.as_tensor(hours))
    plain = Denormalised(model, scale, nonnegative).eval()
    with torch.no_grad():
        y_win = plain(x).numpy()
        y_held = predict(plain, winc, held_pts, args.eval_batch_size).numpy()  # [n_held, T, n_out] kWh
    y_year = y_held[:1]
    onx = run_onnx(args.out, files, x.numpy(), p_norm[held_pts], hourly)
    check, int8 = None, None
    if onx is not None:
        rel = lambda a, b: float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-12))
        check = {"definition": "max |onnx - torch| / max |torch|",
                 "plain_vs_torch": rel(onx["plain"], y_win), "fast_vs_torch": rel(onx["fast"], y_held)}
        if "fused" in onx:
            check["fused_vs_torch"] = rel(onx["fused"], y_held)
        if "vjp" in files:
            check["vjp_vs_torch"] = vjp_check(model, args.out, files["vjp"], p_norm[held_pts[0]], hourly,
                                              scale, nonnegative, args.seed)
            print(f"onnxruntime check: vjp gradient {check['vjp_vs_torch']:.2e} (max |diff| / max |g|)")
        print(f"onnxruntime check (max |diff| / max |y|): plain {check['plain_vs_torch']:.2e}, "
              f"fast {check['fast_vs_torch']:.2e}, fused {check.get('fused_vs_torch', float('nan')):.2e}")
        if "fused_int8" in onx:
            d = onx["fused_int8"] - onx["fused"]
            q = metrics(onx["fused_int8"], outputs[held_pts], names)
            int8 = {"file": files["fused_int8"],
                    "against": "fused float graph, held-out points x all hours",
                    "rmse_vs_float_kwh": {n: float(np.sqrt(np.mean(d[..., k] ** 2))) for k, n in enumerate(names)},
                    "held_out_rmse_kwh": {n: q[n]["rmse_kwh"] for n in names}}
            int8["ratio_to_sigma_eta"] = {n: int8["rmse_vs_float_kwh"][n] / max(held[n]["rmse_kwh"], 1e-12)
                                          for n in names}
            print("int8 graph: RMSE vs float / sigma_eta: " + ", ".join(
                f"{n} {int8['ratio_to_sigma_eta'][n]:.3f}" for n in names))
    parity = {
        "note": "torch outputs (kWh) of the plain model; relative error = max|diff| / max|y|",
        "point": int(i),
        "params_raw": ds["params"][i].tolist(),
        "hours": hours.tolist(),
        "x_shape": list(x.shape),
        "x": x.numpy().ravel().tolist(),
        "y_windows": y_win.tolist(),
        "y_year": y_year[0].tolist(),
    }
    with open(os.path.join(args.out, "parity.json"), "w") as f:
        json.dump(parity, f)

    hourly_names = list(meta["weather_features"]) + time_feature_names(args.time_features)
    if sched_table is not None:
        hourly_names += schedule_column_names(sched_table, [p["name"] for p in specs])
    info = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "model": {"kind": "lstm", "lookback": LOOKBACK, "layers": args.layers, "hidden": args.hidden,
                  "relu_after_lstm": True, "head": "linear"},
        "files": files,
        "onnx": {"opset": 17, "plain": {"inputs": {"x": ["batch", LOOKBACK, n_features]},
                                        "outputs": {"y": ["batch", len(names)]}},
                 "fast": {"inputs": {"p": [1, n_params], "xw": [LOOKBACK, "hours", len(hourly_names)]},
                          "outputs": {"y": [1, "hours", len(names)]}},
                 "fused": {"inputs": {"p": [1, n_params], "xw": ["chunks", CHUNK + LOOKBACK - 1, len(hourly_names)]},
                           "outputs": {"y": ["chunks", CHUNK, len(names)]}, "chunk": CHUNK}},
        "n_features": n_features,
        "feature_names": [p["name"] for p in specs] + hourly_names,
        "params": specs,
        "weather": {"names": list(meta["weather_features"]), "units": meta["weather_units"],
                    "mean": mean.tolist(), "std": std.tolist()},
        "time_features": args.time_features,
        "time_feature_names": time_feature_names(args.time_features),
        **({"schedule_inputs": sched_table} if sched_table is not None else {}),
        "input_layout": "x[:, s, :] = [(p - min)/(max - min) (params order), (w - mean)/std (weather order), "
                        "time features] of hour t-2+s (clamped at 0) for the window ending at hour t",
        "outputs": [{"name": nm, "unit": "kWh", "scale": float(scale[k]),
                     "sigma_eta_kwh": held[nm]["rmse_kwh"]} for k, nm in enumerate(names)],
        "output_scaling": ("y_kwh = max(head, 0) * scale" if nonnegative else "y_kwh = head * scale")
        + "; scale = the output's maximum over the training points",
        "nonnegative": nonnegative,
        "held_out": {"points": held_pts, "metrics": held},
        "onnxruntime_check": check,
        "int8": int8,
        "training": {"seed": args.seed, "epochs_max": args.epochs, "epochs_run": len(history),
                     "best_epoch": best_epoch, "patience": args.patience, "batch_size": args.batch_size,
                     "lr": args.lr, "lr_schedule": schedule, "optimizer": "adam", "init": init, "loss": "mse on scaled targets",
                     "device": str(device), "threads": torch.get_num_threads(), "seconds": train_seconds,
                     "torch_version": torch.__version__, "train_points": train_pts,
                     "history": history},
    }
    with open(os.path.join(args.out, "surrogate.json"), "w") as f:
        json.dump(info, f, indent=1)
    print(f"wrote {args.out}/surrogate.json ({train_seconds:.1f} s)")
    return info
