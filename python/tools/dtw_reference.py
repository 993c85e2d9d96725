#!/usr/bin/env python3
"""Write crates/precal/tests/fixtures/dtw_reference.json: DTW distances from dtaidistance.

Reference values for the Rust DTW (crates/precal/src/dtw.rs). Pairs of series (random, unequal
lengths, and real normalised daily profiles of the NREL RSF 2011 lighting + plug loads meters) with
dtaidistance windows, and dtaidistance.dtw.distance computed with its pure-Python path
(use_c=False) and, when the C extension is available, its C path (use_c=True).

dtaidistance's `window` allows |i - j| < window; bemcal's band w allows |i - j| <= w, so
band = window - 1 (window None = unconstrained).

Usage (throwaway venv outside the repo):
    python3 -m venv /tmp/dtw-venv && /tmp/dtw-venv/bin/pip install dtaidistance numpy
    /tmp/dtw-venv/bin/python python/tools/dtw_reference.py [--rsf ../shared/data/nrel_rsf_2011/rsfmeasureddata2011.csv]
"""
import argparse
import csv
import json
import os
import sys

import numpy as np
import dtaidistance
from dtaidistance import dtw

ROOT = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", ".."))


def rsf_profiles(path, days):
    """Daily lighting + plug-load profiles (hour-beginning), divided by the year's 99th percentile."""
    hourly = {}
    with open(path, newline="") as f:
        rows = csv.reader(f)
        header = next(rows)
        light = next(i for i, h in enumerate(header) if "Lighting" in h)
        plug = next(i for i, h in enumerate(header) if "Plug" in h)
        for k, row in enumerate(rows):
            # 8,759 rows, hour-ending, local standard time, first row = hour 0 of Jan 1.
            hourly[k] = float(row[light]) + float(row[plug])
    vals = np.array([hourly[k] for k in sorted(hourly)])
    p99 = np.percentile(vals, 99)
    return [list(vals[d * 24:(d + 1) * 24] / p99) for d in days]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rsf", default=os.path.join(ROOT, "..", "shared", "data", "nrel_rsf_2011",
                                                  "rsfmeasureddata2011.csv"))
    ap.add_argument("--out", default=os.path.join(ROOT, "crates", "precal", "tests", "fixtures",
                                                  "dtw_reference.json"))
    args = ap.parse_args()

    rng = np.random.RandomState(20240601)
    pairs = []
    for _ in range(5):
        pairs.append(("random 24", rng.rand(24), rng.rand(24)))
    for r, c in [(10, 13), (13, 10), (24, 20), (5, 5), (1, 4)]:
        pairs.append((f"random {r}x{c}", rng.rand(r), rng.randn(c) * 3.0))
    if os.path.exists(args.rsf):
        # Tue Jan 4, Sat Jan 8, Wed Jul 13, Sun Jul 17, Mon Dec 26 2011 (0-based day of year).
        prof = rsf_profiles(args.rsf, [3, 7, 193, 197, 359])
        for a in range(len(prof)):
            for b in range(a + 1, len(prof)):
                pairs.append((f"rsf days {a}-{b}", np.array(prof[a]), np.array(prof[b])))
    else:
        print(f"warning: {args.rsf} not found; only random pairs", file=sys.stderr)

    has_c = dtw.try_import_c(verbose=False)
    cases = []
    for label, s1, s2 in pairs:
        for window in [1, 2, 3, 5, 24, None]:
            kw = {} if window is None else {"window": window}
            d_py = dtw.distance(s1, s2, use_c=False, **kw)
            d_c = dtw.distance(s1.astype(np.double), s2.astype(np.double), use_c=True, **kw) if has_c else None
            cases.append({
                "label": label,
                "s1": [float(v) for v in s1],
                "s2": [float(v) for v in s2],
                "window": window,
                "band": None if window is None else window - 1,
                "distance_py": float(d_py),
                "distance_c": None if d_c is None else float(d_c),
            })
    out = {
        "generator": "python/tools/dtw_reference.py",
        "dtaidistance_version": dtaidistance.__version__,
        "c_available": bool(has_c),
        "note": "bemcal band w = dtaidistance window - 1; window null = unconstrained",
        "cases": cases,
    }
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as f:
        json.dump(out, f, separators=(",", ":"))
    print(f"wrote {len(cases)} cases to {args.out} (dtaidistance {dtaidistance.__version__}, C: {has_c})")


if __name__ == "__main__":
    main()
