"""The family record of a pretrained network (`family.json` beside its weights; issue 66): each
building of a portfolio calibrated from that network, its shift ratios of its last refinement
round, r_j = T_r s^2 S_jj / V_j (bemcal_stats::surrogate_error::shift_ratios: the surrogate's
error in parameter space, in units of the untempered posterior's variance), so that the final
temperature of a later building pools them with its own (bemcal_calibrate::surrogate_error).

    python3 scripts/family_shifts.py OUT MEASURED > family.json

OUT is a portfolio's folder as scripts/portfolio_pretrained.sh leaves it (results/*/NAME/ with
summary.json and refine.json); buildings that did not start from the pretrained network (their
summary's surrogate_start) are left out. MEASURED says what was run. A building pooled later
is never pooled with its own entry (the same name), and only on the parameters it calibrates.
Standard library only.
"""
import glob
import math
import json
import statistics
import sys


def ratios(summary, refine):
    """The last round with recoveries: each calibrated parameter's ratio (left out where the
    round's points have no spread), as the Rust rule computes them."""
    names = [p["name"] for p in summary["parameters"]]
    rounds = [r for r in refine["rounds"] if len(r["recovered"]) == len(r["points"]) >= 2]
    if not rounds:
        return None
    r = rounds[-1]
    points = [p["values"] for p in r["points"]]
    out = {}
    for j, name in enumerate(names):
        column = [p[j] for p in points]
        v = statistics.variance(column)
        if v > 0:
            s2 = sum((rec[j] - p[j]) ** 2 for p, rec in zip(points, r["recovered"])) / len(points)
            ratio = r.get("temperature", 1.0) * r.get("spread", 1.0) ** 2 * s2 / v
            if math.isfinite(ratio):
                out[name] = ratio
    return out


def main():
    out, measured = sys.argv[1], sys.argv[2]
    buildings = []
    for path in sorted(glob.glob(f"{out}/results/*/*/summary.json")):
        cal = path.rsplit("/", 1)[0]
        with open(path) as f:
            summary = json.load(f)
        if (summary.get("surrogate_start") or {}).get("from") != "pretrained":
            continue
        with open(f"{cal}/refine.json") as f:
            r = ratios(summary, json.load(f))
        if r:
            buildings.append({"name": cal.rsplit("/", 1)[1], "ratios": r})
    json.dump({"measured": measured, "buildings": buildings}, sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
