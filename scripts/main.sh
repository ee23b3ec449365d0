#!/usr/bin/env bash
# The main job: set up what is missing, run the default scene end to end, and
# reduce it to tables and figures (gap distribution collapse, Fig. 4 integrand).
# Usage: bash scripts/main.sh [ranks]      (default 2)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/bootstrap.sh"
cd "$PETGAP_ROOT"
ranks=${1:-2}
mkdir -p out
mpirun -n "$ranks" petgap run runs/default.toml --output out/default.h5 --overwrite
mpirun -n "$ranks" petgap-post out/default.h5 --output-dir out/default-post --overwrite
echo "figures and tables: $PETGAP_ROOT/out/default-post"
ls out/default-post
