#!/usr/bin/env bash
# `make bench`: every benchmark, one after the other, with the machine's description.
set -euo pipefail
cd "$(dirname "$0")/.."
echo "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs), $(free -g | awk '/Mem:/ {print $2}') GiB"
for b in scripts/bench_energyplus.sh scripts/bench_surrogate.sh scripts/bench_dtw.sh; do
  bash "$b"
  echo
done
bash scripts/bench_baselines.sh
bash scripts/bench_chains.sh
BENCH_HMC=1 bash scripts/bench_chains.sh
bash scripts/bench_workers.sh
echo
# The whole calibration by stage (issue 8): the demo is the paper-size problem (20-zone model,
# 38 parameters, 20 design points, 4 x 10,000 iterations, 2 local workers). It takes ~20 min, so
# it is run here only with BENCH_DEMO=1; otherwise the last `make demo`'s timings are printed.
[ "${BENCH_DEMO:-0}" = 1 ] && { rm -rf out/demo; make demo >/dev/null; }
python3 scripts/demo_timings.py out/demo/calibration/summary.json
