#!/usr/bin/env python3
"""Prints the hidden true parameters of a synthetic demo beside what the calibration recovered.

    compare_truth.py TRUTH.json SUMMARY.json
"""
import json
import sys

truth = json.load(open(sys.argv[1]))
summary = json.load(open(sys.argv[2]))
estimate = dict(summary["calibrated_values"])
inside = 0
rows = summary["posterior"]["parameters"]
print(f"\n{'parameter':30s} {'truth':>9s} {'estimate':>9s} {'q5':>9s} {'q95':>9s}  in 90 %")
for p in rows:
    t = truth.get(p["name"])
    if t is None:
        continue
    ok = p["q5"] <= t <= p["q95"]
    inside += ok
    print(f"{p['name']:30s} {t:9.4f} {estimate[p['name']]:9.4f} {p['q5']:9.4f} {p['q95']:9.4f}  {'yes' if ok else 'no'}")
print(f"\ntruth inside the 90 % posterior interval for {inside} of {len(rows)} parameters")
for v in summary["validation"]:
    print(f"{v['output']:18s} NMBE {v['nmbe']:6.1f} %  CV-RMSE {v['cv_rmse']:5.1f} %  {'pass' if v['pass'] else 'FAIL'}")
