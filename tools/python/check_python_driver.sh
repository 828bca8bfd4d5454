#!/usr/bin/env bash
# CI step: a Python actuator driver (tools/python/example_driver.py on the module
# tools/python/microrobot_driver.py, iceoryx2 0.10.0 bindings) replaces the simulated arm
# in a real pipeline and runs the seed arm's Table 4 program to its end.
#
# Runs `microrobot run` with actuator.command = [<venv python>, <driver>] on
# config/programs/seed-table4.toml:
#   * free-running, and in lockstep;
#   * in lockstep with a driver that starts slowly (--start-delay 1: its first state
#     comes 1 s after it was started; the planner subscribes after it);
# and passes only if each run exits 0 with "exit_ok": true in --summary-json, the program
# finished (program.state == "finished"), 0 lost and 0 refused messages, and the driver
# sent its final status (actuator last_lifecycle "finalized") and exited 0, and the arm
# followed the plan (tracking error below a generous 0.25 rad).
# A negative control must fail: a driver that never publishes an initial state (nor calls
# update_connections) leaves the lockstep planner without a first measured state.
# Then tools/python/check_layout.py compares the ctypes structs with the Rust payloads.
# Usage: bash tools/python/check_python_driver.sh   (from anywhere; binary from
# $MICROROBOT_BIN, default target/release/microrobot, then target/debug/microrobot;
# $DRIVER replaces tools/python/example_driver.py, e.g. to see a broken driver fail)
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
    echo "check_python_driver: no microrobot binary (set MICROROBOT_BIN or build it)" >&2; exit 1; }
driver="$(realpath "${DRIVER:-tools/python/example_driver.py}")"

work="$(mktemp -d)"
trap '[ -n "${KEEP_WORK:-}" ] || rm -rf "$work"' EXIT
fail() {
    echo "check_python_driver: FAIL: $*" >&2
    exit 1
}

venv="$repo/target/python-venv"
echo "== venv $venv with tools/python/requirements.txt"
if ! "$venv/bin/python" -c 'import importlib.metadata as m; assert m.version("iceoryx2") == "0.10.0"' 2>/dev/null; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet --disable-pip-version-check -r tools/python/requirements.txt \
        || fail "pip install -r tools/python/requirements.txt"
fi
py="$venv/bin/python"

# run NAME DRIVER_FILE [microrobot run options...]: one pipeline; leaves $work/NAME.*
run() {
    local name="$1" drv="$2"; shift 2
    local inst="py-drv-$name-$$"
    cat >"$work/$name.toml" <<EOF2
instance = "$inst"
robot = "$repo/config/robots/seed-arm.toml"
program = "$repo/config/programs/seed-table4.toml"

[realtime]
cpu_affinity = []
pm_qos = false
mlockall = false

[actuator]
command = ["$py", "$drv"${DRIVER_ARGS:-}]
EOF2
    set +e
    timeout 180 "$bin" run --config "$work/$name.toml" --summary-json "$work/$name.json" "$@" \
        >"$work/$name.out" 2>"$work/$name.err"
    echo $? >"$work/$name.rc"
    set -e
}

# judge NAME: the run's verdict (prints one line; exit 1 with the reasons if it failed)
judge() {
    python3 - "$work/$1" <<'PY'
import json, pathlib, sys
base = pathlib.Path(sys.argv[1])
rc = int(pathlib.Path(f"{base}.rc").read_text())
why = []
if rc != 0:
    why.append(f"microrobot run exited {rc}")
try:
    s = json.loads(pathlib.Path(f"{base}.json").read_text())
except (OSError, ValueError) as e:
    s = {}
    why.append(f"no summary: {e}")
if s:
    act = s["services"].get("actuator", {})
    prog = s.get("program") or {}
    checks = [
        (s["exit_ok"] is True, f"exit_ok {s['exit_ok']}: {s.get('failures')}"),
        (prog.get("state") == "finished", f"program {prog.get('state')} ({prog.get('end_reason')})"),
        (s["lost_messages"] == 0, f"{s['lost_messages']} lost messages"),
        (s["refused_messages"] == 0, f"{s['refused_messages']} refused messages"),
        (act.get("last_lifecycle") == "finalized", f"driver's last status {act.get('last_lifecycle')}, not finalized"),
        (act.get("exit") == "exit code 0", f"driver {act.get('exit')}"),
        # Generous: the example tracks within ~0.05 rad; a loop that went unstable is off by > 1 rad.
        (max(s["tracking_error_max_rad"] or [0]) < 0.25,
         f"tracking error max {max(s['tracking_error_max_rad'] or [0]):.3f} rad >= 0.25 rad"),
    ]
    why += [msg for ok, msg in checks if not ok]
    print(f"  {base.name}: rc {rc}, exit_ok {s['exit_ok']}, program {prog.get('state')} at "
          f"{prog.get('time_s')} s, lost {s['lost_messages']}, refused {s['refused_messages']}, "
          f"actuator cycles {act.get('cycles')}, tracking error max "
          f"{max(s['tracking_error_max_rad'] or [0]):.4f} rad, wall {s['wall_time_s']:.1f} s")
if why:
    print(f"  {base.name}: " + "; ".join(why))
    sys.exit(1)
PY
}

show() {
    for f in "$work/$1.err" "$work/$1.out"; do
        [ -s "$f" ] && { echo "--- $(basename "$f")" >&2; tail -n 15 "$f" >&2; }
    done
    local dir
    dir="$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["run_dir"])' "$work/$1.json" 2>/dev/null || true)"
    [ -n "$dir" ] && [ -s "$dir/actuator.log" ] && { echo "--- actuator.log" >&2; tail -n 10 "$dir/actuator.log" >&2; }
    return 0
}

echo "== Table 4 with the Python driver ($driver, $bin)"
run free "$driver"
judge free || { show free; fail "free-running run"; }
run lockstep "$driver" --lockstep
judge lockstep || { show lockstep; fail "lockstep run"; }
DRIVER_ARGS=', "--start-delay", "1"' run slow "$driver" --lockstep
judge slow || { show slow; fail "lockstep run with a driver whose first state comes 1 s late"; }

echo "== negative control: a driver without the start handshake must fail the run"
cat >"$work/no_handshake.py" <<EOF2
import sys
sys.path.insert(0, "$repo/tools/python")
import example_driver, microrobot_driver
# Broken on purpose: no initial state, no update_connections() while waiting.
microrobot_driver.Driver.publish_initial_state = lambda self: self._read()
microrobot_driver.Driver.waiting_for_first_torque = lambda self: None
sys.exit(example_driver.main())
EOF2
run broken "$work/no_handshake.py" --lockstep
if judge broken; then
    fail "a driver that never published an initial state passed: the check cannot tell a broken start"
fi

echo "== driver-check: the Python example driver, free-running and in lockstep"
dcfg="$work/driver-check.toml"
cat >"$dcfg" <<EOF2
robot = "$repo/config/robots/seed-arm.toml"

[realtime]
cpu_affinity = []
pm_qos = false
mlockall = false
EOF2
for mode in "" "--lockstep"; do
    "$bin" driver-check --config "$dcfg" $mode -- "$py" "$driver" >"$work/dc.out" 2>&1 \
        || { cat "$work/dc.out" >&2; fail "driver-check $mode on $driver"; }
    tail -n 1 "$work/dc.out"
done

echo "== driver-check: broken drivers fail on the right clause"
# broken NAME CLAUSE PYTHON-PATCH [driver-check options]: a copy of the example driver with
# one contract clause broken; driver-check must exit 7 and name that clause among the failures.
broken() {
    local name="$1" clause="$2" patch="$3"; shift 3
    cat >"$work/broken_$name.py" <<EOF2
import sys
sys.path.insert(0, "$repo/tools/python")
import example_driver, microrobot_driver
from microrobot_driver import Driver
$patch
sys.exit(example_driver.main())
EOF2
    set +e
    "$bin" driver-check --config "$dcfg" "$@" -- "$py" "$work/broken_$name.py" >"$work/dc_$name.out" 2>&1
    local rc=$?
    set -e
    grep -qE "^driver-check: FAILED: (.*, )?$clause(,|$)" "$work/dc_$name.out" && [ "$rc" = 7 ] || {
        cat "$work/dc_$name.out" >&2
        fail "driver-check on a driver with '$name' broken: exit $rc, want 7 and a failed '$clause' clause"
    }
    echo "broken driver '$name': $(tail -n 1 "$work/dc_$name.out")"
}
# (free-running, a state every period reaches a late subscriber anyway: lockstep shows it)
broken no-initial-state "initial state" '
Driver.publish_initial_state = lambda self: self._read()
Driver.waiting_for_first_torque = lambda self: None' --lockstep
broken tick-not-copied "tick and stamp copied" '
_orig = Driver.state_message
def _no_tick(self, now_ns, final=False):
    s = _orig(self, now_ns, final)
    s.header.tick = 0
    return s
Driver.state_message = _no_tick'
broken ignores-sigterm "SIGTERM" '
Driver._on_signal = lambda self, signum, frame: None'
broken status-latency-zero "status" '
microrobot_driver.LatencyHistogram.record = lambda self, ns: None'
broken status-not-notified "notify" '
def _quiet_status(self, now_ns, final=False):
    self.status_pub.send_copy(self.status_message(now_ns, final))
    self.next_status_ns = now_ns + round(self.cfg.status_period_ms * 1e6)
Driver.publish_status = _quiet_status'

echo "== layout: ctypes structs against the Rust payloads"
"$py" tools/python/check_layout.py || fail "tools/python/check_layout.py"
echo "check_python_driver: ok"
