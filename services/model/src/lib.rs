//! Serial-arm model for the microrobot motion stack: robot files, kinematics,
//! inverse kinematics, workspace and rigid-body dynamics. Pure computation: no I/O
//! beyond [`Robot::from_file`] (DH files, URDF files and their overlays), no IPC,
//! no allocation on the hot path.
//!
//! The design follows Pinocchio's model/data split: a [`Robot`] is immutable and
//! shared; a [`ModelData`] is preallocated scratch owned by one caller, and every
//! algorithm takes `(&Robot, &mut ModelData, ...)`.
//!
//! Conventions (docs/seed-arm.md): standard Denavit-Hartenberg frames
//! `T = Rz(theta) Tz(d) Tx(a) Rx(alpha)` (seed eq. 1), joint variable added to
//! `theta` (revolute) or `d` (prismatic); SI units everywhere inside; vectors are
//! [`JointVector`]s of length [`MAX_JOINTS`] whose entries at and beyond
//! [`Robot::dof`] are zero on output and ignored on input.
//!
//! Robots from URDF ([`Robot::from_file`] on a `.urdf` or an overlay) have
//! placed joints instead ([`JointPlacement`]: a constant rotation and
//! translation from the parent frame, then a motion about or along a unit
//! axis); every algorithm takes them, through a general path beside the DH one.
//!
//! ```
//! use microrobot_model::{Robot, ModelData, JointVector, rnea, forward_kinematics};
//! let text = r#"
//! [robot]
//! name = "pendulum"
//! gravity_mps2 = [0.0, -9.81, 0.0]
//! [[joints]]
//! name = "j1"
//! kind = "revolute"
//! dh = { theta_deg = 0.0, d_mm = 0.0, a_mm = 500.0, alpha_deg = 0.0 }
//! limits = { min_deg = -180.0, max_deg = 180.0, vel_deg_s = 90.0, acc_deg_s2 = 90.0, jerk_deg_s3 = 900.0, torque_nm = 20.0 }
//! link = { mass_kg = 1.0, com_mm = [0.0, 0.0, 0.0], inertia_kgmm2 = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]] }
//! "#;
//! let robot = Robot::from_toml_str(text, "pendulum.toml").unwrap();
//! let mut data = ModelData::new(&robot);
//! let q = JointVector::zeros();
//! let pose = forward_kinematics(&robot, &mut data, &q);
//! assert!((pose.translation.vector.x - 0.5).abs() < 1e-12);
//! // a point mass at 0.5 m held horizontal against gravity: 1 kg * 9.81 * 0.5 m
//! let tau = rnea(&robot, &mut data, &q, &q, &q);
//! assert!((tau[0] - 4.905).abs() < 1e-12);
//! ```

#![warn(missing_docs)]

mod data;
pub mod dynamics;
mod general;
pub mod ik;
mod isa;
pub mod kinematics;
pub mod lagrange_euler;
mod math;
mod robot;
mod robot_file;
pub mod workspace;

pub use data::ModelData;
pub use dynamics::{
    DynamicsError, coriolis_torque, forward_dynamics, gravity_torque, mass_matrix,
    nonlinear_effects, rnea, try_forward_dynamics,
};
pub use kinematics::{
    Dexterity, TaskRows, condition_number, dexterity, forward_kinematics, jacobian, manipulability,
    rank, smallest_singular_value, tool_pose,
};
pub use math::Pose;
pub use robot::{
    DhParameters, Joint, JointKind, JointLimits, JointPlacement, LinkFrame, LinkInertia, Robot,
    RobotError,
};
pub use robot_file::RobotFileError;
pub use robot_file::urdf_writer::{overlay_toml, to_urdf};

/// Largest number of joints a [`Robot`] may have; fixes the size of every
/// statically sized vector and matrix below.
pub const MAX_JOINTS: usize = 8;

/// Joint-space vector (positions, velocities, accelerations or torques), SI.
/// Entries at index `>= dof` are zero on output and ignored on input.
pub type JointVector = nalgebra::SVector<f64, MAX_JOINTS>;

/// Geometric Jacobian of the tool frame origin in the base frame: rows
/// `vx vy vz wx wy wz`, one column per joint, columns `>= dof` zero.
pub type Jacobian = nalgebra::SMatrix<f64, 6, MAX_JOINTS>;

/// Joint-space mass (inertia) matrix, symmetric, zero outside the `dof` block.
pub type MassMatrix = nalgebra::SMatrix<f64, MAX_JOINTS, MAX_JOINTS>;

/// Helpers shared by the unit tests.
#[cfg(test)]
pub(crate) mod test_support {
    /// Uniform numbers in [0, 1) from a xorshift64 generator seeded with `seed`
    /// (repeatable, no dependency).
    pub(crate) fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64
        }
    }
}
