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

/// Why a service refused an input (`ServiceStatus::last_command_refusal`,
/// `ServiceStatus::last_input_refusal`), so a tool can say what was wrong without
/// reading the service's log.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RefusalReason {
    /// Nothing refused yet.
    None = 0,
    UnknownKind = 1,
    UnknownProfile = 2,
    UnknownSpace = 3,
    WrongDof = 4,
    NonFinite = 5,
    OutOfLimits = 6,
    BadDuration = 7,
    BadLimitScale = 8,
    Stale = 9,
    EStopActive = 10,
    SafeStateActive = 11,
    Unreachable = 12,
    BadQuaternion = 13,
    CannotPlan = 14,
    NotStarted = 15,
    OutOfOrder = 16,
    TeleopUnavailable = 17,
    TeleopNotAtRest = 18,
    SecondPublisher = 19,
}

impl RefusalReason {
    /// Decodes the wire value, `None` (the Option) for an unknown value.
    pub fn from_wire(v: u32) -> Option<Self> {
        use RefusalReason::*;
        Some(match v {
            0 => None,
            1 => UnknownKind,
            2 => UnknownProfile,
            3 => UnknownSpace,
            4 => WrongDof,
            5 => NonFinite,
            6 => OutOfLimits,
            7 => BadDuration,
            8 => BadLimitScale,
            9 => Stale,
            10 => EStopActive,
            11 => SafeStateActive,
            12 => Unreachable,
            13 => BadQuaternion,
            14 => CannotPlan,
            15 => NotStarted,
            16 => OutOfOrder,
            17 => TeleopUnavailable,
            18 => TeleopNotAtRest,
            19 => SecondPublisher,
            _ => return Option::None,
        })
    }

    /// What was wrong, in words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::None => "nothing refused",
            Self::UnknownKind => "unknown command kind",
            Self::UnknownProfile => "unknown trajectory profile",
            Self::UnknownSpace => "unknown target space",
            Self::WrongDof => "joint count does not match the robot's",
            Self::NonFinite => "a value is not finite (NaN or infinity)",
            Self::OutOfLimits => "a target or value is outside the joint limits",
            Self::BadDuration => "impossible duration",
            Self::BadLimitScale => "limit scale outside (0, 1]",
            Self::Stale => "stale timestamp (too old, or from the future)",
            Self::EStopActive => "motion is refused during an e-stop; send reset first",
            Self::SafeStateActive => {
                "motion is refused while the actuator is in its safe state; send reset first"
            }
            Self::Unreachable => "the Cartesian target is unreachable",
            Self::BadQuaternion => "the quaternion is not unit length",
            Self::CannotPlan => "no trajectory within the limits",
            Self::NotStarted => "the measured state is not known yet",
            Self::OutOfOrder => "sequence number out of order or duplicated",
            Self::TeleopUnavailable => {
                "teleop is not available (no [teleop] config or master input)"
            }
            Self::TeleopNotAtRest => {
                "teleop is entered at rest only; stop the running motion first"
            }
            Self::SecondPublisher => {
                "from a second publisher while the stream's own publisher is live"
            }
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
    /// Planner: e-stop commands executed (0 elsewhere).
    pub estops: u64,
    /// Planner: time from the receipt of the last e-stop command to its first braking
    /// setpoint, in ns (0: no e-stop yet).
    pub estop_latency_ns: u64,
    /// Planner: the largest such time so far, in ns.
    pub estop_latency_max_ns: u64,
    /// Planner: why the last refused motion command was refused (a [`RefusalReason`]).
    pub last_command_refusal: u32,
    /// Why the last refused bus message (setpoint, torque or state) was refused (a
    /// [`RefusalReason`]).
    pub last_input_refusal: u32,
    /// Actuator: the code of the backend's last fault (e.g. a CiA 402 drive's error code,
    /// object 0x603F); 0 = none. The fault's text is in the service's log.
    pub fault_code: u32,
    /// Actuator: the joint of the backend's last fault, 1-based; 0 = none or the whole drive.
    pub fault_joint: u32,
}
