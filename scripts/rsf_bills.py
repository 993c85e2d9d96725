#!/usr/bin/env python3
"""The NREL RSF 2011's heating as the utility would bill it (issue 69): examples/rsf/heating_bills.csv.

Read dates as a meter reader keeps them (working days, 28 to 33 days apart, from 4 January to
2 December); each bill is the sum of the hourly "Total Heating (kW)" column over its days
(hour-ending stamps: the day D holds D 01:00 to D+1 00:00), in MMBtu, with its peak hour as
the billed demand. The heat meter read zero from 4 to 30 March (an outage): the bill of 3 to
31 March is the utility's estimate (the February bill's daily mean times its days), flagged
estimated. No true-up follows, as the meter counted nothing, so project-bills.toml says
`estimated = "drop"`.

usage: scripts/rsf_bills.py [RSF_CSV] [OUT_CSV]
"""
import csv
import datetime as dt
import sys
from collections import defaultdict

RSF = sys.argv[1] if len(sys.argv) > 1 else "../shared/data/nrel_rsf_2011/rsfmeasureddata2011.csv"
OUT = sys.argv[2] if len(sys.argv) > 2 else "examples/rsf/heating_bills.csv"
KWH_PER_MMBTU = 293.071_07
READS = ["2011-01-04", "2011-02-03", "2011-03-03", "2011-04-01", "2011-05-03", "2011-06-02",
         "2011-07-05", "2011-08-03", "2011-09-01", "2011-10-04", "2011-11-02", "2011-12-02"]
OUTAGE_BILL = "2011-03-03"

daily = defaultdict(float)
peak = defaultdict(float)
with open(RSF, newline="") as f:
    for row in csv.DictReader(f):
        stamp = dt.datetime.strptime(row["Date and Time"], "%m/%d/%Y %H:%M")
        day = (stamp - dt.timedelta(hours=1)).date()  # hour ending: 00:00 closes the day before
        kw = float(row["Total Heating (kW)"])
        daily[day] += kw
        peak[day] = max(peak[day], kw)

reads = [dt.date.fromisoformat(r) for r in READS]
rows = []
for start, nxt in zip(reads, reads[1:]):
    days = [start + dt.timedelta(d) for d in range((nxt - start).days)]
    assert all(d.weekday() < 5 for d in (start, nxt)), "reads on working days"
    kwh = sum(daily[d] for d in days)
    demand = max(peak[d] for d in days)
    estimated = start.isoformat() == OUTAGE_BILL
    if estimated:
        prev = rows[-1]
        kwh = prev["kwh"] / prev["days"] * len(days)
        demand = None
    rows.append({"start": start, "end": days[-1], "kwh": kwh, "days": len(days),
                 "demand": demand, "estimated": estimated})

with open(OUT, "w", newline="") as f:
    w = csv.writer(f, lineterminator="\n")
    w.writerow(["start", "end", "quantity", "unit", "demand_kw", "estimated"])
    for r in rows:
        w.writerow([r["start"], r["end"], f"{r['kwh'] / KWH_PER_MMBTU:.2f}", "MMBtu",
                    "" if r["demand"] is None else f"{r['demand']:.0f}",
                    "E" if r["estimated"] else "A"])
print(f"{OUT}: {len(rows)} bills, {sum(r['kwh'] for r in rows) / 1000:.1f} MWh billed")
