//! The planner's motion program: loaded and checked at start (a bad file is a config
//! error), planned once from the arm's measured start state with
//! `microrobot_trajectory::program` (segments hand over keeping q, q̇ and, where the
//! profile allows, q̈ continuous), then stepped per tick without allocating.

use std::path::Path;

use microrobot_model::Robot;
use microrobot_trajectory::model::ModelIk;
use microrobot_trajectory::program::{Program, ProgramRunner as Runner};
use microrobot_trajectory::{KinematicLimits, MotionState, Sample, Status};

/// A loaded program, then (after [`ProgramRunner::plan`]) its running plan.
#[derive(Debug, Clone)]
pub struct ProgramRunner {
    program: Program,
    runner: Option<Runner>,
}

impl ProgramRunner {
    /// Loads and checks a program file for `robot` (the joint count and every unit's
    /// joint type must match).
    pub fn from_file(path: &Path, robot: &Robot) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("{}: cannot read: {e}", path.display()))?;
        let kinds: Vec<_> = robot.joints().iter().map(|j| j.kind).collect();
        let program = Program::from_toml_str_for(&text, &path.display().to_string(), &kinds)
            .map_err(|e| format!("{e} (robot `{}`)", robot.name()))?;
        Ok(Self {
            program,
            runner: None,
        })
    }

    /// The program's name.
    pub fn name(&self) -> &str {
        &self.program.name
    }

    /// The loaded program (segments in SI units).
    pub fn program(&self) -> &Program {
        &self.program
    }

    /// Plans every segment from `start` within `limits` (allocates; done once).
    pub fn plan(
        &mut self,
        robot: &Robot,
        start: &MotionState,
        limits: &KinematicLimits,
    ) -> Result<(), String> {
        let segments = self
            .program
            .plan_all(start, limits, &ModelIk::new(robot))
            .map_err(|e| e.to_string())?;
        self.runner = Runner::new(segments);
        Ok(())
    }

    /// Total duration of the planned program (s), 0 before planning.
    pub fn duration(&self) -> f64 {
        self.runner.as_ref().map_or(0.0, |r| r.duration())
    }

    /// Advances by `dt`, writing the sample into `out`; `None` (and `out` untouched)
    /// when nothing is planned.
    #[inline]
    pub fn update_into(&mut self, dt: f64, out: &mut Sample) -> Option<Status> {
        self.runner.as_mut().map(|r| r.update_into(dt, out))
    }
}
