#!/usr/bin/env python3
"""Prints the hidden true parameters of a synthetic demo beside what the calibration recovered.

    compare_truth.py TRUTH.json SUMMARY.json
"""
import json
import sys


def triangular_cdf(x, lo, mode, hi):
    """The prior's CDF at x (bemcal's priors are triangular: min, mode, max)."""
    if x <= lo:
        return 0.0
    if x >= hi:
        return 1.0
    if x <= mode:
        return (x - lo) ** 2 / ((hi - lo) * (mode - lo)) if mode > lo else 0.0
    return 1.0 - (hi - x) ** 2 / ((hi - lo) * (hi - mode)) if hi > mode else 1.0


truth = json.load(open(sys.argv[1]))
summary = json.load(open(sys.argv[2]))
estimate = dict(summary["calibrated_values"])  # an object (or [name, value] pairs before issue 22)
rows = summary["posterior"]["parameters"]
# The intervals with the surrogate's error (summary.json surrogate_error), when measured.
carried = {p["name"]: p for p in (summary.get("surrogate_error") or {}).get("parameters", [])}
inside = inside_carried = 0
misses = []
print(f"\n{'parameter':30s} {'truth':>9s} {'estimate':>9s} {'q5':>9s} {'q95':>9s}  in 90 %"
      + ("  with surrogate error: q5 q95 in" if carried else ""))
for p in rows:
    t = truth.get(p["name"])
    if t is None:
        continue
    ok = p["q5"] <= t <= p["q95"]
    inside += ok
    if not ok:
        misses.append((p, t))
    line = f"{p['name']:30s} {t:9.4f} {estimate[p['name']]:9.4f} {p['q5']:9.4f} {p['q95']:9.4f}  {'yes' if ok else 'no ':3s}"
    c = carried.get(p["name"])
    if c:
        ok_c = c["q5"] <= t <= c["q95"]
        inside_carried += ok_c
        line += f"      {c['q5']:9.4f} {c['q95']:9.4f} {'yes' if ok_c else 'no'}"
    print(line)
print(f"\ntruth inside the chains' 90 % interval for {inside} of {len(rows)} parameters")
# Each miss explained: how far outside, where the truth lies in its prior, how wide the
# interval is against the prior's, and the parameters it is correlated with (an unidentifiable
# pair shows here).
priors = {p["name"]: p for p in summary.get("parameters", [])}
pairs = summary["posterior"].get("correlated_pairs", [])
for p, t in misses:
    width = p["q95"] - p["q5"]
    off = (p["q5"] - t if t < p["q5"] else t - p["q95"]) / width if width > 0 else float("inf")
    pr = priors.get(p["name"])
    where = ""
    if pr:
        q = triangular_cdf(t, pr["prior_min"], pr["prior_mode"], pr["prior_max"])
        where = f", the truth at the prior's {100 * q:.0f} % quantile"
    ratio = f", the interval {100 * p['width_ratio']:.0f} % of the prior's width" if "width_ratio" in p else ""
    partners = [f"{c['a'] if c['b'] == p['name'] else c['b']} (r {c['rho']:+.2f})" for c in pairs
                if p["name"] in (c.get("a"), c.get("b")) and "rho" in c]
    corr = f"; correlated with {', '.join(partners)}" if partners else "; no strongly correlated partner"
    print(f"  miss {p['name']}: outside by {100 * off:.0f} % of its interval's width{where}{ratio}{corr}")
if carried:
    print(f"truth inside the 90 % interval with the surrogate's error for {inside_carried} of {len(rows)} parameters")
for v in summary["validation"]:
    print(f"{v['output']:18s} NMBE {v['nmbe']:6.1f} %  CV-RMSE {v['cv_rmse']:5.1f} %  {'pass' if v['pass'] else 'FAIL'}")
