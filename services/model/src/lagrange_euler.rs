//! The seed's Lagrange-Euler formulation (eqs. 18–20) as corrected in docs/seed-arm.md,
//! written literally with 4×4 homogeneous matrices: the independent reference
//! that the tests hold the Newton-Euler fast path against. Slow by design:
//! every `U_pj` and `U_pjk` is a product of 4×4 matrices and every `D` a trace
//! (O(n³) products, O(n⁴) traces; the sums are taken with `p` outermost so each
//! matrix is formed once); not for the control loop.
//!
//! * `U_ij = ∂⁰T_i/∂q_j = ⁰T_{j−1} Q_j ʲ⁻¹T_i` for `j ≤ i`, else 0;
//! * `U_ijk = ∂U_ij/∂q_k`, `Q` inserted at both joints, in chain order;
//! * `D_ij = Σ_{p ≥ max(i,j)} Tr(U_pj J_p U_piᵀ)`,
//!   `D_ijk = Σ_{p ≥ max(i,j,k)} Tr(U_pjk J_p U_piᵀ)`,
//!   `D_i = Σ_{p ≥ i} −m_p gᵀ U_pi r̄_p`;
//! * `τ_i = Σ_j D_ij q̈_j + I_act,i q̈_i + Σ_j Σ_k D_ijk q̇_j q̇_k + D_i` (+ friction);
//! * `J_p = [[½tr(I_O)𝟙 − I_O, m c], [m cᵀ, m]]`, the pseudo-inertia about frame
//!   `p`'s origin (`I_O` by the parallel-axis theorem from the inertia about the
//!   centre of mass).
//!
//! Indices in the code are zero-based: joint `j` (0..n) moves frame `j+1`, and
//! body `p` (0..n) is attached to frame `p+1`.

use crate::math::Pose;
use crate::robot::{Robot, friction};
use crate::{JointVector, MAX_JOINTS, MassMatrix};
use nalgebra::{Matrix3, Matrix4, Vector4};

type Mat4 = Matrix4<f64>;

/// Homogeneous matrices of one configuration.
struct Chain {
    n: usize,
    /// `Q_j` (revolute: ∂Rz; prismatic: ∂Tz), seed eq. 18.
    q_mat: [Mat4; MAX_JOINTS],
    /// `span[a][b] = ᵃT_b` for `a <= b` (frames 0..=n).
    span: [[Mat4; MAX_JOINTS + 1]; MAX_JOINTS + 1],
    /// Pseudo-inertia `J_p` of body `p` about frame `p+1`'s origin.
    pseudo: [Mat4; MAX_JOINTS],
    /// `u_mat[p][j] = U_pj` (zero for `j > p`).
    u_mat: [[Mat4; MAX_JOINTS]; MAX_JOINTS],
}

/// `ʲ⁻¹T_j` for joint `j` (zero-based) at position `q`: seed eq. 1, or for a
/// placed joint the placement times the motion (`X · M(q)`).
fn joint_matrix(robot: &Robot, j: usize, q: f64) -> Mat4 {
    let joint = &robot.joints()[j];
    if let Some(p) = &joint.placement {
        let axis = p.axis.normalize();
        let motion = if joint.kind == crate::JointKind::Revolute {
            nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_unchecked(axis), q)
                .to_homogeneous()
        } else {
            nalgebra::Translation3::from(axis * q).to_homogeneous()
        };
        return p.origin.to_homogeneous() * motion;
    }
    let revolute = robot.consts[j].revolute;
    let theta = joint.dh.theta + if revolute { q } else { 0.0 };
    let d = joint.dh.d + if revolute { 0.0 } else { q };
    let (st, ct) = theta.sin_cos();
    let (sa, ca) = joint.dh.alpha.sin_cos();
    let a = joint.dh.a;
    Mat4::new(
        ct,
        -st * ca,
        st * sa,
        a * ct, //
        st,
        ct * ca,
        -ct * sa,
        a * st, //
        0.0,
        sa,
        ca,
        d, //
        0.0,
        0.0,
        0.0,
        1.0,
    )
}

fn pseudo_inertia(mass: f64, com: &nalgebra::Vector3<f64>, inertia_com: &Matrix3<f64>) -> Mat4 {
    let i_o =
        inertia_com + (Matrix3::identity() * com.norm_squared() - com * com.transpose()) * mass;
    let upper = Matrix3::identity() * (0.5 * i_o.trace()) - i_o;
    let mut j = Mat4::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&upper);
    j.fixed_view_mut::<3, 1>(0, 3).copy_from(&(com * mass));
    j.fixed_view_mut::<1, 3>(3, 0)
        .copy_from(&(com * mass).transpose());
    j[(3, 3)] = mass;
    j
}

impl Chain {
    fn new(robot: &Robot, q: &JointVector) -> Chain {
        let n = robot.dof();
        let mut q_mat = [Mat4::zeros(); MAX_JOINTS];
        let mut pseudo = [Mat4::zeros(); MAX_JOINTS];
        let mut local = [Mat4::identity(); MAX_JOINTS];
        for j in 0..n {
            local[j] = joint_matrix(robot, j, q[j]);
            let joint = &robot.joints()[j];
            let revolute = joint.kind == crate::JointKind::Revolute;
            let mut qm = Mat4::zeros();
            match &joint.placement {
                None if revolute => {
                    qm[(0, 1)] = -1.0;
                    qm[(1, 0)] = 1.0;
                }
                None => qm[(2, 3)] = 1.0,
                // ∂(X M(q))/∂q = X G M(q) = (X G X⁻¹) · X M(q), with G the
                // motion's generator: [a]× (revolute) or a translation (prismatic).
                Some(p) => {
                    let a = p.axis.normalize();
                    let mut g = Mat4::zeros();
                    if revolute {
                        g.fixed_view_mut::<3, 3>(0, 0).copy_from(&a.cross_matrix());
                    } else {
                        g.fixed_view_mut::<3, 1>(0, 3).copy_from(&a);
                    }
                    let x = p.origin.to_homogeneous();
                    let x_inv = Pose {
                        rotation: p.origin.rotation.transpose(),
                        translation: -(p.origin.rotation.transpose() * p.origin.translation),
                    }
                    .to_homogeneous();
                    qm = x * g * x_inv;
                }
            }
            q_mat[j] = qm;
            let b = &robot.bodies[j];
            pseudo[j] = pseudo_inertia(b.mass, &b.com, &b.inertia_com);
        }
        let mut span = [[Mat4::identity(); MAX_JOINTS + 1]; MAX_JOINTS + 1];
        for (a, row) in span.iter_mut().enumerate().take(n + 1) {
            for b in (a + 1)..=n {
                // ᵃT_b = ᵃT_{b-1} A_b; ᵃT_a stays the identity.
                row[b] = row[b - 1] * local[b - 1];
            }
        }
        let mut u_mat = [[Mat4::zeros(); MAX_JOINTS]; MAX_JOINTS];
        for (p, row) in u_mat.iter_mut().enumerate().take(n) {
            for (j, u) in row.iter_mut().enumerate().take(p + 1) {
                // U_pj = ⁰T_j Q_j ʲT_{p+1}
                *u = span[0][j] * q_mat[j] * span[j][p + 1];
            }
        }
        Chain {
            n,
            q_mat,
            span,
            pseudo,
            u_mat,
        }
    }

    /// `U_pj = ∂⁰T_{p+1}/∂q_j = ⁰T_j Q_j ʲT_{p+1}` (zero-based `j <= p`), else 0.
    fn u(&self, p: usize, j: usize) -> &Mat4 {
        &self.u_mat[p][j]
    }

    /// `U_pjk = ∂²⁰T_{p+1}/∂q_j∂q_k`: `Q` inserted at both joints in chain order.
    fn u2(&self, p: usize, j: usize, k: usize) -> Mat4 {
        if j > p || k > p {
            return Mat4::zeros();
        }
        let (lo, hi) = if j <= k { (j, k) } else { (k, j) };
        self.span[0][lo]
            * self.q_mat[lo]
            * self.span[lo][hi]
            * self.q_mat[hi]
            * self.span[hi][p + 1]
    }
}

/// `Tr(A Bᵀ)`.
fn trace_abt(a: &Mat4, b: &Mat4) -> f64 {
    a.component_mul(b).sum()
}

/// `D_ij + I_act,i δ_ij`: the mass matrix of eq. 20, rotor inertia on the diagonal.
pub fn mass_matrix(robot: &Robot, q: &JointVector) -> MassMatrix {
    let ch = Chain::new(robot, q);
    mass_matrix_of(robot, &ch)
}

fn mass_matrix_of(robot: &Robot, ch: &Chain) -> MassMatrix {
    let n = ch.n;
    let mut m = MassMatrix::zeros();
    // D_ij = Σ_{p ≥ max(i,j)} Tr(U_pj J_p U_piᵀ), summed over p outermost.
    for p in 0..n {
        for j in 0..=p {
            let uj = ch.u(p, j) * ch.pseudo[p];
            for i in 0..=p {
                m[(i, j)] += trace_abt(&uj, ch.u(p, i));
            }
        }
    }
    for i in 0..n {
        m[(i, i)] += robot.joints()[i].rotor_inertia;
    }
    m
}

/// `Σ_j Σ_k D_ijk q̇_j q̇_k`: Coriolis and centrifugal torque of eq. 20.
pub fn coriolis(robot: &Robot, q: &JointVector, qd: &JointVector) -> JointVector {
    let ch = Chain::new(robot, q);
    coriolis_of(&ch, qd)
}

fn coriolis_of(ch: &Chain, qd: &JointVector) -> JointVector {
    let n = ch.n;
    let mut tau = JointVector::zeros();
    // Σ_j Σ_k D_ijk q̇_j q̇_k with D_ijk = Σ_{p ≥ max(i,j,k)} Tr(U_pjk J_p U_piᵀ),
    // summed over p outermost; U_pjk = U_pkj, so each pair j < k counts twice.
    for p in 0..n {
        for j in 0..=p {
            for k in j..=p {
                let ujk = ch.u2(p, j, k) * ch.pseudo[p];
                let weight = if j == k {
                    qd[j] * qd[j]
                } else {
                    2.0 * qd[j] * qd[k]
                };
                for i in 0..=p {
                    tau[i] += trace_abt(&ujk, ch.u(p, i)) * weight;
                }
            }
        }
    }
    tau
}

/// `D_i = Σ_{p ≥ i} −m_p gᵀ U_pi r̄_p`: gravity torque of eq. 20.
pub fn gravity(robot: &Robot, q: &JointVector) -> JointVector {
    let ch = Chain::new(robot, q);
    gravity_of(robot, &ch)
}

fn gravity_of(robot: &Robot, ch: &Chain) -> JointVector {
    let g = robot.gravity();
    let g4 = Vector4::new(g.x, g.y, g.z, 0.0);
    let mut tau = JointVector::zeros();
    for i in 0..ch.n {
        for p in i..ch.n {
            let b = &robot.bodies[p];
            let r_bar = Vector4::new(b.com.x, b.com.y, b.com.z, 1.0);
            tau[i] += -b.mass * g4.dot(&(ch.u(p, i) * r_bar));
        }
    }
    tau
}

/// Joint torques of eq. 20 (with rotor inertia) plus the same viscous and
/// Coulomb friction as [`crate::rnea`].
pub fn torque(robot: &Robot, q: &JointVector, qd: &JointVector, qdd: &JointVector) -> JointVector {
    let ch = Chain::new(robot, q);
    let m = mass_matrix_of(robot, &ch);
    let mut tau = coriolis_of(&ch, qd) + gravity_of(robot, &ch);
    for i in 0..ch.n {
        for j in 0..ch.n {
            tau[i] += m[(i, j)] * qdd[j];
        }
        let joint = &robot.joints()[i];
        tau[i] += friction(joint.viscous_friction, joint.coulomb_friction, qd[i]);
    }
    tau
}
