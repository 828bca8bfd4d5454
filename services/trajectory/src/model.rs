//! Adapters to the robot model (`microrobot-model`): joint limits from a robot
//! description, and its inverse kinematics as the programs' [`CartesianSolver`].

use microrobot_model::ik::{self, IkOptions, IkTarget};
use microrobot_model::{ModelData, Pose, Robot};
use nalgebra::Vector3;

use crate::program::{CartesianPose, CartesianSolver};
use crate::{JointVector, KinematicLimits};

impl KinematicLimits {
    /// The position, velocity, acceleration and jerk limits of `robot`'s joints.
    pub fn from_robot(robot: &Robot) -> KinematicLimits {
        let mut l = KinematicLimits::uniform(1.0, 1.0, 1.0, 0.0, 0.0);
        for (i, j) in robot.joints().iter().enumerate() {
            l.velocity[i] = j.limits.velocity;
            l.acceleration[i] = j.limits.acceleration;
            l.jerk[i] = j.limits.jerk;
            l.position_min[i] = j.limits.min;
            l.position_max[i] = j.limits.max;
        }
        l
    }
}

/// The model's damped-least-squares IK, accepting only converged solutions.
#[derive(Debug, Clone, Copy)]
pub struct ModelIk<'a> {
    robot: &'a Robot,
    options: IkOptions,
}

impl<'a> ModelIk<'a> {
    /// IK for `robot` with the model's default options.
    pub fn new(robot: &'a Robot) -> Self {
        Self {
            robot,
            options: IkOptions::default(),
        }
    }

    /// IK with explicit solver options.
    pub fn with_options(robot: &'a Robot, options: IkOptions) -> Self {
        Self { robot, options }
    }
}

impl CartesianSolver for ModelIk<'_> {
    fn solve(&self, pose: &CartesianPose, seed: &JointVector) -> Result<JointVector, String> {
        let [x, y, z] = pose.xyz_m;
        let [r, p, w] = pose.rpy_rad;
        let target = Pose::from_xyz_rpy(Vector3::new(x, y, z), Vector3::new(r, p, w));
        let mut data = ModelData::new(self.robot);
        let sol = ik::solve(
            self.robot,
            &mut data,
            &IkTarget::Pose(target.to_isometry()),
            seed,
            &self.options,
        )
        .map_err(|e| e.to_string())?;
        if sol.converged {
            Ok(sol.q)
        } else {
            Err(format!(
                "IK did not converge (position error {:.3e} m, orientation error {:.3e} rad)",
                sol.position_error_m, sol.orientation_error_rad
            ))
        }
    }
}
