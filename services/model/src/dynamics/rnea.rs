//! Recursive Newton-Euler inverse dynamics in DH link frames: velocities and
//! accelerations outward from the base, forces and moments inward from the tip.

use crate::JointVector;
use crate::data::ModelData;
use crate::kinematics::update_joint_values;
use crate::math::{joint_rot, joint_rot_t};
use crate::robot::{Robot, friction};
use nalgebra::Vector3;

/// Which terms of the equation of motion [`rnea_from_joint_values`] includes.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RneaTerms {
    pub gravity: bool,
    pub friction: bool,
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
    update_joint_values(robot, data, q);
    rnea_from_joint_values(
        robot,
        data,
        qd,
        qdd,
        RneaTerms {
            gravity: true,
            friction: true,
        },
    )
}

/// `h(q, qd) = C(q, qd) qd + g(q) + friction(qd)`: the torque needed for zero
/// acceleration.
pub fn nonlinear_effects(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
) -> JointVector {
    update_joint_values(robot, data, q);
    rnea_from_joint_values(
        robot,
        data,
        qd,
        &JointVector::zeros(),
        RneaTerms {
            gravity: true,
            friction: true,
        },
    )
}

/// Gravity torque `g(q)` (the seed's `D_i`, eq. 20).
pub fn gravity_torque(robot: &Robot, data: &mut ModelData, q: &JointVector) -> JointVector {
    update_joint_values(robot, data, q);
    let zero = JointVector::zeros();
    rnea_from_joint_values(
        robot,
        data,
        &zero,
        &zero,
        RneaTerms {
            gravity: true,
            friction: false,
        },
    )
}

/// Coriolis and centrifugal torque `C(q, qd) qd` alone (no gravity, no friction;
/// the seed's `Σ D_ijk qd_j qd_k`, eq. 20).
pub fn coriolis_torque(
    robot: &Robot,
    data: &mut ModelData,
    q: &JointVector,
    qd: &JointVector,
) -> JointVector {
    update_joint_values(robot, data, q);
    rnea_from_joint_values(
        robot,
        data,
        qd,
        &JointVector::zeros(),
        RneaTerms {
            gravity: false,
            friction: false,
        },
    )
}

/// RNEA on joint values already evaluated into `data` (`cos`, `sin`, `d`).
///
/// Forward pass in frame `i` (origin `O_i`, `p*` = `O_i` from `O_{i-1}` in frame
/// `i` = `(a, d sα, d cα)`, `z = Rᵀ ẑ = (0, sα, cα)`): angular velocity `w`,
/// angular acceleration `wd`, linear acceleration `acc` of `O_i` minus gravity;
/// body wrench about `O_i` with first moment `h = m c` and inertia `I_O`:
/// `f = m acc + wd×h + w×(w×h)`, `n = I_O wd + w×(I_O w) + h×acc`.
/// Backward pass: moment about `O_{i-1}` is `n_i + p*×f_i`; its `z` component is
/// the torque of a revolute joint, `f_i·z` the force of a prismatic one.
#[inline]
pub(crate) fn rnea_from_joint_values(
    robot: &Robot,
    data: &mut ModelData,
    qd: &JointVector,
    qdd: &JointVector,
    terms: RneaTerms,
) -> JointVector {
    let n = robot.dof;
    let mut w = Vector3::zeros();
    let mut wd = Vector3::zeros();
    let mut acc = if terms.gravity {
        -robot.gravity()
    } else {
        Vector3::zeros()
    };
    for i in 0..n {
        let jc = &robot.consts[i];
        let (c, s, d) = (data.cos[i], data.sin[i], data.d[i]);
        let pstar = Vector3::new(jc.a, d * jc.sa, d * jc.ca);
        let (dq, ddq) = (qd[i], qdd[i]);
        if jc.revolute {
            let wp = Vector3::new(w.x, w.y, w.z + dq);
            let wdp = Vector3::new(wd.x + w.y * dq, wd.y - w.x * dq, wd.z + ddq);
            w = joint_rot_t(jc, c, s, &wp);
            wd = joint_rot_t(jc, c, s, &wdp);
            acc = joint_rot_t(jc, c, s, &acc);
            if jc.offset {
                acc += wd.cross(&pstar) + w.cross(&w.cross(&pstar));
            }
        } else {
            let z = Vector3::new(0.0, jc.sa, jc.ca);
            w = joint_rot_t(jc, c, s, &w);
            wd = joint_rot_t(jc, c, s, &wd);
            acc = joint_rot_t(jc, c, s, &acc)
                + z * ddq
                + wd.cross(&pstar)
                + w.cross(&z) * (2.0 * dq)
                + w.cross(&w.cross(&pstar));
        }
        let b = &robot.bodies[i];
        let (iw, iwd) = match &b.diagonal_inertia {
            Some(diag) => (diag.component_mul(&w), diag.component_mul(&wd)),
            None => (b.inertia_origin * w, b.inertia_origin * wd),
        };
        if b.has_h {
            data.force[i] = acc * b.mass + wd.cross(&b.h) + w.cross(&w.cross(&b.h));
            data.moment[i] = iwd + w.cross(&iw) + b.h.cross(&acc);
        } else {
            data.force[i] = acc * b.mass;
            data.moment[i] = iwd + w.cross(&iw);
        }
    }
    let mut tau = JointVector::zeros();
    let mut f_child = Vector3::zeros();
    let mut n_child = Vector3::zeros();
    for i in (0..n).rev() {
        let jc = &robot.consts[i];
        let (c, s, d) = (data.cos[i], data.sin[i], data.d[i]);
        let pstar = Vector3::new(jc.a, d * jc.sa, d * jc.ca);
        let f = data.force[i] + f_child;
        let mut m = data.moment[i] + n_child;
        if jc.offset {
            m += pstar.cross(&f);
        }
        let t = if jc.revolute {
            jc.sa * m.y + jc.ca * m.z
        } else {
            jc.sa * f.y + jc.ca * f.z
        };
        let mut extra = jc.rotor * qdd[i];
        if terms.friction {
            extra += friction(jc.viscous, jc.coulomb, qd[i]);
        }
        tau[i] = t + extra;
        f_child = joint_rot(jc, c, s, &f);
        n_child = joint_rot(jc, c, s, &m);
    }
    tau
}
