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

    /// Lower-case name, as in logs, summaries and exported recordings.
    pub fn name(self) -> &'static str {
        match self {
            Self::Unconfigured => "unconfigured",
            Self::Inactive => "inactive",
            Self::Active => "active",
            Self::Fault => "fault",
            Self::Finalized => "finalized",
        }
    }
}

/// A lifecycle hook of an actuator backend the framework is inside
/// (`ServiceStatus::hook`): while one runs, the cycle is blocked and sends nothing, for
/// up to the hook's declared budget (`ServiceStatus::hook_budget_ms`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum LifecycleHook {
    /// Not inside a hook.
    None = 0,
    /// `on_configure`.
    Configure = 1,
    /// `on_activate`.
    Activate = 2,
    /// `on_deactivate`.
    Deactivate = 3,
    /// `on_reset`.
    Reset = 4,
}

impl LifecycleHook {
    /// Decodes the wire value, `None` for an unknown hook.
    pub fn from_wire(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::None),
            1 => Some(Self::Configure),
            2 => Some(Self::Activate),
            3 => Some(Self::Deactivate),
            4 => Some(Self::Reset),
            _ => None,
        }
    }

    /// The hook's name, as in the backend trait and in verdicts (`on_reset`).
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Configure => "on_configure",
            Self::Activate => "on_activate",
            Self::Deactivate => "on_deactivate",
            Self::Reset => "on_reset",
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
    /// From a process the pipeline's supervisor did not start (a stream is only ever
    /// taken by the pipeline's own services).
    Outsider = 20,
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
            20 => Outsider,
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
            Self::EStopActive => {
                "motion is refused during an e-stop; send reset first (a reset sent while braking takes effect at rest)"
            }
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
            Self::Outsider => "from a process the pipeline's supervisor did not start",
        }
    }
}

/// Where the planner's motion program stands (`ServiceStatus::program_state`), so a
/// supervisor can tell a program that ran to its end from one that was abandoned or never
/// ran: both end with the arm held at rest.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ProgramState {
    /// No program configured (or the status is not the planner's).
    None = 0,
    /// Configured; waiting for the first measured state to plan it from.
    Pending = 1,
    /// Executing.
    Running = 2,
    /// Ran to its end.
    Finished = 3,
    /// Stopped before its end; `ServiceStatus::program_end` says why.
    Abandoned = 4,
    /// Never started; `ServiceStatus::program_end` says why.
    NotRun = 5,
}

impl ProgramState {
    /// Decodes the wire value, `None` (the Option) for an unknown value.
    pub fn from_wire(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::None,
            1 => Self::Pending,
            2 => Self::Running,
            3 => Self::Finished,
            4 => Self::Abandoned,
            5 => Self::NotRun,
            _ => return Option::None,
        })
    }

    /// Lower-case name, as in summaries.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::Pending => "pending",
            Self::Running => "running",
            Self::Finished => "finished",
            Self::Abandoned => "abandoned",
            Self::NotRun => "not_run",
        }
    }
}

/// What a refused command's limit was about (`ServiceStatus::refusal_quantity`), so a
/// tool can say "j2 acceleration −0.62 rad/s² is outside [−0.35, 0.35]" in the user's units.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RefusalQuantity {
    /// The refusal names no value and limit.
    None = 0,
    /// A joint position (rad or m).
    Position = 1,
    /// A joint velocity (rad/s or m/s).
    Velocity = 2,
    /// A joint acceleration (rad/s² or m/s²).
    Acceleration = 3,
    /// A joint jerk (rad/s³ or m/s³).
    Jerk = 4,
    /// The command's duration (s).
    Duration = 5,
}

impl RefusalQuantity {
    /// Decodes the wire value, `None` (the Option) for an unknown value.
    pub fn from_wire(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::None,
            1 => Self::Position,
            2 => Self::Velocity,
            3 => Self::Acceleration,
            4 => Self::Jerk,
            5 => Self::Duration,
            _ => return Option::None,
        })
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "value",
            Self::Position => "position",
            Self::Velocity => "velocity",
            Self::Acceleration => "acceleration",
            Self::Jerk => "jerk",
            Self::Duration => "duration",
        }
    }
}

/// What the planner is doing (`ServiceStatus::activity`), for operators' tools.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Activity {
    /// Not the planner, or no measured state yet.
    Starting = 0,
    /// Holding a position.
    Hold = 1,
    /// Executing the configured program.
    Program = 2,
    /// Executing a `move` command.
    Move = 3,
    /// Braking to rest for a `stop` (or a stale measured state).
    Stopping = 4,
    /// Braking for, or holding after, an e-stop; motion refused until reset.
    EStop = 5,
    /// Following the arm while the actuator holds it in its latched safe state.
    SafeHold = 6,
    /// A master device drives the arm.
    Teleop = 7,
}

impl Activity {
    /// Decodes the wire value, `None` (the Option) for an unknown value.
    pub fn from_wire(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::Starting,
            1 => Self::Hold,
            2 => Self::Program,
            3 => Self::Move,
            4 => Self::Stopping,
            5 => Self::EStop,
            6 => Self::SafeHold,
            7 => Self::Teleop,
            _ => return Option::None,
        })
    }

    /// Lower-case name, as tools show it.
    pub fn name(self) -> &'static str {
        match self {
            Self::Starting => "starting",
            Self::Hold => "hold",
            Self::Program => "program",
            Self::Move => "move",
            Self::Stopping => "stopping",
            Self::EStop => "e-stop",
            Self::SafeHold => "safe-state",
            Self::Teleop => "teleop",
        }
    }
}

/// Why a program was abandoned or never run (`ServiceStatus::program_end`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ProgramEnd {
    /// Not ended early.
    None = 0,
    /// It cannot be planned from the measured start within the limits (a target outside
    /// a joint's range, an unreachable pose, an impossible duration).
    CannotPlan = 1,
    /// The measured state went stale while it ran; the planner stopped the arm.
    StaleState = 2,
    /// The actuator latched its safe state.
    SafeState = 3,
    /// A run-time command (move, stop, e-stop) replaced it.
    Command = 4,
    /// The arm was moving when the planner started; it was brought to rest instead.
    MovingAtStart = 5,
    /// `teleop.enabled`: the planner started in teleop mode instead.
    TeleopAtStart = 6,
}

impl ProgramEnd {
    /// Decodes the wire value, `None` (the Option) for an unknown value.
    pub fn from_wire(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::None,
            1 => Self::CannotPlan,
            2 => Self::StaleState,
            3 => Self::SafeState,
            4 => Self::Command,
            5 => Self::MovingAtStart,
            6 => Self::TeleopAtStart,
            _ => return Option::None,
        })
    }

    /// Why, in words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::None => "not ended early",
            Self::CannotPlan => "it cannot be planned from the measured start within the limits",
            Self::StaleState => "the measured state went stale; the planner stopped the arm",
            Self::SafeState => "the actuator latched its safe state",
            Self::Command => "a run-time command (move, stop or e-stop) replaced it",
            Self::MovingAtStart => "the arm was moving at start; it was brought to rest instead",
            Self::TeleopAtStart => "teleop.enabled: the planner started in teleop mode instead",
        }
    }
}

/// Percentiles of a latency histogram, in ns (0 when no sample yet).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v2::LatencySummary")]
pub struct LatencySummary {
    pub count: u64,
    pub p50_ns: u64,
    pub p99_ns: u64,
    pub p999_ns: u64,
    pub p9999_ns: u64,
    pub max_ns: u64,
}

/// One hop of the pipeline's latency, in ns, as a service measures it: the count, the
/// exact sum of the samples (their mean is `sum_ns / count`, so the means of
/// consecutive hops add up exactly) and percentiles of its histogram (0 when empty).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v2::HopLatency")]
pub struct HopLatency {
    pub count: u64,
    pub sum_ns: u64,
    pub p50_ns: u64,
    pub p99_ns: u64,
    pub p999_ns: u64,
    pub max_ns: u64,
}

/// How many hops a status carries ([`ServiceStatus::hops`]).
pub const STATUS_HOPS: usize = 2;

/// How many recent command verdicts the planner's status carries
/// ([`ServiceStatus::command_verdicts`]).
pub const COMMAND_VERDICTS: usize = 16;

/// The planner's verdict on one motion command ([`ServiceStatus::command_verdicts`]).
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("microrobot::v2::CommandVerdict")]
pub struct CommandVerdict {
    /// The command's `MotionCommand::seq`.
    pub seq: u64,
    /// The iceoryx2 id of the publisher that sent it (`UniquePublisherId`, a u128):
    /// low 64 bits, then high 64 bits.
    pub publisher: [u64; 2],
    /// [`RefusalReason::None`] (0): accepted; otherwise why it was refused.
    pub refusal: u32,
    pub reserved: u32,
}

/// What a status says about one command (see [`ServiceStatus::command_verdict`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VerdictLookup {
    /// Accepted.
    Accepted,
    /// Refused, with why (`None` for a reason this build does not know).
    Refused(Option<RefusalReason>),
    /// Not taken yet by the planner as far as this status shows.
    NotYet,
    /// Not in this status, and newer commands may have pushed it out of the ring.
    MaybeOverwritten,
}

/// Health and counters of one service. Counters are cumulative since the process started.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v2::ServiceStatus")]
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
    /// 1 when the planner's program is over (finished, abandoned or not run) and the arm
    /// holds at rest (planner only); [`ServiceStatus::program_state`] says which.
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
    /// Planner: a [`ProgramState`] value (0 elsewhere).
    pub program_state: u32,
    /// Planner: a [`ProgramEnd`] value, why the program was abandoned or not run.
    pub program_end: u32,
    /// Planner: an [`Activity`] value, what it is doing (0 elsewhere).
    pub activity: u32,
    /// Zero; keeps the size a multiple of 8.
    pub reserved: u32,
    /// Planner: the joint the last refused command's limit was about, as index + 1
    /// (0: none).
    pub refusal_joint: u32,
    /// Planner: a [`RefusalQuantity`] value, what that limit was about.
    pub refusal_quantity: u32,
    /// Planner: the refused value, and the range it had to be in (SI; ±infinity for an
    /// open side).
    pub refusal_value: f64,
    pub refusal_min: f64,
    pub refusal_max: f64,
    /// Planner: the verdicts of the last [`COMMAND_VERDICTS`] motion commands, a ring: the
    /// command taken as number `n` (0-based; `n` = `commands_accepted + commands_refused`
    /// before it) is at index `n % COMMAND_VERDICTS`. Each sender finds its own command
    /// by publisher id and `seq` (see [`ServiceStatus::command_verdict`]).
    pub command_verdicts: [CommandVerdict; COMMAND_VERDICTS],
    /// Actuator: the code of the backend's last fault (e.g. a CiA 402 drive's error code,
    /// object 0x603F); 0 = none. The fault's text is in the service's log.
    pub fault_code: u32,
    /// Actuator: the joint of the backend's last fault, 1-based; 0 = none or the whole drive.
    pub fault_joint: u32,
    /// The exact sum of the samples in `latency`, ns (its mean is
    /// `latency_sum_ns / latency.count`; 0 from a sender that does not keep it).
    pub latency_sum_ns: u64,
    /// The hops of the pipeline's latency this service measures, each from one instant
    /// to the next of the same message (so consecutive hops add up exactly):
    /// planner: `[wake-up → setpoint sent, -]`; dynamics: `[setpoint stamp → wake-up,
    /// wake-up → torque stamp]`; actuator: `[torque stamp → torque taken, plant step →
    /// state sent]`. The end-to-end `latency` of the actuator is the sum of the
    /// dynamics' two hops and its first.
    pub hops: [HopLatency; STATUS_HOPS],
    /// Actuator: the lifecycle hook (a [`LifecycleHook`]) the framework entered just
    /// before this status was sent and has not returned from yet; 0 = none. A status
    /// with a hook is the last until the hook returns.
    pub hook: u32,
    /// Actuator: with `hook`, how long the hook may block the cycle (ms,
    /// `actuator.hook_budget_ms`): the supervisor takes the process for hung only once
    /// it has been silent for longer. 0 without a hook.
    pub hook_budget_ms: u32,
}

impl ServiceStatus {
    /// Motion commands the planner has taken (accepted + refused).
    pub fn commands_taken(&self) -> u64 {
        self.commands_accepted + self.commands_refused
    }

    /// Records the verdict of the next command (call after counting it in
    /// `commands_accepted` / `commands_refused`).
    pub fn record_command_verdict(&mut self, seq: u64, publisher: u128, refusal: RefusalReason) {
        let n = self.commands_taken().saturating_sub(1);
        self.command_verdicts[(n % COMMAND_VERDICTS as u64) as usize] = CommandVerdict {
            seq,
            publisher: [publisher as u64, (publisher >> 64) as u64],
            refusal: refusal as u32,
            reserved: 0,
        };
    }

    /// The verdict on the command `seq` from `publisher`, sent after a status that had
    /// counted `taken_before` commands ([`ServiceStatus::commands_taken`]).
    pub fn command_verdict(&self, publisher: u128, seq: u64, taken_before: u64) -> VerdictLookup {
        let taken = self.commands_taken();
        let oldest = taken
            .saturating_sub(COMMAND_VERDICTS as u64)
            .max(taken_before);
        let id = [publisher as u64, (publisher >> 64) as u64];
        for n in oldest..taken {
            let v = &self.command_verdicts[(n % COMMAND_VERDICTS as u64) as usize];
            if v.seq == seq && v.publisher == id {
                return match RefusalReason::from_wire(v.refusal) {
                    Some(RefusalReason::None) => VerdictLookup::Accepted,
                    r => VerdictLookup::Refused(r),
                };
            }
        }
        if taken > taken_before + COMMAND_VERDICTS as u64 {
            VerdictLookup::MaybeOverwritten
        } else {
            VerdictLookup::NotYet
        }
    }
}
