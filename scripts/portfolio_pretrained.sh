#!/usr/bin/env bash
# Issue 66's portfolio: distinct buildings of the robustness sweep's shapes (and the example
# office) x two climates, meters synthesised by EnergyPlus at hidden truths, calibrated end to end
# through one coordinator and two workers from the pretrained surrogate
# (corpus/pretrained/conditioned-200, own design points POINTS, [refine] spread = 2); and SCRATCH of
# the same buildings calibrated today's way (20 design points, random weights) for the cost ratio.
#
# Resumable across sessions: the coordinator's state lives in $OUT/data (finished jobs stand after
# a restart); a rerun restarts the coordinator and the workers, submits nothing twice, waits, and
# downloads what finished. The cost of a building is its workers' busy seconds (the coordinator's
# attempts table), so gaps between sessions and the interleaving of buildings do not count.
#
#   OUT=dir        state and results (default ~/.cache/bemcal/portfolio66)
#   BIN=path       bemcal binary (copied into $OUT/bin on the first run and used from there)
#   POINTS=n       own design points of the pretrained buildings (default 10)
#   SCRATCH="a b"  buildings also calibrated from random weights (default "B-Golden C-Chicago")
#   WAIT=0         submit and start, then return without waiting
#   python3 scripts/portfolio_table.py $OUT   tabulates (also run at the end)
set -euo pipefail
cd "$(dirname "$0")/.."
REPO=$PWD
OUT=${OUT:-$HOME/.cache/bemcal/portfolio66}
POINTS=${POINTS:-10}
SCRATCH=${SCRATCH:-B-Golden C-Chicago}
WAIT=${WAIT:-1}
PORT=${PORT:-50166}
export BEMCAL_VENV=${BEMCAL_VENV:-$REPO/.venv}
mkdir -p "$OUT/bin" "$OUT/buildings" "$OUT/logs"
if [ ! -x "$OUT/bin/bemcal" ]; then
  cp "${BIN:-target/release/bemcal}" "$OUT/bin/bemcal"
  git log -1 --format='%h %cs' >"$OUT/bin/commit"
fi
B="$OUT/bin/bemcal"
[ -d "$OUT/pretrained" ] || cp -r corpus/pretrained/conditioned-200 "$OUT/pretrained"
[ -f "$OUT/token" ] || head -c 24 /dev/urandom | od -An -tx1 | tr -d ' \n' >"$OUT/token"
export BEMCAL_TOKEN; BEMCAL_TOKEN=$(cat "$OUT/token")
export BEMCAL_COORDINATOR=http://127.0.0.1:$PORT

# name: storeys, footprint, floor-to-floor, zoning, window-to-wall (scripts/sweep.sh's A-D; E's
# ten storeys lie outside the corpus's 1-6) and the example office.
declare -A SPEC=(
  [A]='1 20.0 15.0 3.5 one_per_floor 0.3'
  [B]='3 50.0 30.0 4.0 one_per_floor 0.4'
  [C]='3 50.0 30.0 4.0 perimeter_core 0.4'
  [D]='6 60.0 40.0 3.8 one_per_floor 0.6'
)
declare -A CLIMATE=(
  [Golden]=bundled:USA_CO_Golden-NREL.724666_TMY3.epw
  [Chicago]=bundled:USA_IL_Chicago-OHare.Intl.AP.725300_TMY3.epw
)
# The from-scratch pair third: the cost ratio is known before the last shapes finish.
BATCHES=${BATCHES:-p66-A p66-B p66-scratch p66-C p66-D p66-office}
# Only the buildings of the batches asked for are synthesised (seeds stay each building's own).
wanted() {
  case " $BATCHES " in *" p66-$1 "*) return 0 ;; esac
  case " $BATCHES " in *" p66-scratch "*) case " $SCRATCH " in *" $1-$2 "*) return 0 ;; esac ;; esac
  return 1
}
seed=2100
for s in A B C D office; do
  for c in Golden Chicago; do
    name=$s-$c; seed=$((seed + 1)); dir="$OUT/buildings/$name"
    wanted "$s" "$c" || continue
    [ -f "$dir/meters.csv" ] && continue
    mkdir -p "$dir"
    if [ "$s" = office ]; then
      cp examples/office/model.toml "$dir/model.toml"
    else
      read -r storeys fx fy h zoning wwr <<<"${SPEC[$s]}"
      printf 'name = "sweep-%s"\nstoreys = %s\nfootprint_m = [%s, %s]\nfloor_to_floor_m = %s\nzoning = "%s"\nwindow_to_wall = %s\n' \
        "$s" "$storeys" "$fx" "$fy" "$h" "$zoning" "$wwr" >"$dir/model.toml"
    fi
    # Today's project file with the building's weather; the pretrained variant beside it.
    sed -e "s|^weather = .*|weather = \"${CLIMATE[$c]}\"|" -e "s|^name = .*|name = \"$name\"|" \
      examples/office/project.toml >"$dir/project-scratch.toml"
    sed -e "s|^points = 20 .*|points = $POINTS|" \
        -e "s|^hidden = 64 .*|hidden = 64\npretrained = \"$OUT/pretrained\"|" \
        -e "s|^rounds = 2 .*|rounds = 2\nspread = 2|" "$dir/project-scratch.toml" >"$dir/project.toml"
    echo "synthesising $name (truth seed $seed)"
    "$B" synthesize --model "$dir/model.toml" --weather "${CLIMATE[$c]}" --truth-seed "$seed" \
      --out "$dir/meters.csv.part" --truth "$dir/truth.json" >"$dir/synthesize.log" 2>&1
    mv "$dir/meters.csv.part" "$dir/meters.csv"
  done
done
# One portfolio a shape (its two climates) and one of the from-scratch pair, each submitted when
# the one before has finished: two buildings share the two workers, so finished buildings accumulate
# (a portfolio of all twelve at once would interleave them all to the end).
for s in A B C D office; do
  { echo "name = \"p66-$s\""
    for c in Golden Chicago; do printf '[[building]]\nname = "%s-%s"\nproject = "buildings/%s-%s/project.toml"\n' "$s" "$c" "$s" "$c"; done
  } >"$OUT/p66-$s.toml"
done
{ echo 'name = "p66-scratch"'
  for b in $SCRATCH; do printf '[[building]]\nname = "%s-scratch"\nproject = "buildings/%s/project-scratch.toml"\n' "$b" "$b"; done
} >"$OUT/p66-scratch.toml"
# Workers without EnergyPlus or PyTorch fail every building at once (a fresh machine's missing
# .venv did, 2026-12-07): check the environment first.
"$B" doctor >/dev/null 2>&1 || { echo "bemcal doctor failed: run make setup (or set BEMCAL_VENV)" >&2; exit 1; }

# The coordinator and two workers of one slot each (as `--local-workers 2`), restarted on the
# same state.
pids=()
cleanup() { for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done; wait 2>/dev/null || true; }
trap cleanup EXIT
"$B" coordinator --listen "127.0.0.1:$PORT" --data "$OUT/data" --log-level off --max-runs-per-client 0 \
  >>"$OUT/logs/coordinator.log" 2>&1 &
pids+=($!)
sleep 2
for i in 0 1; do
  "$B" worker --slots 1 --id "local-$i" --cache "$OUT/worker-$i" >>"$OUT/logs/worker-$i.log" 2>&1 &
  pids+=($!)
done
left() {
  "$B" portfolio status "$(cat "$OUT/$1.id")" --json | python3 -c \
    "import json,sys; p=json.load(sys.stdin); print(p['buildings'] - p['done'] - p['failed'])"
}
for m in $BATCHES; do
  if [ ! -s "$OUT/$m.id" ]; then
    if ! (cd "$OUT" && "$B" portfolio submit --allow-outside "$m.toml" >"$m.id.part" 2>>logs/submit.log); then
      echo "$m: not submitted (logs/submit.log)" >&2; exit 1
    fi
    mv "$OUT/$m.id.part" "$OUT/$m.id"
    echo "$(date -u +%FT%TZ) $m: submitted as portfolio $(cat "$OUT/$m.id")"
  fi
  [ "$WAIT" = 1 ] || { trap - EXIT; echo "running: coordinator and workers ${pids[*]}"; exit 0; }
  while [ "$(left "$m")" != 0 ]; do sleep 60; done
  [ -d "$OUT/results/$m" ] || "$B" portfolio results "$(cat "$OUT/$m.id")" --out "$OUT/results/$m" || true
  echo "$(date -u +%FT%TZ) $m: finished"
done
python3 scripts/portfolio_table.py "$OUT"
