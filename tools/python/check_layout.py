#!/usr/bin/env python3
"""Checks the ctypes structs of tools/python/microrobot_driver.py against the Rust types.

The Rust side prints every payload's type name, size, alignment and each field's offset
and size (messages/examples/layout_json.rs, which fails to compile when a Rust field is
not listed there). This compares them with the ctypes structs, field by field, and exits 1
naming every mismatch: a field missing on either side, at another offset or of another
size, another size, alignment or type name of a payload.

Usage: python3 tools/python/check_layout.py [--json FILE]
  (without --json it builds and runs the messages crate's `layout_json` example with the
  workspace's feature set, the one `cargo test --workspace` builds, so nothing is rebuilt)
"""

import argparse
import ctypes
import json
import re
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import microrobot_driver as mr  # noqa: E402


def python_layout(cls):
    fields = []
    for name, _ in cls._fields_:
        d = getattr(cls, name)
        fields.append({"name": name, "offset": d.offset, "size": d.size})
    return {"type_name": cls.type_name(), "size": ctypes.sizeof(cls),
            "align": ctypes.alignment(cls), "fields": fields}


def compare(rust, classes):
    errors = []
    py = {c.__name__: c for c in classes}
    for name in sorted(set(rust) | set(py)):
        if name not in py:
            errors.append(f"{name}: a Rust payload with no ctypes struct in microrobot_driver.py")
            continue
        if name not in rust:
            errors.append(f"{name}: a ctypes struct the Rust layout does not list")
            continue
        r, p = rust[name], python_layout(py[name])
        for key in ("type_name", "size", "align"):
            if r[key] != p[key]:
                errors.append(f"{name}: {key} is {r[key]!r} in Rust, {p[key]!r} in Python")
        rf = {f["name"]: f for f in r["fields"]}
        pf = {f["name"]: f for f in p["fields"]}
        for f in r["fields"]:
            if f["name"] not in pf:
                errors.append(f"{name}.{f['name']}: missing in Python (Rust: offset {f['offset']}, "
                              f"{f['size']} B)")
            elif (pf[f["name"]]["offset"], pf[f["name"]]["size"]) != (f["offset"], f["size"]):
                q = pf[f["name"]]
                errors.append(f"{name}.{f['name']}: offset {q['offset']}, {q['size']} B in Python, "
                              f"offset {f['offset']}, {f['size']} B in Rust")
        for f in p["fields"]:
            if f["name"] not in rf:
                errors.append(f"{name}.{f['name']}: in Python only (offset {f['offset']})")
    return errors


def compare_qos():
    """The QoS constants of messages/src/ports.rs against the Python clients' copies:
    iceoryx2 lets the first creator's settings win, so a Python driver that creates a
    service with other settings locks the Rust services out."""
    repo = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
    src = open(os.path.join(repo, "messages", "src", "ports.rs")).read()
    rust = {k: int(v) for k, v in re.findall(r"pub const ([A-Z_]+): usize = (\d+);", src)}
    want = {"subscriber_max_buffer_size": "SUBSCRIBER_BUFFER", "history_size": "HISTORY",
            "max_publishers": "MAX_PUBLISHERS", "max_subscribers": "MAX_SUBSCRIBERS",
            "max_nodes": "MAX_NODES"}
    import master_device  # noqa: E402  (the README-only master device has its own copy)
    errors = []
    for where, qos in (("microrobot_driver.py", mr.QOS), ("master_device.py", master_device.QOS)):
        for key, const in want.items():
            if const not in rust:
                errors.append(f"qos: {const} not found in messages/src/ports.rs")
            elif qos.get(key) != rust[const]:
                errors.append(f"qos: {key} is {qos.get(key)} in {where}, {rust[const]} in Rust ({const})")
    if mr.SUBSCRIBER_BUFFER != rust.get("SUBSCRIBER_BUFFER"):
        errors.append(f"qos: SUBSCRIBER_BUFFER is {mr.SUBSCRIBER_BUFFER} in microrobot_driver.py")
    return errors


def run_layout_example(repo):
    """Builds `layout_json` for the whole workspace and returns what it prints.

    `cargo run -p microrobot-messages` would resolve that crate's own, smaller feature set
    and rebuild its dependencies; `--workspace` reuses what the test build compiled."""
    built = subprocess.run(["cargo", "build", "-q", "--workspace", "--example", "layout_json",
                            "--message-format=json"], cwd=repo, check=True,
                           capture_output=True, text=True).stdout
    exes = [m["executable"] for m in map(json.loads, built.splitlines())
            if m.get("reason") == "compiler-artifact" and m["target"]["name"] == "layout_json"
            and m.get("executable")]
    if len(exes) != 1:
        raise SystemExit(f"check_layout: cargo built {len(exes)} layout_json executables, expected 1")
    return subprocess.run([exes[0]], check=True, capture_output=True, text=True).stdout


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="the Rust layout (default: run the messages crate's example)")
    a = ap.parse_args(argv)
    if a.json:
        text = open(a.json).read()
    else:
        repo = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
        text = run_layout_example(repo)
    rust = json.loads(text)
    errors = compare(rust, mr.PAYLOADS) + compare_qos()
    for e in errors:
        print(f"check_layout: {e}", file=sys.stderr)
    if errors:
        print(f"check_layout: FAIL: {len(errors)} mismatch(es) between the Rust payloads and "
              "tools/python/microrobot_driver.py", file=sys.stderr)
        return 1
    print(f"check_layout: ok: {len(rust)} payloads, "
          f"{sum(len(t['fields']) for t in rust.values())} fields match")
    return 0


if __name__ == "__main__":
    sys.exit(main())
