//! Forward dynamics for the simulated arm: `qdd = M(q)⁻¹ (tau − h(q, qd))`, with
//! `M` from CRBA, `h` from RNEA, and an in-place `L D Lᵀ` factorisation of the
//! `dof × dof` block (no allocation).

use super::crba::mass_matrix_from_joint_values;
use super::rnea::{RneaTerms, rnea_from_joint_values};
use crate::data::ModelData;
use crate::isa::{Isa, multiversion};
use crate::kinematics::update_joint_values;
use crate::robot::Robot;
use crate::{JointVector, MAX_JOINTS, MassMatrix};

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

#[inline(always)]
pub(crate) fn forward_dynamics_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
    tau: &JointVector,
) -> JointVector {
    match try_forward_dynamics_with::<S>(robot, data, q, qd, tau) {
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

multiversion! {
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
    ) -> JointVector => forward_dynamics_with;
}

multiversion! {
    /// [`forward_dynamics`] that reports a singular mass matrix as an error.
    pub fn try_forward_dynamics(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
        tau: &JointVector,
    ) -> Result<JointVector, DynamicsError> => try_forward_dynamics_with;
}

#[inline(always)]
pub(crate) fn try_forward_dynamics_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
    tau: &JointVector,
) -> Result<JointVector, DynamicsError> {
    let n = robot.dof;
    update_joint_values::<S>(robot, data, q);
    mass_matrix_from_joint_values(robot, data);
    // Factor before the RNEA: the pivots' divisions are a long dependency chain
    // that the CPU can overlap with the independent RNEA work that follows.
    let inv_pivot = factor_ldlt(n, &data.mass, &mut data.chol)?;
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
    // L y = x, D z = y, Lᵀ qdd = z.
    let l = &data.chol;
    for i in 0..n {
        let mut v = x[i];
        for k in 0..i {
            v -= l[(i, k)] * x[k];
        }
        x[i] = v;
    }
    for i in (0..n).rev() {
        let mut v = x[i] * inv_pivot[i];
        for k in (i + 1)..n {
            v -= l[(k, i)] * x[k];
        }
        x[i] = v;
    }
    Ok(x)
}

/// `M = L D Lᵀ` on the `n × n` block (`L` unit lower triangular): `L` below the
/// diagonal of `out`, `D` on it, `L D` (transposed) above it. Returns `1 / D`.
/// Unlike Cholesky it takes no square roots, which would lengthen the chain of
/// dependent operations from pivot to pivot. A pivot that is NaN or not above
/// `1e-14 ×` the largest diagonal entry means `M` is not (numerically) positive
/// definite.
#[inline(always)]
fn factor_ldlt(
    n: usize,
    m: &MassMatrix,
    out: &mut MassMatrix,
) -> Result<[f64; MAX_JOINTS], DynamicsError> {
    let mut scale = 0.0_f64;
    for j in 0..n {
        scale = scale.max(m[(j, j)].abs());
    }
    let tiny = scale * 1e-14;
    let mut inv_pivot = [0.0; MAX_JOINTS];
    for j in 0..n {
        // out[(k, j)] = L_jk D_k for k < j (stored when column k was done).
        let mut pivot = m[(j, j)];
        for k in 0..j {
            pivot -= out[(j, k)] * out[(k, j)];
        }
        if pivot.is_nan() || pivot <= tiny || tiny == 0.0 {
            return Err(DynamicsError::SingularMassMatrix { joint: j, pivot });
        }
        out[(j, j)] = pivot;
        let inv = 1.0 / pivot;
        inv_pivot[j] = inv;
        for i in (j + 1)..n {
            let mut v = m[(i, j)];
            for k in 0..j {
                v -= out[(i, k)] * out[(k, j)];
            }
            out[(j, i)] = v;
            out[(i, j)] = v * inv;
        }
    }
    Ok(inv_pivot)
}
