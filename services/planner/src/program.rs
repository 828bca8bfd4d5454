//! The planner's view of a motion program: a sequence of segments, each planned from
//! the current setpoint state when the previous one has finished (so q, q̇, q̈ stay
//! continuous). Wraps `microrobot_trajectory::program`.

use std::path::Path;

use microrobot_model::Robot;
use microrobot_trajectory::{JointState, KinematicLimits, Trajectory, TrajectoryError};

/// Steps through a loaded program, one segment at a time.
#[derive(Debug, Clone)]
pub struct ProgramRunner {
    name: String,
}

impl ProgramRunner {
    /// Loads and validates a program file for `robot`.
    pub fn from_file(path: &Path, _robot: &Robot) -> Result<Self, String> {
        Err(format!(
            "{}: motion programs are not supported by this build of microrobot-trajectory yet",
            path.display()
        ))
    }

    /// Name of the program (file name).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Plans the next segment from `start`, `None` when the program is finished.
    pub fn next_segment(
        &mut self,
        _dof: usize,
        _start: &JointState,
        _limits: &KinematicLimits,
    ) -> Option<Result<Trajectory, TrajectoryError>> {
        None
    }
}
