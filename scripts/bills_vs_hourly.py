"""`make bills` (scripts/bills_vs_hourly.sh): prepare the three cases, then tabulate them.

prepare OUT CASES...: from OUT/meters_hourly.csv write OUT/bills_<meter>.csv (twelve bills of 28
to 34 days from 1 January, one estimated read) and OUT/<case>/{quick.toml, meters.csv}.
table OUT CASES...: truth inside the 90 % intervals, the median interval width as a share of
the prior's, Guideline 14 at the estimate on the hidden hourly meters and on the bills.
"""
import csv, datetime as dt, json, pathlib, statistics, sys

DAYS = [30, 33, 29, 31, 32, 28, 30, 34, 29, 31, 30, 28]
METERS = {"heating_kwh": ("heating", "therm", 29.307107), "cooling_kwh": ("cooling", "kWh", 1.0),
          "electricity_kwh": ("electricity", "MWh", 1000.0)}
BILLED = {"hourly": [], "bills": list(METERS), "mixed": ["heating_kwh", "cooling_kwh"]}


def prepare(out, cases):
    rows = list(csv.DictReader(open(out / "meters_hourly.csv")))
    daily = {m: {} for m in METERS}
    for r in rows:
        for m in METERS:
            daily[m][r["timestamp"][:10]] = daily[m].get(r["timestamp"][:10], 0.0) + float(r[m])
    for m, (_, unit, per) in METERS.items():
        lines = ["start,end,quantity,unit,estimated"]
        start = dt.date(2021, 1, 1)
        for i, n in enumerate(DAYS):
            end = start + dt.timedelta(days=n - 1)
            kwh = sum(daily[m][str(start + dt.timedelta(days=d))] for d in range(n))
            lines.append(f"{start},{end},{kwh / per:.4f},{unit},{'E' if i == 2 else ''}")
            start = end + dt.timedelta(days=1)
        (out / f"bills_{m}.csv").write_text("\n".join(lines) + "\n")
    quick = pathlib.Path("examples/office/quick.toml").read_text()
    for case in cases:
        d = out / case
        d.mkdir(exist_ok=True)
        (d / "small.toml").write_text((out / "small.toml").read_text())
        billed = BILLED[case]
        text = quick
        for m in billed:
            role = METERS[m][0]
            text = text.replace(f'[[meters.columns]]\ncolumn = "{m}"\nrole = "{role}"\nunit = "kWh"\n', "")
        if len(billed) == len(METERS):
            head, rest = text.split("[meters]\n", 1)
            text = head + rest[rest.index("[design]"):]
        else:
            keep = [m for m in METERS if m not in billed]
            with open(d / "meters.csv", "w", newline="") as f:
                w = csv.writer(f)
                w.writerow(["timestamp"] + keep)
                for r in rows:
                    w.writerow([r["timestamp"]] + [r[m] for m in keep])
        for m in billed:
            # Inside the project's folder: local workers submit it to a coordinator.
            (d / f"bills_{m}.csv").write_text((out / f"bills_{m}.csv").read_text())
            text += f'\n[[meters.bills]]\nfile = "bills_{m}.csv"\nrole = "{METERS[m][0]}"\n'
        (d / "quick.toml").write_text(text)


def table(out, cases):
    truth = json.load(open(out / "truth.json"))
    truth = truth.get("values", truth)
    print("| case | truths inside the 90 % interval | median width / prior | max R-hat | T |"
          " G14 hourly at the estimate (NMBE / CV-RMSE %, heating, cooling, electricity) |"
          " G14 on the bills (same order) |")
    print("|---|---|---|---|---|---|---|")
    for case in cases:
        s = json.load(open(out / case / "calibration" / "summary.json"))
        held, widths = 0, []
        for p in s["posterior"]["parameters"]:
            t = truth[p["name"]]
            prior = next(q for q in s["parameters"] if q["name"] == p["name"])
            held += p["q5"] <= t <= p["q95"]
            widths.append((p["q95"] - p["q5"]) / (prior["prior_max"] - prior["prior_min"]))
        m = json.load(open(out / case / "metrics.json"))
        fmt = lambda res: ", ".join(f"{r['nmbe_percent']:.1f} / {r['cv_rmse_percent']:.1f}"
                                    for r in m if r["resolution"] == res and r["output"] in METERS)
        rhat = s["posterior"].get("max_rhat", float("nan"))
        print(f"| {case} | {held} of {len(widths)} | {statistics.median(widths):.2f} | {rhat:.3f} |"
              f" {s['temperature']['value']:.1f} | {fmt('hourly')} | {fmt('bills')} |")


if __name__ == "__main__":
    out = pathlib.Path(sys.argv[2])
    {"prepare": prepare, "table": table}[sys.argv[1]](out, sys.argv[3:])
