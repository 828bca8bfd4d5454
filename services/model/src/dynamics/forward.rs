//! Forward dynamics for the simulated arm: `qdd = M(q)⁻¹ (tau − h(q, qd))`, with
//! `M` from CRBA, `h` from RNEA, and an in-place Cholesky factorisation of the
//! `dof × dof` block (no allocation).

use super::crba::mass_matrix_from_joint_values;
use super::rnea::{RneaTerms, rnea_from_joint_values};
use crate::data::ModelData;
use crate::kinematics::update_joint_values;
use crate::robot::Robot;
use crate::{JointVector, MAX_JOINTS};

/// Why forward dynamics has no unique answer.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum DynamicsError {
    /// `M(q)` is not positive definite: some joint moves no mass and has no rotor
    /// inertia (or the inputs are not finite).
    #[error("mass matrix is singular at joint index {joint} (pivot {pivot:e})")]
    SingularMassMatrix {
        /// Zero-based joint index where the factorisation failed.
        joint: usize,
        /// The offending pivot.
        pivot: f64,
    },
}

/// Joint accelerations for applied joint torques `tau` (the inverse of
/// [`crate::rnea`], friction and rotor inertia included). When `M(q)` is singular
/// (see [`DynamicsError`]) every entry is NaN, so a caller that validates its
/// outputs refuses it; use [`try_forward_dynamics`] to get the reason.
pub fn forward_dynamics(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
    tau: &JointVector,
) -> JointVector {
    match try_forward_dynamics(robot, data, q, qd, tau) {
        Ok(qdd) => qdd,
        Err(_) => {
            let mut nan = JointVector::zeros();
            for i in 0..robot.dof {
                nan[i] = f64::NAN;
            }
            nan
        }
    }
}

/// [`forward_dynamics`] that reports a singular mass matrix as an error.
pub fn try_forward_dynamics(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
    tau: &JointVector,
) -> Result<JointVector, DynamicsError> {
    let n = robot.dof;
    update_joint_values(robot, data, q);
    mass_matrix_from_joint_values(robot, data);
    let h = rnea_from_joint_values(
        robot,
        data,
        qd,
        &JointVector::zeros(),
        RneaTerms {
            gravity: true,
            friction: true,
        },
    );
    let mut x = JointVector::zeros();
    for i in 0..n {
        x[i] = tau[i] - h[i];
    }
    // Cholesky M = L Lᵀ on the dof block, lower triangle of data.chol; the
    // reciprocal pivots are kept so the solves multiply instead of divide.
    let m = &data.mass;
    let l = &mut data.chol;
    let mut scale = 0.0_f64;
    for j in 0..n {
        scale = scale.max(m[(j, j)].abs());
    }
    let tiny = scale * 1e-14;
    let mut inv_diag = [0.0; MAX_JOINTS];
    for j in 0..n {
        let mut diag = m[(j, j)];
        for k in 0..j {
            diag -= l[(j, k)] * l[(j, k)];
        }
        if diag.is_nan() || diag <= tiny || tiny == 0.0 {
            return Err(DynamicsError::SingularMassMatrix {
                joint: j,
                pivot: diag,
            });
        }
        let ljj = diag.sqrt();
        l[(j, j)] = ljj;
        let inv = 1.0 / ljj;
        inv_diag[j] = inv;
        for i in (j + 1)..n {
            let mut v = m[(i, j)];
            for k in 0..j {
                v -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = v * inv;
        }
    }
    // L y = x, then Lᵀ qdd = y.
    for i in 0..n {
        let mut v = x[i];
        for k in 0..i {
            v -= l[(i, k)] * x[k];
        }
        x[i] = v * inv_diag[i];
    }
    for i in (0..n).rev() {
        let mut v = x[i];
        for k in (i + 1)..n {
            v -= l[(k, i)] * x[k];
        }
        x[i] = v * inv_diag[i];
    }
    Ok(x)
}
