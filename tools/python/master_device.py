#!/usr/bin/env python3
"""A stand-in for a surgeon's master device, written from the bus contract alone.

Publishes `MasterPose` (messages/README.md: `microrobot::v2::MasterPose`, 96 B, align 8)
on the `master` stream of a running pipeline, `microrobot/v2/<instance>/master`, with the
contract's QoS, and `notify()`s the event service of the same name after every sample.
The hand motion is synthetic: a sine per axis (amplitude `--amplitude-mm`, frequency
`--frequency-hz`, starting at 0), the clutch engaged except in the `--clutch-open`
windows, grip 0, identity orientation. Each sample carries its own `CLOCK_MONOTONIC`
stamp and a sequence number +1 per sample (the first is 1).

Needs the iceoryx2 Python bindings, exactly 0.10.0 (tools/python/requirements.txt).
At the end it prints one JSON line on stdout: samples published, late ones, the service.
"""

import argparse
import ctypes
import json
import math
import os
import re
import signal
import sys
import time

try:
    import iceoryx2 as iox2
except ImportError:  # pragma: no cover - depends on the environment
    sys.exit("master_device: the iceoryx2 Python bindings are missing: "
             "pip install -r tools/python/requirements.txt (iceoryx2==0.10.0)")

CONTRACT_VERSION = 2
INSTANCE_RE = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


class MasterPose(ctypes.Structure):
    """`microrobot::v2::MasterPose`: the table in messages/README.md, field by field."""

    _fields_ = [
        ("seq", ctypes.c_uint64),              # +1 per sample
        ("stamp_ns", ctypes.c_uint64),         # CLOCK_MONOTONIC ns when published
        ("device_stamp_ns", ctypes.c_uint64),  # the device's own clock (here: ns since start)
        ("position", ctypes.c_double * 3),     # stylus tip x, y, z, device frame, m
        ("orientation", ctypes.c_double * 4),  # unit quaternion w, x, y, z
        ("grip", ctypes.c_double),             # 0 closed .. 1 open
        ("clutch", ctypes.c_uint32),           # 1 engaged, 0 released
        ("reserved", ctypes.c_uint32),         # 0
    ]

    @classmethod
    def type_name(cls) -> str:
        """The name iceoryx2 compares with the Rust type's `#[type_name]`."""
        return f"microrobot::v{CONTRACT_VERSION}::MasterPose"


# The documented layout; a mismatch would otherwise only show as IncompatibleTypes.
_OFFSETS = {"seq": 0, "stamp_ns": 8, "device_stamp_ns": 16, "position": 24,
            "orientation": 48, "grip": 80, "clutch": 88, "reserved": 92}
assert ctypes.sizeof(MasterPose) == 96 and ctypes.alignment(MasterPose) == 8
assert all(getattr(MasterPose, f).offset == o for f, o in _OFFSETS.items())

# The QoS every process of the pipeline requests (messages/README.md, "QoS").
QOS = {"subscriber_max_buffer_size": 256, "subscriber_max_borrowed_samples": 2,
       "history_size": 1, "max_publishers": 8, "max_subscribers": 16, "max_nodes": 32}
EVENT_PORTS = 16
EVENT_MAX_NODES = 32
EVENT_ID_MAX = 0  # every notification is a plain notify() (id 0)


def service_name(instance: str) -> str:
    """`microrobot/v<contract>/<instance>/master`."""
    return f"microrobot/v{CONTRACT_VERSION}/{instance}/master"


def monotonic_ns() -> int:
    """CLOCK_MONOTONIC in ns, the clock the pipeline's stamps use."""
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(
        description="Stand-in master device: publish a synthetic hand motion as MasterPose "
                    "on a running microrobot pipeline (iceoryx2 0.10.0).")
    p.add_argument("--instance", default="default", metavar="NAME",
                   help="instance name of the running pipeline (default: default)")
    p.add_argument("--duration", type=float, required=True, metavar="S",
                   help="how long to publish (s)")
    p.add_argument("--rate-hz", type=float, default=1000.0, metavar="HZ",
                   help="publishing rate, 1..10000 Hz (default 1000, a haptic device's rate)")
    p.add_argument("--amplitude-mm", default="3,0,0", metavar="X,Y,Z",
                   help="hand motion amplitude per axis, device frame (mm; default 3,0,0)")
    p.add_argument("--frequency-hz", type=float, default=1.0, metavar="F",
                   help="hand motion frequency, (0, 2) Hz (default 1, voluntary motion)")
    p.add_argument("--clutch-open", default=None, metavar="A-B[,C-D...]",
                   help="clutch released in these windows (s since start); engaged otherwise")
    a = p.parse_args(argv)
    if not INSTANCE_RE.match(a.instance):
        p.error(f"--instance {a.instance!r}: must be 1..64 characters of [A-Za-z0-9_-]")
    if not (math.isfinite(a.duration) and a.duration > 0):
        p.error(f"--duration {a.duration}: must be > 0 s")
    if not (math.isfinite(a.rate_hz) and 1.0 <= a.rate_hz <= 10000.0):
        p.error(f"--rate-hz {a.rate_hz}: must be in [1, 10000]")
    if not (math.isfinite(a.frequency_hz) and 0.0 < a.frequency_hz < 2.0):
        p.error(f"--frequency-hz {a.frequency_hz}: voluntary hand motion is in (0, 2) Hz")
    try:
        amp = [float(v) for v in a.amplitude_mm.split(",")]
    except ValueError:
        amp = []
    if len(amp) != 3 or not all(math.isfinite(v) for v in amp):
        p.error(f"--amplitude-mm {a.amplitude_mm!r}: expected three finite numbers X,Y,Z (mm)")
    a.amplitude_m = [v * 1e-3 for v in amp]
    a.clutch_windows = []
    if a.clutch_open:
        for part in a.clutch_open.split(","):
            m = re.fullmatch(r"\s*([0-9.eE+]+)\s*-\s*([0-9.eE+]+)\s*", part)
            try:
                lo, hi = (float(m.group(1)), float(m.group(2))) if m else (math.nan, math.nan)
            except ValueError:
                lo, hi = math.nan, math.nan
            if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
                p.error(f"--clutch-open {part!r}: expected START-END (s) with 0 <= START < END")
            a.clutch_windows.append((lo, hi))
    return a


class StopFlag:
    """Set by SIGINT/SIGTERM: the loop ends after the current sample."""

    def __init__(self):
        self.requested = False
        signal.signal(signal.SIGINT, self._set)
        signal.signal(signal.SIGTERM, self._set)

    def _set(self, _signum, _frame):
        self.requested = True


def open_ports(instance: str):
    """The publisher and notifier of the instance's `master` stream.

    The planner opens the publish-subscribe service when it starts (teleop mode or
    not), so it is opened here, not created: a missing service means no pipeline of
    that instance is running. The paired event service is opened or created.
    """
    name = service_name(instance)
    node_name = f"microrobot-py-master.{instance}.{os.getpid()}"
    node = (iox2.NodeBuilder.new().name(iox2.NodeName.new(node_name))
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .create(iox2.ServiceType.Ipc))
    svc_name = iox2.ServiceName.new(name)
    builder = (node.service_builder(svc_name).publish_subscribe(MasterPose)
               .enable_safe_overflow(True))
    for key, value in QOS.items():
        builder = getattr(builder, key)(value)
    try:
        svc = builder.open()
    except iox2.PublishSubscribeOpenError as e:
        reason = e.args[0] if e.args else str(e)
        if "DoesNotExist" in str(reason):
            raise SystemExit(
                f"master_device: service '{name}' does not exist: no pipeline of instance "
                f"'{instance}' is running (start one: microrobot run --instance {instance} "
                f"with [teleop] enabled = true)") from None
        if "IncompatibleTypes" in str(reason):
            raise SystemExit(
                f"master_device: service '{name}' carries another payload than "
                f"{MasterPose.type_name()} ({ctypes.sizeof(MasterPose)} B, align 8): "
                f"the pipeline was built against another contract version") from None
        raise SystemExit(f"master_device: cannot open service '{name}': {reason}") from None
    try:
        event = (node.service_builder(svc_name).event().max_listeners(EVENT_PORTS)
                 .max_notifiers(EVENT_PORTS).event_id_max_value(EVENT_ID_MAX)
                 .max_nodes(EVENT_MAX_NODES).open_or_create())
    except iox2.EventOpenOrCreateError as e:
        raise SystemExit(f"master_device: cannot open event service '{name}': {e}") from None
    return node, svc.publisher_builder().create(), event.notifier_builder().create(), name


def main(argv=None) -> int:
    args = parse_args(argv)
    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    stop = StopFlag()
    node, publisher, notifier, name = open_ports(args.instance)
    print(f"master_device: publishing {MasterPose.type_name()} on '{name}' at "
          f"{args.rate_hz:g} Hz for {args.duration:g} s", file=sys.stderr)

    period_ns = round(1e9 / args.rate_hz)
    w = 2.0 * math.pi * args.frequency_hz
    start = monotonic_ns()
    seq = late = failed = 0
    while not stop.requested:
        deadline = start + seq * period_ns
        now = monotonic_ns()
        if deadline > now:
            time.sleep((deadline - now) * 1e-9)
        elif now - deadline > period_ns:
            late += 1
        t = seq * period_ns * 1e-9
        if t > args.duration:
            break
        seq += 1
        engaged = not any(lo <= t < hi for lo, hi in args.clutch_windows)
        stamp = monotonic_ns()
        sample = MasterPose(
            seq=seq, stamp_ns=stamp, device_stamp_ns=stamp - start,
            position=(ctypes.c_double * 3)(*(a * math.sin(w * t) for a in args.amplitude_m)),
            orientation=(ctypes.c_double * 4)(1.0, 0.0, 0.0, 0.0),
            grip=0.0, clutch=1 if engaged else 0, reserved=0)
        try:
            publisher.send_copy(sample)
            notifier.notify()
        except (iox2.SendError, iox2.NotifierNotifyError) as e:
            failed += 1
            if failed == 1:
                print(f"master_device: publishing on '{name}' failed: {e}", file=sys.stderr)
    elapsed = (monotonic_ns() - start) * 1e-9
    print(json.dumps({"service": name, "published": seq - failed, "failed": failed,
                      "late": late, "elapsed_s": round(elapsed, 3),
                      "stopped_by_signal": stop.requested}))
    del publisher, notifier, node
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
