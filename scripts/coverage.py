#!/usr/bin/env python3
"""Coverage of the posterior's central intervals over K synthetic calibrations (scripts/coverage.sh).

    coverage.py OUT K

For run k (OUT/truth-k): truth.json (the hidden values), calibration/draws.csv (posterior draws,
all chains), calibration/draws_with_surrogate_error.csv (the same with the surrogate's error
added, when a refinement round measured it) and calibration/summary.json. For both kinds of
interval (the chains' own, and with the surrogate's error: the ones summary.json tells a user to
read) prints per parameter and in all: the fraction of truths inside the central 50 % and 90 %
intervals, the mean interval width as a fraction of the prior range, the truth's normalised rank
among the draws (Talts et al. 2018: uniform on [0, 1] when the posterior is calibrated); and each
run's convergence and Guideline 14.
"""
import csv
import json
import os
import sys

out, k = sys.argv[1], int(sys.argv[2])


def quantile(xs, q):
    """Linear interpolation between order statistics (numpy's default)."""
    s = sorted(xs)
    h = (len(s) - 1) * q
    lo = int(h)
    return s[lo] + (h - lo) * (s[min(lo + 1, len(s) - 1)] - s[lo])


rows = {"chains": [], "with surrogate error": []}  # (run, name, truth, q05, q25, q75, q95, rank, range)
runs = []
for i in range(1, k + 1):
    d = os.path.join(out, f"truth-{i}")
    truth = json.load(open(os.path.join(d, "truth.json")))
    summary = json.load(open(os.path.join(d, "calibration", "summary.json")))
    ranges = {p["name"]: p["prior_max"] - p["prior_min"] for p in summary["parameters"]}
    for kind, file in [("chains", "draws.csv"), ("with surrogate error", "draws_with_surrogate_error.csv")]:
        path = os.path.join(d, "calibration", file)
        if not os.path.exists(path):
            continue
        with open(path) as f:
            draws = list(csv.DictReader(f))
        for name in ranges:
            xs = [float(row[name]) for row in draws]
            t = truth[name]
            rank = sum(x < t for x in xs) / len(xs)
            rows[kind].append((i, name, t, quantile(xs, 0.05), quantile(xs, 0.25), quantile(xs, 0.75),
                               quantile(xs, 0.95), rank, ranges[name]))
    c = summary.get("convergence", {})
    g14 = " ".join(f"{v['output'][:4]} {v['nmbe']:+.1f}/{v['cv_rmse']:.1f}{'' if v['pass'] else '!'}"
                   for v in summary["validation"])
    temperature = (summary.get("temperature") or {}).get("value", 1.0)
    runs.append((i, summary["converged"], c.get("max_rhat"), c.get("min_ess_bulk"),
                 c.get("min_ess_tail"), summary["timings"]["total_s"], temperature, g14))

print(f"\n{'run':>3} {'converged':>9} {'max R-hat':>9} {'ESS bulk':>8} {'ESS tail':>8} {'time s':>7} {'T':>7}  G14 NMBE/CV-RMSE % (! = fail)")
for i, conv, rh, eb, et, ts, temp, g14 in runs:
    f = lambda x, fmt: "n/a" if x is None else format(x, fmt)
    print(f"{i:>3} {str(conv):>9} {f(rh, '.3f'):>9} {f(eb, '.0f'):>8} {f(et, '.0f'):>8} {ts:>7.0f} {temp:>7.1f}  {g14}")

for kind, rs_all in rows.items():
    if not rs_all:
        print(f"\n{kind}: no run has these draws")
        continue
    n_runs = len({r[0] for r in rs_all})
    print(f"\n{kind} ({n_runs} runs)")
    names = sorted({r[1] for r in rs_all}, key=[r[1] for r in rs_all].index)
    print(f"{'parameter':<30} {'in 50 %':>8} {'in 90 %':>8} {'width 50 %':>10} {'width 90 %':>10}  truth's rank per run")
    tot50 = tot90 = n = 0
    w50s, w90s = [], []
    for name in names:
        rs = [r for r in rs_all if r[1] == name]
        c50 = sum(r[4] <= r[2] <= r[5] for r in rs)
        c90 = sum(r[3] <= r[2] <= r[6] for r in rs)
        w50 = sum((r[5] - r[4]) / r[8] for r in rs) / len(rs)
        w90 = sum((r[6] - r[3]) / r[8] for r in rs) / len(rs)
        w50s.append(w50)
        w90s.append(w90)
        tot50 += c50
        tot90 += c90
        n += len(rs)
        ranks = " ".join(f"{r[7]:.2f}" for r in rs)
        print(f"{name:<30} {c50:>3}/{len(rs):<4} {c90:>3}/{len(rs):<4} {w50:>10.3f} {w90:>10.3f}  {ranks}")
    print(f"{kind}: truth inside the 50 % interval {tot50}/{n} = {100 * tot50 / n:.0f} %, "
          f"inside the 90 % interval {tot90}/{n} = {100 * tot90 / n:.0f} % "
          f"(mean width {100 * sum(w50s) / len(w50s):.1f} % / {100 * sum(w90s) / len(w90s):.1f} % of the prior range)")
