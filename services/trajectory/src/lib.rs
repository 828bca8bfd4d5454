//! Joint trajectory generation for the microrobot arm (seed chapter, section 3).
//!
//! Four profiles — cubic, quintic, linear segments with parabolic blends (LSPB) and
//! time-optimal jerk-limited "soft motion" — planned for up to [`MAX_JOINTS`] joints
//! that finish together, then sampled allocation-free per control cycle.
//!
//! * [`Trajectory::plan`] does all planning at construction; [`Trajectory::sample`]
//!   evaluates position, velocity, acceleration and jerk of every joint at any time.
//! * [`stop_trajectory`] is the shortest jerk-limited stop from any state.
//! * [`Generator`] is the per-cycle wrapper (Ruckig's `update()` shape).
//! * [`program`] loads TOML motion programs with via points and plans them segment by
//!   segment, keeping q, qd (and qdd where the profile allows) continuous.
//!
//! Units are SI (rad, s) throughout. No I/O, no allocation after planning.

// Joint loops index several per-joint vectors in step; an index reads clearest.
#![allow(clippy::needless_range_loop)]

mod error;
pub mod generator;
pub mod lspb;
pub mod model;
mod peaks;
mod piecewise;
pub mod polynomial;
pub mod program;
pub mod soft;
mod stop;
mod sync;
mod trajectory;
mod validate;

pub use error::TrajectoryError;
pub use generator::{Generator, Status};
pub use stop::stop_trajectory;
pub use trajectory::{Peaks, Trajectory, minimum_duration};

/// Largest number of joints a trajectory carries (the robot model's capacity), and
/// one value per joint (only the first `dof` entries are meaningful).
pub use microrobot_model::{JointVector, MAX_JOINTS};

/// Kinematic state of all joints (capacity 8, `dof` active).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotionState {
    /// Position (rad).
    pub q: JointVector,
    /// Velocity (rad/s).
    pub qd: JointVector,
    /// Acceleration (rad/s²).
    pub qdd: JointVector,
}

impl MotionState {
    /// A state at rest at position `q`.
    pub fn at_rest(q: JointVector) -> Self {
        Self {
            q,
            ..Self::default()
        }
    }
}

/// One sample of a trajectory: position, velocity, acceleration and jerk per joint.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample {
    /// Position (rad).
    pub q: JointVector,
    /// Velocity (rad/s).
    pub qd: JointVector,
    /// Acceleration (rad/s²).
    pub qdd: JointVector,
    /// Jerk (rad/s³).
    pub jerk: JointVector,
}

impl Sample {
    /// The kinematic state (q, qd, qdd) of this sample, e.g. to replan from it.
    pub fn state(&self) -> MotionState {
        MotionState {
            q: self.q,
            qd: self.qd,
            qdd: self.qdd,
        }
    }
}

/// Symmetric per-joint limits: |qd| ≤ velocity, |qdd| ≤ acceleration,
/// |jerk| ≤ jerk, position_min ≤ q ≤ position_max. All must be finite; the first
/// three strictly positive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KinematicLimits {
    /// Maximum |velocity| (rad/s).
    pub velocity: JointVector,
    /// Maximum |acceleration| (rad/s²).
    pub acceleration: JointVector,
    /// Maximum |jerk| (rad/s³).
    pub jerk: JointVector,
    /// Lowest allowed position (rad).
    pub position_min: JointVector,
    /// Highest allowed position (rad).
    pub position_max: JointVector,
}

impl KinematicLimits {
    /// The same limits on every joint.
    pub fn uniform(velocity: f64, acceleration: f64, jerk: f64, min: f64, max: f64) -> Self {
        Self {
            velocity: JointVector::repeat(velocity),
            acceleration: JointVector::repeat(acceleration),
            jerk: JointVector::repeat(jerk),
            position_min: JointVector::repeat(min),
            position_max: JointVector::repeat(max),
        }
    }
}

/// Which motion law a request uses.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Profile {
    /// Third-order polynomial through start/target positions and velocities over
    /// `duration` (seed eq. 21–22). Acceleration may jump at the ends; jerk is constant.
    Cubic {
        /// Duration (s), > 0. Use [`minimum_duration`] for the shortest one within limits.
        duration: f64,
    },
    /// Fifth-order polynomial through start/target positions, velocities and
    /// accelerations over `duration` (seed eq. 23–24 with the errata of docs/seed-arm.md).
    Quintic {
        /// Duration (s), > 0.
        duration: f64,
    },
    /// Linear segment with parabolic blends, rest to rest (seed section 3.2.3).
    Lspb {
        /// Duration (s), > 0.
        duration: f64,
        /// Cruise velocity per joint; default 1.5·(q1 − q0)/T. Must satisfy
        /// |q1 − q0|/T < |V| ≤ 2|q1 − q0|/T with the sign of q1 − q0.
        cruise_velocity: Option<JointVector>,
    },
    /// Time-optimal jerk-limited motion (seed section 3.2.4) from any start state to
    /// the target at rest; stretched to `min_duration` when that is longer.
    Soft {
        /// Requested duration (s); the motion takes max(minimum, min_duration).
        min_duration: Option<f64>,
    },
}

/// A complete planning problem for `dof` joints.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotionRequest {
    /// Number of active joints, 1..=8.
    pub dof: usize,
    /// Start state (soft motion may start moving; LSPB starts at rest).
    pub start: MotionState,
    /// Target state: qd/qdd are used by cubic (qd) and quintic (qd, qdd); LSPB and
    /// soft motion end at rest.
    pub target: MotionState,
    /// Motion law.
    pub profile: Profile,
    /// Joint limits (soft motion honours them; fixed-duration profiles report against them).
    pub limits: KinematicLimits,
}
