#!/usr/bin/env python3
"""The true savings of a synthetic building's measures: EnergyPlus at its hidden truth, without
and with each measure (`[[measures]]` of its project file: `set`, `scale`, `offset`), annual kWh
per output. Written to DIR/true_savings.json for scripts/savings_coverage.py and its kin.

    true_savings.py DIR BIN MODEL EPW              {"baseline": ..., "savings": {measure: {output: kWh}}}
    true_savings.py DIR BIN MODEL NAME=EPW ...     {NAME: {"baseline": ..., "savings": ...}, ...}

DIR holds truth.json (`bemcal synthesize --truth`) and project.toml; BIN is the bemcal binary,
MODEL the model file. Standard library only.
"""
import json
import subprocess
import sys
import tomllib


def annual(d, bin, model, epw, sets):
    """EnergyPlus's annual kWh per output at the truth (DIR/truth.toml) with `sets` over it."""
    args = [bin, "simulate", "--model", model, "--weather", epw, "--values", f"{d}/truth.toml",
            "--out", f"{d}/truth-run.csv", "--json"]
    for n, v in sets.items():
        args += ["--set", f"{n}={v!r}"]
    return json.loads(subprocess.run(args, check=True, capture_output=True, text=True).stdout)["annual_kwh"]


def true_savings(d, bin, model, epw, truth, measures):
    """The baseline at the truth and each measure's saving (baseline minus after) per output."""
    base = annual(d, bin, model, epw, {})
    true = {}
    for m in measures:
        sets = dict(m.get("set", {}))
        sets.update({n: truth[n] * f for n, f in m.get("scale", {}).items()})
        sets.update({n: truth[n] + a for n, a in m.get("offset", {}).items()})
        after = annual(d, bin, model, epw, sets)
        true[m["name"]] = {o: base[o] - after[o] for o in base}
    return {"baseline": base, "savings": true}


def main():
    d, bin, model, *weathers = sys.argv[1:]
    truth = json.load(open(f"{d}/truth.json"))
    measures = tomllib.load(open(f"{d}/project.toml", "rb"))["measures"]
    with open(f"{d}/truth.toml", "w") as f:
        for n, v in truth.items():
            f.write(f"{n} = {v!r}\n")
    if len(weathers) == 1 and "=" not in weathers[0]:
        out = true_savings(d, bin, model, weathers[0], truth, measures)
    else:
        out = {}
        for w in weathers:
            name, epw = w.split("=", 1)
            out[name] = true_savings(d, bin, model, epw, truth, measures)
    json.dump(out, open(f"{d}/true_savings.json", "w"), indent=1)


if __name__ == "__main__":
    main()
