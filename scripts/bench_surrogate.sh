#!/usr/bin/env bash
# Surrogate evaluation benchmark: Rust/ONNX Runtime vs PyTorch eager, same thread count.
#
#   scripts/bench_surrogate.sh [THREADS=2] [SECONDS=12] [TRAIN_EPOCHS=0]
#
# Paper-size surrogate (38 parameters + 5 weather = 43 inputs, lookback 3, LSTM 2 x 128, 3
# outputs; random seeded weights, exported by bemcal_train's exporter). One evaluation = the
# 8,760 windows of a year for one parameter vector. GFLOP/s use the plain LSTM's count
# (python/tools/bench_torch.py: 1,312,512 FLOP per window = 11.50 GFLOP per evaluation) for every
# row, so they compare throughput; the 'exec' column uses the FLOPs the fused graph actually
# executes (python/bemcal_train/fused.py: 7.80 GFLOP per evaluation).
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
"$PY" - "$OUT" "$ROOT" <<'PYEOF'
import json, os, sys
out, root = sys.argv[1], sys.argv[2]
sys.path.insert(0, os.path.join(root, "python"))
from bemcal_train.fused import fused_flops_per_hour
t = json.load(open(f"{out}/torch.json"))
r = dict(l.strip().split("=", 1) for l in open(f"{out}/rust.txt") if "=" in l)
gf = t["flop_per_eval"] / 1e9
gf_fused = fused_flops_per_hour(5) * 8760 / 1e9
base = t["torch_eager_evals_per_s"]
fused = "fused" in r.get("hot_path_file", "")
print(f"\nthreads {t['threads']}, torch {t['torch_version']}, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
print(f"FLOP per evaluation (8,760 windows, multiply-add = 2): plain LSTM {gf:.2f} GFLOP (all rows' GFLOP/s);")
print(f"  the fused graph executes {gf_fused:.2f} GFLOP (shared window steps once, zero-state steps without")
print(f"  recurrent product / forget gate, parameter projection once per proposal): 'exec' column")
print(f"{'engine':46s} {'evals/s':>8s} {'GFLOP/s':>8s} {'exec':>7s} {'vs torch':>9s}")
hot = "fused graph" if fused else "fast graph"
rows = [("PyTorch eager (no_grad, plain nn.LSTM)", base, gf)]
for key, name, g in [("ort_plain_evals_per_s", "Rust/ort plain graph (x -> y)", gf),
                     ("ort_fast_evals_per_s", f"Rust/ort {hot} f32, 1 proposal/call", gf_fused if fused else None),
                     ("ort_fast_batch4_evals_per_s", f"Rust/ort {hot} f32, evaluate_batch(4)", gf_fused if fused else None),
                     ("ort_fast_int8_evals_per_s", f"Rust/ort {hot} int8, 1 proposal/call", gf_fused if fused else None)]:
    if key in r:
        rows.append((name, float(r[key]), g))
for name, v, g in rows:
    ex = f"{v * g:7.1f}" if g else f"{'-':>7s}"
    print(f"{name:46s} {v:8.2f} {v * gf:8.1f} {ex} {v / base:8.2f}x")
print(f"float hot path vs plain graph: max |diff| / max |y| = {r.get('fast_vs_plain_rel', '?')}")
if "int8_rmse_vs_float_kwh" in r:
    rm, mean = float(r["int8_rmse_vs_float_kwh"]), float(r["float_mean_output_kwh"])
    print(f"int8 vs float: RMSE {rm:.3e} kWh = {100 * rm / max(mean, 1e-12):.2f} % of the mean output ({mean:.3f} kWh);"
          f" vs sigma_eta: {float(r['int8_rmse_vs_min_sigma_eta']):.3f} (this random-weight model's sigma_eta is a"
          f" 1 kWh placeholder; a trained surrogate records int8.ratio_to_sigma_eta in surrogate.json)")
if "train_seconds_per_epoch" in t:
    print(f"training: {t['train_seconds_per_epoch']:.1f} s/epoch -> 200 epochs {t['train_projection_200_epochs_min']:.1f} min")
PYEOF
