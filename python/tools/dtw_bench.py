#!/usr/bin/env python3
"""DTW pairwise-matrix benchmark with dtaidistance's C implementation, on exactly the data of
crates/precal/examples/dtw_bench.rs (compare the printed sums).

Data: BDG2 electricity of 238 buildings; per building its 2016 daily profiles (raw kWh, 24 values),
days with any NaN or fewer than 24 hours skipped. One building-year = the first building with at
least 365 complete days. bemcal band w = dtaidistance window w + 1.

    /tmp/dtw-venv/bin/python python/tools/dtw_bench.py [CSV] [BAND]
"""
import csv
import os
import sys
import time
from collections import OrderedDict

import numpy as np
import dtaidistance
from dtaidistance import dtw

ROOT = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", ".."))


def load(path):
    days = OrderedDict()
    with open(path, newline="") as f:
        rows = csv.reader(f)
        nb = len(next(rows)) - 1
        for row in rows:
            if not row[0].startswith("2016"):
                continue
            d = days.setdefault(row[0][:10], [[] for _ in range(nb)])
            for b in range(nb):
                s = row[b + 1].strip()
                try:
                    v = float(s)
                except ValueError:
                    v = float("nan")
                d[b].append(v)
    per = [[] for _ in range(nb)]
    for d in days.values():
        for b, v in enumerate(d):
            if len(v) == 24 and all(np.isfinite(v)):
                per[b].append(v)
    return [np.array(p, dtype=np.double) for p in per]


def best(f, reps):
    t_best, out = float("inf"), None
    for _ in range(reps):
        t = time.perf_counter()
        out = f()
        t_best = min(t_best, time.perf_counter() - t)
    return t_best * 1e3, out


def main():
    path = sys.argv[1] if len(sys.argv) > 1 else os.path.join(
        ROOT, "..", "shared", "data", "bdg2", "electricity_subset_238bldgs_from_lstm-bgd2.csv")
    band = int(sys.argv[2]) if len(sys.argv) > 2 else 2
    window = band + 1
    t = time.perf_counter()
    per = load(path)
    print(f"loaded {len(per)} buildings, {sum(len(p) for p in per)} complete 2016 days in "
          f"{(time.perf_counter() - t) * 1e3:.0f} ms; dtaidistance {dtaidistance.__version__}, "
          f"window {window}, C available {dtw.try_import_c(verbose=False)}")
    one = next(i for i, p in enumerate(per) if len(p) >= 365)
    s = per[one]

    def mat(x, parallel):
        m = dtw.distance_matrix_fast(x, window=window, parallel=parallel, compact=True)
        return float(np.sum(m))

    for parallel in (True, False):
        ms1, c1 = best(lambda: mat(s, parallel), 20)
        msa, ca = best(lambda: sum(mat(p, parallel) for p in per if len(p) >= 2), 3)
        print(f"dtaidistance C (parallel={parallel}): one building-year (#{one}, {len(s)} x {len(s)}): "
              f"{ms1:.3f} ms, sum {c1:.6f}; all buildings {msa:.1f} ms, sum {ca:.6f}")


if __name__ == "__main__":
    main()
