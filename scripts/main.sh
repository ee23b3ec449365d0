#!/usr/bin/env bash
# The main job: set up what is missing, run the default scene end to end, and
# reduce it to its report: maps, curves, spectrum, patches, the paper's figures, tables.
# Usage: bash scripts/main.sh [ranks]      (default 2)
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/bootstrap.sh"
cd "$PETGAP_ROOT"
ranks=${1:-2}
mkdir -p out
mpirun -n "$ranks" petgap run runs/default.toml --output out/default.h5 --overwrite
mpirun -n "$ranks" petgap-post out/default.h5 --output-dir out/default-post --overwrite
ls out/default-post
echo "report (open in a browser): $PETGAP_ROOT/out/default-post/report.html"
