//! Teleoperation for the microrobot arm: a surgeon's hand motion (a master device's
//! pose) turned into a jerk-limited joint setpoint stream, with the three things that
//! make Zeus / da Vinci style systems usable — tremor filtering, motion scaling and
//! clutching — and the safety a surgical arm needs: Cartesian velocity/acceleration
//! limits on the tool, IK that never flips configuration, slowing near singularities,
//! stopping at the workspace edge, refusing non-finite input, and joint motion that
//! stays within every joint limit and never jumps.
//!
//! Domain only: no I/O, no IPC; [`TeleopController::step`] allocates nothing. The
//! planner's teleop mode (services/planner) feeds it the bus's `MasterPose`.

#![warn(missing_docs)]

mod cartesian_limiter;
mod controller;
mod joint_tracker;
mod scaling;
pub mod tremor_filter;

pub use cartesian_limiter::CartesianLimiter;
pub use controller::{Hand, TeleopController, TeleopError, TeleopSettings, TeleopStep};
pub use joint_tracker::JointTracker;
pub use scaling::MotionScaling;
pub use tremor_filter::{Response, TremorFilter};

/// Bits of [`TeleopStep::flags`] (the planner maps them onto the setpoint's flags).
pub mod flags {
    /// The clutch is released: the tool is brought to rest and held.
    pub const CLUTCH_OPEN: u32 = 1 << 0;
    /// No fresh master sample: the tool is brought to rest and held.
    pub const MASTER_STALE: u32 = 1 << 1;
    /// The target is beyond the reachable workspace (or a joint limit): stopped at the edge.
    pub const WORKSPACE_EDGE: u32 = 1 << 2;
    /// Near a singularity: the tool's speed limit is reduced.
    pub const SINGULARITY: u32 = 1 << 3;
    /// An IK solution that would flip the configuration was refused.
    pub const FLIP_REFUSED: u32 = 1 << 4;
    /// A hand sample was refused (not finite).
    pub const INPUT_REFUSED: u32 = 1 << 5;
    /// The tool's velocity or acceleration limit is active.
    pub const LIMITED: u32 = 1 << 6;
}
