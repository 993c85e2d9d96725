#!/usr/bin/env bash
# `make bills`: what bills can identify against hourly meters, on the same building (issue 69).
#
# make quick's building (the one-zone small model, six parameters, quick.toml's settings) and
# its synthetic meters at make quick's truth (5 % hourly noise, no gap), calibrated three ways:
#
#   hourly  the three meters hour by hour (make quick itself)
#   bills   the three meters as twelve bills each, of 28 to 34 days, summed from the same noisy
#           hours (heating in therms, cooling in kWh, electricity in MWh; one estimated read)
#   mixed   hourly electricity, heating and cooling as those bills
#
# Each case after the first starts from the first's design runs and first surrogate (the same
# outputs): what differs is what the chains and the refinement round see. scripts/bills_vs_hourly.py
# tabulates truth held, interval widths and Guideline 14 (on the hidden hourly meters, and on the
# bills, by `bemcal metrics --bills`).
#
#   CASES="hourly bills mixed"   OUT=out/bills   BIN=target/release/bemcal
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/bemcal}
OUT=${OUT:-out/bills}
PY=${PY:-.venv/bin/python}
CASES=${CASES:-hourly bills mixed}
export BEMCAL_VENV=${BEMCAL_VENV:-$PWD/.venv}
WEATHER=bundled:USA_CO_Golden-NREL.724666_TMY3.epw
TRUTH=(--set wall_insulation_conductivity=0.045 --set shgc=0.62 --set equipment_power_density=14
  --set cooling_setpoint_occupied=23 --set heating_setpoint_occupied=22 --set outdoor_air_ach_occupied=1.25)
echo "binary: $BIN ($(git log -1 --format=%h 2>/dev/null || echo ?)); $(nproc) cores; cases: $CASES"
mkdir -p "$OUT"
cp examples/office/small.toml "$OUT/"
test -f "$OUT/meters_hourly.csv" || "$BIN" synthesize --model "$OUT/small.toml" --weather "$WEATHER" \
  "${TRUTH[@]}" --gap 0:0 --out "$OUT/meters_hourly.csv" --truth "$OUT/truth.json"
"$PY" scripts/bills_vs_hourly.py prepare "$OUT" $CASES
# A case run before (the first of a previous run) seeds the others.
first=""
[ -d "$OUT/hourly/calibration/surrogate" ] && first=hourly
for c in $CASES; do
  cal="$OUT/$c/calibration"
  if [ -n "$first" ] && [ "$first" != "$c" ] && [ ! -d "$cal/surrogate" ]; then
    mkdir -p "$cal/simulations"
    cp "$OUT/$first/calibration/design.csv" "$cal/"
    cp -r "$OUT/$first/calibration/simulations/." "$cal/simulations/"
    cp -r "$OUT/$first/calibration/surrogate" "$cal/surrogate"
  fi
  start=$(date +%s)
  st=0; "$BIN" calibrate "$OUT/$c/quick.toml" --local-workers 2 --out "$cal" > "$OUT/$c/log.txt" 2>&1 || st=$?
  test $st -eq 0 -o $st -eq 3 || { tail -5 "$OUT/$c/log.txt"; exit $st; }
  echo "$c: $(( $(date +%s) - start )) s (exit $st)"
  "$BIN" simulate --project "$OUT/$c/quick.toml" --values "$cal/calibrated.toml" --out "$OUT/$c/estimate.csv" > /dev/null
  "$BIN" metrics --measured "$OUT/meters_hourly.csv" --simulated "$OUT/$c/estimate.csv" \
    $(for m in heating cooling electricity; do echo --bills "${m}_kwh=$OUT/bills_${m}_kwh.csv"; done) \
    --json > "$OUT/$c/metrics.json" 2> /dev/null
  [ -z "$first" ] && first=$c
done
true
"$PY" scripts/bills_vs_hourly.py table "$OUT" $CASES
