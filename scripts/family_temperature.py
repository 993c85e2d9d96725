"""Which final temperature holds the truths: each building of a portfolio's results (synthetic
meters, truths known) under the building's own rule, the family's recoveries alone, all pooled
as one, and its own and the family's weighted half and half (FAMILY_WEIGHT), the family always
the *other* buildings (each left out of the family it is pooled with). For each, the truths
inside the 90 % interval and the intervals narrower than half the prior's, from the building's
posterior draws rescaled to the rule's T in the Gaussian approximation (widths and distances
scale with sqrt(T / T_run)), beside the T its truths needed (scripts/portfolio_table.py).

    python3 scripts/family_temperature.py OUT [BUILDING ...]

OUT as scripts/portfolio_pretrained.sh leaves it; BUILDING restricts the buildings evaluated
(the family is still every other pretrained building). Standard library only.
"""
import csv
import glob
import json
import math
import os
import statistics
import sys
from statistics import NormalDist

sys.path.insert(0, os.path.dirname(__file__))
from family_shifts import ratios  # noqa: E402

Z = NormalDist().inv_cdf(0.95)
LEVEL = 0.9


def coverage(r, t):
    """bemcal_stats::surrogate_error::expected_coverage."""
    return sum(2 * NormalDist().cdf(Z * math.sqrt(t / (1 + x))) - 1 for x in r) / len(r)


def temperature(groups):
    """bemcal_stats::surrogate_error::pooled_temperature: groups of (ratios, weight)."""
    groups = [(r, w) for r, w in groups if r and w > 0]
    total = sum(w for _, w in groups)
    f = lambda t: sum(w / total * coverage(r, t) for r, w in groups)  # noqa: E731
    if f(1.0) >= LEVEL - 1e-12:
        return 1.0
    lo, hi = 0.0, math.log(1 + max(x for r, _ in groups for x in r))
    while hi - lo > 1e-9:
        m = (lo + hi) / 2
        lo, hi = (lo, m) if f(math.exp(m)) >= LEVEL - 1e-12 else (m, hi)
    return math.exp(hi)


def building(out, cal):
    name = cal.rsplit("/", 1)[1]
    with open(f"{cal}/summary.json") as f:
        s = json.load(f)
    if (s.get("surrogate_start") or {}).get("from") != "pretrained":
        return None
    with open(f"{out}/buildings/{name}/truth.json") as f:
        truth = json.load(f)
    with open(f"{cal}/refine.json") as f:
        r = ratios(s, json.load(f))
    with open(f"{cal}/draws.csv") as f:
        rows = list(csv.DictReader(f))
    zs, widths = [], []
    for p in s["posterior"]["parameters"]:
        x = [float(row[p["name"]]) for row in rows]
        sd = statistics.stdev(x)
        if sd > 0:
            zs.append(abs(truth[p["name"]] - statistics.mean(x)) / sd)
        widths.append(p["width_ratio"])
    return dict(name=name, T=s["temperature"]["value"], ratios=list(r.values()), zs=zs, widths=widths)


def held(b, t):
    return sum(z * math.sqrt(b["T"] / t) <= Z for z in b["zs"])


def learned(b, t):
    return sum(w * math.sqrt(t / b["T"]) < 0.5 for w in b["widths"])


def main():
    out, only = sys.argv[1], set(sys.argv[2:])
    bs = [b for c in sorted(glob.glob(f"{out}/results/*/*/summary.json"))
          if (b := building(out, c.rsplit("/", 1)[0]))]
    rules = {
        "own": lambda own, fam: [(own, 1.0)],
        "family": lambda own, fam: [(fam, 1.0)],
        "all as one": lambda own, fam: [(own + fam, 1.0)],
        "half and half": lambda own, fam: [(own, 0.5), (fam, 0.5)],
    }
    print("| building | T needed | " + " | ".join(f"{k}: T, truth, learned" for k in rules) + " |")
    print("|---|---:|" + "---|" * len(rules))
    tot = {k: [0, 0, 0] for k in rules}
    for b in bs:
        if only and b["name"] not in only:
            continue
        fam = [x for c in bs if c is not b for x in c["ratios"]]
        k = math.ceil(LEVEL * len(b["zs"]))
        need = b["T"] * (sorted(b["zs"])[k - 1] / Z) ** 2
        cells = []
        for rule, groups in rules.items():
            t = temperature(groups(b["ratios"], fam))
            h, l = held(b, t), learned(b, t)
            tot[rule][0] += h
            tot[rule][1] += l
            tot[rule][2] += len(b["zs"])
            cells.append(f"{t:.1f}, {h}, {l}")
        print(f"| {b['name']} | {need:.1f} | " + " | ".join(cells) + " |")
    print("| all | | " + " | ".join(f"-, {h} of {n}, {l} of {n}" for h, l, n in tot.values()) + " |")


if __name__ == "__main__":
    main()
