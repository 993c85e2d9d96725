"""Tabulate `make model-form` (scripts/model_form.sh): per cross-model case, without and with the
discrepancy term, how many of the six shared parameters' 90 % intervals hold the truth, how much
the posterior learned, the temperature, convergence, Guideline 14 at the estimate (calibration
and held-out hours), the held-out predictive coverage, and what the term carried.

    python scripts/model_form.py OUT CASE...
"""

import json
import os
import statistics
import sys
from pathlib import Path


def held(summary, truth, intervals):
    """(held, total, missed names) over the calibrated parameters."""
    n, misses = 0, []
    for name, (lo, hi) in intervals.items():
        if lo <= truth[name] <= hi:
            n += 1
        else:
            misses.append(name)
    return n, len(intervals), misses


def chain_intervals(s):
    return {p["name"]: (p["q5"], p["q95"]) for p in s["posterior"]["parameters"]}


def reported_intervals(s):
    """The intervals the report and the CLI give: with the surrogate's error where measured."""
    e = s.get("surrogate_error")
    if not e:
        return chain_intervals(s)
    return {p["name"]: (p["q5"], p["q95"]) for p in e["parameters"]}


def g14(s):
    """'pass' / the failing meters, hourly at the estimate, calibration and held-out hours."""
    cal = [v["output"] for v in s["validation"] if not v["pass"]]
    out = [
        v["output"]
        for v in s["validation"]
        if v.get("held_out") and not v["held_out"]["hourly"]["pass"]
    ]
    f = lambda failed: "pass" if not failed else "fail " + "+".join(m.split("_")[0] for m in failed)
    return f(cal), f(out)


def worst_limit(s):
    ratios = [max(abs(v["nmbe"]) / 10.0, v["cv_rmse"] / 30.0) for v in s["validation"]]
    held = [
        max(abs(h["nmbe"]) / 10.0, h["cv_rmse"] / 30.0)
        for h in (v.get("held_out", {}).get("hourly") for v in s["validation"])
        if h
    ]
    return max(ratios), (max(held) if held else float("nan"))


def predictive_90(s):
    """Held-out 90 % predictive coverage per meter (the chosen error model's)."""
    p = s.get("predictive") or {}
    out = {}
    for o in p.get("outputs", []):
        chosen = o.get("error_model")
        for m in o["by_error_model"]:
            if m["error_model"] == chosen:
                for c in m.get("held_out") or []:
                    if abs(c["nominal"] - 0.9) < 1e-9:
                        out[o["output"]] = c["fraction"]
    return out


def carried(s):
    return {c["meter"]: c["rms_percent_of_mean"] for c in s.get("discrepancy_carried", [])}


def main():
    root = Path(sys.argv[1])
    cases = sys.argv[2:]
    rows = []
    detail = []
    for case in cases:
        d = root / case
        truth = json.loads((d / "truth.json").read_text())
        for term in os.environ.get("TERMS", "none hour_day_season hour_day_season_free").split():
            f = d / f"summary-{term}.json"
            if not f.exists():
                continue
            s = json.loads(f.read_text())
            ci, ri = chain_intervals(s), reported_intervals(s)
            hc, n, _ = held(s, truth, ci)
            hr, _, missed = held(s, truth, ri)
            ratios = [p["width_ratio"] for p in s["posterior"]["parameters"]]
            learned = sum(r < 0.5 for r in ratios)
            cal, ho = g14(s)
            w_cal, w_ho = worst_limit(s)
            pc = predictive_90(s)
            rows.append(
                (
                    case,
                    term,
                    f"{hr}/{n}",
                    f"{hc}/{n}",
                    f"{statistics.median(ratios):.2f}",
                    f"{learned}/{n}",
                    f"{s['temperature']['value']:.3g}",
                    f"{s['posterior']['max_rhat']:.3f}" + ("" if s["converged"] else " (not conv.)"),
                    f"{cal} ({w_cal:.2f})",
                    f"{ho} ({w_ho:.2f})",
                    " / ".join(f"{100 * pc[k]:.0f}" for k in sorted(pc)) if pc else "-",
                    " / ".join(f"{v:.1f}" for k, v in sorted(carried(s).items())) or "-",
                )
            )
            detail.append(
                (
                    case,
                    term,
                    "; ".join(
                        f"{name} {truth[name]:g} in [{ri[name][0]:.4g}, {ri[name][1]:.4g}]"
                        + ("" if name not in missed else " MISSED")
                        for name in ri
                    ),
                )
            )
    head = (
        "| case | discrepancy | truth held (reported) | truth held (chains) | median width ratio "
        "| narrowed < 0.5 | T | max R-hat | G14 at estimate (worst / limit) | held-out G14 "
        "| held-out 90 % predictive, % (cool / elec / heat) | carried, % of mean (cool / elec / heat) |"
    )
    print(head)
    print("|" + "---|" * (head.count("|") - 1))
    for r in rows:
        print("| " + " | ".join(r) + " |")
    print()
    for case, term, text in detail:
        print(f"- {case} / {term}: {text}")


if __name__ == "__main__":
    main()
