#!/usr/bin/env bash
# `make savings-weather`: weather-normalised savings against the truth (issue 70).
#
# K synthetic calibrations of the small model (one time step per hour, the year 2017) against
# meters EnergyPlus made under the weather of the metered year: the EPW `bemcal weather` builds
# from Minneapolis-St Paul's 2017 NOAA ISD-lite observations (../shared/data; bemcal itself
# does not need it at run time). Each project calibrates with that year ([measured_weather]),
# so `bemcal savings` reports every measure under the calibration's weather (2017) and under
# the site's typical year (the project's `weather`, the station's TMY3). The true savings are
# EnergyPlus at the hidden truth without and with each measure under each weather: inside the
# 90 % interval per (truth, measure, meter, weather), and the weather's own effect on the
# saving (typical minus 2017, true against the medians'), so that a check which the two
# weathers would pass alike is seen to be one.
#
# Settings as scripts/savings_coverage.sh (four parameters drawn from their priors, three
# measures, a 32-unit surrogate, one refinement round), with the measured temperature.
#
#   K=3  DRAWS=20  OUT=out/savings-weather  BIN=target/release/bemcal  DATA=../shared/data
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/bemcal}
OUT=${OUT:-out/savings-weather}
DATA=${DATA:-../shared/data}
K=${K:-3}
DRAWS=${DRAWS:-20}
PY=${PY:-.venv/bin/python}
export BEMCAL_VENV=${BEMCAL_VENV:-$PWD/.venv}
TMY=$DATA/epw/USA_MN_Minneapolis-St.Paul.Intl.AP.726580_TMY3.epw
ISD=$DATA/noaa_isd_lite_2017/726580-14922-2017.gz
[ -f "$TMY" ] && [ -f "$ISD" ] || { echo "needs $TMY and $ISD"; exit 1; }
NAMES="lighting_power_density equipment_power_density cooling_setpoint_occupied heating_setpoint_occupied"
mkdir -p "$OUT"
echo "binary: $BIN ($(git log -1 --format=%h 2>/dev/null || echo ?)); $(nproc) cores; K = $K; $DRAWS draws"
cp "$TMY" "$OUT/tmy3.epw"
[ -f "$OUT/msp2017.epw" ] || "$BIN" weather --tmy "$TMY" --year 2017 --isd-lite "$ISD" --out "$OUT/msp2017.epw"
sed -e 's/^timesteps_per_hour = 4$/timesteps_per_hour = 1\nminimum_system_timestep_minutes = 0\nyear = 2017/' \
  examples/office/small.toml > "$OUT/small.toml"
grep -q '^year = 2017' "$OUT/small.toml"
cat > "$OUT/project.toml" <<'TOML'
name = "savings-weather"
model = "small.toml"
weather = "tmy3.epw"
calibrate = ["lighting_power_density", "equipment_power_density", "cooling_setpoint_occupied", "heating_setpoint_occupied"]
[measured_weather]
isd_lite = ["726580-14922-2017.gz"]
[meters]
file = "meters.csv"
timestamp_column = "timestamp"
timestamp_format = "iso8601"
convention = "hour_beginning"
dst = "none"
[[meters.columns]]
column = "heating_kwh"
role = "heating"
unit = "kWh"
[[meters.columns]]
column = "cooling_kwh"
role = "cooling"
unit = "kWh"
[[meters.columns]]
column = "electricity_kwh"
role = "electricity"
unit = "kWh"
[design]
points = 12
parallel = 2
[surrogate]
epochs = 25
patience = 6
warm_epochs = 8
threads = 2
hidden = 32
[mcmc]
chains = 4
iterations = 200
burn_in = 60
segment = 200
max_extensions = 0
temperature = "surrogate_error"
[refine]
rounds = 1
iterations = 40
burn_in = 20
[validation]
predictive_draws = 0
mapping_steps = 0
TOML
# The three measures (scripts/savings_measures.toml, shared with the other savings checks).
cat scripts/savings_measures.toml >> "$OUT/project.toml"
first="$OUT/truth-1/calibration"
for k in $(seq 1 "$K"); do
  d="$OUT/truth-$k"
  mkdir -p "$d"
  cp "$OUT/small.toml" "$OUT/project.toml" "$OUT/tmy3.epw" "$ISD" "$d/"
  if [ ! -f "$d/meters.csv" ]; then
    draw=(); for n in $NAMES; do draw+=(--draw "$n"); done
    "$BIN" synthesize --model "$d/small.toml" --weather "$OUT/msp2017.epw" --truth-seed "$((200 + k))" \
      "${draw[@]}" --seed "$k" --out "$d/meters.csv" --truth "$d/truth.json" >/dev/null
  fi
  if [ "$k" -gt 1 ] && [ ! -e "$d/calibration" ] && [ -f "$first/summary.json" ]; then
    mkdir -p "$d/calibration/simulations"
    cp "$first/design.csv" "$d/calibration/"
    cp "$first"/simulations/design.json "$d/calibration/simulations/"
    for i in $(seq -f '%03g' 0 11); do cp "$first/simulations/point_$i.json" "$d/calibration/simulations/"; done
  fi
  t0=$(date +%s)
  if [ ! -f "$d/calibration/summary.json" ]; then
    st=0; "$BIN" calibrate "$d/project.toml" --out "$d/calibration" > "$d/calibrate.out" 2> "$d/calibrate.log" || st=$?
    [ $st -eq 0 ] || [ $st -eq 3 ] || { tail -20 "$d/calibrate.log"; echo "truth $k: calibration failed"; continue; }
  fi
  t1=$(date +%s)
  "$BIN" savings "$d/project.toml" --out "$d/calibration" --draws "$DRAWS" --json > "$d/savings.json" 2> "$d/savings.log" \
    || { tail -5 "$d/savings.log"; echo "truth $k: savings failed"; continue; }
  # The true savings under each weather: EnergyPlus at the truth, without and with each measure.
  $PY scripts/true_savings.py "$d" "$BIN" "$d/small.toml" calibration="$OUT/msp2017.epw" typical="$OUT/tmy3.epw"
  echo "truth $k: calibration $((t1 - t0)) s, savings $(( $(date +%s) - t1 )) s"
done
"$PY" - "$OUT" "$K" <<'PYEOF'
import json, os, sys
out, k = sys.argv[1], int(sys.argv[2])
rows = []
for i in range(1, k + 1):
    d = os.path.join(out, f"truth-{i}")
    try:
        s = json.load(open(os.path.join(d, "savings.json")))
        t = json.load(open(os.path.join(d, "true_savings.json")))
        metered = json.load(open(os.path.join(d, "calibration", "summary.json")))["outputs"]
    except (OSError, ValueError):
        continue
    for m in s["measures"]:
        by = {(o["output"], o["weather"]): o for o in m["outputs"]}
        for (output, weather), o in by.items():
            if output not in metered:
                continue
            true = t[weather]["savings"][m["measure"]][output]
            lo, hi = o["savings_kwh"]["interval_90"]
            rows.append((i, m["measure"], output, weather, true, o["savings_kwh"]["median"], lo, hi))
if not rows:
    sys.exit("no finished run")
print(f"{len({r[0] for r in rows})} runs; per (truth, measure, meter): the true saving inside the 90 % interval")
print(f"{'measure / meter':<44} {'2017 (calibration)':>20} {'TMY3 (typical)':>16}   true TMY3 - 2017 / medians'")
keys = sorted({(r[1], r[2]) for r in rows})
for key in keys:
    cells, shift = [], []
    for w in ("calibration", "typical"):
        rs = [r for r in rows if (r[1], r[2]) == key and r[3] == w]
        inside = sum(r[6] <= r[4] <= r[7] for r in rs)
        cells.append(f"{inside}/{len(rs)}")
    for i in sorted({r[0] for r in rows}):
        a = [r for r in rows if (r[1], r[2]) == key and r[0] == i]
        c = next((r for r in a if r[3] == "calibration"), None)
        ty = next((r for r in a if r[3] == "typical"), None)
        if c and ty:
            shift.append(f"{ty[4] - c[4]:+.0f}/{ty[5] - c[5]:+.0f}")
    print(f"{key[0] + ' / ' + key[1]:<44} {cells[0]:>20} {cells[1]:>16}   {' '.join(shift)}")
for w in ("calibration", "typical"):
    rs = [r for r in rows if r[3] == w]
    inside = sum(r[6] <= r[4] <= r[7] for r in rs)
    print(f"all, {w}: {inside}/{len(rs)} = {100 * inside / len(rs):.1f} % inside the 90 % interval")
PYEOF
