#!/usr/bin/env python3
"""A simulated actuator driver for the microrobot pipeline,
written from messages/README.md alone (the bus contract page), without the
driver SDK (tools/python/microrobot_driver.py) or any other implementation.

Plant: each joint an inertia J with viscous damping b, torque held over the
period, position clamped into the joint limits. Everything else (ports, QoS,
initial state, per-torque / per-period states, status, stale torques, safe
state, reset, SIGTERM, resume) follows the page's clauses; see FINDINGS.md
next to this file for where the page had to be guessed.

Run by `microrobot run` ([actuator] command) or `microrobot driver-check`:
    python3 drivers/contract-python/driver.py
It reads MICROROBOT_DRIVER_INFO (driver.toml) and the environment the page lists.
"""

import ctypes
import math
import os
import resource
import signal
import sys
import time
import tomllib

import iceoryx2 as iox2

U64_MAX = 2**64 - 1
MAX_JOINTS = 8
c_u64, c_u32, c_f64 = ctypes.c_uint64, ctypes.c_uint32, ctypes.c_double
F8 = c_f64 * MAX_JOINTS


# ---------------------------------------------------------------- payloads (page: "Payloads")
class Header(ctypes.Structure):
    _fields_ = [("seq", c_u64), ("tick", c_u64), ("stamp_ns", c_u64), ("source_stamp_ns", c_u64)]

    @staticmethod
    def type_name():
        return "microrobot::v2::Header"


class TorqueCommand(ctypes.Structure):
    _fields_ = [("header", Header), ("tau", F8), ("q_desired", F8), ("setpoint_seq", c_u64),
                ("state_seq", c_u64), ("dof", c_u32), ("flags", c_u32)]

    @staticmethod
    def type_name():
        return "microrobot::v2::TorqueCommand"


class JointState(ctypes.Structure):
    _fields_ = [("header", Header), ("q", F8), ("qd", F8), ("tau_applied", F8),
                ("torque_seq", c_u64), ("dof", c_u32), ("lifecycle", c_u32), ("flags", c_u32),
                ("reserved", c_u32)]

    @staticmethod
    def type_name():
        return "microrobot::v2::JointState"


class MotionCommand(ctypes.Structure):
    _fields_ = [("seq", c_u64), ("stamp_ns", c_u64), ("kind", c_u32), ("profile", c_u32),
                ("space", c_u32), ("dof", c_u32), ("target", F8), ("duration_s", c_f64),
                ("limit_scale", c_f64)]

    @staticmethod
    def type_name():
        return "microrobot::v2::MotionCommand"


class LatencySummary(ctypes.Structure):
    _fields_ = [("count", c_u64), ("p50_ns", c_u64), ("p99_ns", c_u64), ("p999_ns", c_u64),
                ("p9999_ns", c_u64), ("max_ns", c_u64)]


class HopLatency(ctypes.Structure):
    _fields_ = [("count", c_u64), ("sum_ns", c_u64), ("p50_ns", c_u64), ("p99_ns", c_u64),
                ("p999_ns", c_u64), ("max_ns", c_u64)]


class CommandVerdict(ctypes.Structure):
    _fields_ = [("seq", c_u64), ("publisher", c_u64 * 2), ("refusal", c_u32), ("reserved", c_u32)]


class ServiceStatus(ctypes.Structure):
    _fields_ = [
        ("seq", c_u64), ("stamp_ns", c_u64), ("role", c_u32), ("lifecycle", c_u32),
        ("pid", c_u32), ("ready", c_u32), ("cycles", c_u64), ("deadline_misses", c_u64),
        ("skipped_ticks", c_u64), ("lost_messages", c_u64), ("refused_messages", c_u64),
        ("stale_cycles", c_u64), ("clamped_cycles", c_u64), ("faults", c_u64),
        ("commands_accepted", c_u64), ("commands_refused", c_u64), ("motion_time_s", c_f64),
        ("program_done", c_u32), ("cpu_time_ms", c_u32), ("rss_kib", c_u64),
        ("latency", LatencySummary), ("tracking_error_max", F8), ("peak_torque", F8),
        ("estops", c_u64), ("estop_latency_ns", c_u64), ("estop_latency_max_ns", c_u64),
        ("last_command_refusal", c_u32), ("last_input_refusal", c_u32),
        ("program_state", c_u32), ("program_end", c_u32), ("activity", c_u32),
        ("reserved", c_u32), ("refusal_joint", c_u32), ("refusal_quantity", c_u32),
        ("refusal_value", c_f64), ("refusal_min", c_f64), ("refusal_max", c_f64),
        ("command_verdicts", CommandVerdict * 16), ("fault_code", c_u32), ("fault_joint", c_u32),
        ("latency_sum_ns", c_u64), ("hops", HopLatency * 2), ("hook", c_u32),
        ("hook_budget_ms", c_u32),
    ]

    @staticmethod
    def type_name():
        return "microrobot::v2::ServiceStatus"


def _check_layout():
    """The page's offset tables, checked at start-up (a wrong struct must not reach the bus)."""
    expect = {
        Header: (32, {"seq": 0, "tick": 8, "stamp_ns": 16, "source_stamp_ns": 24}),
        TorqueCommand: (184, {"tau": 32, "q_desired": 96, "setpoint_seq": 160, "state_seq": 168,
                              "dof": 176, "flags": 180}),
        JointState: (248, {"q": 32, "qd": 96, "tau_applied": 160, "torque_seq": 224, "dof": 232,
                           "lifecycle": 236, "flags": 240, "reserved": 244}),
        MotionCommand: (112, {"kind": 16, "profile": 20, "space": 24, "dof": 28, "target": 32,
                              "duration_s": 96, "limit_scale": 104}),
        ServiceStatus: (1024, {"cycles": 32, "motion_time_s": 112, "rss_kib": 128, "latency": 136,
                              "tracking_error_max": 184, "peak_torque": 248, "estops": 312,
                              "last_command_refusal": 336, "last_input_refusal": 340,
                              "activity": 352, "refusal_joint": 360, "refusal_value": 368,
                              "command_verdicts": 392, "fault_code": 904, "fault_joint": 908,
                              "latency_sum_ns": 912, "hops": 920, "hook": 1016,
                              "hook_budget_ms": 1020}),
    }
    for t, (size, offs) in expect.items():
        assert ctypes.sizeof(t) == size, (t.__name__, ctypes.sizeof(t), size)
        assert ctypes.alignment(t) == 8, t.__name__
        for f, o in offs.items():
            assert getattr(t, f).offset == o, (t.__name__, f, getattr(t, f).offset, o)


# ---------------------------------------------------------------- constants
ROLE_ACTUATOR = 3
LC_INACTIVE, LC_ACTIVE, LC_FAULT, LC_FINALIZED = 1, 2, 3, 4
SF_SAFE_STATE, SF_COMMAND_STALE, SF_SATURATED, SF_SLOPE_LIMITED, SF_FINAL, SF_STALLED = 1, 2, 4, 8, 16, 32
CMD_RESET = 4
R_WRONG_DOF, R_NON_FINITE, R_STALE, R_SAFE_STATE, R_ORDER, R_SECOND_PUB = 4, 5, 9, 11, 16, 19


def monotonic_ns():
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


# ---------------------------------------------------------------- ports (page: "Services", "QoS")
def service_name(instance, stream):
    return iox2.ServiceName.new(f"microrobot/v2/{instance}/{stream}")


def open_publish_subscribe(node, instance, stream, payload):
    return (node.service_builder(service_name(instance, stream))
            .publish_subscribe(payload)
            .enable_safe_overflow(True)
            .subscriber_max_buffer_size(256)
            .subscriber_max_borrowed_samples(2)
            .history_size(1)
            .max_publishers(8)
            .max_subscribers(16)
            .max_nodes(32)
            .open_or_create())


def open_event(node, instance, stream):
    return (node.service_builder(service_name(instance, stream))
            .event()
            .max_listeners(16)
            .max_notifiers(16)
            .event_id_max_value(0)
            .max_nodes(32)
            .open_or_create())


# ---------------------------------------------------------------- configuration
class Info:
    """driver.toml (MICROROBOT_DRIVER_INFO) plus the environment the page lists."""

    def __init__(self):
        path = os.environ.get("MICROROBOT_DRIVER_INFO")
        if not path:
            raise SystemExit("driver: MICROROBOT_DRIVER_INFO is not set (run me from "
                             "`microrobot run` or `microrobot driver-check`)")
        with open(path, "rb") as f:
            d = tomllib.load(f)
        self.instance = os.environ.get("MICROROBOT_INSTANCE", d.get("instance", "default"))
        self.rate_hz = float(os.environ.get("MICROROBOT_RATE_HZ", d.get("rate_hz", 1000.0)))
        lock_env = os.environ.get("MICROROBOT_LOCKSTEP")
        self.lockstep = (lock_env == "1") if lock_env is not None else bool(d.get("lockstep", False))
        self.status_period_ms = float(d.get("status_period_ms", 100.0))
        self.dof = int(d["dof"])
        wd = d.get("watchdog", {})
        self.stale_ms = float(wd.get("stale_ms", 50.0))
        self.fault_ms = float(wd.get("fault_ms", 200.0))
        self.safe_state = str(wd.get("safe_state", "hold"))
        self.auto_resume = bool(wd.get("auto_resume", False))
        self.ramp_ms = float(wd.get("ramp_ms", 20.0))
        hold = d.get("hold", {})
        self.kp = float(hold.get("kp_per_s2", 400.0))
        self.kd = float(hold.get("kd_per_s", 40.0))
        self.slope_ms = float(hold.get("torque_slope_ms", 10.0))
        self.qmin, self.qmax, self.effort, self.start = [], [], [], []
        for j in d["joints"][: self.dof]:
            if j.get("kind", "revolute") == "prismatic":
                keys = ("min_m", "max_m", "effort_n", "start_m")
            else:
                keys = ("min_rad", "max_rad", "effort_nm", "start_rad")
            self.qmin.append(float(j.get(keys[0], -math.inf)))
            self.qmax.append(float(j.get(keys[1], math.inf)))
            self.effort.append(float(j.get(keys[2], math.inf)))
            self.start.append(float(j.get(keys[3], 0.0)))
        self.resume = parse_resume(os.environ.get("MICROROBOT_RESUME_STATE"), self.dof)


def parse_resume(text, dof):
    """`q=<v1>,<v2>,...;qd=...;tau=...` (page: "What a driver is told")."""
    if not text:
        return None
    out = {}
    for part in text.strip().split(";"):
        if "=" not in part:
            continue
        k, v = part.split("=", 1)
        vals = [float(x) for x in v.split(",") if x.strip() != ""]
        out[k.strip()] = (vals + [0.0] * dof)[:dof]
    return out if "q" in out else None


# ---------------------------------------------------------------- latency summary
class Latency:
    def __init__(self, cap=200_000):
        self.values, self.cap, self.count, self.max = [], cap, 0, 0

    def add(self, ns):
        ns = max(0, int(ns))
        self.count += 1
        self.max = max(self.max, ns)
        if len(self.values) < self.cap:
            self.values.append(ns)
        else:
            self.values[self.count % self.cap] = ns

    def fill(self, s):
        s.count = self.count
        s.max_ns = self.max
        if not self.values:
            return
        v = sorted(self.values)
        n = len(v)

        def p(x):
            return v[min(n - 1, int(math.ceil(x * n)) - 1)]

        s.p50_ns, s.p99_ns, s.p999_ns, s.p9999_ns = p(0.5), p(0.99), p(0.999), p(0.9999)


# ---------------------------------------------------------------- the driver
class Driver:
    J = 0.3   # kg·m² per joint (the plant and the hold law's inertia estimate)
    B = 0.5   # N·m·s/rad viscous damping

    def __init__(self, info):
        self.c = c = info
        self.n = c.dof
        self.period_ns = int(round(1e9 / c.rate_hz))
        self.T = 1.0 / c.rate_hz
        r = c.resume
        self.q = list(r["q"]) if r else [min(max(s, lo), hi) for s, lo, hi in zip(c.start, c.qmin, c.qmax)]
        self.qd = list(r["qd"]) if r and "qd" in r else [0.0] * self.n
        self.tau = list(r["tau"]) if r and "tau" in r else [0.0] * self.n  # applied
        self.stop = False
        # drives / watchdog
        self.drives_on = False
        self.latched = False
        self.first_torque_exempt = True
        self.blend = 0.0             # 0 = torque stream, 1 = own hold law
        self.q_hold = list(self.q)
        self.damping_phase = False
        self.stalled_from_seq = None    # set after a stall > stale_ms: hold until a torque from a later state
        # torque stream
        self.pub_id = None
        self.last_valid_rx_ns = None    # receipt time of the last valid torque
        self.last_torque_seq = None
        self.cmd = None                 # newest valid torque (TorqueCommand copy)
        self.cmd_unanswered = False
        self.tau_cmd = [0.0] * self.n   # torque of the stream last taken
        # state stream
        self.state_seq = 0
        self.tick = 0
        self.source_stamp = 0
        self.torque_seq = U64_MAX
        # status
        self.status_seq = 0
        self.cnt = dict(cycles=0, lost=0, refused=0, stale=0, clamped=0, faults=0, acc=0, ref=0)
        self.last_input_refusal = 0
        self.latency = Latency()
        self.track_max = [0.0] * self.n
        self.peak = [0.0] * self.n

    # ---- ports
    def open(self):
        c = self.c
        self.node = (iox2.NodeBuilder.new()
                     .name(iox2.NodeName.new(f"contract-python-driver.{c.instance}"))
                     .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
                     .create(iox2.ServiceType.Ipc))
        torque = open_publish_subscribe(self.node, c.instance, "torque", TorqueCommand)
        self.torque_sub = torque.subscriber_builder().create()
        self.torque_listener = open_event(self.node, c.instance, "torque").listener_builder().create()
        command = open_publish_subscribe(self.node, c.instance, "command", MotionCommand)
        self.command_sub = command.subscriber_builder().create()
        self.command_listener = open_event(self.node, c.instance, "command").listener_builder().create()
        state = open_publish_subscribe(self.node, c.instance, "state", JointState)
        self.state_pub = state.publisher_builder().create()
        self.state_notifier = open_event(self.node, c.instance, "state").notifier_builder().create()
        status = open_publish_subscribe(self.node, c.instance, "status", ServiceStatus)
        self.status_pub = status.publisher_builder().create()
        self.status_notifier = open_event(self.node, c.instance, "status").notifier_builder().create()

    # ---- publishing
    def lifecycle(self):
        if self.latched:
            return LC_FAULT
        return LC_ACTIVE if self.drives_on else LC_INACTIVE

    def publish_state(self, flags=0, lifecycle=None):
        s = JointState()
        self.state_seq += 1
        s.header.seq = self.state_seq
        s.header.tick = self.tick
        s.header.stamp_ns = monotonic_ns()
        s.header.source_stamp_ns = self.source_stamp
        for i in range(self.n):
            s.q[i], s.qd[i], s.tau_applied[i] = self.q[i], self.qd[i], self.tau[i]
        s.torque_seq = self.torque_seq
        s.dof = self.n
        s.lifecycle = self.lifecycle() if lifecycle is None else lifecycle
        if self.latched:
            flags |= SF_SAFE_STATE
        s.flags = flags
        self.state_pub.send_copy(s)
        self.state_notifier.notify()

    def publish_status(self, lifecycle=None):
        st = ServiceStatus()
        self.status_seq += 1
        st.seq = self.status_seq
        st.stamp_ns = monotonic_ns()
        st.role = ROLE_ACTUATOR
        st.lifecycle = self.lifecycle() if lifecycle is None else lifecycle
        st.pid = os.getpid()
        st.ready = 1
        k = self.cnt
        st.cycles, st.lost_messages, st.refused_messages = k["cycles"], k["lost"], k["refused"]
        st.stale_cycles, st.clamped_cycles, st.faults = k["stale"], k["clamped"], k["faults"]
        st.commands_accepted, st.commands_refused = k["acc"], k["ref"]
        ru = resource.getrusage(resource.RUSAGE_SELF)
        st.cpu_time_ms = min(2**32 - 1, int((ru.ru_utime + ru.ru_stime) * 1000))
        st.rss_kib = ru.ru_maxrss
        try:
            with open("/proc/self/statm") as f:
                st.rss_kib = int(f.read().split()[1]) * (os.sysconf("SC_PAGE_SIZE") // 1024)
        except OSError:
            pass
        self.latency.fill(st.latency)
        for i in range(self.n):
            st.tracking_error_max[i] = self.track_max[i]
            st.peak_torque[i] = self.peak[i]
        st.last_input_refusal = self.last_input_refusal
        self.status_pub.send_copy(st)
        self.status_notifier.notify()

    # ---- inputs
    def refuse(self, reason):
        self.cnt["refused"] += 1
        self.last_input_refusal = reason

    def take_torques(self, now):
        """Drain the listener, then take every waiting torque; returns the valid ones in order."""
        self.torque_listener.try_wait()
        taken = []
        while True:
            sample = self.torque_sub.receive()
            if sample is None:
                break
            rx = monotonic_ns()
            t = TorqueCommand.from_buffer_copy(sample.payload().contents)
            pub = sample.header.publisher_id.value
            del sample
            if self.validate(t, pub, rx):
                taken.append((t, rx))
        return taken

    def validate(self, t, pub, rx):
        c = self.c
        if t.dof != self.n:
            self.refuse(R_WRONG_DOF)
            return False
        if not all(math.isfinite(t.tau[i]) and math.isfinite(t.q_desired[i]) for i in range(self.n)):
            self.refuse(R_NON_FINITE)
            return False
        live = (self.last_valid_rx_ns is not None and rx - self.last_valid_rx_ns < c.stale_ms * 1e6)
        if self.pub_id is not None and pub != self.pub_id:
            if live:
                self.refuse(R_SECOND_PUB)
                return False
            self.pub_id = pub            # takeover after stale_ms of silence: sequence afresh
            self.last_torque_seq = None
        if not c.lockstep:
            age = rx - t.header.stamp_ns
            if age > c.stale_ms * 1e6 or -age > 1_000_000:
                self.refuse(R_STALE)
                if self.pub_id == pub and (self.last_torque_seq is None or t.header.seq > self.last_torque_seq):
                    # refused, not lost: count gaps against it too (the page does not say)
                    if self.last_torque_seq is not None:
                        self.cnt["lost"] += t.header.seq - self.last_torque_seq - 1
                    self.last_torque_seq = t.header.seq
                return False
        if self.last_torque_seq is not None and t.header.seq <= self.last_torque_seq:
            self.refuse(R_ORDER)
            return False
        if self.last_torque_seq is not None and t.header.seq > self.last_torque_seq + 1:
            self.cnt["lost"] += t.header.seq - self.last_torque_seq - 1
        self.pub_id = pub
        self.last_torque_seq = t.header.seq
        self.last_valid_rx_ns = rx
        self.latency.add(rx - t.header.source_stamp_ns)
        for i in range(self.n):
            self.peak[i] = max(self.peak[i], abs(t.tau[i]))
        if not self.drives_on:
            self.drives_on = True          # the first valid torque switches the drives on
            self.first_torque_exempt = True
            self.blend = 0.0
        return True

    def take_commands(self):
        self.command_listener.try_wait()
        while True:
            sample = self.command_sub.receive()
            if sample is None:
                break
            m = MotionCommand.from_buffer_copy(sample.payload().contents)
            del sample
            if m.kind != CMD_RESET:
                continue                   # the planner's business
            if not self.latched:
                self.cnt["acc"] += 1       # nothing to reset: taken, no effect
            elif self.fresh():
                self.cnt["acc"] += 1
                self.leave_safe_state()
            else:
                self.cnt["ref"] += 1
                self.refuse(R_STALE)

    def fresh(self):
        return (self.last_valid_rx_ns is not None
                and monotonic_ns() - self.last_valid_rx_ns < self.c.stale_ms * 1e6)

    # ---- safe state
    def latch(self):
        if self.latched:
            return
        self.latched = True
        self.cnt["faults"] += 1
        self.q_hold = list(self.q)
        self.damping_phase = self.c.safe_state == "damp"
        print(f"driver: safe state latched (no valid torque for {self.c.fault_ms} ms)",
              file=sys.stderr, flush=True)

    def leave_safe_state(self):
        self.latched = False
        print("driver: safe state left", file=sys.stderr, flush=True)
        if self.c.lockstep and self.cmd_unanswered:
            self.step(self.cmd, new=True)  # owe a state to the last torque taken

    # ---- the plant step
    def hold_torque(self):
        kp = self.c.kp
        if self.damping_phase:
            if all(abs(v) < 1e-3 for v in self.qd):
                self.damping_phase = False
                self.q_hold = list(self.q)
            else:
                kp = 0.0
        return [self.J * (kp * (self.q_hold[i] - self.q[i]) - self.c.kd * self.qd[i]) for i in range(self.n)]

    def step(self, cmd, new, stale=False):
        """One plant step of 1/rate_hz with `cmd` (None = none yet) and publish its state."""
        n, T, c = self.n, self.T, self.c
        flags = 0
        if cmd is not None and new:
            self.tick = cmd.header.tick
            self.source_stamp = cmd.header.source_stamp_ns
            self.torque_seq = cmd.header.seq
            self.cmd_unanswered = False
            if not self.latched:
                self.tau_cmd = [cmd.tau[i] for i in range(n)]
            for i in range(n):
                self.track_max[i] = max(self.track_max[i], abs(self.q[i] - cmd.q_desired[i]))
        else:
            self.tick += 1
        own = self.latched or stale or self.stalled_from_seq is not None
        if stale:
            flags |= SF_COMMAND_STALE
            self.cnt["stale"] += 1
        if self.stalled_from_seq is not None:
            flags |= SF_STALLED
        if own and self.blend == 0.0 and not self.latched:
            self.q_hold = list(self.q)     # hold where the torques stopped
        target = 1.0 if own else 0.0
        rate = T / (c.ramp_ms / 1000.0) if c.ramp_ms > 0 else 1.0
        self.blend = min(target, self.blend + rate) if target > self.blend else max(target, self.blend - rate)
        if self.drives_on:
            hold = self.hold_torque() if self.blend > 0.0 else [0.0] * n
            want = [(1.0 - self.blend) * self.tau_cmd[i] + self.blend * hold[i] for i in range(n)]
        else:
            want = [0.0] * n
        sat = slope = False
        for i in range(n):
            e = c.effort[i]
            w = want[i]
            if self.drives_on and not self.first_torque_exempt and c.slope_ms > 0 and math.isfinite(e):
                d = e * T / (c.slope_ms / 1000.0)
                if w > self.tau[i] + d:
                    w, slope = self.tau[i] + d, True
                elif w < self.tau[i] - d:
                    w, slope = self.tau[i] - d, True
            if w > e:
                w, sat = e, True
            elif w < -e:
                w, sat = -e, True
            self.tau[i] = w
        if self.drives_on:
            self.first_torque_exempt = False
        if sat:
            flags |= SF_SATURATED
        if slope:
            flags |= SF_SLOPE_LIMITED
        if sat or slope:
            self.cnt["clamped"] += 1
        # damped inertia, semi-implicit Euler; brakes hold the arm while the drives are off
        for i in range(n):
            if not self.drives_on:
                self.qd[i] = 0.0
                continue
            self.qd[i] += (self.tau[i] - self.B * self.qd[i]) / self.J * T
            self.q[i] += self.qd[i] * T
            if self.q[i] < c.qmin[i]:
                self.q[i], self.qd[i] = c.qmin[i], 0.0
            elif self.q[i] > c.qmax[i]:
                self.q[i], self.qd[i] = c.qmax[i], 0.0
        self.cnt["cycles"] += 1
        self.publish_state(flags)

    # ---- the loop
    def run(self):
        c = self.c
        self.open()
        # the initial state: tick 0, torque_seq none, lifecycle inactive
        self.publish_state()
        self.publish_status()
        next_status = monotonic_ns() + int(c.status_period_ms * 1e6)
        next_step = monotonic_ns() + self.period_ns
        aligned = False
        print(f"driver: ready ({'lockstep' if c.lockstep else 'free-running'}, {c.rate_hz} Hz, "
              f"dof {self.n}{', resumed' if c.resume else ''})", file=sys.stderr, flush=True)
        while not self.stop:
            now = monotonic_ns()
            wait_ns = max(0, min(next_step, next_status) - now)
            # iceoryx2 0.10.0's Python timed_wait takes a duration under 1 µs as "no
            # timeout" and blocks until the next event: never pass one.
            if wait_ns >= 1000:
                try:
                    self.torque_listener.timed_wait(iox2.Duration.from_nanos(wait_ns))
                except iox2.ListenerWaitError:
                    pass               # interrupted by a signal: the handler set self.stop
            if self.stop:
                break
            now = monotonic_ns()
            taken = self.take_torques(now)
            self.take_commands()
            if c.lockstep:
                for t, _rx in taken:
                    self.cmd, self.cmd_unanswered = t, True
                    if not self.latched:
                        self.step(t, new=True)
            elif taken:
                newest = taken[-1][0]
                if (self.stalled_from_seq is not None and newest.state_seq != U64_MAX
                        and newest.state_seq >= self.stalled_from_seq):
                    self.stalled_from_seq = None   # a torque computed after the stall
                self.cmd, self.cmd_unanswered = newest, True
                if not aligned:
                    # steps half a period after the planner's ticks
                    aligned = True
                    next_step = newest.header.source_stamp_ns + self.period_ns // 2
                    while next_step < now - self.period_ns:
                        next_step += self.period_ns
            now = monotonic_ns()
            if self.drives_on and not self.latched and self.last_valid_rx_ns is not None \
                    and now - self.last_valid_rx_ns >= c.fault_ms * 1e6:
                self.latch()
            if self.latched and c.auto_resume and self.fresh():
                self.leave_safe_state()
            if now >= next_step:
                if not c.lockstep and self.drives_on and now - next_step > c.stale_ms * 1e6:
                    # stalled longer than stale_ms: missed periods are not replayed; hold
                    # until a torque computed from a state after the stall arrives
                    print(f"driver: stalled {(now - next_step) / 1e6:.1f} ms", file=sys.stderr, flush=True)
                    next_step = now
                    self.stalled_from_seq = self.state_seq + 1
                if not self.drives_on:
                    self.state_pub.update_connections()
                    if not c.lockstep:
                        self.cnt["cycles"] += 1
                        self.publish_state()
                elif not c.lockstep or self.latched:
                    stale = (not c.lockstep and not self.latched
                             and now - self.last_valid_rx_ns >= c.stale_ms * 1e6)
                    self.step(self.cmd, new=self.cmd_unanswered, stale=stale)
                next_step += self.period_ns     # shorter stalls are caught up step by step
            if now >= next_status:
                self.publish_status()
                next_status += int(c.status_period_ms * 1e6)
                if next_status < now:
                    next_status = now + int(c.status_period_ms * 1e6)
        # SIGTERM / SIGINT: drives off, final state (same tick), final status, exit 0
        latched = self.latched
        self.drives_on = False
        self.publish_state(SF_FINAL, lifecycle=LC_FAULT if latched else LC_INACTIVE)
        self.publish_status(lifecycle=LC_FINALIZED)
        print("driver: stopped", file=sys.stderr, flush=True)
        return 0


def main():
    _check_layout()
    d = Driver(Info())

    def on_signal(_sig, _frame):
        d.stop = True

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    return d.run()


if __name__ == "__main__":
    sys.exit(main())
