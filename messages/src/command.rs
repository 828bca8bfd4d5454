//! Motion commands sent to the planner at run time (`microrobot send`, a master console,
//! a test). Encoded as fixed-width integers so any language can write them.

use iceoryx2::prelude::ZeroCopySend;

use crate::MAX_JOINTS;

/// What a [`MotionCommand`] asks for (`MotionCommand::kind`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum CommandKind {
    /// Move to `target` with `profile`, replanning from the current setpoint state.
    Move = 1,
    /// Stop smoothly: the shortest jerk-limited stop, then hold.
    Stop = 2,
    /// Emergency stop: brake at once and refuse motion until `Reset`.
    EStop = 3,
    /// Leave e-stop / safe state; motion resumes bumplessly from the measured state.
    Reset = 4,
    /// Enter teleop mode (the arm must be at rest): the master device drives the arm
    /// until a Stop or EStop.
    Teleop = 5,
}

impl CommandKind {
    /// Decodes the wire value, `None` for an unknown kind.
    pub fn from_wire(v: u32) -> Option<Self> {
        match v {
            1 => Some(Self::Move),
            2 => Some(Self::Stop),
            3 => Some(Self::EStop),
            4 => Some(Self::Reset),
            5 => Some(Self::Teleop),
            _ => None,
        }
    }
}

/// Trajectory profile of a move (`MotionCommand::profile`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum ProfileKind {
    /// Time-optimal jerk-limited ("soft motion"); `duration_s` > 0 stretches it.
    Soft = 1,
    /// Cubic polynomial over `duration_s`.
    Cubic = 2,
    /// Quintic polynomial over `duration_s`.
    Quintic = 3,
    /// Linear segments with parabolic blends over `duration_s`.
    Lspb = 4,
}

impl ProfileKind {
    /// Decodes the wire value, `None` for an unknown profile.
    pub fn from_wire(v: u32) -> Option<Self> {
        match v {
            1 => Some(Self::Soft),
            2 => Some(Self::Cubic),
            3 => Some(Self::Quintic),
            4 => Some(Self::Lspb),
            _ => None,
        }
    }
}

/// How `MotionCommand::target` is to be read (`MotionCommand::space`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum TargetSpace {
    /// `target[..dof]` are joint positions (rad or m).
    Joint = 1,
    /// `target[0..7]` is a tool pose: x, y, z (m), then a unit quaternion w, x, y, z.
    Cartesian = 2,
}

impl TargetSpace {
    /// Decodes the wire value, `None` for an unknown space.
    pub fn from_wire(v: u32) -> Option<Self> {
        match v {
            1 => Some(Self::Joint),
            2 => Some(Self::Cartesian),
            _ => None,
        }
    }
}

/// A run-time command to the planner. Every field is validated by the planner; a refused
/// command is counted and reported in its status and never moves the arm.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("microrobot::v2::MotionCommand")]
pub struct MotionCommand {
    /// Sender's sequence number (echoed in the planner's status as the last command seen).
    pub seq: u64,
    /// `CLOCK_MONOTONIC` ns when the command was sent.
    pub stamp_ns: u64,
    /// A [`CommandKind`] value.
    pub kind: u32,
    /// A [`ProfileKind`] value (moves only).
    pub profile: u32,
    /// A [`TargetSpace`] value (moves only).
    pub space: u32,
    /// Number of joint values in `target` for a joint-space move; must equal the robot's.
    pub dof: u32,
    /// Joint target, or a pose (see [`TargetSpace`]).
    pub target: [f64; MAX_JOINTS],
    /// Duration in s for cubic, quintic, LSPB; for soft motion 0 = time-optimal.
    pub duration_s: f64,
    /// Scale (0, 1] applied to the robot's velocity, acceleration and jerk limits.
    pub limit_scale: f64,
}
