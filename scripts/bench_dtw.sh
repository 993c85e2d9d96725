#!/usr/bin/env bash
# DTW pairwise matrices (Sakoe-Chiba band |i-j| <= 2): bemcal (Rust, rayon) vs dtaidistance's C
# implementation on the same data (BDG2: 238 buildings' 2016 daily electricity profiles).
set -euo pipefail
cd "$(dirname "$0")/.."
CSV=${1:-../shared/data/bdg2/electricity_subset_238bldgs_from_lstm-bgd2.csv}
if [ ! -f "$CSV" ]; then echo "== DTW: skipped ($CSV not found)"; exit 0; fi
echo "== DTW pairwise matrices, band 2 ($(nproc) cores, load $(cut -d' ' -f1 /proc/loadavg))"
cargo run --release -q -p bemcal-precal --example dtw_bench -- "$CSV" 2
.venv/bin/python python/tools/dtw_bench.py "$CSV" 2
