//! The three cyclic streams of the control loop: setpoint → torque → measured state.

use iceoryx2::prelude::ZeroCopySend;

use crate::MAX_JOINTS;

/// Common head of every cyclic message: identity, logical time and the timestamps that
/// make end-to-end latency and gaps measurable instead of guessed.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v2::Header")]
pub struct Header {
    /// Per-publisher sequence number, +1 per message; a gap is a lost message.
    pub seq: u64,
    /// Logical time: the planner tick this message belongs to (setpoint tick count).
    pub tick: u64,
    /// `CLOCK_MONOTONIC` ns when this message was written.
    pub stamp_ns: u64,
    /// `CLOCK_MONOTONIC` ns at which the setpoint this message derives from was published
    /// (equal to `stamp_ns` on a setpoint itself).
    pub source_stamp_ns: u64,
}

/// Planner → dynamics (and monitors): the desired joint motion at one tick.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v2::JointSetpoint")]
pub struct JointSetpoint {
    pub header: Header,
    /// Position (rad, or m for prismatic joints).
    pub q: [f64; MAX_JOINTS],
    /// Velocity (rad/s or m/s).
    pub qd: [f64; MAX_JOINTS],
    /// Acceleration (rad/s² or m/s²).
    pub qdd: [f64; MAX_JOINTS],
    /// Jerk (rad/s³ or m/s³).
    pub jerk: [f64; MAX_JOINTS],
    /// Number of active joints.
    pub dof: u32,
    /// Bit set of [`setpoint_flags`].
    pub flags: u32,
}

/// Bits of [`JointSetpoint::flags`].
pub mod setpoint_flags {
    /// A motion is being executed (clear: holding a constant position).
    pub const MOVING: u32 = 1 << 0;
    /// The stream is braking for a stop or an e-stop.
    pub const STOPPING: u32 = 1 << 1;
    /// An e-stop is active; motion commands other than reset are refused.
    pub const ESTOP: u32 = 1 << 2;
    /// The planner is holding because the actuator reported its safe state.
    pub const HOLD_FOR_SAFE_STATE: u32 = 1 << 3;
    /// The motion program has completed.
    pub const PROGRAM_DONE: u32 = 1 << 4;
    /// Teleop mode: the setpoint follows the master device.
    pub const TELEOP: u32 = 1 << 5;
    /// Teleop: the clutch is released; the arm is brought to rest and held.
    pub const TELEOP_CLUTCH_OPEN: u32 = 1 << 6;
    /// Teleop: no valid master sample within `teleop.master_timeout_ms`; holding.
    pub const TELEOP_MASTER_STALE: u32 = 1 << 7;
    /// Teleop: the tool reached the workspace edge (or a joint limit) and stopped there.
    pub const TELEOP_WORKSPACE_EDGE: u32 = 1 << 8;
    /// Teleop: near a singularity; the tool's speed limit is reduced.
    pub const TELEOP_SINGULARITY: u32 = 1 << 9;
    /// Teleop: an IK solution that would flip the configuration was refused.
    pub const TELEOP_FLIP_REFUSED: u32 = 1 << 10;
    /// Teleop: a master sample was refused (not finite, quaternion not unit length).
    pub const TELEOP_INPUT_REFUSED: u32 = 1 << 11;
    /// Teleop: the tool's Cartesian velocity or acceleration limit is active.
    pub const TELEOP_LIMITED: u32 = 1 << 12;
    /// Every flag with its name, in bit order (for tools that print flags).
    pub const NAMES: &[(u32, &str)] = &[
        (MOVING, "MOVING"),
        (STOPPING, "STOPPING"),
        (ESTOP, "ESTOP"),
        (HOLD_FOR_SAFE_STATE, "HOLD_FOR_SAFE_STATE"),
        (PROGRAM_DONE, "PROGRAM_DONE"),
        (TELEOP, "TELEOP"),
        (TELEOP_CLUTCH_OPEN, "TELEOP_CLUTCH_OPEN"),
        (TELEOP_MASTER_STALE, "TELEOP_MASTER_STALE"),
        (TELEOP_WORKSPACE_EDGE, "TELEOP_WORKSPACE_EDGE"),
        (TELEOP_SINGULARITY, "TELEOP_SINGULARITY"),
        (TELEOP_FLIP_REFUSED, "TELEOP_FLIP_REFUSED"),
        (TELEOP_INPUT_REFUSED, "TELEOP_INPUT_REFUSED"),
        (TELEOP_LIMITED, "TELEOP_LIMITED"),
    ];
}

/// Dynamics → actuator: the joint torques (forces for prismatic joints) to apply.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v2::TorqueCommand")]
pub struct TorqueCommand {
    /// `header.tick` and `header.source_stamp_ns` are copied from the setpoint used.
    pub header: Header,
    /// Joint torque (N·m) or force (N), on the joint side of any gear.
    pub tau: [f64; MAX_JOINTS],
    /// The setpoint position this torque tracks, so a backend can hold it if it must.
    pub q_desired: [f64; MAX_JOINTS],
    /// Sequence number of the setpoint used.
    pub setpoint_seq: u64,
    /// Sequence number of the measured state used for feedback (`u64::MAX`: none).
    pub state_seq: u64,
    /// Number of active joints.
    pub dof: u32,
    /// Bit set of [`torque_flags`].
    pub flags: u32,
}

/// Bits of [`TorqueCommand::flags`].
pub mod torque_flags {
    /// At least one joint's torque was clamped to its limit.
    pub const CLAMPED: u32 = 1 << 0;
    /// The measured state was stale: feedback was left out (feed-forward only).
    pub const STATE_STALE: u32 = 1 << 1;
    /// Feedback (computed torque) was applied.
    pub const FEEDBACK: u32 = 1 << 2;
    /// At least one joint's torque change was cut to the slew limit (`torque_slew_ms`).
    pub const SLEW_LIMITED: u32 = 1 << 3;
    /// Every flag with its name, in bit order (for tools that print flags).
    pub const NAMES: &[(u32, &str)] = &[
        (CLAMPED, "CLAMPED"),
        (STATE_STALE, "STATE_STALE"),
        (FEEDBACK, "FEEDBACK"),
        (SLEW_LIMITED, "SLEW_LIMITED"),
    ];
}

/// Actuator → planner and dynamics: the measured joint state.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v2::JointState")]
pub struct JointState {
    /// `header.tick`/`source_stamp_ns` come from the torque command last applied.
    pub header: Header,
    /// Measured position (rad or m).
    pub q: [f64; MAX_JOINTS],
    /// Measured velocity (rad/s or m/s).
    pub qd: [f64; MAX_JOINTS],
    /// Torque actually applied after saturation (N·m or N).
    pub tau_applied: [f64; MAX_JOINTS],
    /// Sequence number of the torque command last applied (`u64::MAX`: none yet).
    pub torque_seq: u64,
    /// Number of active joints.
    pub dof: u32,
    /// The backend's lifecycle state, a [`crate::LifecycleState`] value.
    pub lifecycle: u32,
    /// Bit set of [`state_flags`].
    pub flags: u32,
    /// Padding, always 0 (keeps the layout identical in every language).
    pub reserved: u32,
}

/// Bits of [`JointState::flags`].
pub mod state_flags {
    /// The backend is in its safe state (holding or damping), ignoring torque commands.
    pub const SAFE_STATE: u32 = 1 << 0;
    /// Torque commands are stale: the backend holds position under its own control.
    pub const COMMAND_STALE: u32 = 1 << 1;
    /// A commanded torque was saturated by the backend.
    pub const SATURATED: u32 = 1 << 2;
    /// The applied torque's change was cut by the actuator's torque slope.
    pub const SLOPE_LIMITED: u32 = 1 << 3;
    /// The backend's last state before its process stops (drives disabled, brakes on).
    /// It repeats the tick of the state before it and is not a new period: a planner
    /// ticking on states does not tick on it, and in lockstep the dynamics does not use
    /// it as feedback (so where a run stops never changes what it computed).
    pub const FINAL: u32 = 1 << 4;
    /// The actuator's process stalled (frozen or late) for longer than `stale_ms`: the
    /// missed plant periods were not replayed and it holds with its own law until a
    /// torque command computed from a state published after the stall arrives.
    pub const STALLED: u32 = 1 << 5;
    /// Every flag with its name, in bit order (for tools that print flags).
    pub const NAMES: &[(u32, &str)] = &[
        (SAFE_STATE, "SAFE_STATE"),
        (COMMAND_STALE, "COMMAND_STALE"),
        (SATURATED, "SATURATED"),
        (SLOPE_LIMITED, "SLOPE_LIMITED"),
        (FINAL, "FINAL"),
        (STALLED, "STALLED"),
    ];
}
