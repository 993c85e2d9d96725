#!/usr/bin/env bash
# The pretrained surrogate's corpora (issue 66), resumable, in the order a learning curve can use
# them: the family corpus's first 100 cases, the first five held-out buildings (125 cases), the
# family to 200, the rest of the held-out buildings, then the family to the end. Each `bemcal
# corpus` call skips what its folder holds, so rerunning this after a stop (a session's end, a
# reboot) continues where it stopped. Hours on 2 cores: run it outside the work tree.
#
#   BIN=path/to/bemcal (default target/release/bemcal), CORPUS=dir (default ~/.cache/bemcal/corpus),
#   PARALLEL=2
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${BIN:-target/release/bemcal}
CORPUS=${CORPUS:-$HOME/.cache/bemcal/corpus}
PARALLEL=${PARALLEL:-2}
export BEMCAL_VENV=${BEMCAL_VENV:-$PWD/.venv}
family() { "$BIN" corpus corpus/family.toml --out "$CORPUS/family" --parallel "$PARALLEL" "$@"; }
heldout() { "$BIN" corpus corpus/heldout.toml --out "$CORPUS/heldout" --parallel "$PARALLEL" "$@"; }
family --cases 100
heldout --cases 125
family --cases 200
heldout
family --cases 400
family
