#!/usr/bin/env bash
# CI step: a lockstep run recorded by `microrobot record`, read back by Python's `mcap`
# package (an MCAP reader independent of ours, pinned in recording-requirements.txt):
# every topic present, every message JSON with its schema's required fields, setpoints
# and torques (+ reported gaps) == the run's cycles; zstd chunks read through the indexed
# reader; log times on the wall clock (within a minute of `date`), publish times the
# messages' own monotonic stamps, the offset in the `clocks` metadata; the size per second.
# Usage: bash tools/ci/recording-python.sh [path/to/microrobot]   (from the repo root)
set -euo pipefail
cd "$(dirname "$0")/../.."
bin="${1:-target/release/microrobot}"
[ -x "$bin" ] || cargo build --release --bin microrobot
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install --quiet -r tools/ci/recording-requirements.txt

inst="ci-rec-$$"
"$bin" record --instance "$inst" --out "$work/run.mcap" --until-finalized \
    --ready-file "$work/ready" >"$work/record.out" &
rec=$!
for _ in $(seq 1 200); do [ -e "$work/ready" ] && break; sleep 0.05; done
[ -e "$work/ready" ] || { echo "recorder did not become ready"; kill "$rec"; exit 1; }
"$bin" run --lockstep --duration 2 --instance "$inst" --quiet --summary-json "$work/summary.json" >/dev/null
wait "$rec"

"$work/venv/bin/python" - "$work/run.mcap" "$work/summary.json" "$work/record.out" <<'PY'
import json, sys
from mcap.reader import make_reader
counts, required = {}, {}
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    for schema, channel, message in reader.iter_messages():
        assert channel.message_encoding == "json", channel
        assert schema.encoding == "jsonschema", schema
        req = required.setdefault(channel.topic, set(json.loads(schema.data)["required"]))
        msg = json.loads(message.data)
        assert set(msg) == req, (channel.topic, set(msg) ^ req)
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
import time
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    summary = reader.get_summary()
    assert summary is not None and summary.chunk_indexes, "a finished, indexed file"
    assert {c.compression for c in summary.chunk_indexes} == {"zstd"}, summary.chunk_indexes
    clocks = [m for m in reader.iter_metadata() if m.name == "clocks"]
    assert len(clocks) == 1, clocks
    offset = int(clocks[0].metadata["realtime_minus_monotonic_ns"])
    now = time.time_ns()
    n = 0
    names = {}
    for schema, channel, message in reader.iter_messages():
        names[channel.topic] = schema.name
        msg = json.loads(message.data)
        if channel.topic in ("transforms", "joints", "scene", "log"):
            # Derived for viewers: stamped with the state or setpoint they come from; a
            # log line with its own time.
            t = {"transforms": lambda: msg["transforms"][0]["timestamp"],
                 "scene": lambda: msg["entities"][0]["timestamp"],
                 "joints": lambda: msg["timestamp"],
                 "log": lambda: msg["timestamp"]}[channel.topic]()
            assert t["sec"] * 10**9 + t["nsec"] == message.log_time, (channel.topic, t)
            stamp = message.publish_time
        else:
            stamp = msg["header"]["stamp_ns"] if "header" in msg else msg["stamp_ns"]
        assert message.publish_time == stamp, (channel.topic, message.publish_time, stamp)
        assert message.log_time == stamp + offset, (channel.topic, message.log_time, stamp, offset)
        assert abs(message.log_time - now) < 60e9, ("log time not within a minute of now", message.log_time, now)
        n += 1
assert names["transforms"] == "foxglove.FrameTransforms", names
assert names["joints"] == "microrobot.JointStates", names
assert names["scene"] == "foxglove.SceneUpdate", names
assert names["log"] == "foxglove.Log", names
rec = json.loads(open(sys.argv[3]).read().strip().splitlines()[-1])
print(f"python mcap reader: {n} messages on the wall clock (offset {offset} ns); "
      f"{rec['bytes']} bytes, {rec['bytes_per_s'] / 1e3:.1f} kB/s")
assert rec["bytes"] > 0 and rec["bytes_per_s"] > 0, rec
s = json.load(open(sys.argv[2]))
gaps = json.loads(open(sys.argv[3]).read().strip().splitlines()[-1])["gaps"]  # reported losses
print("python mcap reader:", counts, "run cycles:", s["cycles"])
assert counts.get("setpoint") + gaps["setpoint"] == s["cycles"]["planner"], (counts, gaps, s["cycles"])
assert counts.get("torque") + gaps["torque"] == s["cycles"]["dynamics"], (counts, gaps, s["cycles"])
assert counts.get("status", 0) > 0, counts
assert counts.get("log", 0) >= 3, counts  # at least each service's start-up line
PY
