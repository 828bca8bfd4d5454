//! The hot-path algorithms for robots whose joints are placed by a constant
//! transform and a unit axis ([`crate::JointPlacement`], URDF joints) instead of
//! DH rows. Frame `i` is joint `i`'s child frame:
//!
//! `⁰T_i = ⁰T_{i-1} · X_i · M_i(q_i)`, `X_i = (R_X, p_X)` the placement,
//! `M_i` = Rodrigues' rotation `c·1 + s·[a]× + (1−c)·a aᵀ` about the axis `a`
//! (revolute) or the translation `q·a` (prismatic).
//!
//! The algorithms are Featherstone's (Rigid Body Dynamics Algorithms, 2008) on
//! 3-vectors in the body frames: RNEA (ch. 5.3) with the classical acceleration
//! of each frame origin, CRBA (ch. 6.2) with the composite inertia about each
//! frame origin and the pending columns carried down the chain together. The
//! DH robots keep their specialised paths; every public entry point branches
//! here once, on `Robot::general`, outside their instruction-set dispatch (so
//! the DH builds compile exactly as before). Allocation-free like the DH paths.

use crate::data::ModelData;
use crate::dynamics::forward::{DynamicsError, factor_ldlt, solve_ldlt};
use crate::dynamics::rnea::RneaTerms;
use crate::isa::{Isa, multiversion};
use crate::math::Pose;
use crate::robot::{Robot, friction};
use crate::{Jacobian, JointVector, MAX_JOINTS, MassMatrix};
use nalgebra::{Isometry3, Matrix3, Vector3};

/// Joint values (`sin`/`cos` of revolute angles, prismatic travel) and each
/// joint's transform `X_i M_i(q_i)` into `data.local`.
#[inline(always)]
pub(crate) fn update_joint_values<S: Isa>(robot: &Robot, data: &mut ModelData, q: &JointVector) {
    let n = robot.dof.min(MAX_JOINTS);
    let mut theta = [0.0; MAX_JOINTS];
    for i in 0..n {
        if robot.placed[i].revolute {
            theta[i] = q[i];
            data.d[i] = 0.0;
        } else {
            data.d[i] = q[i];
        }
    }
    // Shared cache with the DH path: it holds sines and cosines of `theta`,
    // whatever robot the angles came from.
    let same = theta
        .iter()
        .zip(&data.theta)
        .fold(n == data.theta_dof, |same, (a, b)| {
            same & (a.to_bits() == b.to_bits())
        });
    if !same {
        data.theta = theta;
        data.theta_dof = n;
        S::sin_cos_joints(n, &theta, &mut data.sin, &mut data.cos);
    }
    for i in 0..n {
        let pc = &robot.placed[i];
        data.local[i] = if pc.revolute {
            let (c, s) = (data.cos[i], data.sin[i]);
            let a = pc.axis;
            let k = Matrix3::new(0.0, -a.z, a.y, a.z, 0.0, -a.x, -a.y, a.x, 0.0);
            let motion = Matrix3::identity() * c + k * s + pc.axis_outer * (1.0 - c);
            Pose {
                rotation: pc.rot * motion,
                translation: pc.pos,
            }
        } else {
            Pose {
                rotation: pc.rot,
                translation: pc.pos + pc.rot_axis * data.d[i],
            }
        };
    }
}

/// Every frame and the tool frame from `data.local`.
#[inline(always)]
fn update_frames(robot: &Robot, data: &mut ModelData) {
    let n = robot.dof.min(MAX_JOINTS);
    let mut frame = data.frames[0];
    for i in 0..n {
        frame = frame.compose(&data.local[i]);
        data.frames[i + 1] = frame;
    }
    data.tool = if robot.tool_is_identity {
        frame
    } else {
        frame.compose(robot.tool())
    };
}

#[inline(always)]
pub(crate) fn update_kinematics_with<S: Isa>(robot: &Robot, data: &mut ModelData, q: &JointVector) {
    update_joint_values::<S>(robot, data, q);
    update_frames(robot, data);
}

multiversion! {
    /// Forward kinematics: every frame and the tool frame for `q`, left in `data`.
    pub(crate) fn update_kinematics(robot: &Robot, data: &mut ModelData, q: &JointVector)
        => update_kinematics_with;
}

#[inline(always)]
pub(crate) fn forward_kinematics_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
) -> Isometry3<f64> {
    update_kinematics_with::<S>(robot, data, q);
    data.tool.to_isometry()
}

multiversion! {
    /// Tool pose for `q` (frames left in `data`).
    pub(crate) fn forward_kinematics(robot: &Robot, data: &mut ModelData, q: &JointVector)
        -> Isometry3<f64> => forward_kinematics_with;
}

#[inline(always)]
pub(crate) fn tool_pose_with<S: Isa>(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Pose {
    update_kinematics_with::<S>(robot, data, q);
    data.tool
}

multiversion! {
    /// Tool pose for `q` as a [`Pose`] (frames left in `data`).
    pub(crate) fn tool_pose(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Pose
        => tool_pose_with;
}

/// Geometric Jacobian of the tool origin from the frames in `data`: column `j`
/// is `[z_j × (p − o_j); z_j]` (revolute) or `[z_j; 0]` (prismatic), with
/// `z_j = ⁰R_j a_j` (the motion keeps the axis) and `o_j` frame `j`'s origin, on
/// the axis.
pub(crate) fn jacobian_from_frames(robot: &Robot, data: &ModelData) -> Jacobian {
    let mut jac = Jacobian::zeros();
    let p = data.tool.translation;
    for j in 0..robot.dof.min(MAX_JOINTS) {
        let pc = &robot.placed[j];
        let f = &data.frames[j + 1];
        let z = f.rotation * pc.axis;
        if pc.revolute {
            let v = z.cross(&(p - f.translation));
            jac.fixed_view_mut::<3, 1>(0, j).copy_from(&v);
            jac.fixed_view_mut::<3, 1>(3, j).copy_from(&z);
        } else {
            jac.fixed_view_mut::<3, 1>(0, j).copy_from(&z);
        }
    }
    jac
}

#[inline(always)]
pub(crate) fn jacobian_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
) -> Jacobian {
    update_kinematics_with::<S>(robot, data, q);
    jacobian_from_frames(robot, data)
}

multiversion! {
    /// Forward kinematics, then the Jacobian.
    pub(crate) fn jacobian(robot: &Robot, data: &mut ModelData, q: &JointVector) -> Jacobian
        => jacobian_with;
}

/// RNEA on the joint values in `data` (`update_joint_values`).
///
/// Forward pass in frame `i` (`R`, `p` = `data.local[i]`): angular velocity
/// `w_i = Rᵀ w_{i-1} + a q̇`, acceleration `ẇ_i = Rᵀ ẇ_{i-1} + (Rᵀ w_{i-1}) × a q̇ + a q̈`,
/// origin acceleration minus gravity `α_i = Rᵀ(α_{i-1} + ẇ_{i-1} × p + w_{i-1} × (w_{i-1} × p))`
/// (prismatic: `+ 2 w_i × a q̇ + a q̈`, and no change to `w`, `ẇ`). Body wrench about
/// the origin: `f = m α + ẇ × h + w × (w × h)`, `n = I_O ẇ + w × (I_O w) + h × α`.
/// Backward pass: `τ_i = a·n_i` (or `a·f_i`), and `f`, `n + p × f` rotated into
/// frame `i-1` are added to the parent's wrench.
#[inline(always)]
fn rnea_from_joint_values(
    robot: &Robot,
    data: &mut ModelData,
    qd: &JointVector,
    qdd: &JointVector,
    terms: RneaTerms,
) -> JointVector {
    let n = robot.dof.min(MAX_JOINTS);
    let mut w = Vector3::zeros();
    let mut wd = Vector3::zeros();
    let mut acc = if terms.gravity {
        -robot.gravity()
    } else {
        Vector3::zeros()
    };
    for i in 0..n {
        let pc = &robot.placed[i];
        let local = &data.local[i];
        let rt = local.rotation.transpose();
        let p = local.translation;
        let acc_parent = acc + wd.cross(&p) + w.cross(&w.cross(&p));
        acc = rt * acc_parent;
        let wp = rt * w;
        let wdp = rt * wd;
        let axis_qd = pc.axis * qd[i];
        if pc.revolute {
            w = wp + axis_qd;
            wd = wdp + wp.cross(&axis_qd) + pc.axis * qdd[i];
        } else {
            w = wp;
            wd = wdp;
            acc += w.cross(&axis_qd) * 2.0 + pc.axis * qdd[i];
        }
        let b = &robot.bodies[i];
        data.force[i] = acc * b.mass + wd.cross(&b.h) + w.cross(&w.cross(&b.h));
        data.moment[i] = b.inertia_origin * wd + w.cross(&(b.inertia_origin * w)) + b.h.cross(&acc);
    }
    let mut tau = JointVector::zeros();
    let mut f_child = Vector3::zeros();
    let mut n_child = Vector3::zeros();
    for i in (0..n).rev() {
        let pc = &robot.placed[i];
        let f = data.force[i] + f_child;
        let m = data.moment[i] + n_child;
        let t = if pc.revolute {
            pc.axis.dot(&m)
        } else {
            pc.axis.dot(&f)
        };
        let mut extra = pc.rotor * qdd[i];
        if terms.friction {
            extra += friction(pc.viscous, pc.coulomb, qd[i]);
        }
        tau[i] = t + extra;
        let local = &data.local[i];
        f_child = local.rotation * f;
        n_child = local.rotation * m + local.translation.cross(&f_child);
    }
    tau
}

const ALL: RneaTerms = RneaTerms {
    gravity: true,
    friction: true,
};

#[inline(always)]
pub(crate) fn rnea_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
    qdd: &JointVector,
) -> JointVector {
    update_joint_values::<S>(robot, data, q);
    rnea_from_joint_values(robot, data, qd, qdd, ALL)
}

#[inline(always)]
pub(crate) fn nonlinear_effects_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
) -> JointVector {
    update_joint_values::<S>(robot, data, q);
    rnea_from_joint_values(robot, data, qd, &JointVector::zeros(), ALL)
}

#[inline(always)]
pub(crate) fn gravity_torque_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
) -> JointVector {
    update_joint_values::<S>(robot, data, q);
    let zero = JointVector::zeros();
    let terms = RneaTerms {
        gravity: true,
        friction: false,
    };
    rnea_from_joint_values(robot, data, &zero, &zero, terms)
}

#[inline(always)]
pub(crate) fn coriolis_torque_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
) -> JointVector {
    update_joint_values::<S>(robot, data, q);
    let terms = RneaTerms {
        gravity: false,
        friction: false,
    };
    rnea_from_joint_values(robot, data, qd, &JointVector::zeros(), terms)
}

multiversion! {
    /// Inverse dynamics, every term.
    pub(crate) fn rnea(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
        qdd: &JointVector,
    ) -> JointVector => rnea_with;
}

multiversion! {
    /// `C(q, qd) qd + g(q) + friction(qd)`.
    pub(crate) fn nonlinear_effects(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
    ) -> JointVector => nonlinear_effects_with;
}

multiversion! {
    /// `g(q)`.
    pub(crate) fn gravity_torque(robot: &Robot, data: &mut ModelData, q: &JointVector)
        -> JointVector => gravity_torque_with;
}

multiversion! {
    /// `C(q, qd) qd`.
    pub(crate) fn coriolis_torque(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
    ) -> JointVector => coriolis_torque_with;
}

/// CRBA on the joint values in `data`; result in `data.mass`.
///
/// From the tip to the base, the composite of bodies `i..n` (mass `m`, first
/// moment `h`, inertia `I` about frame `i`'s origin) gives joint `i`'s column:
/// unit motion about `a` needs the force `a × h` and moment `I a` (prismatic:
/// `m a`, `h × a`), `M_ii` is its component along `a`. The columns `j ≥ i` are
/// then carried into frame `i-1` (`f ↦ R f`, `n ↦ R n + p × R f`), where joint
/// `i-1` reads `M_{i-1,j}`; the composite moves with the parallel-axis shift
/// `I ↦ R I Rᵀ + 2(h'·p) 1 − (h' pᵀ + p h'ᵀ) + m(|p|² 1 − p pᵀ)`, `h' = R h`.
#[inline(always)]
fn mass_matrix_from_joint_values(robot: &Robot, data: &mut ModelData) {
    let n = robot.dof.min(MAX_JOINTS);
    let mass = &mut data.mass;
    *mass = MassMatrix::zeros();
    let mut m = 0.0;
    let mut h = Vector3::zeros();
    let mut inertia = Matrix3::zeros();
    let mut col_force = [Vector3::zeros(); MAX_JOINTS];
    let mut col_moment = [Vector3::zeros(); MAX_JOINTS];
    for i in (0..n).rev() {
        let pc = &robot.placed[i];
        let b = &robot.bodies[i];
        m += b.mass;
        h += b.h;
        inertia += b.inertia_origin;
        let a = pc.axis;
        let (force, moment) = if pc.revolute {
            (a.cross(&h), inertia * a)
        } else {
            (a * m, h.cross(&a))
        };
        col_force[i] = force;
        col_moment[i] = moment;
        for j in i..n {
            let mij = if pc.revolute {
                a.dot(&col_moment[j])
            } else {
                a.dot(&col_force[j])
            };
            mass[(i, j)] = mij;
            mass[(j, i)] = mij;
        }
        mass[(i, i)] += pc.rotor;
        if i == 0 {
            break;
        }
        let local = &data.local[i];
        let (r, p) = (&local.rotation, &local.translation);
        for j in i..n {
            let f = r * col_force[j];
            col_moment[j] = r * col_moment[j] + p.cross(&f);
            col_force[j] = f;
        }
        let hr = r * h;
        let ir = r * inertia * r.transpose();
        let hp = hr.dot(p);
        let pp = p.norm_squared();
        inertia = ir + Matrix3::identity() * (2.0 * hp + m * pp)
            - (hr * p.transpose() + p * hr.transpose())
            - p * p.transpose() * m;
        h = hr + p * m;
    }
}

#[inline(always)]
pub(crate) fn mass_matrix_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
) -> MassMatrix {
    update_joint_values::<S>(robot, data, q);
    mass_matrix_from_joint_values(robot, data);
    data.mass
}

multiversion! {
    /// Joint-space mass matrix for `q` (rotor inertia on the diagonal).
    pub(crate) fn mass_matrix(robot: &Robot, data: &mut ModelData, q: &JointVector) -> MassMatrix
        => mass_matrix_with;
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
            for i in 0..robot.dof.min(MAX_JOINTS) {
                nan[i] = f64::NAN;
            }
            nan
        }
    }
}

multiversion! {
    /// `M(q)⁻¹ (tau − h(q, qd))`, NaN where `M` is singular.
    pub(crate) fn forward_dynamics(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
        tau: &JointVector,
    ) -> JointVector => forward_dynamics_with;
}

multiversion! {
    /// `M(q)⁻¹ (tau − h(q, qd))` by `L D Lᵀ`, a singular `M` as an error.
    pub(crate) fn try_forward_dynamics(
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
    let n = robot.dof.min(MAX_JOINTS);
    update_joint_values::<S>(robot, data, q);
    mass_matrix_from_joint_values(robot, data);
    let mut a = data.mass.data.0;
    let inv_pivot = factor_ldlt(n, &mut a)?;
    let terms = RneaTerms {
        gravity: true,
        friction: true,
    };
    let h = rnea_from_joint_values(robot, data, qd, &JointVector::zeros(), terms);
    let mut x = [0.0; MAX_JOINTS];
    for i in 0..n {
        x[i] = tau[i] - h[i];
    }
    solve_ldlt(n, &a, &inv_pivot, &mut x);
    let mut qdd = JointVector::zeros();
    for i in 0..n {
        qdd[i] = x[i];
    }
    Ok(qdd)
}
