"""The demo building, today's path and the pretrained one side by side (issue 66's Must show):
for each calibration folder, the surrogate's error against EnergyPlus at each refinement round's
posterior draws (hourly CV-RMSE per meter), the final temperature T, how many parameters have a
90 % interval narrower than half the prior's, the truth inside the 90 % interval, Guideline 14
hourly and monthly at the estimate (and which estimate), convergence and wall time.

    python3 scripts/demo_side_by_side.py TRUTH.json LABEL=CAL_DIR [LABEL=CAL_DIR ...]

Reads only summary.json and the truth file (standard library only).
"""
import json
import sys


def row(label, cal, truth):
    with open(f"{cal}/summary.json") as f:
        s = json.load(f)
    post = s["posterior"]["parameters"]
    learned = sum(1 for p in post if p["width_ratio"] < 0.5)
    held = sum(1 for p in post if p["name"] in truth and p["q5"] <= truth[p["name"]] <= p["q95"])
    rounds = []
    for r in s.get("refinement", []):
        err = {e["output"]: e["cv_rmse"] for e in r["surrogate_error"]}
        rounds.append(f"round {r['round']}: " + " / ".join(f"{err[o]:.1f}" for o in
                                                          ("heating_kwh", "cooling_kwh", "electricity_kwh") if o in err)
                      + f" (T {r['temperature']:.0f})")
    g14 = []
    for v in s["validation"]:
        m = v.get("monthly", {})
        g14.append(f"{v['output'].replace('_kwh', '')} {v['nmbe']:.1f}/{v['cv_rmse']:.1f} "
                   f"{'pass' if v['pass'] else 'FAIL'}, monthly {m.get('nmbe', float('nan')):.1f}/"
                   f"{m.get('cv_rmse', float('nan')):.1f} {'pass' if m.get('pass') else 'FAIL'}")
    c = s["convergence"]
    start = s.get("surrogate_start") or {"from": "scratch"}
    return {
        "label": label, "start": start.get("from"),
        "surrogate_error": "; ".join(rounds),
        "T": s["temperature"]["value"],
        "learned": f"{learned} of {len(post)}",
        "median_width_ratio": sorted(p["width_ratio"] for p in post)[len(post) // 2],
        "truth_held": f"{held} of {sum(1 for p in post if p['name'] in truth)}",
        "estimate": s["estimate_choice"]["chosen"],
        "g14": "; ".join(g14),
        "converged": f"{c['converged']} (R-hat {c['max_rhat']:.3f}, ESS {c['min_ess_bulk']:.0f} / {c['min_ess_tail']:.0f}, "
                     f"{s.get('chain_extensions', 0)} extensions)",
        "wall_s": s["timings"]["total_s"],
        "timings": {k: round(v) for k, v in s["timings"].items()},
    }


def main():
    with open(sys.argv[1]) as f:
        truth = json.load(f)
    rows = [row(*a.split("=", 1), truth) for a in sys.argv[2:]]
    for r in rows:
        print(f"## {r['label']}")
        for k, v in r.items():
            if k != "label":
                print(f"- {k}: {v}")
    if len(rows) == 2:
        print(f"\nwall time ratio {rows[1]['label']} / {rows[0]['label']}: {rows[1]['wall_s'] / rows[0]['wall_s']:.2f}")


if __name__ == "__main__":
    main()
