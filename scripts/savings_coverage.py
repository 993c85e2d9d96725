#!/usr/bin/env python3
"""Coverage of the savings intervals over K synthetic calibrations (scripts/savings_coverage.sh).

    savings_coverage.py OUT K

For run k (OUT/truth-k): savings.json (`bemcal savings --json`) and true_savings.json (EnergyPlus
at the hidden truth with and without each measure). Per measure and meter, and in all: the
share of true savings inside the 90 % and 50 % intervals, the mean 90 % width (kWh, and over the
true saving's size), the error of the saving at the estimate and of the median. Outputs a measure
cannot touch (a true saving of exactly 0 with a [0, 0] interval) are counted apart. Beside it,
how much each posterior learned (summary.json): the temperature T of its chains and the share of
parameters whose 90 % interval is narrower than half the prior's.
"""
import json
import os
import sys
from collections import defaultdict

out, k = sys.argv[1], int(sys.argv[2])
rows = defaultdict(list)  # (measure, output) -> [(truth, q05, q25, q75, q95, at_estimate, median)]
zero = defaultdict(int)
runs = 0
learned = []  # (T, parameters narrower than half the prior's, parameters)
for i in range(1, k + 1):
    d = os.path.join(out, f"truth-{i}")
    try:
        s = json.load(open(os.path.join(d, "savings.json")))
        t = json.load(open(os.path.join(d, "true_savings.json")))
    except (OSError, ValueError):
        continue
    runs += 1
    try:
        summary = json.load(open(os.path.join(d, "calibration", "summary.json")))
        ratios = [p["width_ratio"] for p in summary["posterior"]["parameters"]]
        t_value = (summary.get("temperature") or {}).get("value") or 1.0
        learned.append((float(t_value), sum(r is not None and r < 0.5 for r in ratios), len(ratios)))
    except (OSError, ValueError, KeyError, TypeError):
        pass
    for m in s["measures"]:
        for o in m["outputs"]:
            if o["weather"] != "calibration":
                continue
            truth = t["savings"][m["measure"]][o["output"]]
            lo, hi = o["savings_kwh"]["interval_90"]
            if truth == 0 and lo == 0 and hi == 0:
                zero[m["measure"]] += 1
                continue
            q25, q75 = o["savings_kwh"]["interval_50"]
            rows[(m["measure"], o["output"])].append(
                (truth, lo, q25, q75, hi, o["at_estimate_kwh"], o["savings_kwh"]["median"]))


def line(label, rs):
    n = len(rs)
    in90 = sum(lo <= t <= hi for t, lo, _, _, hi, _, _ in rs)
    in50 = sum(a <= t <= b for t, _, a, b, _, _, _ in rs)
    width = sum(hi - lo for _, lo, _, _, hi, _, _ in rs) / n
    rel = sum((hi - lo) / abs(t) for t, lo, _, _, hi, _, _ in rs if t) / max(1, sum(1 for r in rs if r[0]))
    err_est = sum(abs(e - t) for t, *_, e, _ in rs) / n
    err_med = sum(abs(m - t) for t, *_, m in rs) / n
    size = sum(abs(t) for t, *_ in rs) / n
    print(f"{label:<48} {n:>4} {in90:>4} ({100 * in90 / n:5.1f} %) {in50:>4} ({100 * in50 / n:5.1f} %)"
          f" {width:>9.0f} {rel:>7.2f} {size:>9.0f} {err_est:>9.0f} {err_med:>9.0f}")
    return n, in90, in50


print(f"{runs} runs with savings and true savings")
if learned:
    ts = sorted(t for t, _, _ in learned)
    narrowed = sum(a for _, a, _ in learned)
    total = sum(b for _, _, b in learned)
    print(f"how much the posteriors learned: temperature T median {ts[len(ts) // 2]:.3g} "
          f"(range {ts[0]:.3g}-{ts[-1]:.3g}); {narrowed} of {total} parameters "
          f"({100 * narrowed / max(1, total):.0f} %) with a 90 % interval narrower than half the prior's")
print(f"{'measure / output':<48} {'n':>4} {'in 90 %':>13} {'in 50 %':>13} {'width90':>9} {'w/|t|':>7}"
      f" {'|truth|':>9} {'err est':>9} {'err med':>9}")
tot = [0, 0, 0]
for (m, o), rs in sorted(rows.items()):
    n, a, b = line(f"{m} / {o}", rs)
    tot = [tot[0] + n, tot[1] + a, tot[2] + b]
metered = [r for (m, o), rs in rows.items() if o in ("heating_kwh", "cooling_kwh", "electricity_kwh") for r in rs]
if metered:
    line("all metered outputs", metered)
if tot[0]:
    line("all outputs", [r for rs in rows.values() for r in rs])
for m, n in sorted(zero.items()):
    print(f"{m}: {n} outputs it cannot touch, true saving 0 inside [0, 0]")
