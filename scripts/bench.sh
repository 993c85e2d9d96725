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
bash scripts/bench_workers.sh
