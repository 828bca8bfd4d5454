//! Forward dynamics for the simulated arm: `qdd = M(q)⁻¹ (tau − h(q, qd))`, with
//! `M` from CRBA, `h` from RNEA, and an in-place `L D Lᵀ` factorisation of the
//! `dof × dof` block (no allocation).

use super::crba::mass_matrix_from_joint_values;
use super::rnea::{RneaTerms, rnea_from_joint_values};
use crate::data::ModelData;
use crate::isa::{Isa, for_shape, multiversion};
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
    /// [`forward_dynamics`] for DH robots.
    #[inline(always)]
    fn forward_dynamics_dh(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
        tau: &JointVector,
    ) -> JointVector => forward_dynamics_with;
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
    if robot.general {
        crate::general::forward_dynamics(robot, data, q, qd, tau)
    } else {
        forward_dynamics_dh(robot, data, q, qd, tau)
    }
}

multiversion! {
    /// [`try_forward_dynamics`] for DH robots.
    #[inline(always)]
    fn try_forward_dynamics_dh(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
        tau: &JointVector,
    ) -> Result<JointVector, DynamicsError> => try_forward_dynamics_with;
}

/// [`forward_dynamics`] that reports a singular mass matrix as an error.
pub fn try_forward_dynamics(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
    tau: &JointVector,
) -> Result<JointVector, DynamicsError> {
    if robot.general {
        crate::general::try_forward_dynamics(robot, data, q, qd, tau)
    } else {
        try_forward_dynamics_dh(robot, data, q, qd, tau)
    }
}

#[inline(always)]
pub(crate) fn try_forward_dynamics_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
    tau: &JointVector,
) -> Result<JointVector, DynamicsError> {
    for_shape!(robot, |n, plain| solve_forward_dynamics::<S>(
        robot, data, q, qd, tau, n, plain
    ))
}

/// [`try_forward_dynamics`] for the `n = dof` joints (`plain`: `robot.plain`).
#[inline(always)]
fn solve_forward_dynamics<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
    tau: &JointVector,
    n: usize,
    plain: bool,
) -> Result<JointVector, DynamicsError> {
    // n <= MAX_JOINTS lets the compiler drop the bounds checks below.
    let n = n.min(MAX_JOINTS);
    update_joint_values::<S>(robot, data, q, n, plain);
    mass_matrix_from_joint_values(robot, data, n, plain);
    // Factor before the RNEA: the pivots' divisions are a long dependency chain
    // that the CPU can overlap with the independent RNEA work that follows.
    // M is symmetric, so its column-major storage reads as rows too.
    let mut a: Square = data.mass.data.0;
    let inv_pivot = factor_ldlt(n, &mut a)?;
    let h = rnea_from_joint_values(
        robot,
        data,
        qd,
        &JointVector::zeros(),
        RneaTerms {
            gravity: true,
            friction: true,
        },
        n,
        plain,
    );
    let mut x = [0.0; MAX_JOINTS];
    for i in 0..n {
        x[i] = tau[i] - h[i];
    }
    // L y = x, D z = y, Lᵀ qdd = z.
    for i in 0..n {
        let mut v = x[i];
        for k in 0..i {
            v -= a[i][k] * x[k];
        }
        x[i] = v;
    }
    for i in (0..n).rev() {
        let mut v = x[i] * inv_pivot[i];
        for k in (i + 1)..n {
            v -= a[k][i] * x[k];
        }
        x[i] = v;
    }
    let mut qdd = JointVector::zeros();
    for i in 0..n {
        qdd[i] = x[i];
    }
    Ok(qdd)
}

/// An `n × n` block in the top left, `n <= MAX_JOINTS`, row by row.
pub(crate) type Square = [[f64; MAX_JOINTS]; MAX_JOINTS];

/// `M = L D Lᵀ` in place (`L` unit lower triangular) of the symmetric block
/// `a`: `L` below the diagonal, `D` on it, `L D` (transposed) above it; returns
/// `1 / D`. Unlike Cholesky it takes no square roots, which would lengthen the
/// chain of dependent operations from pivot to pivot. A pivot that is NaN or
/// not above `1e-14 ×` the largest diagonal entry means `M` is not
/// (numerically) positive definite.
#[inline(always)]
#[allow(clippy::needless_range_loop)] // index loops read like the matrix formulas
pub(crate) fn factor_ldlt(n: usize, a: &mut Square) -> Result<[f64; MAX_JOINTS], DynamicsError> {
    let n = n.min(MAX_JOINTS);
    let mut scale = 0.0_f64;
    for j in 0..n {
        scale = scale.max(a[j][j].abs());
    }
    let tiny = scale * 1e-14;
    let mut inv_pivot = [0.0; MAX_JOINTS];
    for j in 0..n {
        // a[k][j] = L_jk D_k for k < j (stored when column k was done).
        let mut pivot = a[j][j];
        for k in 0..j {
            pivot -= a[j][k] * a[k][j];
        }
        if pivot.is_nan() || pivot <= tiny || tiny == 0.0 {
            return Err(DynamicsError::SingularMassMatrix { joint: j, pivot });
        }
        a[j][j] = pivot;
        let inv = 1.0 / pivot;
        inv_pivot[j] = inv;
        for i in (j + 1)..n {
            let mut v = a[i][j];
            for k in 0..j {
                v -= a[i][k] * a[k][j];
            }
            a[j][i] = v;
            a[i][j] = v * inv;
        }
    }
    Ok(inv_pivot)
}

/// Solves `L D Lᵀ y = x` in place with the factors of [`factor_ldlt`]:
/// `L y = x`, `D z = y`, `Lᵀ qdd = z` (the placed-joint path's copy of the
/// solve in `solve_forward_dynamics`).
#[inline(always)]
pub(crate) fn solve_ldlt(
    n: usize,
    a: &Square,
    inv_pivot: &[f64; MAX_JOINTS],
    x: &mut [f64; MAX_JOINTS],
) {
    let n = n.min(MAX_JOINTS);
    for i in 0..n {
        let mut v = x[i];
        for k in 0..i {
            v -= a[i][k] * x[k];
        }
        x[i] = v;
    }
    for i in (0..n).rev() {
        let mut v = x[i] * inv_pivot[i];
        for k in (i + 1)..n {
            v -= a[k][i] * x[k];
        }
        x[i] = v;
    }
}
