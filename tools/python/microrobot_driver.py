"""The microrobot bus contract in Python, and a base class for an actuator driver.

A driver replaces the simulated arm (`actuator.command` in the pipeline config): it
subscribes to `torque`, publishes `state` and `status`, and keeps the arm safe on its
own when torque commands stop, as the Rust actuator does (services/actuator/src/lib.rs).
A subclass of `Driver` provides only the hardware:

    class MyArm(Driver):
        def read(self):              # measured q, qd, tau applied (sequences of dof floats)
            ...
        def write(self, tau, period):  # apply tau (N m) for one period (s); may return
            ...                        # True when the drive saturated a torque

    if __name__ == "__main__":
        sys.exit(MyArm.main())

`Driver` does the rest: the start handshake (the initial state, then
`update_connections()` on the state publisher until the first torque arrives, so a
planner that subscribed meanwhile still gets it), one state per torque in lockstep or per
period when free-running, the header bookkeeping, torque validation, the stale-torque
hold, the fault latch and its reset, status at ~10 Hz, and on SIGTERM/SIGINT a final
state and a final status, then exit 0. The contract itself is messages/README.md; the
structs below are checked against the Rust types by tools/python/check_layout.py.

Needs the iceoryx2 Python bindings, exactly 0.10.0 (tools/python/requirements.txt).
"""

import ctypes
import math
import os
import re
import signal
import sys
import time
import tomllib

try:
    import iceoryx2 as iox2
except ImportError:  # pragma: no cover - depends on the environment
    sys.exit("microrobot_driver: the iceoryx2 Python bindings are missing: "
             "pip install -r tools/python/requirements.txt (iceoryx2==0.10.0)")

CONTRACT_VERSION = 2
MAX_JOINTS = 8
U64_MAX = (1 << 64) - 1
INSTANCE_RE = re.compile(r"^[A-Za-z0-9_-]{1,64}$")

F64x8 = ctypes.c_double * MAX_JOINTS


def _named(name):
    """Class decorator: the `type_name()` iceoryx2 compares with the Rust `#[type_name]`."""
    def deco(cls):
        cls.type_name = classmethod(lambda c: f"microrobot::v{CONTRACT_VERSION}::{name}")
        return cls
    return deco


# --- payloads (messages/src/*.rs, field by field) -------------------------------------

@_named("Header")
class Header(ctypes.Structure):
    _fields_ = [("seq", ctypes.c_uint64), ("tick", ctypes.c_uint64),
                ("stamp_ns", ctypes.c_uint64), ("source_stamp_ns", ctypes.c_uint64)]


@_named("JointSetpoint")
class JointSetpoint(ctypes.Structure):
    _fields_ = [("header", Header), ("q", F64x8), ("qd", F64x8), ("qdd", F64x8),
                ("jerk", F64x8), ("dof", ctypes.c_uint32), ("flags", ctypes.c_uint32)]


@_named("TorqueCommand")
class TorqueCommand(ctypes.Structure):
    _fields_ = [("header", Header), ("tau", F64x8), ("q_desired", F64x8),
                ("setpoint_seq", ctypes.c_uint64), ("state_seq", ctypes.c_uint64),
                ("dof", ctypes.c_uint32), ("flags", ctypes.c_uint32)]


@_named("JointState")
class JointState(ctypes.Structure):
    _fields_ = [("header", Header), ("q", F64x8), ("qd", F64x8), ("tau_applied", F64x8),
                ("torque_seq", ctypes.c_uint64), ("dof", ctypes.c_uint32),
                ("lifecycle", ctypes.c_uint32), ("flags", ctypes.c_uint32),
                ("reserved", ctypes.c_uint32)]


@_named("MotionCommand")
class MotionCommand(ctypes.Structure):
    _fields_ = [("seq", ctypes.c_uint64), ("stamp_ns", ctypes.c_uint64),
                ("kind", ctypes.c_uint32), ("profile", ctypes.c_uint32),
                ("space", ctypes.c_uint32), ("dof", ctypes.c_uint32), ("target", F64x8),
                ("duration_s", ctypes.c_double), ("limit_scale", ctypes.c_double)]


@_named("LatencySummary")
class LatencySummary(ctypes.Structure):
    _fields_ = [("count", ctypes.c_uint64), ("p50_ns", ctypes.c_uint64),
                ("p99_ns", ctypes.c_uint64), ("p999_ns", ctypes.c_uint64),
                ("p9999_ns", ctypes.c_uint64), ("max_ns", ctypes.c_uint64)]


@_named("HopLatency")
class HopLatency(ctypes.Structure):
    _fields_ = [("count", ctypes.c_uint64), ("sum_ns", ctypes.c_uint64),
                ("p50_ns", ctypes.c_uint64), ("p99_ns", ctypes.c_uint64),
                ("p999_ns", ctypes.c_uint64), ("max_ns", ctypes.c_uint64)]


COMMAND_VERDICTS = 16
STATUS_HOPS = 2


@_named("CommandVerdict")
class CommandVerdict(ctypes.Structure):
    _fields_ = [("seq", ctypes.c_uint64), ("publisher", ctypes.c_uint64 * 2),
                ("refusal", ctypes.c_uint32), ("reserved", ctypes.c_uint32)]


@_named("ServiceStatus")
class ServiceStatus(ctypes.Structure):
    _fields_ = [("seq", ctypes.c_uint64), ("stamp_ns", ctypes.c_uint64),
                ("role", ctypes.c_uint32), ("lifecycle", ctypes.c_uint32),
                ("pid", ctypes.c_uint32), ("ready", ctypes.c_uint32),
                ("cycles", ctypes.c_uint64), ("deadline_misses", ctypes.c_uint64),
                ("skipped_ticks", ctypes.c_uint64), ("lost_messages", ctypes.c_uint64),
                ("refused_messages", ctypes.c_uint64), ("stale_cycles", ctypes.c_uint64),
                ("clamped_cycles", ctypes.c_uint64), ("faults", ctypes.c_uint64),
                ("commands_accepted", ctypes.c_uint64), ("commands_refused", ctypes.c_uint64),
                ("motion_time_s", ctypes.c_double), ("program_done", ctypes.c_uint32),
                ("cpu_time_ms", ctypes.c_uint32), ("rss_kib", ctypes.c_uint64),
                ("latency", LatencySummary), ("tracking_error_max", F64x8),
                ("peak_torque", F64x8), ("estops", ctypes.c_uint64),
                ("estop_latency_ns", ctypes.c_uint64), ("estop_latency_max_ns", ctypes.c_uint64),
                ("last_command_refusal", ctypes.c_uint32), ("last_input_refusal", ctypes.c_uint32),
                ("program_state", ctypes.c_uint32), ("program_end", ctypes.c_uint32),
                ("activity", ctypes.c_uint32), ("reserved", ctypes.c_uint32),
                ("refusal_joint", ctypes.c_uint32), ("refusal_quantity", ctypes.c_uint32),
                ("refusal_value", ctypes.c_double), ("refusal_min", ctypes.c_double),
                ("refusal_max", ctypes.c_double),
                ("command_verdicts", CommandVerdict * COMMAND_VERDICTS),
                ("fault_code", ctypes.c_uint32), ("fault_joint", ctypes.c_uint32),
                ("latency_sum_ns", ctypes.c_uint64), ("hops", HopLatency * STATUS_HOPS),
                ("hook", ctypes.c_uint32), ("hook_budget_ms", ctypes.c_uint32)]


@_named("MasterPose")
class MasterPose(ctypes.Structure):
    _fields_ = [("seq", ctypes.c_uint64), ("stamp_ns", ctypes.c_uint64),
                ("device_stamp_ns", ctypes.c_uint64), ("position", ctypes.c_double * 3),
                ("orientation", ctypes.c_double * 4), ("grip", ctypes.c_double),
                ("clutch", ctypes.c_uint32), ("reserved", ctypes.c_uint32)]


PAYLOADS = [Header, JointSetpoint, TorqueCommand, JointState, MotionCommand, LatencySummary,
            HopLatency, CommandVerdict, ServiceStatus, MasterPose]


# --- enums and flags (u32 on the wire) -------------------------------------------------

class ServiceRole:
    PLANNER, DYNAMICS, ACTUATOR = 1, 2, 3


class LifecycleState:
    UNCONFIGURED, INACTIVE, ACTIVE, FAULT, FINALIZED = 0, 1, 2, 3, 4


class CommandKind:
    MOVE, STOP, ESTOP, RESET, TELEOP = 1, 2, 3, 4, 5


class RefusalReason:
    NONE, UNKNOWN_KIND, UNKNOWN_PROFILE, UNKNOWN_SPACE, WRONG_DOF, NON_FINITE = 0, 1, 2, 3, 4, 5
    OUT_OF_LIMITS, BAD_DURATION, BAD_LIMIT_SCALE, STALE, ESTOP_ACTIVE = 6, 7, 8, 9, 10
    SAFE_STATE_ACTIVE, UNREACHABLE, BAD_QUATERNION, CANNOT_PLAN, NOT_STARTED = 11, 12, 13, 14, 15
    OUT_OF_ORDER, TELEOP_UNAVAILABLE, TELEOP_NOT_AT_REST, SECOND_PUBLISHER, OUTSIDER = 16, 17, 18, 19, 20


class StateFlags:
    SAFE_STATE, COMMAND_STALE, SATURATED, SLOPE_LIMITED, FINAL = 1, 2, 4, 8, 16


class TorqueFlags:
    CLAMPED, STATE_STALE, FEEDBACK, SLEW_LIMITED = 1, 2, 4, 8


# --- services and QoS (messages/src/ports.rs) ------------------------------------------

QOS = {"subscriber_max_buffer_size": 256, "subscriber_max_borrowed_samples": 2,
       "history_size": 1, "max_publishers": 8, "max_subscribers": 16, "max_nodes": 32}
SUBSCRIBER_BUFFER = 256
EVENT_PORTS = 16
EVENT_MAX_NODES = 32
EVENT_ID_MAX = 0  # every notification is a plain notify() (id 0)
STREAMS = {"setpoint": JointSetpoint, "torque": TorqueCommand, "state": JointState,
           "command": MotionCommand, "status": ServiceStatus, "master": MasterPose}


def service_name(instance, stream):
    """`microrobot/v2/<instance>/<stream>`."""
    return f"microrobot/v{CONTRACT_VERSION}/{instance}/{stream}"


def monotonic_ns():
    """CLOCK_MONOTONIC in ns, the time base of every stamp on the bus."""
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


def open_node(name):
    """An iceoryx2 node with the default config; iceoryx2 leaves the signals to us."""
    return (iox2.NodeBuilder.new().name(iox2.NodeName.new(name))
            .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
            .create(iox2.ServiceType.Ipc))


def open_publish_subscribe(node, instance, stream):
    """Opens (or creates) the publish-subscribe service of `stream` with the contract's QoS."""
    builder = (node.service_builder(iox2.ServiceName.new(service_name(instance, stream)))
               .publish_subscribe(STREAMS[stream]).enable_safe_overflow(True))
    for key, value in QOS.items():
        builder = getattr(builder, key)(value)
    return builder.open_or_create()


def open_event(node, instance, stream):
    """Opens (or creates) the event service paired with `stream`."""
    return (node.service_builder(iox2.ServiceName.new(service_name(instance, stream))).event()
            .max_listeners(EVENT_PORTS).max_notifiers(EVENT_PORTS)
            .event_id_max_value(EVENT_ID_MAX).max_nodes(EVENT_MAX_NODES).open_or_create())


def open_subscriber(node, instance, stream, history=0):
    """A subscriber (buffer 64, `history` samples requested) and a listener on `stream`."""
    sub = (open_publish_subscribe(node, instance, stream).subscriber_builder()
           .buffer_size(SUBSCRIBER_BUFFER).history_request(history).create())
    return sub, open_event(node, instance, stream).listener_builder().create()


def open_publisher(node, instance, stream):
    """A publisher and a notifier on `stream`."""
    pub = open_publish_subscribe(node, instance, stream).publisher_builder().create()
    return pub, open_event(node, instance, stream).notifier_builder().create()


def take(subscriber, cls):
    """Every waiting sample as (copy of the payload, publisher id); each sample is released
    at once (holding more than 2 gives ExceedsMaxBorrows)."""
    out = []
    while True:
        s = subscriber.receive()
        if s is None:
            return out
        out.append((cls.from_buffer_copy(s.payload().contents),
                    s.header.publisher_id.value))
        s.delete()


# --- the pipeline config the supervisor hands the driver (MICROROBOT_CONFIG) ------------

def parse_resume_state(text, dof):
    """`q=..;qd=..;tau=..` (comma-separated SI values, `dof` each) as a dict of lists;
    None when `text` is empty. Anything malformed is refused (SystemExit naming it):
    a driver must never start from a state it cannot read."""
    if not text:
        return None
    out = {}
    for part in text.split(";"):
        key, sep, values = part.partition("=")
        try:
            nums = [float(v) for v in values.split(",")] if sep else []
        except ValueError:
            nums = []
        if key not in ("q", "qd", "tau") or len(nums) != dof or not all(map(math.isfinite, nums)):
            raise SystemExit(f"driver: MICROROBOT_RESUME_STATE: bad part {part!r} "
                             f"(want q=..;qd=..;tau=.. with {dof} finite values each)")
        out[key] = nums
    if set(out) != {"q", "qd", "tau"}:
        raise SystemExit(f"driver: MICROROBOT_RESUME_STATE: {text!r} lacks one of q, qd, tau")
    return out


class DriverConfig:
    """What a driver needs from the resolved pipeline config and its robot file."""

    def __init__(self, path=None, instance=None):
        info = os.environ.get("MICROROBOT_DRIVER_INFO")
        if info and not path:
            self._from_driver_info(info, instance)
            return
        path = path or os.environ.get("MICROROBOT_CONFIG")
        raw = {}
        if path:
            with open(path, "rb") as f:
                raw = tomllib.load(f)
        wd = raw.get("watchdog", {})
        act = raw.get("actuator", {})
        self.instance = instance or os.environ.get("MICROROBOT_INSTANCE") or raw.get("instance", "default")
        if not INSTANCE_RE.match(self.instance):
            raise SystemExit(f"driver: instance {self.instance!r}: must be 1..64 of [A-Za-z0-9_-]")
        self.rate_hz = float(os.environ.get("MICROROBOT_RATE_HZ") or raw.get("rate_hz", 1000.0))
        lockstep = os.environ.get("MICROROBOT_LOCKSTEP")
        self.lockstep = lockstep == "1" if lockstep is not None else bool(raw.get("lockstep", False))
        self.status_period_ms = float(raw.get("status_period_ms", 100.0))
        self.stale_ms = float(wd.get("stale_ms", 50.0))
        self.fault_ms = float(wd.get("fault_ms", 200.0))
        self.safe_state = wd.get("safe_state", "hold")
        self.auto_resume = bool(wd.get("auto_resume", False))
        self.ramp_ms = float(wd.get("ramp_ms", 20.0))
        self.hold_kp = float(act.get("hold_kp_per_s2", 400.0))
        self.hold_kd = float(act.get("hold_kd_per_s", 40.0))
        # The robot: joint count, kinds, effort limits, and the configured start position.
        self.joints = []
        robot = raw.get("robot")
        if robot:
            if not os.path.isabs(robot):
                robot = os.path.join(os.path.dirname(os.path.abspath(path)), robot)
            with open(robot, "rb") as f:
                self.joints = tomllib.load(f).get("joints", [])
        self.dof = len(self.joints) or 6
        self.effort = [float(j.get("limits", {}).get("torque_nm", math.inf)) for j in self.joints] \
            or [math.inf] * self.dof
        deg = act.get("sim", {}).get("initial_q_deg") or []
        kinds = [j.get("kind", "revolute") for j in self.joints] or ["revolute"] * self.dof
        self.initial_q = [(math.radians(deg[i]) if kinds[i] == "revolute" else deg[i] * 1e-3)
                          if i < len(deg) else 0.0 for i in range(self.dof)]
        self.initial_qd = [0.0] * self.dof
        # A restart after a crash: the supervisor hands over the dead driver's last state
        # (MICROROBOT_RESUME_STATE, "q=..;qd=..;tau=..", SI). A simulated plant starts
        # there, as the physical arm has not moved; a hardware driver reads its encoders.
        self.resume = parse_resume_state(os.environ.get("MICROROBOT_RESUME_STATE"), self.dof)
        if self.resume is not None:
            self.initial_q = list(self.resume["q"])
            self.initial_qd = list(self.resume["qd"])

    def _from_driver_info(self, path, instance):
        """Everything from the supervisor's driver.toml (MICROROBOT_DRIVER_INFO): SI, any
        robot description (DH, URDF, overlay)."""
        try:
            with open(path, "rb") as f:
                raw = tomllib.load(f)
            wd, hold = raw["watchdog"], raw["hold"]
            self.instance = instance or raw["instance"]
            self.rate_hz = float(raw["rate_hz"])
            self.lockstep = bool(raw["lockstep"])
            self.status_period_ms = float(raw["status_period_ms"])
            self.stale_ms = float(wd["stale_ms"])
            self.fault_ms = float(wd["fault_ms"])
            self.safe_state = wd["safe_state"]
            self.auto_resume = bool(wd["auto_resume"])
            self.ramp_ms = float(wd["ramp_ms"])
            self.hold_kp = float(hold["kp_per_s2"])
            self.hold_kd = float(hold["kd_per_s"])
            self.joints = raw["joints"]
            self.dof = int(raw["dof"])
            unit = {"revolute": ("nm", "rad"), "prismatic": ("n", "m")}
            self.effort = [float(j["effort_" + unit[j["kind"]][0]]) for j in self.joints]
            self.initial_q = [float(j["start_" + unit[j["kind"]][1]]) for j in self.joints]
        except (OSError, tomllib.TOMLDecodeError, KeyError, TypeError, ValueError) as e:
            raise SystemExit(f"driver: {path} (MICROROBOT_DRIVER_INFO): {type(e).__name__}: {e}")
        if not INSTANCE_RE.match(self.instance):
            raise SystemExit(f"driver: instance {self.instance!r}: must be 1..64 of [A-Za-z0-9_-]")
        if len(self.joints) != self.dof:
            raise SystemExit(f"driver: {path}: dof = {self.dof} but {len(self.joints)} [[joints]]")
        self.initial_qd = [0.0] * self.dof
        self.resume = parse_resume_state(os.environ.get("MICROROBOT_RESUME_STATE"), self.dof)
        if self.resume is not None:
            self.initial_q = list(self.resume["q"])
            self.initial_qd = list(self.resume["qd"])

    @property
    def period_ns(self):
        return round(1e9 / self.rate_hz)


# --- latency histogram (status.latency) -------------------------------------------------

class LatencyHistogram:
    """µs buckets up to 1 ms, 100 µs buckets up to 100 ms, one overflow bucket."""

    def __init__(self):
        self.counts = [0] * 2001
        self.n = 0
        self.sum_ns = 0
        self.max_ns = 0

    def record(self, ns):
        us = ns // 1000
        i = us if us < 1000 else min(1000 + (us - 1000) // 100, 2000)
        self.counts[i] += 1
        self.n += 1
        self.sum_ns += ns
        self.max_ns = max(self.max_ns, ns)

    def summary(self):
        s = LatencySummary(count=self.n, max_ns=self.max_ns)
        if self.n == 0:
            return s
        wants = [("p50_ns", 0.5), ("p99_ns", 0.99), ("p999_ns", 0.999), ("p9999_ns", 0.9999)]
        acc, k = 0, 0
        for i, c in enumerate(self.counts):
            acc += c
            while k < len(wants) and acc >= math.ceil(wants[k][1] * self.n):
                us = i if i < 1000 else 1000 + (i - 1000) * 100
                setattr(s, wants[k][0], min(us * 1000, self.max_ns))
                k += 1
            if k == len(wants):
                break
        return s


# --- the driver ---------------------------------------------------------------------------

COMMAND, STALE_HOLD, SAFE = "command", "stale_hold", "safe"
REST_QD = 1e-3  # rad/s: "at rest" for the damp safe state


class Driver:
    """The actuator's loop around a subclass's `read()` and `write()`.

    Modes (as the Rust actuator's safety layer): COMMAND applies the newest valid torque;
    STALE_HOLD (free-running only: no valid torque for `watchdog.stale_ms`) holds the
    position with the driver's own law and follows commands again once they are fresh;
    SAFE (no valid torque for `watchdog.fault_ms` once the drive is active) is latched:
    the state says SAFE_STATE and lifecycle Fault until a `Reset` command arrives on the
    `command` stream while torques are fresh (or `watchdog.auto_resume`). Every switch is
    blended over `watchdog.ramp_ms`, never a torque step.
    """

    #: Per-joint inertia (kg m^2) by which the own hold law scales its gains
    #: (`actuator.hold_kp_per_s2`, `hold_kd_per_s`); set it to the arm's.
    hold_inertia = 1.0

    def __init__(self, cfg=None):
        self.cfg = cfg or DriverConfig()
        self.dof = self.cfg.dof
        self.period_s = 1.0 / self.cfg.rate_hz
        self.stop_requested = False
        self.lifecycle = LifecycleState.INACTIVE
        self.mode = COMMAND
        self.latest = None                  # the newest accepted TorqueCommand
        self.latest_unapplied = False
        self.steps_on_latest = 0
        self.last_torque_ns = None          # watchdog: receipt of the last valid torque
        self.publisher = None               # the torque publisher followed (id)
        self.last_seq = None
        self.state_seq = 0
        self.q_hold = [0.0] * self.dof
        self.damping = False
        self.blend_from = [0.0] * self.dof
        self.blend_step = self.ramp_steps = max(0, math.ceil(self.cfg.ramp_ms * 1e-3 / self.period_s))
        self.last_tau = [0.0] * self.dof
        self.saturated = False
        self.measured = None
        self.counters = dict(cycles=0, refused=0, lost=0, stale=0, saturated=0, faults=0,
                             resets_refused=0)
        self.last_refusal = RefusalReason.NONE
        self.tracking_error_max = [0.0] * self.dof
        self.peak_torque = [0.0] * self.dof
        self.latency = LatencyHistogram()
        self.status_seq = 0
        self.next_status_ns = 0

    # -- what a subclass provides -------------------------------------------------------
    def read(self):
        """The measured (q, qd, tau_applied), each a sequence of `dof` floats."""
        raise NotImplementedError

    def write(self, tau, period):
        """Apply `tau` (N m, or N) for `period` s. Return True if a torque was saturated."""
        raise NotImplementedError

    # -- hooks a subclass may override ---------------------------------------------------
    def activate(self):
        """The first valid torque arrived: switch the drives on (brakes off)."""

    def deactivate(self):
        """Shutting down: drives off, brakes on."""

    def own_law(self, q, qd):
        """The torque of the driver's own hold (stale commands, safe state): a joint PD
        around the position held, scaled by `hold_inertia`; `damp` damps to rest first."""
        if self.damping and all(abs(v) < REST_QD for v in qd):
            self.damping = False
            self.q_hold = list(q)
        kp = 0.0 if self.damping else self.cfg.hold_kp
        inertia = self.hold_inertia
        out = []
        for i in range(self.dof):
            m = inertia[i] if isinstance(inertia, (list, tuple)) else inertia
            out.append(m * (kp * (self.q_hold[i] - q[i]) - self.cfg.hold_kd * qd[i]))
        return out

    # -- torque commands -----------------------------------------------------------------
    def refuse(self, reason):
        self.counters["refused"] += 1
        self.last_refusal = reason
        return False

    def accept_torque(self, msg, publisher, now_ns):
        """Validates a torque command as the Rust actuator does; a good one becomes the
        command to apply. Refused: wrong dof, non-finite, stale (free-running only: older
        than `stale_ms` or > 1 ms in the future), out of order, a second publisher."""
        if msg.dof != self.dof or self.dof > MAX_JOINTS:
            return self.refuse(RefusalReason.WRONG_DOF)
        if not all(math.isfinite(msg.tau[i]) and math.isfinite(msg.q_desired[i])
                   for i in range(self.dof)):
            return self.refuse(RefusalReason.NON_FINITE)
        stale_ns = round(self.cfg.stale_ms * 1e6)
        stamp = msg.header.stamp_ns
        if not self.cfg.lockstep and (stamp > now_ns + 1_000_000 or now_ns - stamp > stale_ns):
            return self.refuse(RefusalReason.STALE)
        takeover = self.publisher is None or self.publisher == publisher or \
            self.last_torque_ns is None or now_ns - self.last_torque_ns >= stale_ns
        if not takeover:
            return self.refuse(RefusalReason.SECOND_PUBLISHER)
        if self.publisher == publisher and self.last_seq is not None:
            if msg.header.seq <= self.last_seq:
                return self.refuse(RefusalReason.OUT_OF_ORDER)
            self.counters["lost"] += msg.header.seq - self.last_seq - 1
        self.publisher, self.last_seq = publisher, msg.header.seq
        self.latest, self.latest_unapplied = msg, True
        self.last_torque_ns = now_ns
        if self.lifecycle == LifecycleState.INACTIVE and self.mode != SAFE:
            self.activate()
            self.lifecycle = LifecycleState.ACTIVE
            self.log("first torque command: drives on, following torque commands")
        return True

    def _switch(self, mode, q):
        if mode == self.mode:
            return
        if mode != COMMAND and self.mode == COMMAND:
            self.q_hold = list(q)
        if mode == SAFE:
            self.damping = self.cfg.safe_state == "damp"
        self.mode = mode
        self.blend_from = list(self.last_tau)
        self.blend_step = 0

    def check_watchdog(self, now_ns):
        """Stale → own hold (free-running only); fault → latch the safe state."""
        if self.last_torque_ns is None:
            return
        age = now_ns - self.last_torque_ns
        q = self.measured[0]
        if age >= self.cfg.fault_ms * 1e6:
            if self.mode != SAFE and self.lifecycle == LifecycleState.ACTIVE:
                self.counters["faults"] += 1
                self._switch(SAFE, q)
                self.log(f"no valid torque command for {self.cfg.fault_ms:g} ms: safe state "
                         f"latched ({self.cfg.safe_state}); send a reset to resume")
        elif age >= self.cfg.stale_ms * 1e6:
            if not self.cfg.lockstep and self.mode == COMMAND:
                self._switch(STALE_HOLD, q)
        elif self.mode == STALE_HOLD or (self.mode == SAFE and self.cfg.auto_resume):
            self._switch(COMMAND, q)

    def reset(self, now_ns):
        """A Reset command: leaves the safe state if torque commands are fresh."""
        if self.mode != SAFE:
            return False
        if self.last_torque_ns is not None and now_ns - self.last_torque_ns < self.cfg.stale_ms * 1e6:
            self._switch(COMMAND, self.measured[0])
            self.log("reset: following torque commands again")
            return True
        self.counters["resets_refused"] += 1
        self.log("reset refused: torque commands are not fresh")
        return False

    def steps_on_timer(self):
        return not self.cfg.lockstep or self.mode == SAFE

    # -- one plant step --------------------------------------------------------------------
    def step(self, now_ns):
        """Applies one period's torque (the command, or the own law, blended after a
        switch), reads the arm and returns the state message."""
        active = self.lifecycle == LifecycleState.ACTIVE
        use_cmd = self.mode == COMMAND and self.latest is not None
        fresh = None
        if active:
            q, qd, _ = self.measured
            target = list(self.latest.tau[:self.dof]) if use_cmd else self.own_law(q, qd)
            if self.blend_step < self.ramp_steps:
                self.blend_step += 1
                a = self.blend_step / self.ramp_steps
                target = [(1 - a) * b + a * t for b, t in zip(self.blend_from, target)]
            self.saturated = bool(self.write(target, self.period_s))
            self.last_tau = target
            if use_cmd and self.latest_unapplied:
                fresh, self.steps_on_latest = self.latest, 0
            self.steps_on_latest += 1
            self.latest_unapplied = False
        self._read()
        q, qd, tau = self.measured
        c = self.counters
        c["cycles"] += 1
        if active and not use_cmd:
            c["stale"] += 1
        if active and self.saturated:
            c["saturated"] += 1
        for i in range(self.dof):
            self.peak_torque[i] = max(self.peak_torque[i], abs(tau[i]))
            if fresh is not None:
                self.tracking_error_max[i] = max(self.tracking_error_max[i],
                                                 abs(q[i] - fresh.q_desired[i]))
        return self.state_message(now_ns)

    def _read(self):
        q, qd, tau = self.read()
        self.measured = (list(q)[:self.dof], list(qd)[:self.dof], list(tau)[:self.dof])

    def state_message(self, now_ns, final=False):
        """The measured state as a `JointState` (seq +1; tick and source stamp from the
        torque command last applied; torque_seq its seq, U64_MAX before the first)."""
        self.state_seq += 1
        q, qd, tau = self.measured
        s = JointState(dof=self.dof, lifecycle=self.reported_lifecycle(), torque_seq=U64_MAX)
        s.header.seq, s.header.stamp_ns = self.state_seq, now_ns
        if self.latest is not None:
            s.header.tick = self.latest.header.tick + max(self.steps_on_latest - 1, 0)
            s.header.source_stamp_ns = self.latest.header.source_stamp_ns
            s.torque_seq = self.latest.header.seq
        for i in range(self.dof):
            s.q[i], s.qd[i], s.tau_applied[i] = q[i], qd[i], tau[i]
        s.flags = ((StateFlags.SAFE_STATE if self.mode == SAFE else 0)
                   | (StateFlags.COMMAND_STALE if self.mode == STALE_HOLD else 0)
                   | (StateFlags.SATURATED if self.saturated else 0)
                   | (StateFlags.FINAL if final else 0))
        return s

    def reported_lifecycle(self):
        return LifecycleState.FAULT if self.mode == SAFE else self.lifecycle

    # -- status ----------------------------------------------------------------------------
    def status_message(self, now_ns, final=False):
        c = self.counters
        st = ServiceStatus(role=ServiceRole.ACTUATOR, pid=os.getpid(), ready=1,
                           lifecycle=LifecycleState.FINALIZED if final else self.reported_lifecycle(),
                           cycles=c["cycles"], lost_messages=c["lost"],
                           refused_messages=c["refused"] + c["resets_refused"],
                           stale_cycles=c["stale"], clamped_cycles=c["saturated"],
                           faults=c["faults"], last_input_refusal=self.last_refusal,
                           latency=self.latency.summary(),
                           latency_sum_ns=min(self.latency.sum_ns, 2**64 - 1))
        self.status_seq += 1
        st.seq, st.stamp_ns = self.status_seq, now_ns
        st.motion_time_s = self.latest.header.tick * self.period_s if self.latest else 0.0
        st.cpu_time_ms = min(int(time.process_time() * 1000), 0xFFFFFFFF)
        for i in range(self.dof):
            st.tracking_error_max[i] = self.tracking_error_max[i]
            st.peak_torque[i] = self.peak_torque[i]
        return st

    def publish_status(self, now_ns, final=False):
        self.status_pub.send_copy(self.status_message(now_ns, final))
        self.status_notifier.notify()
        self.next_status_ns = now_ns + round(self.cfg.status_period_ms * 1e6)

    def publish_state(self, s):
        self.answered_seq = s.torque_seq
        self.state_pub.send_copy(s)
        self.state_notifier.notify()

    # -- ports, handshake, loop ----------------------------------------------------------
    def log(self, msg):
        print(f"driver: {msg}", file=sys.stderr, flush=True)

    def open_ports(self):
        inst = self.cfg.instance
        self.node = open_node(f"microrobot-py-driver.{inst}.{os.getpid()}")
        self.torque_sub, self.torque_listener = open_subscriber(self.node, inst, "torque")
        self.cmd_sub, self.cmd_listener = open_subscriber(self.node, inst, "command")
        self.state_pub, self.state_notifier = open_publisher(self.node, inst, "state")
        self.status_pub, self.status_notifier = open_publisher(self.node, inst, "status")
        # iceoryx2's own SIGINT/SIGTERM handling off (node and WaitSet): it would take the
        # signals from Python's handlers, and the loop would never see the stop.
        self.waitset = (iox2.WaitSetBuilder.new()
                        .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
                        .create(iox2.ServiceType.Ipc))
        self._guards = [self.waitset.attach_notification(self.torque_listener),
                        self.waitset.attach_notification(self.cmd_listener)]

    def publish_initial_state(self):
        """Step 1 of the handshake: the measured state before any torque (torque_seq
        U64_MAX, lifecycle Inactive). History 1 keeps it for a late subscriber."""
        self._read()
        self.publish_state(self.state_message(monotonic_ns()))

    def waiting_for_first_torque(self):
        """Step 2, every wake-up until the first torque: iceoryx2 hands the stored
        state to a subscriber that joined since the last send only at the publisher's
        next send() or update_connections(); without this the planner never gets it."""
        self.state_pub.update_connections()

    def _wait(self, timeout_ns):
        if timeout_ns > 0:
            try:
                _, result = self.waitset.wait_and_process_with_timeout(
                    iox2.Duration.from_nanos(int(timeout_ns)))
                if result == iox2.WaitSetRunResult.TerminationRequest:
                    self.stop_requested = True
            except iox2.WaitSetRunError:  # interrupted by a signal: the loop looks at it
                pass
        self.torque_listener.try_wait()
        self.cmd_listener.try_wait()

    def _on_signal(self, _signum, _frame):
        self.stop_requested = True

    def run(self):
        """The loop; returns the process exit code (0 after a clean stop)."""
        signal.signal(signal.SIGTERM, self._on_signal)
        signal.signal(signal.SIGINT, self._on_signal)
        iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
        cfg = self.cfg
        self.open_ports()
        self.publish_initial_state()
        self.publish_status(monotonic_ns())
        self.log(f"{type(self).__name__}: {self.dof} joints at {cfg.rate_hz:g} Hz, "
                 f"{'lockstep' if cfg.lockstep else 'free-running'}, instance {cfg.instance}; "
                 "initial state published, waiting for the first torque command")
        p = cfg.period_ns
        next_tick = monotonic_ns() + p
        phased = False
        while not self.stop_requested:
            self._wait(min(next_tick, self.next_status_ns) - monotonic_ns())
            if self.stop_requested:
                break
            for msg, publisher in take(self.torque_sub, TorqueCommand):
                now = monotonic_ns()
                if not self.accept_torque(msg, publisher, now):
                    continue
                self.latency.record(max(now - msg.header.source_stamp_ns, 0))
                if not cfg.lockstep and not phased:
                    # Steps half a period after the planner's ticks, as the simulated arm.
                    phased = True
                    next_tick = msg.header.source_stamp_ns + p // 2
                    while next_tick <= now:
                        next_tick += p
                if not self.steps_on_timer():
                    self.check_watchdog(now)
                    self.publish_state(self.step(monotonic_ns()))
            for cmd, _ in take(self.cmd_sub, MotionCommand):
                if cmd.kind == CommandKind.RESET and self.reset(monotonic_ns()):
                    # Lockstep: a torque taken while latched and not yet answered by a
                    # timer step is answered now, or the loop (which ticks on states)
                    # would wait for a state while this waits for a torque.
                    if cfg.lockstep and self.latest is not None \
                            and getattr(self, "answered_seq", None) != self.latest.header.seq:
                        now = monotonic_ns()
                        self.check_watchdog(now)
                        self.publish_state(self.step(now))
            now = monotonic_ns()
            if now >= next_tick:
                if self.latest is None:
                    self.waiting_for_first_torque()
                n = 0
                while next_tick <= now:
                    next_tick += p
                    self.check_watchdog(now)
                    if self.steps_on_timer() and n < 100:
                        self.publish_state(self.step(now))
                        n += 1
            if now >= self.next_status_ns:
                self.publish_status(now)
        # Safe on the way out: drives off, the last state says so (FINAL), then the
        # final status (lifecycle Finalized).
        if self.lifecycle == LifecycleState.ACTIVE:
            self.deactivate()
            self.lifecycle = LifecycleState.INACTIVE
        self._read()
        self.publish_state(self.state_message(monotonic_ns(), final=True))
        self.publish_status(monotonic_ns(), final=True)
        self.log(f"stopped after {self.counters['cycles']} plant steps, drives off")
        return 0

    @classmethod
    def main(cls, argv=None):
        """Runs the driver with the config the supervisor hands over (environment)."""
        return cls().run()


_OK = {"Header": 32, "JointSetpoint": 296, "TorqueCommand": 184, "JointState": 248,
       "MasterPose": 96}
assert all(ctypes.sizeof(globals()[n]) == s for n, s in _OK.items())
