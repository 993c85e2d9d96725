#!/usr/bin/env bash
# Issue 70 on issue 66's portfolio: do the savings intervals of buildings calibrated from the
# pretrained network hold? For each finished building of scripts/portfolio_pretrained.sh (OUT),
# three measures (LED lighting x 0.6, cooling set-point +1 K, heating set-point -1 K), `bemcal
# savings` over DRAWS posterior draws, against the true savings (EnergyPlus at the building's
# hidden truth without and with each measure); tabulated by scripts/savings_coverage.py.
#
#   BUILDINGS="A-Golden B-Golden"   (each must have finished: OUT/results/*/NAME)
#   OUT=~/.cache/bemcal/portfolio66   WORK=out/portfolio-savings   DRAWS=20
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-$PWD/target/release/bemcal}
OUT=${OUT:-$HOME/.cache/bemcal/portfolio66}
WORK=${WORK:-out/portfolio-savings}
DRAWS=${DRAWS:-20}
BUILDINGS=${BUILDINGS:-A-Golden B-Golden}
PY=${PY:-$PWD/.venv/bin/python}
export BEMCAL_VENV=${BEMCAL_VENV:-$PWD/.venv}
mkdir -p "$WORK"
k=0
for b in $BUILDINGS; do
  k=$((k + 1)); d="$WORK/truth-$k"
  src=$(ls -d "$OUT"/results/*/"$b" | head -1)
  mkdir -p "$d"
  [ -d "$d/calibration" ] || cp -r "$src" "$d/calibration"
  cp "$OUT/buildings/$b"/{model.toml,meters.csv,truth.json} "$d/"
  # The project as calibrated, its measures the three above, the network the binary's.
  sed 's|^pretrained = .*|pretrained = "bundled:conditioned-200"|' "$OUT/buildings/$b/project.toml" > "$d/project.toml"
  cat scripts/savings_measures.toml >> "$d/project.toml"
  echo "$b" > "$d/building"
  "$BIN" savings "$d/project.toml" --out "$d/calibration" --draws "$DRAWS" --json > "$d/savings.json" 2> "$d/savings.log" \
    || { tail -5 "$d/savings.log"; echo "$b: savings failed"; continue; }
  weather=$(sed -n 's/^weather = "\(.*\)"/\1/p' "$d/project.toml")
  $PY scripts/true_savings.py "$d" "$BIN" "$d/model.toml" "$weather"
  echo "$b: done"
done
"$PY" scripts/savings_coverage.py "$WORK" "$k"
