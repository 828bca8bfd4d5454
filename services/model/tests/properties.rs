//! Property tests on random serial chains (1–8 joints, revolute and prismatic,
//! random DH offsets, SPD inertias, friction, tool and payload) and random states.
#![allow(clippy::needless_range_loop)] // index loops read like the matrix formulas

mod common;

use common::{build, jv, robot_spec, scale, state};
use microrobot_model::{
    JointVector, ModelData, coriolis_torque, forward_dynamics, gravity_torque, jacobian,
    lagrange_euler, mass_matrix, nonlinear_effects, rnea, tool_pose,
};
use nalgebra::DMatrix;
use proptest::prelude::*;

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: 48,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn mass_matrix_is_symmetric_positive_definite(spec in robot_spec(8), (q, _, _) in state()) {
        let robot = build(&spec);
        let mut data = ModelData::new(&robot);
        let n = robot.dof();
        let m = mass_matrix(&robot, &mut data, &jv(&robot, &q, true));
        let block = DMatrix::from_fn(n, n, |r, c| m[(r, c)]);
        let big = block.abs().max();
        prop_assert!((&block - block.transpose()).abs().max() <= 1e-12 * big);
        let eig = nalgebra::SymmetricEigen::new(block).eigenvalues;
        prop_assert!(eig.min() > 0.0, "eigenvalues {eig}");
        for r in 0..8 {
            for c in 0..8 {
                if r >= n || c >= n {
                    prop_assert_eq!(m[(r, c)], 0.0);
                }
            }
        }
    }

    #[test]
    fn inverse_dynamics_at_rest_is_gravity(spec in robot_spec(8), (q, _, _) in state()) {
        let robot = build(&spec);
        let mut data = ModelData::new(&robot);
        let q = jv(&robot, &q, true);
        let zero = JointVector::zeros();
        let tau = rnea(&robot, &mut data, &q, &zero, &zero);
        let g = gravity_torque(&robot, &mut data, &q);
        let tol = 1e-12 * (1.0 + scale(&g, robot.dof()));
        prop_assert!((tau - g).amax() <= tol, "rnea {tau} gravity {g}");
    }

    #[test]
    fn forward_dynamics_inverts_inverse_dynamics(spec in robot_spec(8), (q, qd, qdd) in state()) {
        let robot = build(&spec);
        let mut data = ModelData::new(&robot);
        let (q, qd, qdd) = (jv(&robot, &q, true), jv(&robot, &qd, false), jv(&robot, &qdd, false));
        let tau = rnea(&robot, &mut data, &q, &qd, &qdd);
        let back = forward_dynamics(&robot, &mut data, &q, &qd, &tau);
        let m = mass_matrix(&robot, &mut data, &q);
        let n = robot.dof();
        let cond = {
            let block = DMatrix::from_fn(n, n, |r, c| m[(r, c)]);
            let e = nalgebra::SymmetricEigen::new(block).eigenvalues;
            e.max() / e.min()
        };
        let tol = 1e-13 * cond * (1.0 + scale(&qdd, n));
        prop_assert!((back - qdd).amax() <= tol.max(1e-10), "qdd {qdd} back {back} cond {cond:e}");
    }

    #[test]
    fn mass_matrix_columns_equal_rnea_differences(spec in robot_spec(8), (q, _, _) in state()) {
        let robot = build(&spec);
        let mut data = ModelData::new(&robot);
        let q = jv(&robot, &q, true);
        let m = mass_matrix(&robot, &mut data, &q);
        let zero = JointVector::zeros();
        let g = rnea(&robot, &mut data, &q, &zero, &zero);
        for j in 0..robot.dof() {
            let mut e = JointVector::zeros();
            e[j] = 1.0;
            let col = rnea(&robot, &mut data, &q, &zero, &e) - g;
            let tol = 1e-10 * (1.0 + m.column(j).amax() + g.amax());
            prop_assert!((col - m.column(j)).amax() <= tol, "column {j}");
        }
    }

    #[test]
    fn jacobian_equals_finite_differences_of_fk(spec in robot_spec(8), (q, _, _) in state()) {
        let robot = build(&spec);
        let mut data = ModelData::new(&robot);
        let q = jv(&robot, &q, true);
        let jac = jacobian(&robot, &mut data, &q);
        let h = 1e-6;
        for j in 0..robot.dof() {
            let (mut qp, mut qm) = (q, q);
            qp[j] += h;
            qm[j] -= h;
            let pp = tool_pose(&robot, &mut data, &qp);
            let pm = tool_pose(&robot, &mut data, &qm);
            let v = (pp.translation - pm.translation) / (2.0 * h);
            // Small rotation dR ≈ 1 + [θ]×: θ from its skew part (acos of the trace
            // would lose half the digits at this size).
            let dr = pp.rotation * pm.rotation.transpose();
            let w = nalgebra::Vector3::new(dr[(2, 1)] - dr[(1, 2)], dr[(0, 2)] - dr[(2, 0)], dr[(1, 0)] - dr[(0, 1)])
                / (4.0 * h);
            for r in 0..3 {
                prop_assert!((jac[(r, j)] - v[r]).abs() < 1e-6, "linear [{r}][{j}]: {} vs {}", jac[(r, j)], v[r]);
                prop_assert!((jac[(r + 3, j)] - w[r]).abs() < 1e-6, "angular [{r}][{j}]: {} vs {}", jac[(r + 3, j)], w[r]);
            }
        }
        for c in robot.dof()..8 {
            prop_assert!(jac.column(c).iter().all(|x| *x == 0.0));
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    #[test]
    fn lagrange_euler_equals_newton_euler(spec in robot_spec(7), (q, qd, qdd) in state()) {
        let robot = build(&spec);
        let mut data = ModelData::new(&robot);
        let n = robot.dof();
        let (q, qd, qdd) = (jv(&robot, &q, true), jv(&robot, &qd, false), jv(&robot, &qdd, false));
        let close = |a: &JointVector, b: &JointVector| {
            let tol = 1e-10 * (1.0 + scale(b, n));
            (a - b).amax() <= tol
        };
        let ne = rnea(&robot, &mut data, &q, &qd, &qdd);
        let le = lagrange_euler::torque(&robot, &q, &qd, &qdd);
        prop_assert!(close(&le, &ne), "tau LE {le} NE {ne}");
        let g_ne = gravity_torque(&robot, &mut data, &q);
        let g_le = lagrange_euler::gravity(&robot, &q);
        prop_assert!(close(&g_le, &g_ne), "gravity LE {g_le} NE {g_ne}");
        let c_ne = coriolis_torque(&robot, &mut data, &q, &qd);
        let c_le = lagrange_euler::coriolis(&robot, &q, &qd);
        prop_assert!(close(&c_le, &c_ne), "coriolis LE {c_le} NE {c_ne}");
        let m_ne = mass_matrix(&robot, &mut data, &q);
        let m_le = lagrange_euler::mass_matrix(&robot, &q);
        prop_assert!((m_le - m_ne).amax() <= 1e-10 * (1.0 + m_ne.amax()), "M LE {m_le} NE {m_ne}");
        // h = C qd + g + friction
        let h = nonlinear_effects(&robot, &mut data, &q, &qd);
        let zero = JointVector::zeros();
        prop_assert!(close(&h, &rnea(&robot, &mut data, &q, &qd, &zero)));
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// `ModelData` keeps the last joint angles' sine and cosine for the next call
    /// at the same angles: shared between two robots and between calls at the
    /// same and at other states, it must give exactly what fresh scratch gives.
    #[test]
    fn reused_scratch_gives_what_fresh_scratch_gives(
        a in robot_spec(8),
        b in robot_spec(8),
        (q, qd, qdd) in state(),
    ) {
        let (ra, rb) = (build(&a), build(&b));
        let mut shared = ModelData::new(&ra);
        for round in 0..2 {
            for robot in [&ra, &rb, &rb, &ra] {
                let (q, qd, qdd) = (jv(robot, &q, true), jv(robot, &qd, false), jv(robot, &qdd, false));
                let q = if round == 0 { q } else { q * 0.5 };
                let mut fresh = ModelData::new(robot);
                prop_assert_eq!(
                    tool_pose(robot, &mut shared, &q),
                    tool_pose(robot, &mut fresh, &q)
                );
                prop_assert_eq!(
                    rnea(robot, &mut shared, &q, &qd, &qdd),
                    rnea(robot, &mut ModelData::new(robot), &q, &qd, &qdd)
                );
                prop_assert_eq!(
                    mass_matrix(robot, &mut shared, &q),
                    mass_matrix(robot, &mut ModelData::new(robot), &q)
                );
            }
        }
    }
}
