#!/usr/bin/env bash
# The main job: set up what is missing, then run the default scene end to end.
# Usage: bash scripts/main.sh [ranks]      (default 2)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/bootstrap.sh"
cd "$PETGAP_ROOT"
ranks=${1:-2}
mkdir -p out
exec mpirun -n "$ranks" petgap run runs/default.toml --output out/default.h5 --overwrite
