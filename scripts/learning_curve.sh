#!/usr/bin/env bash
# The pretrained surrogate's learning curve (issue 66): for each corpus size, the building-
# conditioned LSTM pretrained on the family corpus's first N cases, then on each held-out
# building (new buildings, two left-out climates, new parameter points): zero-shot, fine-tuned on
# 5 / 10 / 20 of its own EnergyPlus years, and today's from-scratch surrogate on the same 20;
# hourly CV-RMSE per meter on the building's last 5 points. Resumes from OUT/curve.json (sizes
# measured before are kept). Corpora from scripts/corpus.sh.
#
#   SIZES=100,200,400,800  CORPUS=~/.cache/bemcal/corpus  OUT=~/.cache/bemcal/curve  THREADS=2
set -euo pipefail
cd "$(dirname "$0")/.."
CORPUS=${CORPUS:-$HOME/.cache/bemcal/corpus}
OUT=${OUT:-$HOME/.cache/bemcal/curve}
SIZES=${SIZES:-100,200,400,800}
THREADS=${THREADS:-2}
PYTHONPATH=python .venv/bin/python -m bemcal_train.pretrain curve \
  --corpus "$CORPUS/family" --heldout "$CORPUS/heldout" --sizes "$SIZES" \
  --threads "$THREADS" --out "$OUT"
mkdir -p corpus/curve
cp "$OUT/curve.json" corpus/curve/curve.json
