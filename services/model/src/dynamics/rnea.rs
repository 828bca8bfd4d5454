//! Recursive Newton-Euler inverse dynamics in DH link frames: velocities and
//! accelerations outward from the base, forces and moments inward from the tip.

use crate::data::ModelData;
use crate::isa::{Isa, for_shape, multiversion};
use crate::kinematics::update_joint_values;
use crate::math::{cross_sparse, joint_rot, joint_rot_t, point_accel};
use crate::robot::{Robot, Sparsity, Twist, friction};
use crate::{JointVector, MAX_JOINTS};
use nalgebra::Vector3;

/// Which terms of the equation of motion [`rnea_from_joint_values`] includes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RneaTerms {
    pub gravity: bool,
    pub friction: bool,
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
    for_shape!(robot, |n, plain| {
        update_joint_values::<S>(robot, data, q, n, plain);
        rnea_from_joint_values(robot, data, qd, qdd, ALL, n, plain)
    })
}

#[inline(always)]
pub(crate) fn nonlinear_effects_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
) -> JointVector {
    for_shape!(robot, |n, plain| {
        update_joint_values::<S>(robot, data, q, n, plain);
        rnea_from_joint_values(robot, data, qd, &JointVector::zeros(), ALL, n, plain)
    })
}

#[inline(always)]
pub(crate) fn gravity_torque_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
) -> JointVector {
    for_shape!(robot, |n, plain| {
        update_joint_values::<S>(robot, data, q, n, plain);
        let zero = JointVector::zeros();
        let terms = RneaTerms {
            gravity: true,
            friction: false,
        };
        rnea_from_joint_values(robot, data, &zero, &zero, terms, n, plain)
    })
}

#[inline(always)]
pub(crate) fn coriolis_torque_with<S: Isa>(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
) -> JointVector {
    for_shape!(robot, |n, plain| {
        update_joint_values::<S>(robot, data, q, n, plain);
        let terms = RneaTerms {
            gravity: false,
            friction: false,
        };
        rnea_from_joint_values(robot, data, qd, &JointVector::zeros(), terms, n, plain)
    })
}

multiversion! {
    /// [`rnea`] for DH robots.
    #[inline(always)]
    fn rnea_dh(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
        qdd: &JointVector,
    ) -> JointVector => rnea_with;
}

/// Joint torques for the full equation of motion (see [`crate::dynamics`]):
/// rigid bodies including the payload, gravity, rotor inertia `I_rotor·qdd`,
/// viscous and Coulomb friction. Allocation-free.
pub fn rnea(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
    qdd: &JointVector,
) -> JointVector {
    if robot.general {
        crate::general::rnea(robot, data, q, qd, qdd)
    } else {
        rnea_dh(robot, data, q, qd, qdd)
    }
}

multiversion! {
    /// [`nonlinear_effects`] for DH robots.
    #[inline(always)]
    fn nonlinear_effects_dh(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
    ) -> JointVector => nonlinear_effects_with;
}

/// `h(q, qd) = C(q, qd) qd + g(q) + friction(qd)`: the torque needed for zero
/// acceleration.
pub fn nonlinear_effects(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
) -> JointVector {
    if robot.general {
        crate::general::nonlinear_effects(robot, data, q, qd)
    } else {
        nonlinear_effects_dh(robot, data, q, qd)
    }
}

multiversion! {
    /// [`gravity_torque`] for DH robots.
    #[inline(always)]
    fn gravity_torque_dh(robot: &Robot, data: &mut ModelData, q: &JointVector) -> JointVector => gravity_torque_with;
}

/// Gravity torque `g(q)` (the seed's `D_i`, eq. 20).
pub fn gravity_torque(robot: &Robot, data: &mut ModelData, q: &JointVector) -> JointVector {
    if robot.general {
        crate::general::gravity_torque(robot, data, q)
    } else {
        gravity_torque_dh(robot, data, q)
    }
}

multiversion! {
    /// [`coriolis_torque`] for DH robots.
    #[inline(always)]
    fn coriolis_torque_dh(
        robot: &Robot,
        data: &mut ModelData,
        q: &JointVector,
        qd: &JointVector,
    ) -> JointVector => coriolis_torque_with;
}

/// Coriolis and centrifugal torque `C(q, qd) qd` alone (no gravity, no friction;
/// the seed's `Σ D_ijk qd_j qd_k`, eq. 20).
pub fn coriolis_torque(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
) -> JointVector {
    if robot.general {
        crate::general::coriolis_torque(robot, data, q, qd)
    } else {
        coriolis_torque_dh(robot, data, q, qd)
    }
}

/// RNEA on joint values already evaluated into `data` (`cos`, `sin`, `d`); `plain`
/// is `robot.plain` (a constant where the caller is specialised by `for_shape!`).
///
/// Forward pass in frame `i` (origin `O_i`, `p*` = `O_i` from `O_{i-1}` in frame
/// `i` = `(a, d sα, d cα)`, `z = Rᵀ ẑ = (0, sα, cα)`): angular velocity `w`,
/// angular acceleration `wd`, linear acceleration `acc` of `O_i` minus gravity;
/// body wrench about `O_i` with first moment `h = m c` and inertia `I_O`:
/// `f = m acc + wd×h + w×(w×h)`, `n = I_O wd + w×(I_O w) + h×acc`.
/// Backward pass: moment about `O_{i-1}` is `n_i + p*×f_i`; its `z` component is
/// the torque of a revolute joint, `f_i·z` the force of a prismatic one.
#[inline(always)]
pub(crate) fn rnea_from_joint_values(
    robot: &Robot,
    data: &mut ModelData,
    qd: &JointVector,
    qdd: &JointVector,
    terms: RneaTerms,
    n: usize,
    plain: bool,
) -> JointVector {
    let n = n.min(MAX_JOINTS);
    let mut w = Vector3::zeros();
    let mut wd = Vector3::zeros();
    let mut acc = if terms.gravity {
        -robot.gravity()
    } else {
        Vector3::zeros()
    };
    for i in 0..n {
        let jc = &robot.consts[i];
        let (c, s) = (data.cos[i], data.sin[i]);
        let (dq, ddq) = (qd[i], qdd[i]);
        if plain || jc.revolute {
            let wp = Vector3::new(w.x, w.y, w.z + dq);
            let wdp = Vector3::new(wd.x + w.y * dq, wd.y - w.x * dq, wd.z + ddq);
            w = joint_rot_t(jc, c, s, &wp);
            wd = joint_rot_t(jc, c, s, &wdp);
            acc = joint_rot_t(jc, c, s, &acc);
            if jc.pstar_kind != Sparsity::Zero {
                acc += point_accel(&w, &wd, &jc.pstar, jc.pstar_kind);
            }
        } else {
            let d = data.d[i];
            let pstar = Vector3::new(jc.a, d * jc.sa, d * jc.ca);
            let z = Vector3::new(0.0, jc.sa, jc.ca);
            w = joint_rot_t(jc, c, s, &w);
            wd = joint_rot_t(jc, c, s, &wd);
            acc = joint_rot_t(jc, c, s, &acc)
                + z * ddq
                + w.cross(&z) * (2.0 * dq)
                + point_accel(&w, &wd, &pstar, Sparsity::General);
        }
        let b = &robot.bodies[i];
        let (iw, iwd) = if plain || b.diagonal {
            (
                b.inertia_diag.component_mul(&w),
                b.inertia_diag.component_mul(&wd),
            )
        } else {
            (b.inertia_origin * w, b.inertia_origin * wd)
        };
        if b.h_kind == Sparsity::Zero {
            data.force[i] = acc * b.mass;
            data.moment[i] = iwd + w.cross(&iw);
        } else {
            // h × acc = −(acc × h)
            data.force[i] = acc * b.mass + point_accel(&w, &wd, &b.h, b.h_kind);
            data.moment[i] = iwd + w.cross(&iw) - cross_sparse(&acc, &b.h, b.h_kind);
        }
    }
    let mut tau = JointVector::zeros();
    let mut f_child = Vector3::zeros();
    let mut n_child = Vector3::zeros();
    for i in (0..n).rev() {
        let jc = &robot.consts[i];
        let (c, s) = (data.cos[i], data.sin[i]);
        let f = data.force[i] + f_child;
        // Moment about O_{i-1}: + p* × f = − f × p*.
        let m = if plain || jc.revolute {
            let m = data.moment[i] + n_child;
            if jc.pstar_kind == Sparsity::Zero {
                m
            } else {
                m - cross_sparse(&f, &jc.pstar, jc.pstar_kind)
            }
        } else {
            let d = data.d[i];
            let pstar = Vector3::new(jc.a, d * jc.sa, d * jc.ca);
            data.moment[i] + n_child - f.cross(&pstar)
        };
        // Joint axis z_{i-1} in frame i is (0, sα, cα).
        let along_axis = |v: &Vector3<f64>| match jc.twist {
            Twist::Zero => v.z,
            Twist::PlusQuarter => v.y,
            Twist::MinusQuarter => -v.y,
            Twist::General => jc.sa * v.y + jc.ca * v.z,
        };
        let t = if plain || jc.revolute {
            along_axis(&m)
        } else {
            along_axis(&f)
        };
        let mut extra = jc.rotor * qdd[i];
        if !plain && terms.friction && (jc.viscous != 0.0 || jc.coulomb != 0.0) {
            extra += friction(jc.viscous, jc.coulomb, qd[i]);
        }
        tau[i] = t + extra;
        f_child = joint_rot(jc, c, s, &f);
        n_child = joint_rot(jc, c, s, &m);
    }
    tau
}
