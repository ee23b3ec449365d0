#!/usr/bin/env bash
# The whole test suite under mpirun -n 2, after setting up what is missing.
# Every rank runs every test; failures are combined across ranks (tests/conftest.py).
# Rank 0 prints the report; the other ranks' output goes to a log shown on failure.
# Usage: bash scripts/test.sh [pytest arguments]
set -euo pipefail
# chromium: the tests render the report in a browser (the main job needs none)
PETGAP_EXTRA_PACKAGES="chromium ${PETGAP_EXTRA_PACKAGES:-}" \
  source "$(dirname "${BASH_SOURCE[0]}")/bootstrap.sh"
cd "$PETGAP_ROOT"
log=$(mktemp -d)/rank-logs
mkdir -p "$log"
# Run the whole suite unless test paths are given.
case " $* " in *" tests"*) ;; *) set -- tests "$@" ;; esac
status=0
timeout --signal=TERM --kill-after=30 ${PETGAP_TEST_TIMEOUT:-2400} \
  mpirun -n 2 bash -c 'if [ "$OMPI_COMM_WORLD_RANK" = 0 ]; then exec python -m pytest "$@";
                       else exec python -m pytest "$@" > "'"$log"'/rank-$OMPI_COMM_WORLD_RANK.txt" 2>&1; fi' \
  pytest -p no:cacheprovider --color=no "$@" || status=$?
if [ "$status" -ne 0 ]; then
  for f in "$log"/rank-*.txt; do
    [ -f "$f" ] && { echo "===== output of ${f##*/} (last 60 lines) ====="; tail -n 60 "$f"; }
  done
fi
exit "$status"
