"""Issue 66's portfolio table (scripts/portfolio_pretrained.sh): per building, how its surrogate
started, the final temperature T, the parameters whose 90 % interval is narrower than half the
prior's, the truth inside the 90 % interval, Guideline 14 hourly and monthly at the estimate,
convergence, the temperature at which 90 % of the truths would have been inside
([temperature_needed]), and its cost: the workers' busy seconds (the coordinator's attempts, by job kind),
from each batch's portfolio.json (`worker_s`), so that session gaps and the interleaving of
buildings do not count. Then the totals: pass rate, coverage, and buildings per core-hour of each
start, with their ratio.

    python3 scripts/portfolio_table.py OUT [--json]

Standard library only.
"""
import csv
import glob
import json
import math
import os
import re
import statistics
import sqlite3
import sys


def portfolio_rows(out):
    """Each building's row of its batch's portfolio.json (`bemcal portfolio results`): its run
    time and the workers' busy seconds on its jobs, by stage (attempts that ended done or
    failed; one lost when a session stopped the workers was run again and is not counted)."""
    rows = {}
    for path in glob.glob(f"{out}/results/*/portfolio.json"):
        with open(path) as f:
            for r in json.load(f)["rows"]:
                rows[r["building"]] = r
    return rows


def temperature_needed(cal, truth, s):
    """The temperature at which 90 % of the truths would lie inside their 90 % intervals, in
    the Gaussian approximation: each truth's distance from the posterior mean in posterior
    standard deviations z_j; widening the posterior from T to T' scales them by sqrt(T / T'), so
    the k-th smallest (k = ceil(0.9 d)) reaches 1.645 at T' = T (z_k / 1.645)^2. Beside the T the
    rule chose, it says whether the rule erred low (intervals too narrow) or high."""
    with open(f"{cal}/draws.csv") as f:
        rows = list(csv.DictReader(f))
    zs = []
    for p in s["posterior"]["parameters"]:
        if p["name"] not in truth:
            continue
        x = [float(r[p["name"]]) for r in rows]
        sd = statistics.stdev(x)
        if sd > 0:
            zs.append(abs(truth[p["name"]] - statistics.mean(x)) / sd)
    if not zs:
        return None
    zs.sort()
    k = math.ceil(0.9 * len(zs))
    return s["temperature"]["value"] * (zs[k - 1] / 1.645) ** 2


def where_time_goes(out, run):
    """The run's busy seconds in finer parts than its stages, from the coordinator's attempts
    table (read-only): EnergyPlus (design points, refinement draws, validation), surrogate
    training, the refinement rounds' random-walk chains, and the final HMC chains with their
    extensions."""
    db = f"{out}/data/coordinator.db"
    if not os.path.exists(db):
        return {}
    c = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    parts = {}
    for label, stage, s in c.execute(
            "SELECT j.label, j.stage, (a.ended_ms - a.started_ms) / 1000.0 FROM attempts a "
            "JOIN jobs j ON a.job_id = j.id WHERE j.run_id = ? AND a.outcome IN ('done', 'failed')",
            (run,)):
        if stage == "chains":
            key = "round chains (MH)" if re.search(r"refinement round", label) else "final chains (HMC)"
        elif stage in ("simulate", "refine", "validate"):
            key = "EnergyPlus"
        else:
            key = stage
        parts[key] = parts.get(key, 0.0) + s
    return {k: round(v) for k, v in parts.items()}


def row(out, portfolio, summary_path):
    cal = os.path.dirname(summary_path)
    building = os.path.basename(cal)
    base = building.removesuffix("-scratch")
    with open(summary_path) as f:
        s = json.load(f)
    with open(f"{out}/buildings/{base}/truth.json") as f:
        truth = json.load(f)
    post = s["posterior"]["parameters"]
    learned = sum(1 for p in post if p["width_ratio"] < 0.5)
    judged = [p for p in post if p["name"] in truth]
    held = sum(1 for p in judged if p["q5"] <= truth[p["name"]] <= p["q95"])
    fitted = [v for v in s["validation"] if v["output"] not in (s.get("not_fitted") or [])]
    hourly = all(v["pass"] for v in fitted)
    monthly = all(v.get("monthly", {}).get("pass", False) for v in fitted)
    start = (s.get("surrogate_start") or {}).get("from", "scratch")
    c = s["convergence"]
    p = portfolio[building]
    busy = p["worker_s_by_stage"]
    rounds = [r["surrogate_error"] for r in s.get("refinement", [])]
    last = {e["output"]: e["cv_rmse"] for e in rounds[-1]} if rounds else {}
    return {
        "building": building, "start": start, "T": s["temperature"]["value"],
        "T_pooled_with": s["temperature"].get("pooled_with_buildings"),
        "learned": learned, "parameters": len(post), "held": held, "judged": len(judged),
        "g14_hourly": hourly, "g14_monthly": monthly, "estimate": s["estimate_choice"]["chosen"],
        "g14": " ".join(f"{v['output'].replace('_kwh', '')} {v['nmbe']:.1f}/{v['cv_rmse']:.1f}" for v in fitted),
        "surrogate_cv_rmse_last_round": " / ".join(f"{last[o]:.1f}" for o in
                                                   ("heating_kwh", "cooling_kwh", "electricity_kwh") if o in last),
        "converged": c["converged"], "rhat": c["max_rhat"], "ess": (c["min_ess_bulk"], c["min_ess_tail"]),
        "busy_s": sum(busy.values()), "busy_by_stage": {k: round(v) for k, v in busy.items()},
        "wall_s": p["run_time_s"], "parts": where_time_goes(out, p["run"]),
        "T_needed": temperature_needed(cal, truth, s),
    }


def main():
    out = sys.argv[1]
    portfolio = portfolio_rows(out)
    rows = [row(out, portfolio, p) for p in sorted(glob.glob(f"{out}/results/*/*/summary.json"))]
    if "--json" in sys.argv:
        print(json.dumps(rows, indent=1))
        return
    print("| building | start | T (needed for 90 % coverage) | learned (< 0.5 of prior) | truth in 90 % | G14 hourly / monthly at the estimate (NMBE/CV-RMSE %) | surrogate at the last round's draws (CV-RMSE %) | converged (R-hat, ESS bulk/tail) | worker s (by stage) |")
    print("|---|---|---:|---|---|---|---|---|---|")
    for r in rows:
        pooled = f", pooled with {r['T_pooled_with']}" if r["T_pooled_with"] else ""
        print(f"| {r['building']} | {r['start']} | {r['T']:.1f}{pooled} ({r['T_needed']:.1f}) | {r['learned']} of {r['parameters']} | "
              f"{r['held']} of {r['judged']} | {'pass' if r['g14_hourly'] else 'FAIL'} / "
              f"{'pass' if r['g14_monthly'] else 'FAIL'} ({r['estimate']}: {r['g14']}) | "
              f"{r['surrogate_cv_rmse_last_round']} | {r['converged']} ({r['rhat']:.3f}, {r['ess'][0]:.0f}/{r['ess'][1]:.0f}) | "
              f"{r['busy_s']:.0f} ({', '.join(f'{k} {v}' for k, v in sorted(r['busy_by_stage'].items()))}) |")
    for start in sorted({r["start"] for r in rows}):
        rs = [r for r in rows if r["start"] == start]
        busy = sum(r["busy_s"] for r in rs)
        print(f"\n{start}: {len(rs)} buildings; Guideline 14 hourly {sum(r['g14_hourly'] for r in rs)} / "
              f"monthly {sum(r['g14_monthly'] for r in rs)} of {len(rs)}; truth in the 90 % interval "
              f"{sum(r['held'] for r in rs)} of {sum(r['judged'] for r in rs)}; learned "
              f"{sum(r['learned'] for r in rs)} of {sum(r['parameters'] for r in rs)}; median T "
              f"{sorted(r['T'] for r in rs)[len(rs) // 2]:.1f}; {busy / len(rs):.0f} busy s a building, "
              f"{3600 * len(rs) / busy:.2f} buildings per core-hour")
    print("\nWhere the busy seconds go (the coordinator's attempts):\n")
    kinds = ["EnergyPlus", "train", "round chains (MH)", "final chains (HMC)"]
    print("| building | " + " | ".join(kinds) + " |")
    print("|---|" + "---:|" * len(kinds))
    for r in rows:
        if r["parts"]:
            total = sum(r["parts"].values())
            print(f"| {r['building']} | " + " | ".join(
                f"{r['parts'].get(k, 0)} ({100 * r['parts'].get(k, 0) / total:.0f} %)" for k in kinds) + " |")
    # The ratio on the buildings both starts calibrated.
    pairs = [(r, s) for r in rows for s in rows
             if s["building"] == r["building"] + "-scratch" and r["start"] != s["start"]]
    if pairs:
        a = sum(s["busy_s"] for _, s in pairs) / sum(r["busy_s"] for r, _ in pairs)
        print(f"\nsame buildings ({', '.join(r['building'] for r, _ in pairs)}): from scratch / pretrained "
              f"busy seconds = {a:.2f}")


if __name__ == "__main__":
    main()
