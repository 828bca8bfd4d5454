//! Service status / heartbeat, published by every service at about 10 Hz for the
//! supervisor, `microrobot top`, recorders and soak tests.

use iceoryx2::prelude::ZeroCopySend;

/// Which service sent a status (`ServiceStatus::role`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ServiceRole {
    Planner = 1,
    Dynamics = 2,
    Actuator = 3,
}

impl ServiceRole {
    /// Decodes the wire value, `None` for an unknown role.
    pub fn from_wire(v: u32) -> Option<Self> {
        match v {
            1 => Some(Self::Planner),
            2 => Some(Self::Dynamics),
            3 => Some(Self::Actuator),
            _ => None,
        }
    }

    /// Lower-case name, as used in service names, logs and summaries.
    pub fn name(self) -> &'static str {
        match self {
            Self::Planner => "planner",
            Self::Dynamics => "dynamics",
            Self::Actuator => "actuator",
        }
    }
}

/// Lifecycle of a service and of an actuator backend (after ros2_control's hardware
/// lifecycle): `Unconfigured → Inactive → Active`, `Fault` latched until an explicit reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum LifecycleState {
    Unconfigured = 0,
    Inactive = 1,
    Active = 2,
    /// Latched safe state (hold position or damp to rest); left only by a reset.
    Fault = 3,
    /// Shutting down cleanly.
    Finalized = 4,
}

impl LifecycleState {
    /// Decodes the wire value, `None` for an unknown state.
    pub fn from_wire(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Unconfigured),
            1 => Some(Self::Inactive),
            2 => Some(Self::Active),
            3 => Some(Self::Fault),
            4 => Some(Self::Finalized),
            _ => None,
        }
    }
}

/// Percentiles of a latency histogram, in ns (0 when no sample yet).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v1::LatencySummary")]
pub struct LatencySummary {
    pub count: u64,
    pub p50_ns: u64,
    pub p99_ns: u64,
    pub p999_ns: u64,
    pub p9999_ns: u64,
    pub max_ns: u64,
}

/// Health and counters of one service. Counters are cumulative since the process started.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v1::ServiceStatus")]
pub struct ServiceStatus {
    /// Sequence number of this status message.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` ns when written.
    pub stamp_ns: u64,
    /// A [`ServiceRole`] value.
    pub role: u32,
    /// A [`LifecycleState`] value.
    pub lifecycle: u32,
    /// OS process id.
    pub pid: u32,
    /// 1 once the service has opened all its ports and is ready to run.
    pub ready: u32,
    /// Control cycles executed (planner ticks, torque computations, plant steps).
    pub cycles: u64,
    /// Planner: ticks that started more than one period late. Others: 0.
    pub deadline_misses: u64,
    /// Ticks skipped by the overrun policy (planner).
    pub skipped_ticks: u64,
    /// Sequence gaps seen on the input stream(s).
    pub lost_messages: u64,
    /// Input messages refused (non-finite, wrong dof, out of order, out of limits, bad command).
    pub refused_messages: u64,
    /// Cycles in which the input was older than `stale_ms`.
    pub stale_cycles: u64,
    /// Cycles in which an output was clamped to a limit.
    pub clamped_cycles: u64,
    /// Times the safe state was latched (actuator) or a fault was raised.
    pub faults: u64,
    /// Motion commands accepted / refused (planner).
    pub commands_accepted: u64,
    pub commands_refused: u64,
    /// Planner: program (or motion) time in s; others: logical time of the last input.
    pub motion_time_s: f64,
    /// 1 when the planner has finished its program and holds (planner only).
    pub program_done: u32,
    /// Process CPU time (user + system) in ms.
    pub cpu_time_ms: u32,
    /// Resident set size in KiB.
    pub rss_kib: u64,
    /// Planner: wake-up lateness; dynamics: setpoint publish → torque publish;
    /// actuator: setpoint publish → torque receipt (end-to-end).
    pub latency: LatencySummary,
    /// Largest |q_measured − q_setpoint| (rad or m) seen per joint at the same tick
    /// (actuator, when it sees setpoints; dynamics otherwise).
    pub tracking_error_max: [f64; crate::MAX_JOINTS],
    /// Largest |τ| commanded per joint so far.
    pub peak_torque: [f64; crate::MAX_JOINTS],
}
