#!/usr/bin/env bash
# Regenerates tests/reference/urdf_reference.json with Pinocchio 4.1.0 from PyPI (pinned,
# hash-checked: urdf_requirements.txt) in a venv under target/baselines/. Not part of CI: it
# needs the network, and the committed JSON is what the tests read.
#
#   tools/baselines/run_urdf_reference.sh
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
venv="$root/target/baselines/venv-pin"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install -q --only-binary :all: --require-hashes \
        -r "$root/tools/baselines/urdf_requirements.txt"
fi
"$venv/bin/python" "$root/tools/baselines/urdf_reference.py"
