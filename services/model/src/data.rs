//! [`ModelData`]: preallocated scratch space for the algorithms (Pinocchio's
//! "Data"), so that no call on the hot path allocates.

use crate::math::Pose;
use crate::robot::Robot;
use crate::{MAX_JOINTS, MassMatrix};
use nalgebra::Vector3;

/// Scratch space and last results of the algorithms for one caller. Create it
/// once with [`ModelData::new`] and pass it to every call; its size is fixed, so
/// it can serve any robot of up to [`MAX_JOINTS`] joints.
#[derive(Clone, Debug)]
pub struct ModelData {
    /// Each joint's DH theta (with `q` for revolute joints) that `cos` and `sin`
    /// belong to (0 beyond `dof`): a call with the same angles as the last one
    /// (kinematics, then dynamics at the same `q`) reuses them.
    pub(crate) theta: [f64; MAX_JOINTS],
    /// The joint count `theta` was evaluated for (0: nothing cached yet).
    pub(crate) theta_dof: usize,
    /// `cos` of each joint's DH theta.
    pub(crate) cos: [f64; MAX_JOINTS],
    /// `sin` of each joint's DH theta.
    pub(crate) sin: [f64; MAX_JOINTS],
    /// Each joint's DH d (with `q` for prismatic joints).
    pub(crate) d: [f64; MAX_JOINTS],
    /// Frame poses in the base frame: `frames[0]` is the base, `frames[i]` frame `i`
    /// (DH frame `i`, or joint `i`'s child frame for placed joints).
    pub(crate) frames: [Pose; MAX_JOINTS + 1],
    /// Tool frame in the base frame.
    pub(crate) tool: Pose,
    /// RNEA: body forces and moments (frame `i`, about its origin).
    pub(crate) force: [Vector3<f64>; MAX_JOINTS],
    pub(crate) moment: [Vector3<f64>; MAX_JOINTS],
    /// Last mass matrix.
    pub(crate) mass: MassMatrix,
    /// Placed joints: each joint's transform from frame `i-1` to frame `i`
    /// (placement, then the motion for `q`).
    pub(crate) local: [Pose; MAX_JOINTS],
}

impl ModelData {
    /// Scratch for `robot` (any robot of up to [`MAX_JOINTS`] joints fits).
    pub fn new(_robot: &Robot) -> ModelData {
        ModelData {
            theta: [0.0; MAX_JOINTS],
            theta_dof: 0,
            cos: [1.0; MAX_JOINTS],
            sin: [0.0; MAX_JOINTS],
            d: [0.0; MAX_JOINTS],
            frames: [Pose::IDENTITY; MAX_JOINTS + 1],
            local: [Pose::IDENTITY; MAX_JOINTS],
            tool: Pose::IDENTITY,
            force: [Vector3::zeros(); MAX_JOINTS],
            moment: [Vector3::zeros(); MAX_JOINTS],
            mass: MassMatrix::zeros(),
        }
    }

    /// Pose of frame `i` (DH frame `i`, or placed joint `i`'s child link frame)
    /// in the base frame after the last kinematics call
    /// ([`crate::forward_kinematics`], [`crate::jacobian`], [`crate::tool_pose`]):
    /// `frame(0)` is the base, `frame(dof)` the last joint frame. Indices beyond
    /// [`MAX_JOINTS`] give the identity.
    pub fn frame(&self, i: usize) -> Pose {
        self.frames.get(i).copied().unwrap_or(Pose::IDENTITY)
    }

    /// Tool frame in the base frame after the last kinematics call.
    pub fn tool_frame(&self) -> Pose {
        self.tool
    }

    /// Mass matrix of the last [`crate::mass_matrix`] or
    /// [`crate::forward_dynamics`] call.
    pub fn last_mass_matrix(&self) -> &MassMatrix {
        &self.mass
    }
}
