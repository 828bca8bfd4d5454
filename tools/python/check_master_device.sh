#!/usr/bin/env bash
# CI step: a Python master device, written only from messages/README.md and
# using the official iceoryx2 0.10.0 bindings, drives the arm of a real pipeline.
#
# Starts `microrobot run` in teleop mode (seed arm, ratio 3:1), publishes a 0.5 Hz hand
# motion of 3 mm on x from tools/python/master_device.py for 6 s (clutch released for
# the last second) while `microrobot teleop-report` listens, then stops the pipeline
# with SIGINT and asserts:
#   * the planner took the Python samples: its log counts >= 95 % of those published,
#     none refused; teleop-report saw them on the bus;
#   * the arm moved in teleop mode as the hand commanded: the scaled hand amplitude is
#     3 mm / 3 = 1 mm (the documented units and the ratio), the tool's amplitude at
#     0.5 Hz is 0.5..1.5 times it with a phase lag below 90 deg; setpoints carry TELEOP,
#     and TELEOP_CLUTCH_OPEN during the released window; no sample refused;
#   * every process (pipeline, publisher, report) exited 0 and the summary says ok.
# Usage: bash tools/python/check_master_device.sh   (from anywhere; binary from
# $MICROROBOT_BIN, default target/release/microrobot, then target/debug/microrobot)
set -euo pipefail
cd "$(dirname "$0")/../.."
repo="$(pwd)"

bin="${MICROROBOT_BIN:-}"
if [ -z "$bin" ]; then
    # A real-time pipeline is meant to run optimised: the release binary first.
    for b in target/release/microrobot target/debug/microrobot; do
        [ -x "$b" ] && { bin="$b"; break; }
    done
fi
[ -n "$bin" ] && [ -x "$bin" ] || {
    echo "check_master_device: no microrobot binary (set MICROROBOT_BIN or build it)" >&2; exit 1; }

work="$(mktemp -d)"
pipeline="" report="" device=""
cleanup() {
    for pid in $device $report $pipeline; do
        kill -TERM "$pid" 2>/dev/null || true
    done
    for pid in $device $report $pipeline; do
        wait "$pid" 2>/dev/null || true
    done
    rm -rf "$work"
}
trap cleanup EXIT
fail() {
    echo "check_master_device: FAIL: $*" >&2
    for f in run.out run.err report.json report.err device.out device.err; do
        [ -s "$work/$f" ] && { echo "--- $f" >&2; tail -n 20 "$work/$f" >&2; }
    done
    exit 1
}

echo "== venv with tools/python/requirements.txt"
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install --quiet --disable-pip-version-check -r tools/python/requirements.txt \
    || fail "pip install -r tools/python/requirements.txt"

inst="py-master-$$"
ratio=3.0 amp_mm=3 freq_hz=0.5 device_s=6 clutch_open="5-6"
cat >"$work/pipeline.toml" <<EOF
instance = "$inst"
robot = "$repo/config/robots/seed-arm.toml"

[realtime]
cpu_affinity = []
pm_qos = false
mlockall = false

[actuator.sim]
initial_q_deg = [0, 30, 60, 0, 30, 0]

[teleop]
enabled = true
ratio = $ratio
EOF

echo "== pipeline $inst in teleop mode ($bin)"
"$bin" run --config "$work/pipeline.toml" --no-program --duration 30 --instance "$inst" \
    --summary-json "$work/summary.json" >"$work/run.out" 2>"$work/run.err" &
pipeline=$!
for _ in $(seq 1 300); do
    [ "$(grep -c ' ready (pid' "$work/run.err" 2>/dev/null)" = 3 ] && break
    kill -0 "$pipeline" 2>/dev/null || fail "the pipeline exited before it was ready"
    sleep 0.1
done
[ "$(grep -c ' ready (pid' "$work/run.err")" = 3 ] || fail "the pipeline was not ready after 30 s"

echo "== python master device: ${amp_mm} mm at ${freq_hz} Hz for ${device_s} s, clutch open ${clutch_open} s"
"$bin" teleop-report --instance "$inst" --config "$work/pipeline.toml" --duration 6.5 \
    --settle 1 --voluntary-hz "$freq_hz" --json >"$work/report.json" 2>"$work/report.err" &
report=$!
sleep 0.3
set +e
"$work/venv/bin/python" tools/python/master_device.py --instance "$inst" --duration "$device_s" \
    --rate-hz 1000 --amplitude-mm "$amp_mm,0,0" --frequency-hz "$freq_hz" \
    --clutch-open "$clutch_open" >"$work/device.out" 2>"$work/device.err"
device_rc=$?
device=""
wait "$report"
report_rc=$?
report=""
kill -INT "$pipeline"
wait "$pipeline"
pipeline_rc=$?
pipeline=""
set -e
[ "$device_rc" = 0 ] || fail "master_device.py exited $device_rc"
[ "$report_rc" = 0 ] || fail "teleop-report exited $report_rc"
[ "$pipeline_rc" = 0 ] || fail "microrobot run exited $pipeline_rc"

python3 - "$work" "$ratio" "$amp_mm" "$device_s" <<'PY' || fail "assertions (above)"
import json, re, sys, pathlib
work, ratio, amp_mm, device_s = pathlib.Path(sys.argv[1]), *map(float, sys.argv[2:])
def check(ok, what):
    if not ok:
        sys.exit(f"check_master_device: {what}")
dev = json.loads((work / "device.out").read_text().strip().splitlines()[-1])
rep = json.loads((work / "report.json").read_text())
summ = json.loads((work / "summary.json").read_text())
log = (pathlib.Path(summ["run_dir"]) / "planner.log").read_text(errors="replace")
m = re.findall(r"teleop: (\d+) master samples, (\d+) refused", log)
check(m, f"no teleop line in {summ['run_dir']}/planner.log")
taken, refused = map(int, m[-1])
published = dev["published"]
vol, flags = rep["voluntary"], rep["flag_counts"]
want_mm = amp_mm / ratio
print("python master device:", json.dumps({
    "published": published, "late": dev["late"], "planner_took": taken, "planner_refused": refused,
    "report_master_samples": rep["master_samples"], "hand_scaled_amplitude_mm": round(vol["hand_scaled_amplitude_mm"], 4),
    "tool_amplitude_mm": round(vol["tool_amplitude_mm"], 4), "gain_db": round(vol["gain_db"], 2),
    "phase_lag_deg": round(vol["phase_lag_deg"], 1), "teleop_setpoints": flags["teleop"],
    "clutch_open_setpoints": flags["clutch_open"], "input_refused": flags["input_refused"]}))
check(summ["exit_ok"] is True, f"pipeline summary not ok: {summ.get('stop_reason')}")
check(published >= 0.95 * 1000 * device_s, f"published {published} samples, want >= 95 % of {1000 * device_s:.0f}")
check(taken >= 0.95 * published, f"the planner took {taken} master samples of {published} published")
check(refused == 0 and flags["input_refused"] == 0, f"samples refused: planner {refused}, setpoints flagged {flags['input_refused']}")
check(rep["master_samples"] >= 0.8 * published, f"teleop-report saw {rep['master_samples']} of {published} samples")
check(abs(vol["hand_scaled_amplitude_mm"] - want_mm) <= 0.05 * want_mm,
      f"scaled hand amplitude {vol['hand_scaled_amplitude_mm']:.4f} mm, want {want_mm:.4f} mm (units or ratio)")
check(0.5 * want_mm <= vol["tool_amplitude_mm"] <= 1.5 * want_mm,
      f"tool amplitude {vol['tool_amplitude_mm']:.4f} mm, want 0.5..1.5 x {want_mm:.4f} mm")
check(0.0 <= vol["phase_lag_deg"] < 90.0, f"phase lag {vol['phase_lag_deg']:.1f} deg, want 0..90")
check(flags["teleop"] > 0, "no setpoint in teleop mode")
check(flags["clutch_open"] > 0, "no setpoint flagged TELEOP_CLUTCH_OPEN in the clutch-open window")
PY
echo "check_master_device: ok"
