#!/usr/bin/env bash
# A documentation tool, not a test (and not part of CI): records a short run of the seed
# arm's Table 4 program with the release CLI, opens the recording in Foxglove Studio's
# open-source web build (the pinned npm package @foxglove/studio-base, served here on
# 127.0.0.1) in headless Chromium with layout.json beside this script (3D panel and a plot
# of the joint positions), seeks to a moment where the arm is posed and writes a PNG.
#
#   tools/view/screenshot/screenshot.sh [OUT.png]     (default: docs/img/foxglove-recording.png)
#
# Environment: AT (seconds after the first message to show, default 7.4: the arm bent, on its way to θf), WIDTH, HEIGHT
# (default 1280x800), CHROMIUM (default: chromium on PATH, installed with apt-get if
# missing). Needs node and npm; every step stops the script with the reason.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../../.." && pwd)"
out="${1:-$repo/docs/img/foxglove-recording.png}"
at="${AT:-7.4}"

die() {
  echo "screenshot.sh: $*" >&2
  exit 1
}

command -v node >/dev/null || die "node is not installed (Node.js 18 or newer is needed)"
command -v npm >/dev/null || die "npm is not installed"
command -v cargo >/dev/null || die "cargo is not installed"

chromium="${CHROMIUM:-$(command -v chromium || true)}"
if [[ -z "$chromium" ]]; then
  [[ "$(id -u)" == 0 ]] || die "chromium is missing and installing it needs root: apt-get install -y chromium"
  echo "screenshot.sh: installing Debian's chromium" >&2
  apt-get update >&2 || die "apt-get update failed"
  DEBIAN_FRONTEND=noninteractive apt-get install -y chromium >&2 || die "apt-get install chromium failed"
  chromium="$(command -v chromium)" || die "chromium is still not on PATH after apt-get install"
fi
"$chromium" --version >&2 || die "$chromium does not run"

(cd "$here" && npm ci --no-audit --no-fund >&2) || die "npm ci in $here failed"

work="$(mktemp -d)"  # kept when a step fails, for its files
mcap="$work/table4.mcap"

echo "screenshot.sh: building the release CLI and the three services" >&2
(cd "$repo" && cargo build --release --bin microrobot --bin microrobot-planner \
  --bin microrobot-dynamics --bin microrobot-actuator) || die "cargo build --release failed"

echo "screenshot.sh: recording the seed arm's Table 4 program" >&2
(cd "$repo" && cargo run --release --bin microrobot -- run \
  --program config/programs/seed-table4.toml \
  --instance "screenshot-$$" \
  --duration 12 \
  --record "$mcap" >"$work/run.json") || die "microrobot run --record failed (its summary: $work/run.json)"
[[ -s "$mcap" ]] || die "the run wrote no recording at $mcap"

mkdir -p "$(dirname "$out")"
node "$here/shoot.mjs" --mcap "$mcap" --at "$at" --out "$out" --chromium "$chromium" \
  --width "${WIDTH:-1280}" --height "${HEIGHT:-800}" || die "the screenshot failed (see above)"
rm -rf "$work"
echo "screenshot.sh: wrote $out" >&2
