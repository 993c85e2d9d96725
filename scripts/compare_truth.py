#!/usr/bin/env python3
"""Prints the hidden true parameters of a synthetic demo beside what the calibration recovered.

    compare_truth.py TRUTH.json SUMMARY.json
"""
import json
import sys

truth = json.load(open(sys.argv[1]))
summary = json.load(open(sys.argv[2]))
estimate = dict(summary["calibrated_values"])  # an object (or [name, value] pairs before issue 22)
rows = summary["posterior"]["parameters"]
# The intervals with the surrogate's error (summary.json surrogate_error), when measured.
carried = {p["name"]: p for p in (summary.get("surrogate_error") or {}).get("parameters", [])}
inside = inside_carried = 0
print(f"\n{'parameter':30s} {'truth':>9s} {'estimate':>9s} {'q5':>9s} {'q95':>9s}  in 90 %"
      + ("  with surrogate error: q5 q95 in" if carried else ""))
for p in rows:
    t = truth.get(p["name"])
    if t is None:
        continue
    ok = p["q5"] <= t <= p["q95"]
    inside += ok
    line = f"{p['name']:30s} {t:9.4f} {estimate[p['name']]:9.4f} {p['q5']:9.4f} {p['q95']:9.4f}  {'yes' if ok else 'no ':3s}"
    c = carried.get(p["name"])
    if c:
        ok_c = c["q5"] <= t <= c["q95"]
        inside_carried += ok_c
        line += f"      {c['q5']:9.4f} {c['q95']:9.4f} {'yes' if ok_c else 'no'}"
    print(line)
print(f"\ntruth inside the chains' 90 % interval for {inside} of {len(rows)} parameters")
if carried:
    print(f"truth inside the 90 % interval with the surrogate's error for {inside_carried} of {len(rows)} parameters")
for v in summary["validation"]:
    print(f"{v['output']:18s} NMBE {v['nmbe']:6.1f} %  CV-RMSE {v['cv_rmse']:5.1f} %  {'pass' if v['pass'] else 'FAIL'}")
