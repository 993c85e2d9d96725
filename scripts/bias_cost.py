"""What a persistent bias costs the calibration's likelihood (docs/benchmarks-history.md, issue 17).

    python scripts/bias_cost.py FOLDER [KEY]

FOLDER holds `meters.csv` (columns named as the model's outputs, no bases) and the calibration's
output folder `calibration/`; KEY is the validation run's key (0: the MAP draw). For each meter:
the NMBE of EnergyPlus's run, the profile AR(1) coefficient of its residuals, and the nats the
log likelihood gains when the residuals' mean is removed, with each meter's variance integrated
out (`-n/2 ln S`): independent residuals, and AR(1) with `phi` profiled, as the chains use it
(`bemcal_stats::likelihood::log_marginal_sigma_ar1`, without its run terms). Divide the AR(1)
figure by the chains' temperature for what the tempered posterior feels.
"""
import csv
import json
import math
import sys
from pathlib import Path

import numpy as np


def profile_ar1(r):
    a, b = r[1:], r[:-1]
    m = ~np.isnan(a) & ~np.isnan(b)
    phi = float(np.clip(np.sum(a[m] * b[m]) / np.sum(b[m] ** 2), -0.999, 0.999))
    return phi, float(np.sum((a[m] - phi * b[m]) ** 2))


def main(folder: Path, key: int) -> None:
    rows = list(csv.DictReader(open(folder / "meters.csv")))
    run = json.loads((folder / "calibration" / "validation" / f"point_{key:03d}.json").read_text())
    sims = dict(zip(run["outputs"]["names"], run["outputs"]["series"]))
    for name, sim in sims.items():
        if name not in rows[0]:
            continue
        y = np.array([float(r[name]) if r[name] not in ("", "NaN", "nan") else np.nan for r in rows])
        r = y - np.array(sim)
        n, c = int((~np.isnan(r)).sum()), float(np.nanmean(r))
        iid = -0.5 * n * (math.log(np.nansum((r - c) ** 2)) - math.log(np.nansum(r ** 2)))
        phi, s = profile_ar1(r)
        _, s0 = profile_ar1(r - c)
        ar1 = -0.5 * n * (math.log(s0) - math.log(s))
        print(f"{name:<16} NMBE {100 * c / np.nanmean(y):6.1f} %  phi {phi:.3f}  "
              f"the bias costs: iid {iid:8.1f} nats, AR(1) {ar1:7.1f} nats")


if __name__ == "__main__":
    main(Path(sys.argv[1]), int(sys.argv[2]) if len(sys.argv) > 2 else 0)
