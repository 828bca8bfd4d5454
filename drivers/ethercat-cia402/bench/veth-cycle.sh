#!/bin/bash
# The EtherCAT driver's cycle over a veth pair, beside the simulated arm in the same
# minutes: RUNS times, the pipeline holding the seed arm through the CiA 402 driver and
# the emulated 6-drive chain (free-running at RATE_HZ, in a private network namespace),
# then the same pipeline on the simulated arm. Needs root (veth, namespace, raw socket).
#
#   drivers/ethercat-cia402/bench/veth-cycle.sh [OUT_DIR] [RUNS] [SECONDS] [RATE_HZ]
#
# Writes OUT_DIR/ecat_N.json and OUT_DIR/sim_N.json (run summaries: the hop
# "actuator step → state sent" is the exchange: frame sent, frame back, state
# published) and prints one line per run. Both pipelines use the default config with
# cpu_affinity = [] (the driver's transport thread and the emulator then find a CPU);
# the drive file is the example's with the rig's tolerance for a shared machine
# (max_lost_cycles 100, drive_watchdog_ms 1000).
set -euo pipefail
cd "$(dirname "$0")/../../.."
OUT=${1:-target/ethercat-bench}; RUNS=${2:-3}; SECS=${3:-60}; RATE=${4:-1000}
NS=microrobot-ecat-bench
mkdir -p "$OUT"
OUT=$(realpath "$OUT")
# Two builds, as the quick start and the driver's README do (each its own feature set),
# into $CARGO_TARGET_DIR when it is set.
cargo build --release -q -p microrobot
cargo build --release -q -p microrobot-ethercat-cia402 -p microrobot-ethercat-emulator --bins
BIN=$(realpath "${CARGO_TARGET_DIR:-target}/release")
ROOT=$(pwd)
CYCLE_US=$(( 1000000 / RATE ))
sed -e 's/^interface = .*/interface = "ecm0"/' -e "s/^cycle_us = .*/cycle_us = $CYCLE_US/" \
    -e 's/^max_lost_cycles = [0-9]*/max_lost_cycles = 100/' \
    -e 's/^drive_watchdog_ms = [0-9]*/drive_watchdog_ms = 1000/' \
    drivers/ethercat-cia402/example.drive.toml > "$OUT/seed.drive.toml"
base() {
  sed -e "s#^robot = \"#robot = \"$ROOT/config/#" -e "s#^program = \"#program = \"$ROOT/config/#" \
      -e 's/^cpu_affinity = .*/cpu_affinity = []/' -e "s/^instance = .*/instance = \"$1\"/" \
      config/pipeline.toml
}
base ecatbench | sed "s#^backend = \"sim\"#command = [\"$BIN/microrobot-ethercat-cia402\", \"--instance\", \"{instance}\", \"--rate-hz\", \"{rate_hz}\", \"--drive-file\", \"$OUT/seed.drive.toml\", \"--interface\", \"ecm0\"]#" > "$OUT/ecat.toml"
base simbench > "$OUT/sim.toml"
cleanup() { ip netns del "$NS" 2>/dev/null || true; }
trap cleanup EXIT
summary() {
  python3 -c 'import json,sys
p = json.load(open(sys.argv[1])); e = p["e2e_latency_us"]; x = p["hops"]["actuator_step_to_state_us"]
print("%-5s ok=%s e2e p50 %.1f p99 %.1f us | step->state p50 %.1f p99 %.1f max %.1f us | lost %d | %s" % (sys.argv[2], p["exit_ok"], e["p50"], e["p99"], x["p50"], x["p99"], x["max"], p["lost_messages"], "; ".join(p["failures"])))' "$1" "$2"
}
for i in $(seq 1 "$RUNS"); do
  cleanup
  ip netns add "$NS"
  ip -n "$NS" link add ecm0 type veth peer name ecm1
  for l in ecm0 ecm1 lo; do ip -n "$NS" link set "$l" up; done
  ip netns exec "$NS" "$BIN/microrobot-ethercat-emulator" --interface ecm1 --seed-arm > "$OUT/emulator_$i.log" 2>&1 &
  EMU=$!
  sleep 2
  ip netns exec "$NS" "$BIN/microrobot" run --config "$OUT/ecat.toml" --no-program --rate-hz "$RATE" \
      --duration "$SECS" --summary-json "$OUT/ecat_$i.json" > "$OUT/ecat_$i.txt" 2>&1 || true
  kill "$EMU"; wait "$EMU" 2>/dev/null || true
  cleanup
  "$BIN/microrobot" run --config "$OUT/sim.toml" --no-program --rate-hz "$RATE" --duration "$SECS" \
      --summary-json "$OUT/sim_$i.json" > "$OUT/sim_$i.txt" 2>&1 || true
  summary "$OUT/ecat_$i.json" "ecat$i"
  summary "$OUT/sim_$i.json" "sim$i"
done
