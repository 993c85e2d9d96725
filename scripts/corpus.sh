#!/usr/bin/env bash
# The pretrained surrogate's corpora (issue 66), resumable: the family corpus to its first
# FIRST cases, the learning curve's held-out buildings, then the family corpus to the end. Each
# `bemcal corpus` call skips what its folder holds, so rerunning this after a stop (a session's
# end, a reboot) continues where it stopped. Hours on 2 cores: run it outside the work tree.
#
#   BIN=path/to/bemcal (default target/release/bemcal), CORPUS=dir (default ~/.cache/bemcal/corpus),
#   FIRST=200, PARALLEL=2
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/bemcal}
CORPUS=${CORPUS:-$HOME/.cache/bemcal/corpus}
FIRST=${FIRST:-200}
PARALLEL=${PARALLEL:-2}
export BEMCAL_VENV=${BEMCAL_VENV:-$PWD/.venv}
"$BIN" corpus corpus/family.toml --out "$CORPUS/family" --cases "$FIRST" --parallel "$PARALLEL"
"$BIN" corpus corpus/heldout.toml --out "$CORPUS/heldout" --parallel "$PARALLEL"
"$BIN" corpus corpus/family.toml --out "$CORPUS/family" --parallel "$PARALLEL"
