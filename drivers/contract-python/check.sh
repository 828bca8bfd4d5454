#!/usr/bin/env bash
# Check the contract-python driver (drivers/contract-python/driver.py, written from
# messages/README.md alone) with the stack's own `microrobot driver-check`, free-running
# and in lockstep. Run from the repository root:
#   bash drivers/contract-python/check.sh [path/to/microrobot]   (default target/release/microrobot)
set -euo pipefail

BIN=${1:-target/release/microrobot}
HERE=drivers/contract-python
[ -x "$BIN" ] || { echo "check.sh: no microrobot binary at $BIN" >&2; exit 1; }
[ -f "$HERE/driver.py" ] || { echo "check.sh: run me from the repository root" >&2; exit 1; }

TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
python3 -m venv "$TMP/venv"
"$TMP/venv/bin/pip" install -q -r "$HERE/requirements.txt"
PY="$TMP/venv/bin/python"

status=0
for mode in free-running lockstep; do
    args=()
    [ "$mode" = lockstep ] && args=(--lockstep)
    echo "== driver-check ($mode)"
    if "$BIN" driver-check "${args[@]}" --summary-json "$TMP/$mode.json" -- "$PY" "$HERE/driver.py"; then
        echo "== $mode: every clause passed"
    else
        rc=$?
        echo "== $mode: FAILED (exit code $rc)" >&2
        status=1
    fi
done
exit $status
