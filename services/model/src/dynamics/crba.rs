//! Composite-rigid-body algorithm for the joint-space mass matrix, in base-frame
//! spatial coordinates (moments about the base origin): with `I_c(j)` the
//! composite inertia of bodies `j..n` and `S_j` joint `j`'s motion axis,
//! `M_ij = S_iᵀ I_c(max(i, j)) S_j`, plus rotor inertia on the diagonal.

use crate::data::ModelData;
use crate::kinematics::{update_frames, update_joint_values};
use crate::robot::Robot;
use crate::{JointVector, MassMatrix};

use nalgebra::{Matrix3, Vector3};

/// Joint-space mass matrix `M(q)` (the seed's `D_ij`, eq. 20) with rotor inertia
/// on the diagonal; symmetric, zero outside the `dof` block. Allocation-free;
/// leaves the frames in `data`.
pub fn mass_matrix(robot: &Robot, data: &mut ModelData, q: &JointVector) -> MassMatrix {
    update_joint_values(robot, data, q);
    update_frames(robot, data);
    mass_matrix_from_frames(robot, data);
    data.mass
}

/// CRBA on the frames already in `data`; result in `data.mass`.
#[inline]
pub(crate) fn mass_matrix_from_frames(robot: &Robot, data: &mut ModelData) {
    let n = robot.dof;
    let mass = &mut data.mass;
    mass.fill(0.0);
    let mut m_c = 0.0;
    let mut h_c = Vector3::zeros();
    let mut i_c = Matrix3::zeros();
    for i in (0..n).rev() {
        // Body i in frame i+1 → base frame, about the base origin.
        let b = &robot.bodies[i];
        let frame = &data.frames[i + 1];
        let r = &frame.rotation;
        let c = frame.translation + r * b.com;
        let rot_inertia = r * b.inertia_com * r.transpose();
        let c2 = c.norm_squared();
        let mcc = c * (c.transpose() * b.mass);
        m_c += b.mass;
        h_c += c * b.mass;
        i_c += rot_inertia - mcc;
        i_c[(0, 0)] += b.mass * c2;
        i_c[(1, 1)] += b.mass * c2;
        i_c[(2, 2)] += b.mass * c2;
        // Joint i moves about/along z_{i} of frame i (the seed's z_{i-1}).
        let axis = &data.frames[i];
        let z: Vector3<f64> = axis.rotation.column(2).into_owned();
        let revolute = robot.consts[i].revolute;
        // S = (omega, v at base origin); F = I_c S = (moment about base origin, force).
        let (moment, force) = if revolute {
            let v = axis.translation.cross(&z);
            (i_c * z + h_c.cross(&v), v * m_c + z.cross(&h_c))
        } else {
            (h_c.cross(&z), z * m_c)
        };
        let moments = &mut data.crba_moment;
        let forces = &mut data.crba_force;
        moments[i] = moment;
        forces[i] = force;
        // M_ij = S_i · F_j for j >= i (motion · force = omega·moment + v·force).
        let (omega, v) = if revolute {
            (z, axis.translation.cross(&z))
        } else {
            (Vector3::zeros(), z)
        };
        for j in i..n {
            let mij = omega.dot(&moments[j]) + v.dot(&forces[j]);
            mass[(i, j)] = mij;
            mass[(j, i)] = mij;
        }
        mass[(i, i)] += robot.consts[i].rotor;
    }
}
