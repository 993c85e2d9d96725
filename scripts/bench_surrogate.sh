#!/usr/bin/env bash
# Surrogate evaluation benchmark: Rust/ONNX Runtime vs PyTorch eager, same thread count.
#
#   scripts/bench_surrogate.sh [THREADS=2] [SECONDS=12] [TRAIN_EPOCHS=0]
#
# Paper-size surrogate (38 parameters + 5 weather = 43 inputs, lookback 3, LSTM 2 x 128, 3
# outputs; random seeded weights, exported by bemcal_train's exporter). One evaluation = the
# 8,760 windows of a year for one parameter vector. GFLOP/s use the plain LSTM's count
# (python/tools/bench_torch.py: 1,312,512 FLOP per window = 11.50 GFLOP per evaluation) for every
# row, so they compare throughput; the fast graph does ~9 % fewer FLOPs (the parameter part of
# the first layer's input projection is computed once per proposal).
# Rates are the best of 4 rounds (the machine may be shared).
# TRAIN_EPOCHS > 0 also times that many training epochs on a paper-size training set
# (20 design points x 8,760 h).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
THREADS="${1:-2}"; SECONDS_PER="${2:-12}"; EPOCHS="${3:-0}"
PY="${BEMCAL_PYTHON:-$ROOT/.venv/bin/python}"
[ -x "$PY" ] || { echo "no Python environment at $PY: run 'make setup' (or set BEMCAL_PYTHON)" >&2; exit 1; }
OUT="$(mktemp -d)"; trap 'rm -rf "$OUT"' EXIT
export OMP_NUM_THREADS="$THREADS"
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
(cd "$ROOT" && cargo build --release -q -p bemcal-surrogate --example bench_surrogate)
"$PY" "$ROOT/python/tools/bench_torch.py" --out "$OUT" --threads "$THREADS" --seconds "$SECONDS_PER" --train-epochs "$EPOCHS"
"$CARGO_TARGET_DIR/release/examples/bench_surrogate" "$OUT/model" "$THREADS" "$SECONDS_PER" 4 | tee "$OUT/rust.txt"
"$PY" - "$OUT" <<'PYEOF'
import json, sys
out = sys.argv[1]
t = json.load(open(f"{out}/torch.json"))
r = dict(l.strip().split("=", 1) for l in open(f"{out}/rust.txt") if "=" in l)
gf = t["flop_per_eval"] / 1e9
base = t["torch_eager_evals_per_s"]
print(f"\nthreads {t['threads']}, {gf:.2f} GFLOP per evaluation (plain LSTM count), torch {t['torch_version']}")
print(f"{'engine':44s} {'evals/s':>9s} {'GFLOP/s':>9s} {'vs torch':>9s}")
rows = [("PyTorch eager (no_grad)", base)]
for key, name in [("ort_plain_evals_per_s", "Rust/ort plain graph (x -> y)"),
                  ("ort_fast_evals_per_s", "Rust/ort fast graph, 1 proposal/call"),
                  ("ort_fast_batch4_evals_per_s", "Rust/ort fast graph, evaluate_batch(4)"),
                  ("ort_fast_int8_evals_per_s", "Rust/ort fast graph, int8 weights")]:
    if key in r:
        rows.append((name, float(r[key])))
for name, v in rows:
    print(f"{name:44s} {v:9.2f} {v * gf:9.1f} {v / base:8.2f}x")
for k in ("fast_vs_plain_rel", "int8_rmse_vs_float_kwh", "float_mean_output_kwh"):
    if k in r:
        print(f"{k} = {r[k]}")
if "train_seconds_per_epoch" in t:
    print(f"training: {t['train_seconds_per_epoch']:.1f} s/epoch -> 200 epochs {t['train_projection_200_epochs_min']:.1f} min")
PYEOF
